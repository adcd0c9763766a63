"""Before/after pictures of real pulls (docs/deformation.md): for each pull of `realpulls.PULLS`
(and any `--case NAME/VIEW` given), the view at rest, the same pull with one binding per
Gaussian and nothing attached (how it was), and the pull now (needles split, attached parts, the
shell trimmed where it parts, clamped ends eased), cropped around the rod, with the needle and tear
fractions in the captions.

    python benches/pull_gallery.py OUT_DIR [--case guitar_neck/az270 ...]

Each pull is written to OUT_DIR/pull_<case>.png. OUT_DIR/pull_free_tip.png is the bundled plant's
stem held at its base only, its tip free: before and after what continues the stem past the
stroke rides with the tip (docs/deformation.md, "Continuations"). OUT_DIR/pull_rope_on_floor.png
is a rope lifted off a floor of another colour: before and after the floor was left out of it.
OUT_DIR/pull_large_leaf.png is the long side stem pulled in az090: before and after a leaf
reaching past 20 R, with fewer Gaussians than the stem, rode along (docs/deformation.md,
"Segmentation", Attached parts). OUT_DIR/pull_split_bands.png is the second held-out sprinkle pulled
in az135, at three times the resolution: its needles split into one piece an edge, as before, and
into two (docs/deformation.md, "Subdivision", Why two pieces an edge).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from sketchrodgs import data, extract_rod, load_scene, render, segment, synthetic
from sketchrodgs import subdivide as sd
from sketchrodgs.animate import Animation, Pull
from sketchrodgs.images import save_png, to_uint8
from sketchrodgs.realcases import load_cases
from sketchrodgs.realpulls import PULLS, PullResult, pull_case

CASES = Path(__file__).parent.parent / "tests" / "data" / "real_cases" / "cases.json"
HELDOUT2 = CASES.with_name("heldout2_cases.json")
MARGIN_PX = 50
WIDTH = 420  # of each panel


def crop_box(result: PullResult, other: PullResult) -> tuple[int, int, int, int]:
    camera = result.camera
    points = np.concatenate([result.rest_axis, result.deformed_axis, other.deformed_axis])
    uv, _ = camera.project(points)
    low, high = np.nanmin(uv, axis=0) - MARGIN_PX, np.nanmax(uv, axis=0) + MARGIN_PX
    return (max(0, int(low[0])), max(0, int(low[1])), min(camera.width, int(high[0])), min(camera.height, int(high[1])))


def panel(scene, result: PullResult, box, caption: str) -> Image.Image:
    image = Image.fromarray(to_uint8(render(scene, result.camera).rgb)).crop(box)
    image = image.resize((WIDTH, max(1, round(image.height * WIDTH / image.width))), Image.LANCZOS)
    out = Image.new("RGB", (image.width, image.height + 22), "white")
    out.paste(image, (0, 22))
    ImageDraw.Draw(out).text((4, 5), caption, fill=(0, 0, 0))
    return out


def free_tip(out: Path) -> None:
    """The bundled stem held at its base, its middle dragged 25 px right and 45 px up, held."""
    scene, camera = load_scene(data.sample("plant")), data.sample_camera("plant")
    box = (430, 180, 730, 420)

    def pulled(continuations: bool) -> np.ndarray:
        keep = segment._with_continuations
        if not continuations:
            segment._with_continuations = lambda binding, *_: binding  # as before they were taken
        try:
            extraction = extract_rod(scene, camera, data.sample_stroke("plant"))
        finally:
            segment._with_continuations = keep
        middle = len(extraction.polyline) // 2
        drag = tuple(camera.screen_offset(extraction.polyline[middle], (25, -45)))
        animation = Animation(scene, [extraction], clamp="start")
        for _ in animation.frames(Pull(vertex=middle, offset=drag, duration=0.4, hold=0.3, release=False), fps=30):
            pass  # held out
        return render(animation.current_scene(), camera).rgb

    side_by_side(
        out / "pull_free_tip.png",
        box,
        [
            (render(scene, camera).rgb, "the bundled stem at rest"),
            (pulled(False), "held at its base, before: its tip stays"),
            (pulled(True), "now: the tip and its leaves follow"),
        ],
    )
    print(f"{out / 'pull_free_tip.png'}: the free tip")


def rope_on_floor(out: Path) -> None:
    """`synthetic.rope_on_floor_scene` seen from 60 degrees, the rope's middle lifted 8 R and held:
    before and after the floor under it was left out of the part (docs/deformation.md,
    "Segmentation")."""
    tubes = synthetic.rope_on_floor_scene(radius=0.01, seed=1)
    camera = synthetic.floor_camera(60)
    stroke = synthetic.floor_stroke(tubes.axes[0], camera)

    def lifted(colours: bool) -> tuple[np.ndarray, int]:
        keep = segment._part_and_attached
        if not colours:  # segmentation as it was: the centres only
            segment._part_and_attached = lambda *args, colours=None, **kwargs: keep(*args, **kwargs)
        try:
            extraction = extract_rod(tubes.scene, camera, stroke, radius=tubes.radius)
        finally:
            segment._part_and_attached = keep
        floor = int((tubes.labels[extraction.gaussian_ids] < 0).sum())
        animation = Animation(tubes.scene, [extraction])
        lift = Pull(len(extraction.polyline) // 2, (0.0, -0.08, 0.0), duration=0.3, hold=0.2, release=False, settle=0.0)
        for _ in animation.frames(lift, fps=30):
            pass  # held up
        return render(animation.current_scene(), camera).rgb, floor

    (before, floor_before), (now, floor_now) = lifted(False), lifted(True)
    side_by_side(
        out / "pull_rope_on_floor.png",
        (180, 200, 780, 430),
        [
            (render(tubes.scene, camera).rgb, "a rope on a floor, at rest"),
            (before, f"lifted, before: {floor_before:,} floor Gaussians bound"),
            (now, f"now: {floor_now:,} floor Gaussians bound"),
        ],
    )
    print(f"{out / 'pull_rope_on_floor.png'}: floor Gaussians bound {floor_before} before, {floor_now} now")


def large_leaf(out: Path, scenes: dict, cases: list[dict]) -> None:
    """The long side stem pulled in az090 (a rod of 42.6 R, of `load_cases(CASES)`'s `scenes` and
    `cases`): with every attached part within 20 R, as before, and now (its leaf reaching 20-21 R
    rides along)."""
    case = next(c for c in cases if c["name"] == "plant_side_stem_long")
    scene = scenes[case["scene"]]
    before = pull_case(scene, case, "az090", extract={"attach_size": segment.ATTACH_MAX * case["radius"]})
    now = pull_case(scene, case, "az090")
    box = crop_box(now, before)
    attached = [int(r.extraction.binding.attached.sum()) for r in (before, now)]
    side_by_side(
        out / "pull_large_leaf.png",
        box,
        [
            (render(now.rest, now.camera).rgb, "the long side stem at rest"),
            (render(before.deformed, before.camera).rgb, f"pulled, before: {attached[0]:,} attached"),
            (render(now.deformed, now.camera).rgb, f"now: {attached[1]:,} attached (its leaf)"),
        ],
    )
    print(f"{out / 'pull_large_leaf.png'}: attached {attached[0]} before, {attached[1]} now")


def split_bands(out: Path) -> None:
    """The second held-out sprinkle in az135 at rest and pulled, its needles split as before (one
    piece an edge, each at most 1.5/k of the parent's deviation; its table fitted here) and now."""
    scenes, cases = load_cases(HELDOUT2)
    case = next(c for c in cases if c["name"] == "donut_sprinkle_e")
    scene = scenes[case["scene"]]
    now = pull_case(scene, case, "az135")
    constants = (sd.PIECE_STD, sd.PIECES_PER_EDGE, sd.SPLIT_FROM, sd.MIN_PIECES, sd.MAX_PIECES, sd.piece_table)
    fitted: dict[int, tuple] = {}
    try:
        sd.PIECE_STD, sd.PIECES_PER_EDGE, sd.SPLIT_FROM, sd.MIN_PIECES, sd.MAX_PIECES = 1.5, 1.0, 1.0, 1, 16
        sd.piece_table = lambda k: fitted.setdefault(k, sd.fit_piece_table(k))
        before = pull_case(scene, case, "az135")
    finally:
        sd.PIECE_STD, sd.PIECES_PER_EDGE, sd.SPLIT_FROM, sd.MIN_PIECES, sd.MAX_PIECES, sd.piece_table = constants
    zoom = 3
    camera = now.camera.resized(now.camera.width * zoom)
    box = tuple(zoom * v for v in crop_box(now, before))
    side_by_side(
        out / "pull_split_bands.png",
        box,
        [
            (render(before.rest, camera).rgb, "at rest, one piece an edge"),
            (render(before.deformed, camera).rgb, "pulled: bands"),
            (render(now.rest, camera).rgb, "at rest, two pieces an edge (now)"),
            (render(now.deformed, camera).rgb, "pulled, now"),
        ],
    )
    added = [len(r.rest) - len(scene) for r in (before, now)]
    print(f"{out / 'pull_split_bands.png'}: pieces added {added[0]} before, {added[1]} now")


def side_by_side(path: Path, box: tuple[int, int, int, int], images: list[tuple[np.ndarray, str]]) -> None:
    """The crops `box` of `images` (RGB, with a caption each) side by side, written to `path`."""
    panels = []
    for rgb, caption in images:
        image = Image.fromarray(to_uint8(rgb)).crop(box)
        image = image.resize((WIDTH, round(image.height * WIDTH / image.width)), Image.LANCZOS)
        framed = Image.new("RGB", (image.width, image.height + 22), "white")
        framed.paste(image, (0, 22))
        ImageDraw.Draw(framed).text((4, 5), caption, fill=(0, 0, 0))
        panels.append(framed)
    sheet = Image.new("RGB", (sum(p.width for p in panels) + 8 * (len(panels) - 1), panels[0].height), "white")
    for k, p in enumerate(panels):
        sheet.paste(p, (k * (p.width + 8), 0))
    save_png(path, np.asarray(sheet))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--case", action="append", default=[], help="NAME/VIEW (default: the tested pulls)")
    args = parser.parse_args()
    pulls = [tuple(c.split("/")) for c in args.case] or list(PULLS)
    scenes, cases = load_cases(CASES)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, view in pulls:
        case = next(c for c in cases if c["name"] == name)
        scene = scenes[case["scene"]]
        old = pull_case(scene, case, view, extract={"attach": False}, subdivide=False, end_ramp=0.0, separate=False)
        new = pull_case(scene, case, view)
        box = crop_box(new, old)
        panels = [
            panel(new.rest, new, box, f"{name} at rest"),
            panel(old.deformed, old, box, f"before: needles {old.needles:.1%}, tears {old.tears:.1%}"),
            panel(new.deformed, new, box, f"now: needles {new.needles:.1%}, tears {new.tears:.1%}"),
        ]
        sheet = Image.new(
            "RGB", (sum(p.width for p in panels) + 8 * (len(panels) - 1), max(p.height for p in panels)), "white"
        )
        x = 0
        for p in panels:
            sheet.paste(p, (x, 0))
            x += p.width + 8
        path = args.out / f"pull_{name}.png"
        save_png(path, np.asarray(sheet))
        print(
            f"{path}: before needles {old.needles:.2%} tears {old.tears:.2%}; now needles {new.needles:.2%} "
            f"tears {new.tears:.2%}"
        )
    free_tip(args.out)
    rope_on_floor(args.out)
    large_leaf(args.out, scenes, cases)
    split_bands(args.out)


if __name__ == "__main__":
    main()
