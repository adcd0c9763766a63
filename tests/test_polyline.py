"""The axis smoothing of extraction (`polyline.smooth_axis`, docs/extraction.md, "Polyline"): it
takes out the scatter of recentred cross-sections and a cross-section pulled aside by what touches
the part, and keeps the part's own bends."""

from __future__ import annotations

import numpy as np

from sketchrodgs import polyline as pl

R = 0.01


def distance_to(points: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest of `curve`'s (dense) points."""
    return np.min(np.linalg.norm(points[:, None, :] - curve[None, :, :], axis=2), axis=1)


def test_a_cross_section_pulled_aside_by_a_leaf_does_not_bend_the_axis():
    # a straight axis 40 R long sampled every R/2, centroids scattered by 0.15 R; over 1 R in the
    # middle a leaf pulls the centroids 2 R aside (a node)
    x = np.arange(0, 40 * R, R / 2)
    rng = np.random.default_rng(0)
    points = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1) + rng.normal(0, 0.15 * R, (len(x), 3))
    node = np.abs(x - 20 * R) <= R / 2
    points[node, 1] += 2 * R
    smoothed = pl.smooth_axis(points, R)
    off = np.linalg.norm(smoothed[:, 1:], axis=1) / R
    assert off[node].max() < 0.2, off[node].max()
    # the scatter is smoothed, the ends included (they are fitted, not kept)
    assert off.max() < 0.5 and np.median(off) < 0.1, (off.max(), np.median(off))
    # a plain smoothing of the same length is pulled towards the leaf
    assert np.linalg.norm(pl.laplacian_smooth(points, 10)[node, 1:], axis=1).max() / R > 0.3


def test_the_parts_own_bends_are_kept():
    # a quarter circle of radius 8 R (a bent twig), scattered by 0.1 R
    angle = np.arange(0, np.pi / 2, (R / 2) / (8 * R))
    arc = 8 * R * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    rng = np.random.default_rng(1)
    smoothed = pl.smooth_axis(arc + rng.normal(0, 0.1 * R, arc.shape), R)
    dense = 8 * R * np.stack([np.cos(a := np.linspace(0, np.pi / 2, 2000)), np.sin(a), np.zeros_like(a)], axis=1)
    error = distance_to(smoothed, dense) / R
    assert error.mean() < 0.08 and error.max() < 0.3, (error.mean(), error.max())


def test_a_short_axis_that_zigzags_becomes_a_parabola():
    # a sprinkle 5 R long, gently bent, whose few Gaussians per cross-section zigzag its recentred
    # points by 0.8 R from one to the next (donut_sprinkle_d's jittered rods folded back by 3.2 R)
    x = np.arange(0, 5 * R + 1e-12, R / 2)
    axis = np.stack([x, 0.02 * (x / R) ** 2 * R, np.zeros_like(x)], axis=1)
    zigzag = axis + np.stack([np.zeros_like(x), 0.8 * R * (-1) ** np.arange(len(x)), np.zeros_like(x)], axis=1)
    smoothed = pl.smooth_axis(zigzag, R)
    # its turns are gone (the smoother alone left turns of 65-90 degrees), and it stays on the axis
    steps = np.diff(smoothed, axis=0)
    turns = np.abs(np.diff(np.degrees(np.arctan2(steps[:, 1], steps[:, 0]))))
    assert turns.max() < 20, turns
    assert distance_to(smoothed, axis).max() / R < 0.75


def test_a_short_axis_bending_under_half_a_radius_is_straight_and_one_bent_further_keeps_its_bend():
    # a straight sprinkle 8 R long whose few Gaussians scatter its recentred points by 0.3 R: their
    # parabola bends by a fraction of a radius, which the axis does not keep (jittered strokes bent
    # sprinkles' axes by 1-2 R at an end so)
    x = np.arange(0, 8 * R + 1e-12, R / 2)
    scatter = np.random.default_rng(3).normal(0, 0.3 * R, (len(x), 2))
    straight = pl.smooth_axis(np.stack([x, scatter[:, 0], scatter[:, 1]], axis=1), R)
    chord = (straight[-1] - straight[0]) / np.linalg.norm(straight[-1] - straight[0])
    off_chord = straight - straight[0] - ((straight - straight[0]) @ chord)[:, None] * chord
    assert np.linalg.norm(off_chord, axis=1).max() < 1e-9 * R
    # a part 8 R long bent 2.1 R off its chord (1.4 R off its least-squares line) keeps most of it
    u = x / (8 * R)
    bent = np.stack([x, 8.4 * R * u * (1 - u), np.zeros_like(u)], axis=1)
    assert distance_to(pl.smooth_axis(bent, R), bent).max() / R < 0.25


def test_a_short_part_bent_round_keeps_its_bend():
    # three diameters round a tight curve (180 degrees over 6 R: the ring's tip), kept as it is bent
    angle = np.linspace(0, np.pi, 13)
    arc = 6 * R / np.pi * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    smoothed = pl.smooth_axis(arc, R)
    assert distance_to(smoothed, arc).max() / R < 0.25


def test_no_smoothing_keeps_the_points_and_short_inputs_pass_through():
    points = np.random.default_rng(2).normal(size=(20, 3))
    np.testing.assert_array_equal(pl.smooth_axis(points, R, 0.0), points)
    np.testing.assert_array_equal(pl.smooth_axis(points[:4], R), points[:4])
    # points all in one place are no division by zero
    assert np.isfinite(pl.smooth_axis(np.zeros((10, 3)), R)).all()


def straight_with_hook(length_r: float, hook_r: float, turn_deg: float) -> np.ndarray:
    """A straight axis along x, `length_r` radii long, every R/2, whose first `hook_r` radii turn
    off it by `turn_deg` (the path stepping onto a bud at the part's end)."""
    x = np.arange(0, length_r * R + 1e-12, R / 2)
    axis = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    s = np.arange(hook_r * R, 0, -R / 2)[::-1]  # arc from the hook's base, outwards
    turn = np.radians(turn_deg)
    hook = np.stack([-s * np.cos(turn), s * np.sin(turn), np.zeros_like(s)], axis=1)
    return np.vstack([hook[::-1], axis])


def test_an_end_hooking_off_the_axis_is_cut_and_a_bend_is_kept():
    # a 90-degree hook of 2.5 R at the start: cut in two steps, the axis left where it was
    hooked = straight_with_hook(30, 2.5, 90)
    cut = pl.cut_hooked_ends(hooked, R)
    assert np.abs(cut[:, 1]).max() < 0.6 * R, np.abs(cut[:, 1]).max()
    assert pl.polyline_length(cut) > 28 * R
    # both ends are judged: the same hook at the far end goes too
    cut = pl.cut_hooked_ends(hooked[::-1], R)
    assert np.abs(cut[:, 1]).max() < 0.6 * R
    # a 30-degree turn at the end and the quarter circle of radius 8 R (a bent twig) are kept
    for kept in (
        straight_with_hook(30, 2.5, 30),
        8 * R * np.stack([np.cos(a := np.arange(0, np.pi / 2, 1 / 16)), np.sin(a), 0 * a], axis=1),
    ):
        np.testing.assert_array_equal(pl.cut_hooked_ends(kept, R), kept)
    # a part shorter than 6.5 R (a sprinkle): its hook is judged against the rest of its axis
    short = straight_with_hook(4, 1.5, 90)
    cut = pl.cut_hooked_ends(short, R)
    assert np.abs(cut[:, 1]).max() < 0.6 * R and pl.polyline_length(cut) > 3.5 * R
    # one shorter than 3.5 R is left alone, and points in one place are no division by zero
    tiny = straight_with_hook(1.5, 1.5, 90)
    np.testing.assert_array_equal(pl.cut_hooked_ends(tiny, R), tiny)
    assert len(pl.cut_hooked_ends(np.zeros((30, 3)), R)) == 30


def test_an_end_run_off_the_axis_for_radii_is_cut_at_its_corner_and_a_bend_is_kept():
    # a 6 R end run at 90 degrees (a leg's end run onto the other leg where they meet): too long for
    # the 1.5 R chord, cut at the corner; the axis is left as it was
    hooked = straight_with_hook(30, 6, 90)
    cut = pl.cut_hooked_ends(hooked, R)
    assert np.abs(cut[:, 1]).max() < 0.6 * R, np.abs(cut[:, 1]).max()
    assert pl.polyline_length(cut) > 29 * R
    assert np.abs(pl.cut_hooked_ends(hooked[::-1], R)[:, 1]).max() < 0.6 * R
    # a 30-degree bend 6 R from the end is the part's, and so is a 90-degree one on an axis under 20 R
    for kept in (straight_with_hook(30, 6, 30), straight_with_hook(12, 6, 90)):
        np.testing.assert_array_equal(pl.cut_hooked_ends(kept, R), kept)


def test_an_end_run_onto_something_in_front_and_back_is_cut_where_it_rejoins_the_axis():
    # Seen from the side: the axis along x, but its last 14 R (the stroke's end, where the part
    # passes behind a leaf) run 3 R along the part, 6.4 R out onto the leaf in front and 5 R back.
    # The sharpest corner is on the leaf; cut there, the leaf's leg back to the part would be the
    # new end, so it is judged again and goes too.
    corners = np.array([[0, 0], [3, 0], [8, -4], [11, 0], [40, 0]], float) * R
    pieces = [
        np.linspace(a, b, int(round(np.linalg.norm(b - a) / (R / 2))) + 1)[:-1] for a, b in zip(corners, corners[1:])
    ]
    side = np.vstack([*pieces, corners[-1:]])
    run = np.stack([side[:, 0], np.zeros(len(side)), side[:, 1]], axis=1)
    for drawn in (run, run[::-1]):
        cut = pl.cut_hooked_ends(drawn, R)
        assert np.abs(cut[:, 2]).max() < 0.6 * R, np.abs(cut[:, 2]).max()
        assert pl.polyline_length(cut) > 28 * R


def _seen_from(points: np.ndarray, eye_z: float = -1.0, focal: float = 800.0) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of `points` for a pinhole at (0, 0, eye_z) looking along +z, and R in pixels there."""
    depth = points[:, 2] - eye_z
    return focal * points[:, :2] / depth[:, None], focal * R / depth


def test_a_detour_in_depth_or_doubling_back_is_bridged_and_a_bend_is_kept():
    # a straight axis 30 R along x, every R/2; from 11 R to 15 R it runs 4 R towards the camera
    # and back (the path over a leaf in front of the stem), straight on screen
    x = np.arange(0, 30.01, 0.5) * R
    bump = 4 * R * np.clip(1 - np.abs(x - 13 * R) / (2 * R), 0, None)
    spiked = np.stack([x, 0 * x, -bump], axis=1)
    bridged = pl.bridge_detours(spiked, R, *_seen_from(spiked))
    assert np.abs(bridged[:, 2]).max() < 1e-12
    # the points outside it stay; those on it go onto the chord in order, spaced as along the arc
    outside = (x < 9.9 * R) | (x > 16.1 * R)
    np.testing.assert_array_equal(bridged[outside], spiked[outside])
    assert np.all(np.diff(bridged[:, 0]) > 0) and np.allclose(bridged[:, 1], 0)
    # the same excursion seen from the side (on screen it leaves the line, and its arc is 1.9
    # times its chord) is a bend, kept
    sideways = spiked[:, [0, 2, 1]]
    np.testing.assert_array_equal(pl.bridge_detours(sideways, R, *_seen_from(sideways)), sideways)
    # a finger out 4 R and back beside itself (a path onto a side branch at a node and back),
    # seen from any side: bridged, the axis straight again
    out = np.stack([np.full(8, 12.0), np.arange(0.5, 4.01, 0.5), np.zeros(8)], axis=1)
    finger = R * np.concatenate(
        [
            np.stack([x[x <= 12 * R] / R, 0 * x[x <= 12 * R], 0 * x[x <= 12 * R]], axis=1),
            out,
            out[::-1][1:] + [0.5, 0, 0],
        ]
        + [np.stack([x[x >= 12.5 * R] / R, 0 * x[x >= 12.5 * R], 0 * x[x >= 12.5 * R]], axis=1)]
    )
    for seen in (finger, finger[:, [0, 2, 1]]):
        assert np.abs(pl.bridge_detours(seen, R, *_seen_from(seen))[:, 1:]).max() < 1e-12
    # a shallow arch (2 R out over 12 R) is the part's own curve, kept
    arch = np.stack([x, 0 * x, -2 * R * np.sin(np.pi * np.clip((x - 9 * R) / (12 * R), 0, 1))], axis=1)
    np.testing.assert_array_equal(pl.bridge_detours(arch, R, *_seen_from(arch)), arch)
    # within 3 R of an end it is left to cut_hooked_ends
    at_end = np.stack([x, 0 * x, -4 * R * np.clip(1 - np.abs(x - 3 * R) / (2 * R), 0, None)], axis=1)
    np.testing.assert_array_equal(pl.bridge_detours(at_end, R, *_seen_from(at_end)), at_end)
    # too short to hold a stretch, and points in one place: unchanged, no division by zero
    for kept in (spiked[:2], np.zeros((30, 3))):
        np.testing.assert_array_equal(pl.bridge_detours(kept, R, *_seen_from(kept)), kept)


def _tube_gaussians(axis: np.ndarray, seed: int = 0) -> np.ndarray:
    """(N, 3) float32 centres over a tube of radius R around the polyline `axis` (points R/2 apart
    or closer), 40 per point, as a capture seen from all sides has them."""
    rng = np.random.default_rng(seed)
    tangent = pl.tangents(axis)
    side = np.cross(tangent, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    up = np.cross(tangent, side)
    angle = rng.uniform(0, 2 * np.pi, (len(axis), 40))
    ring = np.cos(angle)[..., None] * side[:, None] + np.sin(angle)[..., None] * up[:, None]
    return (axis[:, None] + R * rng.uniform(0.6, 1.0, angle.shape)[..., None] * ring).reshape(-1, 3).astype(np.float32)


def test_a_long_detour_in_depth_is_bridged_where_the_part_runs_on_behind_it():
    # A stem 40 R along x passes behind a leaf from 12 R to 28 R: the axis (recentred between the
    # leaf and the stem) runs 5 R towards the camera and back over 16 R, too long for a detour.
    x = np.arange(0, 40.01, 0.5) * R
    climb = 5 * R * np.clip(1 - np.abs(x - 20 * R) / (8 * R), 0, None)
    over_leaf = np.stack([x, 0 * x, -climb], axis=1)
    stem = np.stack([x, 0 * x, 0 * x], axis=1)
    seen = _seen_from(over_leaf)
    np.testing.assert_array_equal(pl.bridge_detours(over_leaf, R, *seen), over_leaf)
    # the capture has the stem's Gaussians behind the leaf: the axis goes onto the chord, back on it
    bridged = pl.bridge_detours(over_leaf, R, *seen, centres=_tube_gaussians(stem))
    assert np.abs(bridged[:, 2]).max() < 1e-12
    # a stem that itself bends towards the camera so: its Gaussians follow the bend, none lie on the
    # chord, and the bend is kept
    np.testing.assert_array_equal(pl.bridge_detours(over_leaf, R, *seen, centres=_tube_gaussians(over_leaf)), over_leaf)


def test_a_bump_out_and_back_into_line_is_bridged_and_a_bend_or_a_wave_is_kept():
    # a straight axis 30 R along x, every R/2; from 10 R to 16 R it runs 2.5 R aside and back into
    # line (the path onto a leaf pair's stalks at a node), seen from any side: bridged
    x = np.arange(0, 30.01, 0.5) * R
    tent = 2.5 * R * np.clip(1 - np.abs(x - 13 * R) / (3 * R), 0, None)
    for bumped in (np.stack([x, tent, 0 * x], axis=1), np.stack([x, 0 * x, -tent], axis=1)):
        bridged = pl.bridge_detours(bumped, R, *_seen_from(bumped))
        assert np.abs(bridged[:, 1:]).max() < 1e-12
        outside = (x < 9.9 * R) | (x > 16.1 * R)
        np.testing.assert_array_equal(bridged[outside], bumped[outside])
    # a bend of 40 degrees, and a wave 2 R high every 16 R: the part's own shape, kept
    bend = np.stack([x, np.maximum(x - 13 * R, 0) * np.tan(np.radians(40)), 0 * x], axis=1)
    wave = np.stack([x, 2 * R * np.sin(x / R * 2 * np.pi / 16), 0 * x], axis=1)
    for kept in (bend, wave):
        np.testing.assert_array_equal(pl.bridge_detours(kept, R, *_seen_from(kept)), kept)


def rings(x: np.ndarray, radius: float, count: int) -> np.ndarray:
    """`count` points on a circle of `radius` around the x axis at each of `x`, float32."""
    angle = np.arange(count) * 2 * np.pi / count
    return np.array([[xi, radius * np.cos(a), radius * np.sin(a)] for xi in x for a in angle], np.float32)


def test_an_end_that_turns_off_among_what_the_part_meets_is_cut_where_it_leaves_the_line():
    # a part 30 R long along x (its surface: rings of radius R every R/4); over its last 8 R what it
    # meets lies around it (rings 1.8 R off the axis: a node's leaves, a limb it joins)
    x = np.arange(0, 30 * R, R / 2)
    surface = rings(np.arange(0, 30 * R, R / 4), R, 12)
    around = np.concatenate([surface, rings(np.arange(22 * R, 30 * R, R / 4), 1.8 * R, 24)])
    straight = np.stack([x, 0 * x, 0 * x], axis=1)
    # its axis turns off over the last 3 R (onto a stalk the stroke's end led to)
    turned = straight.copy()
    turned[:, 1] = 0.6 * np.maximum(x - 27 * R, 0)
    cut = pl.cut_junction_ends(turned, around, R)
    assert np.abs(cut[:, 1]).max() <= 0.75 * R and cut[-1, 0] >= 27 * R, cut[-1] / R
    np.testing.assert_array_equal(cut, turned[: len(cut)])  # what is kept stays where it was
    np.testing.assert_array_equal(pl.cut_junction_ends(turned[::-1], around, R), cut[::-1])  # either end
    # so is one where what lies around the part is a bud over its last 3 R, which the stroke's end led onto
    bud = np.concatenate([surface, rings(np.arange(27 * R, 30 * R, R / 4), 1.8 * R, 24)])
    np.testing.assert_array_equal(pl.cut_junction_ends(turned, bud, R), cut)
    # kept: the same end where nothing lies around the part (its surface turning with it), a straight
    # end among what it meets, and a bend 8 R from the end (the part's own: over 5 R deep)
    turned_surface = surface.copy()
    turned_surface[:, 1] += np.repeat(0.6 * np.maximum(np.arange(0, 30 * R, R / 4) - 27 * R, 0), 12)
    bent = straight.copy()
    bent[:, 1] = 0.3 * np.maximum(x - 22 * R, 0)
    for points, centres in ((turned, turned_surface), (straight, around), (bent, around)):
        np.testing.assert_array_equal(pl.cut_junction_ends(points, centres, R), points)
    # a part crowded all along (a sprinkle on its icing) has no line to judge its end by
    crowded = np.concatenate([surface, rings(np.arange(0, 30 * R, R / 4), 1.8 * R, 24)])
    np.testing.assert_array_equal(pl.cut_junction_ends(turned[-20:], crowded, R), turned[-20:])


def test_a_stalk_past_a_node_is_cut_at_the_node_and_a_part_running_on_past_what_it_meets_is_kept():
    # a stem 27 R long along x; what it meets lies around its last 7 R (rings 1.8 R off the axis: a
    # node's leaves); the axis runs on 2 R past the node up a stalk that turns 45 degrees, free of the
    # node (so the last cross-sections are not crowded: the stroke's end led onto the stalk)
    x = np.arange(0, 27 * R, R / 2)
    diagonal = np.array([np.sqrt(0.5), np.sqrt(0.5), 0.0])
    stalk = np.array([27 * R, 0, 0]) + np.arange(R / 2, 2.01 * R, R / 2)[:, None] * diagonal
    points = np.concatenate([np.stack([x, 0 * x, 0 * x], axis=1), stalk])
    stalk_surface = rings(np.arange(-R / 2, 2 * R, R / 4), R, 12) @ np.array(
        [diagonal, [-diagonal[1], diagonal[0], 0], [0, 0, 1]]
    ).astype(np.float32) + np.array([27 * R, 0, 0], np.float32)
    node = rings(np.arange(20 * R, 27.5 * R, R / 4), 1.8 * R, 24)
    centres = np.concatenate([rings(np.arange(0, 27 * R, R / 4), R, 12), stalk_surface, node])
    cut = pl.cut_junction_ends(points, centres, R)
    assert np.abs(cut[:, 1]).max() <= 0.75 * R and cut[-1, 0] >= 27 * R and len(cut) < len(points), cut[-1] / R
    np.testing.assert_array_equal(cut, points[: len(cut)])
    np.testing.assert_array_equal(pl.cut_junction_ends(points[::-1], centres, R), cut[::-1])  # either end
    # kept: a part that runs on past what it meets, its axis pushed 1 R aside there and back parallel
    # (the guitar's front foot past the leg that stands on it; unguarded, this end lost 4 R)
    x = np.arange(0, 29.01 * R, R / 2)
    shift = np.clip((x - 24 * R) / (2 * R), 0, 1)
    shifted = np.stack([x, R * shift * shift * (3 - 2 * shift), 0 * x], axis=1)
    surface = rings(np.arange(0, 29.01 * R, R / 2), R, 12)
    surface[:, 1] += np.repeat(shifted[:, 1], 12).astype(np.float32)
    centres = np.concatenate([surface, node])
    np.testing.assert_array_equal(pl.cut_junction_ends(shifted, centres, R), shifted)
