"""Sketch-to-rod extraction at 960x540 with K and Z given (the render is not timed).

A rope spanning the whole image width is stroked end to end; per-stage times of `extract_rod`
and the paper's k-NN baseline (same weight over a 3D 8-NN graph of centres) on the same input.
"""

from __future__ import annotations

import time

import numpy as np
from _table import print_table

from sketchrodgs import Camera, synthetic
from sketchrodgs.baseline import knn_path
from sketchrodgs.extract import extract_rod
from sketchrodgs.render import render

CAMERA = Camera.look_at((0, 0, -1.5), (0, 0, 0), up=(0, 1, 0), width=960, height=540, fov_y_deg=40)
REPEAT = 7


def wide_rope(u: np.ndarray) -> np.ndarray:
    """A rope across the whole view (about 940 px of 960), sagging and winding in depth."""
    return np.stack([1.95 * (u - 0.5), 0.25 * np.sin(3 * np.pi * u), 0.15 * np.cos(2 * np.pi * u)], axis=1)


def main() -> None:
    rows = []
    for name, curves, clutter in (("rope across the image", [wide_rope], 3000),
                                  ("rope behind a pole", [wide_rope, synthetic.pole], 3000),
                                  ("self-crossing loop", [synthetic.loop], 3000)):
        tubes = synthetic.tube_scene(curves, radius=0.01, clutter=clutter, seed=4)
        uv, _ = CAMERA.project(tubes.axes[0])
        stroke = uv[np.r_[0:len(uv) - 1:25, len(uv) - 1]]
        images = render(tubes.scene, CAMERA, outputs="index")
        runs = []
        for _ in range(REPEAT):
            start = time.perf_counter()
            ex = extract_rod(tubes.scene, CAMERA, stroke, radius=tubes.radius, render=images)
            runs.append((time.perf_counter() - start, ex.timings))
        total, stages = min(runs, key=lambda r: r[0])
        base = min((knn_path(tubes.scene.means, CAMERA, stroke, int(ex.path_gaussian_ids[0]),
                             int(ex.path_gaussian_ids[-1])) for _ in range(3)), key=lambda b: b.seconds)
        span = np.ptp(stroke[:, 0])
        rows.append([
            name, f"{len(tubes.scene):,}", f"{span:.0f}", f"{len(ex.polyline)}",
            f"{stages['path_search'] * 1e3:.1f}", f"{stages['polyline'] * 1e3:.1f}",
            f"{stages['segment_bind'] * 1e3:.1f}", f"{total * 1e3:.1f}",
            f"{base.seconds * 1e3:.0f}", "goal" if base.reached_goal else f"stopped at {base.progress:.0%}",
            f"{base.seconds / total:.1f}x",
        ])
    print_table(
        f"extract_rod at {CAMERA.width}x{CAMERA.height}, K and Z given (best of {REPEAT})",
        ["case", "gaussians", "stroke px", "rod vertices", "path ms", "polyline ms", "segment+bind ms", "total ms",
         "k-NN baseline ms", "baseline", "baseline / ours"],
        rows,
    )


if __name__ == "__main__":
    main()
