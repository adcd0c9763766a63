"""The real-capture stroke sets drawn by hand (tests/data/real_cases: cases.json and the three
held-out sets) are well formed, and the number
changes to extraction are compared by (`CaseScore.log_excess`) adds up what it should."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from sketchrodgs import Camera, data

ROOT = Path(__file__).parent.parent
DATA = ROOT / "tests" / "data" / "real_cases"
# the hand-drawn sets: the cases and the three held-out sets, drawn the same way
DRAWN = {
    name: json.loads((DATA / f"{name}.json").read_text(encoding="utf-8"))
    for name in ("cases", "heldout_cases", "heldout2_cases", "heldout3_cases")
}
CASES = DRAWN["cases"]


def test_scenes_exist() -> None:
    assert set(CASES["scenes"]) == {"plant", "guitar", "tree", "donut"}
    for spec in CASES["scenes"].values():
        path = data.sample(spec.split(":", 1)[1]) if spec.startswith("sample:") else ROOT / spec
        assert Path(path).is_file(), spec


def test_at_least_twelve_parts_over_four_scenes() -> None:
    names = [case["name"] for case in CASES["cases"]]
    assert len(names) >= 12 and len(set(names)) == len(names)
    assert {case["scene"] for case in CASES["cases"]} == set(CASES["scenes"])


def test_no_part_is_in_two_sets() -> None:
    names = [case["name"] for cases in DRAWN.values() for case in cases["cases"]]
    assert len(set(names)) == len(names)


@pytest.mark.parametrize(
    "case",
    [case for cases in DRAWN.values() for case in cases["cases"]],
    ids=lambda case: case["name"],
)
def test_case(case: dict) -> None:
    assert case["radius"] > 0 and case["description"]
    assert 2 <= len(case["views"]) <= 3
    assert len({view["name"] for view in case["views"]}) == len(case["views"])
    directions = []
    for view in case["views"]:
        camera = Camera.from_dict(view["camera"], view["name"])
        stroke = np.asarray(view["stroke"], dtype=np.float64)
        assert stroke.ndim == 2 and stroke.shape[1] == 2 and 8 <= len(stroke) <= 25
        assert (stroke >= 0).all() and (stroke[:, 0] <= camera.width).all() and (stroke[:, 1] <= camera.height).all()
        directions.append(camera.camera_to_world[:3, 2])
    # Each view sees the part from a direction 30-90 degrees (within 0.5) from another view's.
    angles = {
        (i, j): np.degrees(np.arccos(np.clip(directions[i] @ directions[j], -1, 1)))
        for i, j in itertools.combinations(range(len(directions)), 2)
    }
    for i in range(len(directions)):
        assert any(29.5 <= a <= 90.5 for pair, a in angles.items() if i in pair)


def test_log_excess_sums_how_far_each_missed_distance_is_from_its_target() -> None:
    """The number changes to extraction are compared by: only the issue's missed distances count,
    each as ln(measured / target); the radius targets, our folding back and the stroke's share do
    not; an unmeasurable distance is infinitely far."""
    from sketchrodgs.realcases import CaseScore

    met = dict(cross_mean=0.1, cross_max=0.5, cross_mean_estimated=0.1, cross_max_estimated=0.5, reverse_max=0.0)
    score = CaseScore(
        name="c",
        views=3,
        failures=0,
        **met,
        jitter_mean=0.1,
        jitter_max=3.0,
        jitter_failures=0,
        jitter_count=30,
        radius_low=0.5,
        radius_high=2.0,
        radius_spread=4.0,
        jaccard=0.9,
        end_gap=1.0,
        fold_back=5.0,
        stroke_share=0.3,
    )
    assert score.log_excess() == pytest.approx(np.log(3.0 / 1.5))
    # jitter max, folding back, the stroke's share, the radius range and spread
    assert len(score.misses()) == 5
    score.cross_max = np.inf
    assert score.log_excess() == np.inf


@pytest.mark.parametrize("factor", [1.5, 1 / 1.5])
def test_a_zoomed_view_shows_the_part_at_that_many_times_its_pixels_about_the_strokes_centre(factor) -> None:
    """`realcases.zoomed` (benches/real_case_shifts.py --zoom): every point of the scene lands
    `factor` times as far from the stroke's centre as it did, and the stroke drawn in the zoomed
    view lies over what it lay over."""
    from sketchrodgs.realcases import zoomed

    view = CASES["cases"][0]["views"][0]
    camera = Camera.from_dict(view["camera"])
    stroke = np.asarray(view["stroke"], np.float64)
    zoomed_camera, zoomed_stroke = zoomed(camera, stroke, factor)
    centre = (stroke.min(axis=0) + stroke.max(axis=0)) / 2
    points = camera.unproject(stroke, np.full(len(stroke), 0.7))
    uv, z = camera.project(points)
    uv_zoomed, z_zoomed = zoomed_camera.project(points)
    np.testing.assert_allclose(uv_zoomed, centre + (uv - centre) * factor, atol=1e-6)
    np.testing.assert_allclose(z_zoomed, z)
    np.testing.assert_allclose(uv_zoomed, zoomed_stroke, atol=1e-6)
    assert (zoomed_camera.width, zoomed_camera.height) == (camera.width, camera.height)
