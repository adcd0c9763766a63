"""The scene's units do not matter (docs/extraction.md, "Search"): a capture is in whatever units its
reconstruction chose, so the same scene and cameras in units 4 times larger (exact in floating
point) give the same rod, 4 times larger, and the same radius in its units. The path's stroke term
(paper Eq. 1) was added to world distances as it is, and in these units the plant's main stem from
az315 came out 1.3 R from its rod."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from sketchrodgs import Camera
from sketchrodgs.extract import extract_rod
from sketchrodgs.realcases import load_cases

CASES = Path(__file__).parent / "data" / "real_cases" / "cases.json"
SCALE = 4.0


def in_other_units(scene, camera: Camera):
    larger = dataclasses.replace(scene, means=scene.means * np.float32(SCALE), scales=scene.scales * np.float32(SCALE))
    world_to_camera = camera.world_to_camera.copy()
    world_to_camera[:3, 3] *= SCALE
    moved = Camera(camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy, world_to_camera,
                   camera.name, camera.near * SCALE)  # fmt: skip
    return larger, moved


@pytest.mark.parametrize("name, view_name", [("plant_main_stem", "az315"), ("guitar_stand_foot_front", "az090")])
def test_the_same_scene_in_other_units_gives_the_same_rod(name, view_name):
    scenes, cases = load_cases(CASES)
    case = next(c for c in cases if c["name"] == name)
    view = next(v for v in case["views"] if v["name"] == view_name)
    scene, camera = scenes[case["scene"]], Camera.from_dict(view["camera"], view_name)
    stroke, radius = np.asarray(view["stroke"], np.float64), case["radius"]
    larger, moved = in_other_units(scene, camera)
    for given in (radius, None):
        rod = extract_rod(scene, camera, stroke, radius=given)
        other = extract_rod(larger, moved, stroke, radius=None if given is None else given * SCALE)
        assert other.radius == pytest.approx(rod.radius * SCALE, rel=1e-5)
        np.testing.assert_array_equal(other.path_gaussian_ids, rod.path_gaussian_ids)
        np.testing.assert_allclose(other.polyline, rod.polyline * SCALE, atol=1e-3 * radius * SCALE)
        np.testing.assert_array_equal(np.sort(other.gaussian_ids), np.sort(rod.gaussian_ids))
