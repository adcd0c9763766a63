"""Extraction on real captures (tests/data/real_cases: 14 slender parts of the plant, guitar, tree
and donut captures, 2-3 views each, 10 held-out parts of the same captures that no extraction
was tuned on, 6 and 6 more drawn blind later (heldout2, heldout3), and 18 more sprinkles whose strokes were made
from the image's colour alone), scored as the issue asks, without a true axis: between views,
against the reversed stroke, under jitter, and the radius estimate (`sketchrodgs.realcases`).

What holds on every case is asserted outright. The per-case geometric targets are asserted per
case; where a case does not meet a target yet it is marked xfail(strict): the test then fails the
day the case starts to pass, so that the list stays true. The lists are what we measured; the
reasons are in docs/real_captures.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import close_up
from sketchrodgs import Camera, render
from sketchrodgs.consistency import jittered_strokes, polyline_agreement
from sketchrodgs.errors import PathNotFoundError
from sketchrodgs.extract import extract_rod
from sketchrodgs.polyline import polyline_length
from sketchrodgs.realcases import (
    SOLID_OUTPUTS,
    TARGETS,
    end_gap,
    jitter_seed,
    load_cases,
    off_shown,
    overshooting,
    part_strokes,
    run_case,
    score_case,
    short_stroke,
    sideways,
    turned_camera,
    zoomed,
)
from sketchrodgs.viewer.feedback import describe_failure

DATA = Path(__file__).parent / "data" / "real_cases"
CASE_FILES = {
    "cases": DATA / "cases.json",
    "heldout": DATA / "heldout_cases.json",
    "heldout2": DATA / "heldout2_cases.json",
    "heldout3": DATA / "heldout3_cases.json",
    "sprinkles": DATA / "sprinkle_cases.json",
}
JITTER = 10

# Measured misses (see the module docstring), as "set/case".
MISSES = {
    "unjittered": set(),
    "cross_given": {
        "heldout/plant_petiole_right",
        "heldout2/guitar_cradle_hook_right",
        "heldout3/guitar_cradle_arm_right",
    },
    "cross_estimated": {
        "heldout/plant_petiole_right",
        "heldout2/guitar_cradle_hook_right",
        "heldout3/donut_sprinkle_h",
        "heldout3/guitar_cradle_arm_right",
    },
    "jitter": {
        "heldout/plant_stem_back",
        "heldout/plant_petiole_right",
        "heldout/tree_branch_far_right",
        "heldout2/guitar_cradle_hook_right",
        "heldout3/tree_fork_side_arm",
        "heldout3/guitar_cradle_arm_right",
    },
    "radius": {
        "heldout/donut_sprinkle_d",
        "heldout2/tree_tip_back_centre",
        "heldout3/guitar_cradle_arm_right",
        *(f"sprinkles/sprinkle_{k:02d}" for k in (15, 17)),
    },
    "end_gap": {"heldout/plant_petiole_right"},
    "fold_back": {"heldout/plant_petiole_right", "heldout3/guitar_cradle_arm_right"},
    "stroke_share": {"heldout/plant_petiole_right"},
    "off_shown": set(),
}


@pytest.fixture(scope="module")
def scored():
    results = {}
    for group, path in CASE_FILES.items():
        scenes, cases = load_cases(path)
        for case in cases:
            views = run_case(scenes[case["scene"]], case, jitter=JITTER)
            results[f"{group}/{case['name']}"] = (views, score_case(case, views))
    return results


def _names() -> list[str]:
    return [
        f"{group}/{case['name']}"
        for group, path in CASE_FILES.items()
        for case in json.loads(path.read_text(encoding="utf-8"))["cases"]
    ]


def per_case(target: str):
    """Parametrise over the cases, strict-xfail where `target` is a measured miss."""
    return pytest.mark.parametrize(
        "name",
        [
            pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=f"{target} not met yet"))
            if n in MISSES[target]
            else n
            for n in _names()
        ],
    )


@per_case("unjittered")
def test_no_unjittered_stroke_fails(scored, name):
    """Every stroke as drawn, with R given, with R estimated and reversed, gives a rod."""
    for view in scored[name][0]:
        assert view.given is not None and view.estimated is not None and view.reversed is not None, (
            view.name,
            view.errors,
        )


def _strokes_that_fail(group: str, moved, radius_given: bool) -> list[str]:
    """Every view of `group` with each stroke `moved(scene, case, camera, stroke, images)` gives in place
    of its own, extracted with R estimated (and with R given where `radius_given`): those that make
    no rod, named with the error."""
    scenes, cases = load_cases(CASE_FILES[group])
    failed = []
    for case in cases:
        scene = scenes[case["scene"]]
        radii = (case["radius"], None) if radius_given else (None,)
        for view in case["views"]:
            camera = Camera.from_dict(view["camera"], view["name"])
            images = render(scene, camera, outputs=SOLID_OUTPUTS)
            strokes = moved(scene, case, camera, np.asarray(view["stroke"], np.float64), images)
            for k, stroke in enumerate(strokes):
                for radius in radii:
                    try:
                        extract_rod(scene, camera, stroke, radius=radius, render=images)
                    except PathNotFoundError as error:
                        failed.append(f"{case['name']}/{view['name']} #{k} R {radius}: {error}")
    return failed


@pytest.mark.parametrize(
    "group",
    [
        pytest.param(
            g,
            marks=pytest.mark.xfail(strict=True, reason="the right cradle arm in az065 moved a pixel down runs across"),
        )
        if g == "heldout3"
        else g
        for g in sorted(CASE_FILES)
    ],
)
def test_a_stroke_a_pixel_off_still_gives_a_rod(group):
    """Every view's stroke moved by a pixel left, right, up or down gives a rod with R estimated,
    where the radius estimate and the depth chain decide most (benches/real_case_shifts.py measures
    how far such rods move; docs/real_captures.md, "A pixel's shift")."""
    offsets = ((-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0))
    failed = _strokes_that_fail(group, lambda scene, case, camera, stroke, images: [stroke + o for o in offsets], False)
    assert not failed, failed


@pytest.mark.parametrize("group", sorted(CASE_FILES))
def test_a_stroke_half_a_radius_off_the_middle_still_gives_a_rod(group):
    """Every view's stroke moved half R aside, either way (`realcases.sideways`), gives a rod with R
    given and estimated: users draw off a part's middle (benches/real_case_shifts.py --sideways
    measures how far such rods move; docs/real_captures.md, "Drawn along an edge")."""

    def aside(scene, case, camera, stroke, images):
        drawn = extract_rod(scene, camera, stroke, radius=case["radius"], render=images)
        return sideways(stroke, camera, drawn.polyline, case["radius"], 0.5)

    failed = _strokes_that_fail(group, aside, True)
    assert not failed, failed


@pytest.mark.parametrize(
    "group",
    [
        pytest.param(g, marks=pytest.mark.xfail(strict=True, reason="a short stroke over sprinkle f in az090 fails"))
        if g == "heldout2"
        else g
        for g in sorted(CASE_FILES)
    ],
)
def test_a_stroke_three_diameters_long_gives_a_rod(group):
    """The issue's short stroke: 3 diameters along each view's rod where the part is seen
    (`realcases.short_stroke`) gives a rod, R given and estimated. Over sprinkle_15 in az000, whose
    few big Gaussians' centres lie closer together than its ends, the path at the estimated R was
    taken for one shorter than the rod, and R cut to a quarter of it: no rod (benches/real_case_shifts.py
    --diameters 3 measures how far such rods lie; docs/extraction.md, "Radius")."""

    def short(scene, case, camera, stroke, images):
        drawn = extract_rod(scene, camera, stroke, radius=case["radius"], render=images)
        stroke = short_stroke(camera, drawn.polyline, case["radius"], 3.0, images)
        return [] if stroke is None else [stroke]

    failed = _strokes_that_fail(group, short, True)
    assert not failed, failed


def test_at_most_3_percent_of_jittered_strokes_fail(scored):
    failures = sum(score.jitter_failures for _, score in scored.values())
    count = sum(score.jitter_count for _, score in scored.values())
    assert count >= 24 * 2 * JITTER
    assert failures <= TARGETS["jitter_fail_share"] * count, f"{failures} of {count} jittered strokes failed"


@per_case("end_gap")
def test_rods_reach_the_ends_of_their_paths(scored, name):
    """The rod covers what the stroke found: a rod cut short would pass the measures below, which
    compare rods only where they overlap."""
    score = scored[name][1]
    assert score.end_gap <= TARGETS["end_gap"], score.end_gap


@per_case("stroke_share")
def test_rods_as_drawn_cover_their_strokes(scored, name):
    """A rod cut where its path was cut passes the end gap: the stand's back foot, its chain cut at
    the leg in front, gave a rod over 42 % of its stroke, and sprinkle_13 one over 29 %."""
    score = scored[name][1]
    assert score.stroke_share >= TARGETS["stroke_share"], score.stroke_share


@per_case("off_shown")
def test_rods_as_drawn_lie_on_what_their_views_show(scored, name):
    """Views agreeing with each other can be off the part alike: the third held-out fork arm's rods
    lay between its thin finger and the fork's other arm in all three views, 0.52 R past the
    finger's silhouette in az250 (docs/real_captures.md, "Third held-out cases")."""
    score = scored[name][1]
    assert score.off_shown <= TARGETS["off_shown"], score.off_shown


@per_case("fold_back")
def test_no_rod_folds_back_along_its_stroke(scored, name):
    """Where the path doubles back (around a node, at a junction), the rod must not: a loop in the
    rest polyline is a loop in the simulated rod. Every extraction counts, jittered ones too."""
    score = scored[name][1]
    assert score.fold_back <= TARGETS["fold_back"], score.fold_back


def test_the_reversed_stroke_gives_the_same_rod(scored):
    for name, (_, score) in scored.items():
        assert score.reverse_max <= TARGETS["reverse_max"], (name, score.reverse_max)


@per_case("cross_given")
def test_views_agree_with_radius_given(scored, name):
    score = scored[name][1]
    assert score.cross_mean <= TARGETS["cross_mean"] and score.cross_max <= TARGETS["cross_max"], (
        score.cross_mean,
        score.cross_max,
    )


@per_case("cross_estimated")
def test_views_agree_with_radius_estimated(scored, name):
    score = scored[name][1]
    assert score.cross_mean_estimated <= TARGETS["cross_mean"] and score.cross_max_estimated <= TARGETS["cross_max"], (
        score.cross_mean_estimated,
        score.cross_max_estimated,
    )


@per_case("jitter")
def test_jittered_strokes_give_the_same_rod(scored, name):
    score = scored[name][1]
    assert score.jitter_mean <= TARGETS["jitter_mean"] and score.jitter_max <= TARGETS["jitter_max"], (
        score.jitter_mean,
        score.jitter_max,
    )


@per_case("radius")
def test_radius_estimate_matches_the_visible_radius(scored, name):
    score = scored[name][1]
    assert TARGETS["radius_low"] <= score.radius_low and score.radius_high <= TARGETS["radius_high"], (
        score.radius_low,
        score.radius_high,
    )
    assert score.radius_spread <= TARGETS["radius_spread"], score.radius_spread


def _case_view(group: str, name: str, view_name: str):
    """The scene, the case, the camera and the stroke of one view of a real case."""
    scenes, cases = load_cases(CASE_FILES[group])
    case = next(c for c in cases if c["name"] == name)
    view = next(v for v in case["views"] if v["name"] == view_name)
    return (
        scenes[case["scene"]],
        case,
        Camera.from_dict(view["camera"], view_name),
        np.asarray(view["stroke"], np.float64),
    )


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_stroke_sample_far_off_the_image_makes_no_nan():
    """A stray sample near float32's largest (a glitch of the input device) in the long side stem's
    az090 stroke: the stroke's line to it crosses the image, and the rod found is finite; no sum
    overflows into NaN on the way (the check that the rod runs along the stroke did, and then
    passed whatever the angle)."""
    scene, case, camera, stroke = _case_view("cases", "plant_side_stem_long", "az090")
    stroke[1, 0] += 3e38
    rod = extract_rod(scene, camera, stroke, radius=case["radius"])
    assert np.isfinite(rod.polyline).all() and len(rod.polyline) >= 2


def test_a_sprinkle_under_a_faint_far_off_gaussian_gets_its_rod_along_the_stroke():
    """Over sprinkle_15 in az270, a faint icing Gaussian 13 R long owns most of the path's pixels
    (the largest weight there, though the pixels show the sprinkle's blue) and its centre lies 400
    px away. The rod must be the sprinkle's, along the stroke: not built towards that Gaussian (it
    ran 360 px off once), and not refused as too short for lack of the Gaussians it hides."""
    scene, case, camera, stroke = _case_view("sprinkles", "sprinkle_15", "az270")
    rod = extract_rod(scene, camera, stroke, radius=case["radius"])
    uv, z = camera.project(rod.polyline.astype(np.float64))
    radius_px = case["radius"] * camera.fx / np.median(z)
    off = np.min(np.linalg.norm(uv[:, None] - stroke[None], axis=2), axis=1)
    assert off.max() < 1.5 * radius_px, off.max() / radius_px
    # it spans the sprinkle: each end of the stroke (drawn 2-6 px past the sprinkle's) lies within
    # 1.5 R of the rod's
    ends = np.linalg.norm(stroke[[0, -1]] - uv[[0, -1]], axis=1) / radius_px
    assert ends.max() < 1.5, ends


def test_a_sprinkle_stroked_over_the_icing_beside_it_keeps_its_rod_on_the_sprinkle():
    """sprinkle_14 in az000, stroked as the jitter set's fourth stroke (up to 8 px off, running
    along the sprinkle's upper edge and past its right end over the icing). The icing lies at the
    sprinkle's depth and its Gaussians are large, so by depth, width and length the path followed
    the stroke onto it, and the rod ran 4.7 R off the rod of the stroke as drawn. The icing's pink
    keeps the path on the sprinkle's blue (docs/extraction.md, "A part lying on a surface")."""
    scene, case, camera, stroke = _case_view("sprinkles", "sprinkle_14", "az000")
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    jittered = np.array(
        [[868.5, 330.8], [858.2, 309.1], [849.8, 295.6], [811.3, 278.5], [785.3, 273.8], [776.5, 284.4],
         [765.1, 277.0], [727.8, 268.9]]
    )  # fmt: skip
    rod = extract_rod(scene, camera, jittered, radius=case["radius"])
    agreement = polyline_agreement(drawn.polyline, rod.polyline, case["radius"])
    assert agreement["max"] <= TARGETS["jitter_max"], agreement


@pytest.mark.parametrize("view_name", ["az250", "az205"])
def test_a_thin_finger_at_a_fork_keeps_its_rod_on_the_finger(view_name):
    """The third held-out fork arm: its R (the arm's, below the fork) is about 2.5 times the half-width
    of the thin finger the stroke starts on, and the recentring's cross-sections there took in the
    fork's other arm: the rod's upper end lay between the two arms, off the finger (0.52 R past its
    silhouette in az250, 0.37 in az205). Where the part is outlined by background, they reach no
    further than its visible half-width allows (docs/extraction.md, "Polyline, segmentation,
    binding", Outlined thinner than R): every point of the rod projects onto what the view shows."""
    scene, case, camera, stroke = _case_view("heldout3", "tree_fork_side_arm", view_name)
    images = render(scene, camera, outputs=SOLID_OUTPUTS)
    rod = extract_rod(scene, camera, stroke, radius=case["radius"], render=images)
    off = off_shown(rod.polyline, camera, images.solid, case["radius"])
    assert off <= TARGETS["off_shown"], off


def test_a_stem_whose_path_breaks_at_a_petiole_in_front_keeps_its_length():
    """The held-out back stem in az270 with R estimated (0.985 R): a petiole crosses in front of
    it, the path breaks there, and its first piece climbed onto the petiole before it was lost (its
    last pixels 4-5 R in front of the stem on both sides of the gap). The axis dipped 3 R towards
    the petiole, and the corner cut took the 11 R from the dip to the rod's end: the rod was 22 R
    long against 31 R with R given. The climbed pixels are taken off (docs/extraction.md, "Piece
    ends on an occluder"), and the rod spans the stem either way."""
    scene, case, camera, stroke = _case_view("heldout", "plant_stem_back", "az270")
    given = extract_rod(scene, camera, stroke, radius=case["radius"])
    estimated = extract_rod(scene, camera, stroke)
    assert len(estimated.pixel_path) == 2  # the break
    lengths = [polyline_length(rod.polyline) for rod in (given, estimated)]
    assert lengths[1] >= 0.9 * lengths[0], np.array(lengths) / case["radius"]
    assert end_gap(estimated) <= TARGETS["end_gap"], end_gap(estimated)


def test_a_petiole_stroke_shifted_by_a_pixel_keeps_its_length():
    """The held-out petiole in az000 (R given) lies in a valley in depth with a flat bottom. Its
    stroke shifted by (-1, +1) px had the first 45 % cut as a turn off the part: the turn's apex
    was the bottom's member nearest the stroke's start, which made that side the shorter one, and
    the rod came out at 10.4 R against 25.5 as drawn. The sides are compared beyond the bottom
    (docs/extraction.md, "Stroke clean-up" 6, and docs/real_captures.md, "A pixel's shift")."""
    scene, case, camera, stroke = _case_view("heldout", "plant_petiole_right", "az000")
    lengths = [
        polyline_length(extract_rod(scene, camera, s, radius=case["radius"]).polyline)
        for s in (stroke, stroke + [-1.0, 1.0])
    ]
    assert lengths[1] >= 0.8 * lengths[0], np.array(lengths) / case["radius"]


def test_a_sprinkle_on_the_icings_rim_keeps_its_rod_when_the_stroke_moves_a_pixel():
    """Held-out sprinkle d in az000 lies on the icing's rim, seen against the background beyond it:
    the icing lies at its depth on one side only. Without the surface's colours there, its stroke
    moved 1 px up (R estimated) traced the sprinkle's upper edge: R 0.41 x and a rod 37 % as long
    as the stroke's as drawn. One side of the ring on the surface now finds them
    (docs/extraction.md, "A part lying on a surface", One side on the surface)."""
    scene, case, camera, stroke = _case_view("heldout", "donut_sprinkle_d", "az000")
    drawn, moved = (extract_rod(scene, camera, s) for s in (stroke, stroke + [0.0, -1.0]))
    assert 0.7 <= moved.radius / case["radius"] <= 1.4, moved.radius / case["radius"]
    lengths = [polyline_length(rod.polyline) for rod in (drawn, moved)]
    assert lengths[1] >= 0.75 * lengths[0], np.array(lengths) / case["radius"]


def test_a_jittered_stroke_over_a_sprinkle_as_much_on_the_icing_finds_both_colours():
    """sprinkle_14 in az000 under a jittered stroke (the fifth draw's third, `real_case_misses.py
    --draws`) that runs 10 px past both ends: about as many of the colours near it are the icing's
    as the sprinkle's, so their median lay between the two, the 2-means found no two colours, the
    path had no colour term, and the rod ran over the icing, 4.9 R from the rod as drawn. The
    2-means now starts again from the two sides of the median (docs/extraction.md, "A part lying on
    a surface")."""
    scene, case, camera, stroke = _case_view("sprinkles", "sprinkle_14", "az000")
    jittered = jittered_strokes(stroke, count=10, seed=jitter_seed("sprinkle_14", "az000", 4))[2]
    drawn, rod = (extract_rod(scene, camera, s, radius=case["radius"]) for s in (stroke, jittered))
    assert polyline_agreement(drawn.polyline, rod.polyline, case["radius"])["max"] <= TARGETS["jitter_max"]


def test_a_jittered_stroke_over_the_seam_of_two_fingers_keeps_to_the_one_it_follows():
    """The held-out left finger in az315 lies behind a nearer finger, and its stroke runs along its
    visible strip beside the seam. A jittered stroke (the third draw's tenth) runs over the seam:
    the nearer finger, within the band at more samples, outscored the stroke's finger by 17 % (52
    samples at 0.85 each on average, against 41 at 0.92), and the rod lay on it, 15.5 R from the rod
    as drawn. Where two chains at different depths nearly tie, the one whose surfaces lie nearer the
    stroke is taken (docs/extraction.md, "Stroke clean-up", A rival at another depth)."""
    scene, case, camera, stroke = _case_view("heldout", "tree_finger_left", "az315")
    jittered = jittered_strokes(stroke, count=10, seed=jitter_seed("tree_finger_left", "az315", 2))[9]
    drawn, rod = (extract_rod(scene, camera, s, radius=case["radius"]) for s in (stroke, jittered))
    assert polyline_agreement(drawn.polyline, rod.polyline, case["radius"])["max"] <= TARGETS["jitter_max"]


@pytest.mark.parametrize("group", sorted(CASE_FILES))
def test_a_stroke_drawn_30_px_past_either_end_still_gives_a_rod(group):
    """Every view's stroke with its first or its last point carried 30 px on along its end's
    direction (`realcases.overshooting`: the issue's overshoots run 10-30 px onto the background or
    a neighbour) gives a rod, R given and estimated: the stroke is trimmed to where it meets the
    part, not refused (docs/real_captures.md, "Drawn on past an end")."""
    failed = _strokes_that_fail(group, lambda scene, case, camera, stroke, images: overshooting(stroke, 30.0), True)
    assert not failed, failed


@pytest.mark.parametrize(
    ("group", "name", "view", "k", "side", "radius_given"),
    [("sprinkles", "sprinkle_15", "az270", 0.7, 0, True), ("heldout", "tree_finger_far_left", "az315", 1.0, 0, False)],
)
def test_a_stroke_drawn_along_the_parts_edge_gives_its_rod(group, name, view, k, side, radius_given):
    """A stroke drawn along one side of the part (`realcases.sideways`, docs/real_captures.md, "Drawn
    along an edge"): sprinkle_15's along its edge, 0.7 R aside, found no colours (the icing's two
    shades split first) and its path ran over the icing's edge, one big Gaussian: refused as too
    short. A tree finger's on its silhouette, a pixel outside it, with R estimated, had no covered
    pixel under any sample: refused as lying on the background."""
    scene, case, camera, stroke = _case_view(group, name, view)
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    moved = sideways(stroke, camera, drawn.polyline, case["radius"], k)[side]
    rod = extract_rod(scene, camera, moved, radius=case["radius"] if radius_given else None)
    assert polyline_agreement(drawn.polyline, rod.polyline, case["radius"])["max"] <= TARGETS["jitter_max"]
    assert TARGETS["radius_low"] <= rod.radius / case["radius"] <= TARGETS["radius_high"]


def test_a_stroke_along_a_sprinkles_edge_that_fails_says_to_draw_along_its_middle():
    """sprinkle_01 in az180 stroked along its edge, 0.7 R aside: the path runs 120 px over the
    icing's edge, which one big icing Gaussian owns, and no rod can be made. The error says what to
    change: not a longer stroke or a smaller radius, but the stroke along the middle
    (docs/real_captures.md, "Drawn along an edge"); the viewer says it in the user's terms."""
    scene, case, camera, stroke = _case_view("sprinkles", "sprinkle_01", "az180")
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    moved = sideways(stroke, camera, drawn.polyline, case["radius"], 0.7)[0]
    with pytest.raises(PathNotFoundError, match="along the object's middle, not its edge") as failure:
        extract_rod(scene, camera, moved, radius=case["radius"])
    assert len(failure.value.pixel_path) > 0  # the overlay still draws the path it found
    assert "edge" in describe_failure(failure.value)


def test_a_sprinkle_on_the_icing_estimates_its_radius_across_its_colour():
    """Sprinkle b in az270, R estimated: the widths under its stroke ran over the icing at its depth
    and the colour rule did not fire (1.89 x R). Measured from the path across the sprinkle's colour
    against the icing's, it is within the target."""
    scene, case, camera, stroke = _case_view("cases", "donut_sprinkle_b", "az270")
    rod = extract_rod(scene, camera, stroke)
    assert TARGETS["radius_low"] <= rod.radius / case["radius"] <= TARGETS["radius_high"], rod.radius / case["radius"]


def test_a_branch_in_front_of_the_trunk_estimates_its_radius_from_its_silhouette():
    """A stub branch of the tree seen in front of the trunk (0.24 behind it), stroked along its
    upper edge (not a case: drawn by hand on 2026-12-05). Its baked shading changes across it, so
    by colour it measured half its width, and the colour rule took that (R estimated at 0.50 of
    its visible half-width, 10-13 px: 0.015 at its depth). Its walks end on the trunk far behind,
    its silhouette as much as the background is, so the plain width stands."""
    scenes, cases = load_cases(CASE_FILES["cases"])
    view = next(v for c in cases for v in c["views"] if v["camera"].get("name") == "tree_az000_el10")
    camera = Camera.from_dict(view["camera"], "tree_az000_el10")
    stroke = np.array([[548, 403], [535, 412], [520, 422], [505, 434], [492, 446]], np.float64)
    rod = extract_rod(scenes["tree"], camera, stroke)
    assert TARGETS["radius_low"] <= rod.radius / 0.015 <= TARGETS["radius_high"], rod.radius


@pytest.mark.parametrize(
    ("name", "view", "how"), [("tree_branch_centre", "az060", "middle half"), ("tree_finger_far_left", "az315", "edge")]
)
def test_a_branch_shaded_across_estimates_its_radius_from_its_width_not_its_light_side(name, view, how):
    """A tree branch's baked shading darkens one side without changing its hue. The centre branch in
    az060 stroked over the middle half of its stroke (`realcases.part_strokes`), and the far left
    finger in az315 along its edge, 0.7 R aside, have walks ending on branches just behind, not on
    the background: the colour rule took the lit side's width, 0.30 and 0.15 of the radius
    (docs/extraction.md, "A part lying on a surface", Shading is not a surface)."""
    group = "cases" if name == "tree_branch_centre" else "heldout"
    scene, case, camera, stroke = _case_view(group, name, view)
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    if how == "edge":
        moved = sideways(stroke, camera, drawn.polyline, case["radius"], 0.7)
    else:
        moved = [part_strokes(stroke, camera, drawn.polyline, 0.5)[1]]
    for other in moved:
        rod = extract_rod(scene, camera, other)
        assert TARGETS["radius_low"] <= rod.radius / case["radius"] <= TARGETS["radius_high"], (
            rod.radius / case["radius"]
        )


def test_a_rod_running_across_its_stroke_is_refused_and_says_why():
    """The last half of the stroke over its rod (`realcases.part_strokes`) over the lower left
    branch in az045 lies on the nearer finger that hides the branch: its rod ran across both
    fingers, 46 degrees from the stroke. Refused, with what to change (docs/extraction.md,
    "Failures", A rod across its stroke)."""
    scene, case, camera, stroke = _case_view("cases", "tree_branch_lower_left", "az045")
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    half = part_strokes(stroke, camera, drawn.polyline, 0.5)[2]
    with pytest.raises(PathNotFoundError, match="runs across the stroke") as failure:
        extract_rod(scene, camera, half, radius=case["radius"])
    assert len(failure.value.pixel_path) > 0  # the overlay still draws the path it found
    assert "could not be followed" in describe_failure(failure.value)
    # its first half follows the part
    first = extract_rod(scene, camera, part_strokes(stroke, camera, drawn.polyline, 0.5)[0], radius=case["radius"])
    assert polyline_agreement(drawn.polyline, first.polyline, case["radius"])["max"] <= TARGETS["jitter_max"]


@pytest.mark.parametrize(("name", "view", "k"), [("plant_main_stem", "az315", 2), ("plant_side_stem_long", "az045", 1)])
def test_a_stroke_lying_wholly_on_the_leaf_that_hides_a_stem_follows_the_stem_behind(name, view, k):
    """Halves of the strokes over their rods (`realcases.part_strokes`): the main stem's last in
    az315 lies on a leaf that hides the stem under all of it, the long side stem's middle in az045
    on one that hides it but at two neighbouring samples. The chains behind, seen at neither end or
    over less than a rod, were not taken, and the rods lay on the leaves, 28.8 and 36.7 `R` from
    the stems (docs/extraction.md, "What lies behind", Seen nowhere)."""
    scene, case, camera, stroke = _case_view("cases", name, view)
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    half = part_strokes(stroke, camera, drawn.polyline, 0.5)[k]
    rod = extract_rod(scene, camera, half, radius=case["radius"])
    assert polyline_agreement(drawn.polyline, rod.polyline, case["radius"])["max"] <= TARGETS["jitter_max"]
    assert polyline_length(rod.polyline) > 0.8 * 0.5 * polyline_length(drawn.polyline)


def test_a_foot_receding_behind_a_leg_keeps_its_rod_past_the_leg():
    """The stand's back foot in az090 (held out) recedes towards the camera, 17 R nearer at the
    stroke's end than at its start, and a leg crosses in front of it halfway. The depth chain runs
    from the foot onto the leg and steps back onto the foot, which then comes on to 2.6 depth gaps
    in front of the leg, so the short-run rule took the foot's nearer half (61 px, under 4 R) for
    a nearer part and cut it: the rod covered 42 % of the stroke. That run goes on as the chain before it went, and is kept
    (docs/extraction.md, "Stroke clean-up")."""
    scene, case, camera, stroke = _case_view("heldout", "guitar_stand_foot_back", "az090")
    rod = extract_rod(scene, camera, stroke, radius=case["radius"])
    on_screen = camera.project(rod.polyline)[0]
    drawn = np.linalg.norm(np.diff(stroke, axis=0), axis=1).sum()
    assert np.linalg.norm(np.diff(on_screen, axis=0), axis=1).sum() >= 0.85 * drawn
    assert (
        np.linalg.norm(on_screen[-1] - stroke[-1])
        <= 2 * case["radius"] * camera.fx / camera.project(rod.polyline)[1][-1]
    )


def test_a_sprinkle_whose_chain_took_the_icing_for_a_stretch_keeps_its_rod_to_its_end():
    """sprinkle_13 in az270, as drawn. Over a stretch of the stroke the sprinkle measures as wide
    as the icing it lies on, and the depth chain takes the icing beside it instead, a depth gap
    behind; then it steps back onto the sprinkle's near half. Against that one member behind, the
    short-run rule took the sprinkle's near half for a nearer part and cut it: the rod covered 29 %
    of the stroke. That run is level with the chain before it (its median depth), and is kept
    (docs/extraction.md, "Stroke clean-up")."""
    scene, case, camera, stroke = _case_view("sprinkles", "sprinkle_13", "az270")
    rod = extract_rod(scene, camera, stroke, radius=case["radius"])
    on_screen = np.linalg.norm(np.diff(camera.project(rod.polyline)[0], axis=0), axis=1).sum()
    assert on_screen >= 0.6 * np.linalg.norm(np.diff(stroke, axis=0), axis=1).sum()


def test_a_sprinkle_seen_from_twice_as_far_gets_the_rod_it_gets_close_up():
    """Sprinkle a in az000 with the view zoomed out 2 x (the sprinkle 10 px wide, as a user sees it
    with more of the donut in view). The chain behind the front took a strip of icing far behind
    for the part and ran under the sprinkle, which measures as wide as the icing it lies on: its
    path showed one Gaussian and the stroke was refused. A trace over the layers behind that makes
    no rod now leaves the front's (docs/extraction.md, "What lies behind")."""
    scene, case, camera, stroke = _case_view("cases", "donut_sprinkle_a", "az000")
    radius = case["radius"]
    close = extract_rod(scene, camera, stroke, radius=radius)
    far_camera, far_stroke = zoomed(camera, stroke, 0.5)
    far = extract_rod(scene, far_camera, far_stroke, radius=radius)
    assert polyline_agreement(close.polyline, far.polyline, radius)["max"] <= 0.5
    blue = scene.colors_of(far.path_gaussian_ids)
    assert (blue[:, 2] > blue[:, 0]).all()  # the sprinkle's Gaussians, not the pink icing's


def test_a_sprinkle_drawn_by_two_big_gaussians_is_not_refused_as_too_short():
    """A jittered stroke over sprinkle_13 in az270 (the second draw's fifth) keeps 2 big Gaussians
    on its path. Their centres lie 1.8 R apart (lightly smoothed), under the 2 R a rod needs, though
    the pixels they show on the path span 3.3 R. The rod is then the line through those pixels, each
    unprojected at its Gaussian's depth (docs/extraction.md, "Polyline, segmentation, binding")."""
    scene, case, camera, stroke = _case_view("sprinkles", "sprinkle_13", "az270")
    radius = case["radius"]
    drawn = extract_rod(scene, camera, stroke, radius=radius)
    jittered = jittered_strokes(stroke, count=10, seed=jitter_seed("sprinkle_13", "az270", 1))[4]
    rod = extract_rod(scene, camera, jittered, radius=radius)
    assert len(rod.path_gaussian_ids) == 2
    assert polyline_length(rod.polyline) >= 2 * radius
    assert polyline_agreement(drawn.polyline, rod.polyline, radius)["max"] <= TARGETS["jitter_max"]


def test_a_sprinkle_of_few_gaussians_keeps_its_ends_straight_under_jitter():
    """sprinkle b in az180 is some 20 Gaussians, two per radius. Near an end a cross-section of the
    axis held one of them, and the axis went to that Gaussian, on the sprinkle's side: 4 of the 10
    jittered strokes' rods hooked there, 1.56-1.64 R from the rod as drawn. A cross-section of one
    Gaussian is now taken over a slab twice as wide (docs/extraction.md, "A cross-section of one
    Gaussian"); those rods lie within 0.45 R of it."""
    scene, case, camera, stroke = _case_view("cases", "donut_sprinkle_b", "az180")
    radius = case["radius"]
    images = render(scene, camera, outputs=SOLID_OUTPUTS)
    drawn = extract_rod(scene, camera, stroke, radius=radius, render=images)
    for jittered in jittered_strokes(stroke, count=JITTER, seed=jitter_seed("donut_sprinkle_b", "az180")):
        rod = extract_rod(scene, camera, jittered, radius=radius, render=images)
        assert polyline_agreement(drawn.polyline, rod.polyline, radius)["max"] <= 1.0


def test_a_sprinkle_sketched_close_up_gives_the_rod_of_its_far_view():
    """The held-out sprinkle c as a viewer user sketches it: 0.06 away, looking as its az180 view
    does (fov 50 degrees, viser's near plane 0.01), stroked where that view's stroke lies. Its chain
    over the layers behind scored more than the visible one but, cut to its visible ends, spanned two
    neighbouring samples: the path was one pixel, and the stroke was refused as too short. The rod
    is the far view's, within the issue's targets."""
    scene, case, far, stroke = _case_view("heldout", "donut_sprinkle_c", "az180")
    far_rod = extract_rod(scene, far, stroke, radius=case["radius"])
    depth = float(np.median(far.project(far_rod.polyline.astype(np.float64))[1]))
    close, points = close_up(far, stroke, depth, 0.06, fov_y_deg=50, near=0.01)
    close_stroke, _ = close.project(points)
    rod = extract_rod(scene, close, close_stroke)
    agreement = polyline_agreement(far_rod.polyline, rod.polyline, case["radius"])
    assert agreement["mean"] <= TARGETS["cross_mean"] and agreement["max"] <= TARGETS["cross_max"], agreement
    assert TARGETS["radius_low"] <= rod.radius / case["radius"] <= TARGETS["radius_high"], rod.radius


def test_a_stroke_beside_a_leaf_stalk_over_a_faint_haze_keeps_its_rod_on_the_stalk():
    """The leaf stalk rising left from the plant's lowest node in az000 (not a case; stroked on
    2026-12-05 a few pixels right of its middle). Right of it one flat Gaussian, 0.04 opaque and of
    scale 0.1 (the stalk's half-width is 0.0064), owns the pixels (alpha 0.01-0.04: nothing solid).
    Jittered strokes over it took it for a slender surface 10 R behind the stalk, and 3 of these 10
    rods ran onto the leaf behind, 19 R away or sharing nothing with the rod as drawn. A surface with
    no solid pixel near a sample is a haze (docs/extraction.md, "Stroke clean-up" 2)."""
    scene, _, camera, _ = _case_view("cases", "plant_main_stem", "az000")
    radius = 0.0064  # half the stalk's visible width, as estimated (0.0061-0.0065)
    stroke = np.array([[438.0, 322.0], [448.0, 340.0], [458.0, 356.0], [468.0, 372.0], [476.0, 384.0]])
    drawn = extract_rod(scene, camera, stroke, radius=radius)
    assert polyline_length(drawn.polyline) >= 10 * radius
    for jittered in jittered_strokes(stroke, count=10, seed=jitter_seed("plant leaf stalk", "az000")):
        rod = extract_rod(scene, camera, jittered, radius=radius)
        assert polyline_agreement(drawn.polyline, rod.polyline, radius)["max"] <= TARGETS["jitter_max"]


def test_a_stroke_over_the_leaf_hiding_the_main_stem_follows_the_stem_behind_it():
    """The plant's main stem seen from behind (the az000 camera turned 180 degrees about the stem;
    not a case, stroked on 2026-12-06), where a leaf covers its left half over a third of the
    stroke. A stroke drawn 6-8 px left of the stem runs over the leaf there: the visible chain took
    the leaf, 3-9 R in front, and its rod lay on the leaf, 11 R from the rod as drawn. Over the
    whole stroke the chain behind gains 14 %, under `BEHIND_GAIN`; over the stretch where the two
    differ, where the visible one lies on the leaf, 48 % (docs/extraction.md, "What lies behind")."""
    scene, _, camera, _ = _case_view("cases", "plant_main_stem", "az000")
    behind = turned_camera(camera, np.array([0.007, -0.136, 0.020]), "up", 180.0, name="az000 turned 180")
    drawn = extract_rod(scene, behind, np.array([[506.0, 525], [503, 490], [498, 455], [494, 420], [492, 395]]))
    beside = extract_rod(
        scene, behind, np.array([[502.0, 536], [508, 533], [506, 491], [494, 462], [486, 395], [501, 385]])
    )
    assert polyline_agreement(drawn.polyline, beside.polyline, drawn.radius)["max"] <= TARGETS["jitter_max"]
    # on the stem, not on the leaf in front of it
    assert behind.project(beside.polyline)[1].min() >= behind.project(drawn.polyline)[1].min() - drawn.radius


def test_a_stroke_ending_over_a_nearer_branch_that_hides_the_part_is_not_refused():
    """A jittered stroke over the tree's lower left branch in az045 (the case's stroke, drawn again
    with hand noise: it doubles back near its end) ends over a nearer branch, 10 R in front, that
    hides the part there. Its depth chain keeps to the part, whose nearest pixel to the last samples
    lies at the edge of the band; no band pixel lies near the stroke's last sample, and the stroke
    was refused as meeting the object at one sample. The search's end now moves inwards to the
    first sample with band pixels near it (docs/extraction.md, "Search")."""
    scene, case, camera, stroke = _case_view("cases", "tree_branch_lower_left", "az045")
    drawn = extract_rod(scene, camera, stroke, radius=case["radius"])
    jittered = np.array(
        [[326.1, 328.5], [323.9, 324.7], [328.3, 369.4], [324.3, 372.8], [344.3, 389.3]]
        + [[347.4, 419.2], [330.4, 411.7], [346.7, 431.0], [340.0, 438.8], [348.1, 436.7]]
    )
    rod = extract_rod(scene, camera, jittered, radius=case["radius"])
    assert polyline_agreement(drawn.polyline, rod.polyline, case["radius"])["max"] <= TARGETS["jitter_max"]


@pytest.mark.parametrize(
    "radius_given",
    [
        True,
        pytest.param(False, marks=pytest.mark.xfail(strict=True, reason="zoom is not resolution: R falls to 0.25")),
    ],
)
def test_a_leg_zoomed_in_binds_the_leg(radius_given):
    """The right stand leg in az090 seen with the focal length doubled about its stroke
    (`realcases.zoomed`): the rod still binds at least half the Gaussians it binds unzoomed. With R
    given it does, which is what the README tells a user zoomed in on a flat part to do. With R
    estimated the estimate falls to 0.25 x R (the widths' depth floor is in pixels, and the leg's
    oblique face splits at twice the zoom), its rod runs along the leg's edge and binds 41 Gaussians
    of 3,084: a pull moves the rod and leaves the leg (docs/real_captures.md, "Zoomed in: the depth
    gap of the widths is in pixels")."""
    scene, case, camera, stroke = _case_view("cases", "guitar_stand_leg_right", "az090")
    radius = case["radius"] if radius_given else None
    unzoomed = extract_rod(scene, camera, stroke, radius=radius)
    zoomed_camera, zoomed_stroke = zoomed(camera, stroke, 2.0)
    rod = extract_rod(scene, zoomed_camera, zoomed_stroke, radius=radius)
    assert len(rod.gaussian_ids) >= 0.5 * len(unzoomed.gaussian_ids)


def _points_every(stroke: np.ndarray, px: float) -> np.ndarray:
    """The same stroke given as points about `px` apart along its segments (its corners kept), as
    a pointer's events give it."""
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(stroke, axis=0), axis=1))]
    at = np.union1d(np.linspace(0.0, arc[-1], int(round(arc[-1] / px)) + 1), arc)
    return np.column_stack([np.interp(at, arc, stroke[:, 0]), np.interp(at, arc, stroke[:, 1])])


@pytest.mark.parametrize("name, view_name", [("plant_main_stem", "az045"), ("plant_side_stem_left", "az045")])
def test_jittered_strokes_of_points_closer_than_their_noise_give_the_rod_as_drawn(name, view_name):
    """The issue's jitter (3-8 px of noise on every point) on a stroke given as points 4 px apart
    makes a zigzag across the stem. Its points are now averaged over their noise (docs/extraction.md,
    "Stroke clean-up", **Points closer than their noise**): before, a jittered rod of the main stem
    lay 2.54 R from the rod as drawn and 4 of the left side stem's 1.47-1.56 R; now every one lies
    within 0.83 R."""
    scene, case, camera, stroke = _case_view("cases", name, view_name)
    radius = case["radius"]
    dense = _points_every(stroke, 4.0)
    images = render(scene, camera, outputs=SOLID_OUTPUTS)
    drawn = extract_rod(scene, camera, dense, radius=radius, render=images)
    for jittered in jittered_strokes(dense, count=JITTER, seed=jitter_seed(name, view_name)):
        rod = extract_rod(scene, camera, jittered, radius=radius, render=images)
        assert polyline_agreement(drawn.polyline, rod.polyline, radius)["max"] <= 1.2
