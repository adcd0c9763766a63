"""Pulls of real captured parts (issue: pulled real objects deform cleanly): a part of the
real-capture case set (tests/data/real_cases) extracted in one of its views, both ends clamped,
its middle vertex pulled across the view by 0.35 of the rod's length and held; scored at the end
of the hold by the needle fraction (over the rod's own Gaussians, attached parts left out), the
tear fraction (over all) and the fraction left behind where the part was, of `deform_metrics`.

Used by `tests/test_deform.py`, `benches/bench_skin.py` and `benches/pull_gallery.py`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from . import deform_metrics
from .animate import Animation, Pull
from .camera import Camera
from .extract import extract_rod
from .polyline import polyline_length
from .rod_file import Extraction
from .scene import GaussianScene

# (case, view) pairs pulled: the guitar neck, a tree branch and a plant stem, as the issue asks.
PULLS = (("guitar_neck", "az270"), ("tree_branch_centre", "az000"), ("plant_side_stem_left", "az000"))
PULL_SHARE = 0.35  # of the rod's length
FPS = 30


@dataclass
class PullResult:
    """A held pull: the scene at rest and deformed (same rows), the axes, and the scores."""

    name: str
    camera: Camera
    extraction: Extraction
    rest: GaussianScene
    deformed: GaussianScene
    rest_axis: np.ndarray
    deformed_axis: np.ndarray
    radius: float
    needles: float
    tears: float
    left_behind: float
    skin_seconds: float  # per frame, mean


def across_view(camera: Camera, polyline: np.ndarray) -> np.ndarray:
    """Unit world direction in the image plane, perpendicular to the polyline's chord on screen
    (turned towards the image's top, so that a pull reads the same in every view)."""
    uv, _ = camera.project(polyline[[0, -1]])
    chord = uv[1] - uv[0]
    across = np.array([chord[1], -chord[0]]) / max(np.linalg.norm(chord), 1e-12)
    if across[1] > 0:  # pixel y grows downwards: point up
        across = -across
    rotation = camera.camera_to_world[:3, :3]  # camera x right, y down
    world = rotation @ np.array([across[0], across[1], 0.0])
    return world / np.linalg.norm(world)


def pull_case(
    scene: GaussianScene, case: dict[str, Any], view_name: str, extract: dict[str, Any] | None = None, **animation: Any
) -> PullResult:
    """Extract `case` in `view_name` with its measured radius, pull and hold, and score it.

    `extract` goes to `extract_rod` (segmentation options), `animation` to `Animation`."""
    view = next(v for v in case["views"] if v["name"] == view_name)
    camera = Camera.from_dict(view["camera"])
    extraction = extract_rod(
        scene, camera, np.asarray(view["stroke"], np.float64), radius=case["radius"], **(extract or {})
    )
    anim = Animation(scene, [extraction], **animation)
    rod = anim.rods[0]
    offset = PULL_SHARE * polyline_length(extraction.polyline) * across_view(camera, extraction.polyline)
    pull = Pull(rod.num_vertices // 2, tuple(offset), duration=0.5, hold=0.5, release=False)
    skin_times = [frame.timings["skin"] for frame in anim.frames(pull, fps=FPS)]
    rest, deformed = anim.rest_scene, anim.current_scene()
    bound = anim.rig.bound[0]
    axis_now = np.asarray(rod.positions, np.float64)
    radius = float(extraction.radius)
    return PullResult(
        f"{case['name']}/{view_name}",
        camera,
        extraction,
        rest,
        deformed,
        extraction.polyline,
        axis_now,
        radius,
        deform_metrics.needle_fraction(
            rest,
            deformed,
            [extraction.polyline],
            [axis_now],
            radius,
            rows=np.setdiff1d(np.arange(len(rest)), bound.gaussian_ids[bound.attached]),
        ),
        deform_metrics.tear_fraction(rest, deformed, radius),
        deform_metrics.left_behind_fraction(rest, deformed, extraction.polyline, axis_now, radius),
        float(np.mean(skin_times)),
    )
