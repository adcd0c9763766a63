"""Overlays of the real-capture cases (tests/data/real_cases): for every case and view, the view
cropped around the stroke with the stroke (green), the pixel path (red), the rod (blue) and the
bound Gaussians (yellow), as `sketchrodgs extract --overlay` draws them, so a person can check the
strokes and what extraction made of them.

    python benches/real_case_overlays.py OUT_DIR [--case NAME ...] [--gallery docs/gallery/real_cases.png]
    python benches/real_case_overlays.py OUT_DIR --turned [--view CASE/SOURCE/TURN ...] [--gallery G.png]
    python benches/real_case_overlays.py OUT_DIR --held-out [--case NAME ...] [--gallery G.png]
    python benches/real_case_overlays.py OUT_DIR --second-held-out [--case NAME ...] [--gallery G.png]
    python benches/real_case_overlays.py OUT_DIR --third-held-out [--case NAME ...] [--gallery G.png]

`--gallery` also writes one picture of the first view of each named case side by side (with
`--turned`: of every turned view drawn). `--turned` draws the turned views
(tests/data/real_cases/turned_views.json) with R estimated, as a user who gives no radius gets them.
`--held-out` draws the held-out cases (tests/data/real_cases/heldout_cases.json) instead of the cases,
`--second-held-out` the second held-out cases (heldout2_cases.json), `--third-held-out` the third
(heldout3_cases.json).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from sketchrodgs import Camera, realcases, render
from sketchrodgs.errors import PathNotFoundError
from sketchrodgs.extract import extract_rod
from sketchrodgs.images import draw_overlay, save_png

CASES = Path(__file__).parent.parent / "tests" / "data" / "real_cases" / "cases.json"
TURNED = CASES.parent / "turned_views.json"
HELD_OUT = CASES.parent / "heldout_cases.json"
SECOND_HELD_OUT = CASES.parent / "heldout2_cases.json"
THIRD_HELD_OUT = CASES.parent / "heldout3_cases.json"
MARGIN_PX = 40
ZOOM = 2


def case_view_overlay(scene, case: dict, view: dict, radius_given: bool = True) -> tuple[Image.Image, str]:
    """The cropped, zoomed overlay of one view and a one-line summary."""
    camera = Camera.from_dict(view["camera"], view["name"])
    stroke = np.asarray(view["stroke"], np.float64)
    images = render(scene, camera, background=(1.0, 1.0, 1.0))
    label = f"{case['name']} / {view['name']}"
    try:
        ex = extract_rod(scene, camera, stroke, radius=case["radius"] if radius_given else None, render=images)
        image = draw_overlay(images.rgb, camera, stroke, ex.pixel_path, ex.polyline, scene.means[ex.gaussian_ids])
        summary = f"{len(ex.polyline)} vertices, {len(ex.gaussian_ids):,} Gaussians, coverage {ex.coverage:.2f}"
        if not radius_given:
            label += f" (R est. {ex.radius / case['radius']:.2f} R)"
    except PathNotFoundError as err:
        image = draw_overlay(
            images.rgb, camera, stroke, getattr(err, "pixel_path", []), stops=getattr(err, "lost_at", [])
        )
        summary = f"failed: {err}"
    low = np.maximum(stroke.min(axis=0) - MARGIN_PX, 0).astype(int)
    high = np.minimum(stroke.max(axis=0) + MARGIN_PX, [camera.width, camera.height]).astype(int)
    crop = image.crop((*low, *high))
    crop = crop.resize((crop.width * ZOOM, crop.height * ZOOM), Image.LANCZOS)
    ImageDraw.Draw(crop).text((4, 4), label, fill=(255, 255, 255))
    return crop, summary


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--case", action="append", help="only this case (repeatable)")
    parser.add_argument("--gallery", type=Path, help="also write the first views of these cases side by side")
    parser.add_argument("--turned", action="store_true", help="draw the turned views, R estimated")
    parser.add_argument("--view", action="append", help="with --turned: only this CASE/SOURCE/TURN (repeatable)")
    parser.add_argument("--held-out", action="store_true", help="draw the held-out cases instead of the cases")
    parser.add_argument("--second-held-out", action="store_true", help="draw the second held-out cases")
    parser.add_argument("--third-held-out", action="store_true", help="draw the third held-out cases")
    args = parser.parse_args()
    scenes, cases = realcases.load_cases(
        THIRD_HELD_OUT
        if args.third_held_out
        else SECOND_HELD_OUT
        if args.second_held_out
        else HELD_OUT
        if args.held_out
        else CASES
    )
    args.out_dir.mkdir(parents=True, exist_ok=True)
    tiles = []
    by_name = {case["name"]: case for case in cases}
    for turned in realcases.load_turned_views(TURNED) if args.turned else []:
        name = realcases.turned_view_name(turned)
        if (args.case and turned["case"] not in args.case) or (args.view and name not in args.view):
            continue
        case = by_name[turned["case"]]
        view = {"name": f"{turned['source']}/{turned['turn']}", "camera": turned["camera"], "stroke": turned["stroke"]}
        image, summary = case_view_overlay(scenes[case["scene"]], case, view, radius_given=False)
        save_png(args.out_dir / f"{name.replace('/', '__')}.png", image)
        print(f"{name:40s} {summary}")
        tiles.append(image)
    for case in cases if not args.turned else []:
        if args.case and case["name"] not in args.case:
            continue
        for i, view in enumerate(case["views"]):
            image, summary = case_view_overlay(scenes[case["scene"]], case, view)
            save_png(args.out_dir / f"{case['name']}__{view['name']}.png", image)
            print(f"{case['name']:26s} {view['name']:6s} {summary}")
            if i == 0:
                tiles.append(image)
    if args.gallery and tiles:
        height = 360
        tiles = [t.resize((max(1, round(t.width * height / t.height)), height), Image.LANCZOS) for t in tiles]
        sheet = Image.new("RGB", (sum(t.width for t in tiles) + 4 * (len(tiles) - 1), height), (255, 255, 255))
        x = 0
        for tile in tiles:
            sheet.paste(tile, (x, 0))
            x += tile.width + 4
        save_png(args.gallery, sheet)
        print(f"gallery -> {args.gallery}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
