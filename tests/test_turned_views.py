"""Extraction from views nobody chose by hand (tests/data/real_cases/turned_views.json): each real
case's rod seen from cameras turned about it by 20-60 degrees, with a stroke along its projection
(`benches/turned_views.py`). Leaves in front of a stem, a fork seen across, a bar seen edge-on: what
a user's own view brings. Per view: extraction works with R given and estimated, the estimate is
within the issue's 0.7-1.4 x R, and no rod folds back along its stroke. Where a view does not meet
a target yet it is marked xfail(strict), so the lists stay true; the reasons are in
docs/real_captures.md ("Turned views").
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sketchrodgs.realcases import (
    TARGETS,
    TurnedResult,
    load_cases,
    load_turned_views,
    run_turned_view,
    turned_view_name,
)

DATA = Path(__file__).parent / "data" / "real_cases"
TURNED = load_turned_views(DATA / "turned_views.json")

# Measured misses (see the module docstring).
RADIUS_MISSES = {
    # the stem thin against leaves and sky, seen from below or above
    "plant_side_stem_right/az315/pitch+20",
    "plant_side_stem_right/az315/pitch-20",
    # a flat bar seen turned from below, its narrow side
    "guitar_stand_leg_left/az090/pitch-20",
    # half hidden by the trunk or another branch
    "tree_twig_v/az000/yaw+60",
    "tree_branch_centre/az000/yaw+30",
    "tree_branch_lower_left/az045/yaw+60",
    # a sprinkle seen end-on at the donut's silhouette beside another of its colour, 46 % seen:
    # measured across the blue of both from the path, 1.60 (docs/extraction.md, "A part lying on a
    # surface"; 0.76 while the path's pixels on the icing past its end were measured too)
    "donut_sprinkle_b/az270/yaw+60",
}
# (the branch's forked end seen across its two prongs, where the rod with R estimated ran over
# both, no longer folds: its hooked end is cut, docs/extraction.md "Polyline")
FOLD_MISSES: set[str] = set()


@pytest.fixture(scope="module")
def results() -> dict[str, TurnedResult]:
    scenes, cases = load_cases(DATA / "cases.json")
    by_name = {case["name"]: case for case in cases}
    out = {}
    for view in TURNED:
        case = by_name[view["case"]]
        out[turned_view_name(view)] = run_turned_view(scenes[case["scene"]], case, view)
    return out


def per_view(misses: set[str], what: str):
    """Parametrise over the turned views, strict-xfail where `what` is a measured miss."""
    names = [turned_view_name(view) for view in TURNED]
    assert misses <= set(names), misses - set(names)
    return pytest.mark.parametrize(
        "name",
        [
            pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=f"{what} not met yet")) if n in misses else n
            for n in names
        ],
    )


def test_the_set_covers_every_case_from_two_views():
    names = [case["name"] for case in json.loads((DATA / "cases.json").read_text(encoding="utf-8"))["cases"]]
    sources = {(view["case"], view["source"]) for view in TURNED}
    assert sorted({case for case, _ in sources}) == sorted(names)
    assert len(sources) == 2 * len(names) and len(TURNED) >= 4 * len(sources)


def test_no_turned_view_fails(results):
    failed = {name: r.failed for name, r in results.items() if r.failed}
    assert not failed, failed


@per_view(RADIUS_MISSES, "radius")
def test_the_radius_estimate_is_the_parts(results, name):
    ratio = results[name].radius_ratio
    assert TARGETS["radius_low"] <= ratio <= TARGETS["radius_high"], ratio


@per_view(FOLD_MISSES, "folding back")
def test_turned_rods_do_not_fold_back(results, name):
    assert results[name].fold_back <= TARGETS["fold_back"], results[name].fold_back
