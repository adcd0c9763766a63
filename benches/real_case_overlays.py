"""Overlay PNGs of the real-capture test strokes, for a person to check them.

For every case and view in tests/data/real_cases/cases.json this renders the view and draws the
stroke on it in green (its points as small red rings), the case and view named in the corner,
into OUT_DIR/<case>__<view>.png.

With --extract it also runs `extract_rod(scene, camera, stroke, radius=R)` once per view, draws
the extracted polyline projected into the view in magenta, prints one line per view (or the
error), and the agreement between the polylines of each pair of views
(`consistency.polyline_agreement`, in units of R).

    python benches/real_case_overlays.py OUT_DIR [--case NAME ...] [--extract]
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import sketchrodgs
from sketchrodgs import Camera, data, load_scene, render
from sketchrodgs.consistency import polyline_agreement

ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "tests" / "data" / "real_cases" / "cases.json"
BACKGROUND = (0.3, 0.3, 0.35)


def scene_path(spec: str) -> Path:
    """A scene entry of cases.json: "sample:NAME" or a path relative to the repository root."""
    if spec.startswith("sample:"):
        return Path(data.sample(spec.split(":", 1)[1]))
    return ROOT / spec


def load_cases(path: Path = CASES) -> dict:
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def draw(rgb: np.ndarray, stroke: np.ndarray, label: str, polyline_uv: np.ndarray | None) -> Image.Image:
    image = Image.fromarray((np.clip(rgb, 0, 1) * 255).astype(np.uint8))
    pen = ImageDraw.Draw(image)
    if polyline_uv is not None:
        finite = polyline_uv[np.isfinite(polyline_uv).all(axis=1)]
        if len(finite) > 1:
            pen.line([tuple(p) for p in finite], fill=(255, 0, 255), width=1)
    pen.line([tuple(p) for p in stroke], fill=(0, 255, 0), width=1)
    for x, y in stroke:
        pen.ellipse([x - 2, y - 2, x + 2, y + 2], outline=(255, 40, 40))
    pen.rectangle([0, 0, 8 + 6 * len(label), 14], fill=(0, 0, 0))
    pen.text((4, 2), label, fill=(255, 255, 0))
    return image


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--case", action="append", help="only this case (repeatable)")
    parser.add_argument("--extract", action="store_true", help="also run extract_rod per view")
    parser.add_argument("--cases-file", type=Path, default=CASES)
    args = parser.parse_args()
    spec = load_cases(args.cases_file)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    scenes: dict[str, sketchrodgs.GaussianScene] = {}
    failures = 0
    for case in spec["cases"]:
        if args.case and case["name"] not in args.case:
            continue
        name = case["scene"]
        if name not in scenes:
            scenes[name] = load_scene(scene_path(spec["scenes"][name]))
        scene, radius = scenes[name], float(case["radius"])
        polylines = {}
        for view in case["views"]:
            camera = Camera.from_dict(view["camera"], f"{case['name']}/{view['name']}")
            stroke = np.asarray(view["stroke"], dtype=np.float64)
            images = render(scene, camera, background=BACKGROUND)
            polyline_uv = None
            label = f"{case['name']} / {view['name']}  R={radius:g}"
            if args.extract:
                start = time.perf_counter()
                try:
                    result = sketchrodgs.extract_rod(scene, camera, stroke, radius=radius, render=images)
                except sketchrodgs.SketchRodGSError as exc:
                    failures += 1
                    print(f"{case['name']:28s} {view['name']:6s} FAILED {type(exc).__name__}: {exc}")
                else:
                    line = np.asarray(result.polyline, dtype=np.float64)
                    polylines[view["name"]] = line
                    polyline_uv, _ = camera.project(line)
                    length = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
                    print(f"{case['name']:28s} {view['name']:6s} ok  {len(line):4d} vertices, length {length:.4g}, "
                          f"coverage {result.coverage:.2f}, pieces reached goal {result.pieces_reached_goal}, "
                          f"{time.perf_counter() - start:.2f} s")
            image = draw(images.rgb, stroke, label, polyline_uv)
            image.save(args.out_dir / f"{case['name']}__{view['name']}.png")
        for (va, a), (vb, b) in itertools.combinations(polylines.items(), 2):
            agreement = polyline_agreement(a, b, radius)
            print(f"{case['name']:28s} {va}-{vb}: mean {agreement['mean']:.2f} R, max {agreement['max']:.2f} R, "
                  f"overlap {agreement['overlap']:.2f}")
    print(f"overlays in {args.out_dir}")
    return 1 if failures and args.extract else 0


if __name__ == "__main__":
    sys.exit(main())
