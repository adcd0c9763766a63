"""Every view of the hand-drawn real parts (the cases and the held-out parts), zoomed in: the camera
moved towards its stroke's middle to `--fraction` of the distance (same orientation, same
intrinsics), the stroke's points as drawn unprojected at the rod's depth and projected again. Prints,
per view, R estimated against the case's R and how far the rod lies from the unzoomed view's (R
given), in R (docs/real_captures.md, "Zoomed in: the depth gap of the widths is in pixels").

    python benches/zoomed_views.py [--fraction 0.5]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _table import print_table
from sketchrodgs import Camera, PathNotFoundError, realcases
from sketchrodgs.consistency import polyline_agreement
from sketchrodgs.extract import extract_rod
from sketchrodgs.render import SOLID_OUTPUTS, render

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "real_cases"


def zoomed(camera: Camera, stroke: np.ndarray, depth: float, fraction: float) -> tuple[Camera, np.ndarray]:
    """`camera` moved towards the stroke's middle (at `depth`) to `fraction` of the distance, and the
    stroke as it then sees the same points."""
    points = camera.unproject(stroke, depth)
    moved = camera.camera_to_world.copy()
    moved[:3, 3] += (1 - fraction) * (points[len(points) // 2] - moved[:3, 3])
    near = min(camera.near, 0.5 * fraction * depth)
    closer = Camera(
        camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy, np.linalg.inv(moved), "zoomed", near
    )
    return closer, closer.project(points)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fraction", type=float, default=0.5, help="the zoomed camera's share of the distance")
    args = parser.parse_args()
    rows = []
    for name in ("cases.json", "heldout_cases.json"):
        scenes, cases = realcases.load_cases(DATA / name)
        for case in cases:
            scene, radius = scenes[case["scene"]], float(case["radius"])
            for view in case["views"]:
                camera = Camera.from_dict(view["camera"], view["name"])
                stroke = np.asarray(view["stroke"], np.float64)
                images = render(scene, camera, outputs=SOLID_OUTPUTS)
                source = extract_rod(scene, camera, stroke, radius=radius, render=images)
                depth = float(np.median(camera.project(source.polyline.astype(np.float64))[1]))
                closer, closer_stroke = zoomed(camera, stroke, depth, args.fraction)
                try:
                    rod = extract_rod(scene, closer, closer_stroke)
                except PathNotFoundError as err:
                    rows.append([case["name"], view["name"], "failed", str(err)[:60], ""])
                    continue
                agreement = polyline_agreement(source.polyline, rod.polyline, radius)
                rows.append([case["name"], view["name"], rod.radius / radius, agreement["max"], agreement["mean"]])
    estimates = np.array([r[2] for r in rows if not isinstance(r[2], str)])
    outside = int(np.sum((estimates < 0.7) | (estimates > 1.4)))
    print_table(
        f"{len(rows)} views zoomed to {args.fraction:g} of the distance: {len(rows) - len(estimates)} failed, "
        f"R estimated outside 0.7-1.4 x R in {outside}",
        ["case", "view", "R est. / R", "max from the view's rod (R)", "mean (R)"],
        rows,
    )


if __name__ == "__main__":
    main()
