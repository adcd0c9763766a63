"""Polyline post-processing (docs/extraction.md, "Polyline, segmentation, binding"): recentre visible surface
points onto the object's axis, smooth, resample (segmentation and binding: `segment`).

Smoothing, resampling and the recentring and binding logic are numpy; the two per-Gaussian loops
(nearest point on the polyline, cross-section sums) run in Rust (`sketchrodgs-polyline`), where
they take about a millisecond instead of tens. Shapes are in the docstrings.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solveh_banded
from scipy.spatial import cKDTree

from . import _core

# The axis is fitted this many times, each with weights from the last fit's residuals (Tukey's
# biweight, zero past `_TUKEY_RADII` radii: at 1.5 the pull of a leaf's base at a node or of the
# limb a branch joins bent the axis by 1-2 R; docs/extraction.md, "Polyline").
_ROBUST_FITS = 4
_TUKEY_RADII = 1.3
# An axis shorter than this many radii is smoothed into the least-squares parabola along its arc: a
# short part (a sprinkle) has a few Gaussians per cross-section, and its recentred points zigzag by
# a radius or more, which the smoother (over 2 pi R, longer than the part) passes through its ends
# (docs/extraction.md, "Polyline").
_SHORT_AXIS_RADII = 10.0
# ... unless its halves' chords turn by this many degrees or more (a part bent round within its few
# radii, such as the ring's tip stroked three diameters long: 88-94 degrees; sprinkles under 40-80)
_SHORT_AXIS_TURN = 60.0
# ... and that parabola is the least-squares line along the arc where it bends less than the first of
# these radii off that line, blended towards the parabola up to the second: so few cross-sections
# cannot tell a bend of half a radius from their scatter (jittered strokes bent a straight
# sprinkle's axis by 1-2 R at an end; docs/extraction.md, "Polyline, segmentation, binding")
_SHORT_AXIS_STRAIGHT = (0.5, 1.5)

# Recentring looks for the cross-section within 2.2 radii of a surface point, then refines twice
# around the centroid with a tighter reach (each pass also steadies the tangent that orients the slab).
REACHES = (2.2, 1.5, 1.5)
# cut_hooked_ends: an end's first radii, the axis beyond them (to this far from the end, or to the
# other end on a short axis, at least _HOOK_AXIS_LEAST long), the turn that is a hook, how often an
# end is cut (at 60 degrees, or once an end, the main stem's ends stayed hooked), and how much a
# cut leaves at least
_HOOK_REACH = 1.5
_HOOK_INWARD = 5.0
_HOOK_AXIS_LEAST = 2.0
_HOOK_DEG = 45.0
_HOOK_CUTS = 3
_HOOK_KEEP = 2.0
# ... then corners: within _CORNER_REACH radii of an end, the directions over the _CORNER_BEFORE
# radii before a point and the _CORNER_AFTER radii after it turning by over _CORNER_DEG (the hook's
# angle at the scale of radii); axes under _CORNER_LEAST radii are left alone, and a cut leaves
# that less _CORNER_REACH
_CORNER_DEG = 45.0
_CORNER_BEFORE = 2.0
_CORNER_AFTER = 4.0
_CORNER_REACH = 10.0
_CORNER_LEAST = 20.0
# hooks and corners are cut again while a round cuts, at most this many rounds
_CUT_ROUNDS = 3
# bridge_detours: the longest stretch bridged; how far it leaves its chord in depth and how little
# on screen; how many times its chord its arc is where it doubles back, and how far it then leaves
# the chord; how far from the ends it lies (ends are cut_hooked_ends'). In radii but the ratio.
_DETOUR_SPAN = 10.0
_DETOUR_DEPTH = 3.5
_DETOUR_SCREEN = 0.7
_DETOUR_BACK_RATIO = 2.5
_DETOUR_BACK = 3.0
_DETOUR_END = 3.0
# ... and a longer one in depth, up to _BEHIND_SPAN radii and within _BEHIND_SCREEN of its chord on
# screen, where the part runs on behind it: every chord sample has _BEHIND_CHORD times as many
# Gaussians within R as the axis around the stretch has (the median over _BEHIND_AROUND radii each
# side), and some point of the stretch under _BEHIND_GAP times as many
_BEHIND_SPAN = 20.0
_BEHIND_SCREEN = 1.5
_BEHIND_CHORD = 0.5
_BEHIND_GAP = 0.25
_BEHIND_AROUND = 5.0
_NEVER = 1e9  # a limit no stretch reaches (the doubling back is not judged in that pass)
# bridge_detours, bumps: the longest stretch, how far it leaves its chord, within what angle (deg)
# of the chord the axis runs over how long a lead either side, how far from the ends it lies
_BUMP_SPAN = 8.0
_BUMP_OFF = 1.5
_BUMP_ANGLE = 15.0
_BUMP_LEAD = 3.0
_BUMP_END = 3.0
# cut_junction_ends: over the first `_JUNCTION_REGION` radii of each end, how crowded each cross-section
# `2 * _JUNCTION_SLAB` R thick is (`_core.crowding`: the Gaussians `_JUNCTION_INNER` to `_JUNCTION_OUTER` R
# off the axis over those within `_JUNCTION_INNER` R; averaged with its two neighbours); an end run
# crowded over `_JUNCTION_CROWDED` is judged against the line of the `_JUNCTION_BODY` R of axis just
# inward of it, and cut from where it strays over `_JUNCTION_OFF` R from that line, unless that lies
# over `_JUNCTION_DEEPEST` R from the end. A run may also start up to `_JUNCTION_FREE_TIP` R in from the end
# (past a node onto a stalk); that free tip is cut only where it heads over `_JUNCTION_TURN` degrees off the line
_JUNCTION_REGION = 16.0
_JUNCTION_SLAB = 0.5
_JUNCTION_INNER = 1.25
_JUNCTION_OUTER = 2.5
_JUNCTION_CROWDED = 0.4
_JUNCTION_BODY = 6.0
_JUNCTION_OFF = 0.75
_JUNCTION_DEEPEST = 5.0
_JUNCTION_FREE_TIP = 2.0
_JUNCTION_TURN = 30.0


def tangents(points: np.ndarray, reach: int = 1) -> np.ndarray:
    """(M, 3) unit tangents of a polyline: the direction from point i - reach to point i + reach
    (clipped at the ends, so the ends look `reach` points inwards)."""
    if len(points) < 2:
        return np.zeros_like(points)
    index = np.arange(len(points))
    t = points[np.minimum(index + reach, len(points) - 1)] - points[np.maximum(index - reach, 0)]
    norms = np.linalg.norm(t, axis=1, keepdims=True)
    return np.divide(t, norms, out=np.zeros_like(t), where=norms > 0)


def recentre(
    points: np.ndarray, centres: np.ndarray, radius: float, reach_scale: np.ndarray | None = None
) -> np.ndarray:
    """Move points on an object's surface onto its axis.

    Each point becomes the centroid of its cross-section: the Gaussians within R/2 of its plane
    across the local tangent and within 2.2 R of it; then twice more within 1.5 R of the moved
    points. A cross-section of one Gaussian or none (a part of few, such as a sprinkle) is taken
    within R of the plane instead; points with no Gaussians around even then stay where they are.

    Args:
        points: (M, 3) polyline on the visible surface, in order, about R/2 apart.
        centres: (N, 3) Gaussian centres near the object (a pre-filtered subset keeps it fast).
        radius: R, the object's radius.
        reach_scale: (M,) how far each point's cross-sections reach, as a share of those reaches
            (where the part shows thinner than R: `extract._outlined_scale`); None: 1 everywhere.

    Returns:
        (M, 3) float64 recentred points.
    """
    axis = np.ascontiguousarray(points, np.float64)
    if len(centres) == 0 or len(axis) < 2:
        return axis.copy()
    members = _f32(centres)
    # The points move by about R at most, so a Gaussian's cross-sections stay among its nearest
    # point (found once, here) and that point's neighbours (points are ~R/2 apart, a slab R wide).
    segment, t, _ = _core.nearest_on_polyline(_f32(axis), members, (REACHES[0] + 1) * radius)
    nearest = np.where(segment >= 0, segment + (t >= 0.5), -1).astype(np.int32)
    scale = None if reach_scale is None else np.ascontiguousarray(reach_scale, np.float64)
    for reach in REACHES:
        # surface points are noisy: take tangents over +-2 R of the smoothed line
        spacing = max(polyline_length(axis) / (len(axis) - 1), 1e-12)
        tangent = tangents(laplacian_smooth(axis, 5), reach=max(1, int(round(2 * radius / spacing))))
        axis, _ = _core.cross_section_centroids(
            axis, tangent, members, nearest, radius / 2, radius, reach * radius, scale
        )
    return _straighten_ends(axis, np.asarray(points, np.float64), radius)


def _straighten_ends(axis: np.ndarray, surface: np.ndarray, radius: float) -> np.ndarray:
    """Within R of each end a cross-section is cut short by the object's end and its centroid is
    unreliable: put those points on the axis line continued from R inwards, level with where the
    surface points were."""
    spacing = polyline_length(axis) / max(len(axis) - 1, 1)
    k = int(np.ceil(radius / max(spacing, 1e-12)))
    if len(axis) < 2 * k + 3:
        return axis
    t = tangents(axis, reach=k)
    for ends, anchor in ((np.arange(k), k), (np.arange(len(axis) - k, len(axis)), len(axis) - 1 - k)):
        along = (surface[ends] - axis[anchor]) @ t[anchor]
        axis[ends] = axis[anchor] + along[:, None] * t[anchor]
    return axis


def smooth_axis(points: np.ndarray, radius: float, length: float = 1.0) -> np.ndarray:
    """Smooth a recentred axis: a Whittaker smoother with a third-difference penalty over the points
    (taken as evenly spaced along the arc), fitted again with Tukey weights from the residuals so
    that a cross-section pulled aside by what touches the part (a leaf at a node, a body at an end)
    does not bend the axis. The third difference leaves circular arcs alone, ends included (a
    curvature penalty would straighten the last radii of a bent part). An axis shorter than
    `_SHORT_AXIS_RADII` radii whose halves turn by less than `_SHORT_AXIS_TURN` then becomes the
    least-squares parabola along its arc, or its line where that parabola bends less than
    `_SHORT_AXIS_STRAIGHT` radii off the line.

    Args:
        points: (M, 3) axis points in order, about R/2 apart.
        radius: R, the object's radius.
        length: the smoothing length in radii: bends much shorter than 2 pi `length` R are smoothed
            out. 0: no smoothing.

    Returns:
        (M, 3) float64.
    """
    points = np.asarray(points, np.float64)
    n = len(points)
    spacing = polyline_length(points) / max(n - 1, 1)
    if length <= 0 or n < 5 or not spacing > 0:
        return points.copy()
    # the penalty passes wavenumbers below about 1 / (length / spacing) per sample
    lam = (length * radius / spacing) ** 6
    penalty = lam * _third_difference_gram(n)
    weights = np.ones(n)
    fit = points
    for _ in range(_ROBUST_FITS):
        system = penalty.copy()
        system[-1] += weights  # the main diagonal
        fit = solveh_banded(system, weights[:, None] * points)
        residual = np.linalg.norm(points - fit, axis=1) / (_TUKEY_RADII * radius)
        weights = np.where(residual < 1, (1 - residual**2) ** 2, 0.0) + 1e-3
    arc = arc_lengths(fit)
    if 0 < arc[-1] < _SHORT_AXIS_RADII * radius and _chord_turn(fit) < _SHORT_AXIS_TURN:
        fit = _straightened(_least_squares_along(fit, arc, 2), _least_squares_along(fit, arc, 1), radius)
    return np.asarray(fit, np.float64)


def _least_squares_along(points: np.ndarray, arc: np.ndarray, degree: int) -> np.ndarray:
    """The least-squares polynomial of `degree` in the arc length `arc` through `points`, at `arc`."""
    powers = np.vander(arc / arc[-1], degree + 1)
    return powers @ np.linalg.lstsq(powers, points, rcond=None)[0]


def _straightened(parabola: np.ndarray, line: np.ndarray, radius: float) -> np.ndarray:
    """A short axis's `parabola`, taken to its `line` by how little it bends off it: all the way
    under `_SHORT_AXIS_STRAIGHT[0]` radii, not at all over `_SHORT_AXIS_STRAIGHT[1]`, in proportion
    between (no step, so that a jittered stroke does not flip a part between the two)."""
    low, high = _SHORT_AXIS_STRAIGHT
    bend = float(np.linalg.norm(parabola - line, axis=1).max()) / radius
    share = float(np.clip((bend - low) / (high - low), 0.0, 1.0))
    return line + share * (parabola - line)


def _chord_turn(points: np.ndarray) -> float:
    """The angle in degrees between the chords of the first and the second half of `points`."""
    first, second = points[len(points) // 2] - points[0], points[-1] - points[len(points) // 2]
    cosine = np.dot(first, second) / max(float(np.linalg.norm(first) * np.linalg.norm(second)), 1e-30)
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def cut_hooked_ends(points: np.ndarray, radius: float) -> np.ndarray:
    """Cut the ends that hook off the axis (docs/extraction.md, "Polyline"). Where the chord over an
    end's first `_HOOK_REACH` radii turns by more than `_HOOK_DEG` from the axis over the radii
    after it (to `_HOOK_INWARD`, or to the other end of an axis shorter than that), those radii go,
    up to `_HOOK_CUTS` times an end. A slender part seldom turns that sharply within a radius or
    two of its end: the hook is mostly the path stepping onto what the part touches there (a bud,
    a leaf's base, the body a leg stands on). Axes shorter than `_HOOK_REACH + _HOOK_AXIS_LEAST`
    radii are left alone, and no cut leaves less than `_HOOK_KEEP` radii. Then the corners
    (`_uncornered`); where a round cut anything, the new ends are judged again.

    Args:
        points: (M, 3) axis points in order.
        radius: R, the object's radius.

    Returns:
        (K, 3) float64, the points kept (K <= M).
    """
    points = np.array(points, np.float64)
    # A corner cut can leave the run's other leg as the new end (the path stepped from the part onto
    # a leaf in front near the end and back): judged again, at most `_CUT_ROUNDS` times.
    for _ in range(_CUT_ROUNDS):
        count = len(points)
        points = _uncornered(_unhooked(points, radius), radius)
        if len(points) == count:
            break
    return points


def cut_junction_ends(points: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Cut the ends that turn off the part where it meets something (docs/extraction.md, "Ends at a
    junction"). Where a part ends at a node, a fork or a thicker part it joins, what it meets lies
    around its last cross-sections (they are crowded: `_core.crowding`), and the path and the axis
    follow whichever stalk or side the stroke's last pixels lead to. Such an end run is cut where the
    axis strays from the line of the part before it; a part that runs on straight through a crowded
    end keeps it. Within a crowded run the end's course says nothing about the part. A rod that ran
    through a node and a little way up a stalk past it (a free tip) is cut there if that tip turns off.

    Args:
        points: (M, 3) axis points in order, about R/2 apart.
        centres: (N, 3) float32 Gaussian centres around the part (those the recentring read).
        radius: R, the object's radius.

    Returns:
        (K, 3) float64, the points kept (K <= M); all of them where less than 2 R would be left.
    """
    points = np.asarray(points, np.float64)
    keep = [0, len(points)]
    for end in (0, 1):
        cut = _junction_cut(points if end == 0 else points[::-1], centres, radius)
        keep[end] = cut if end == 0 else len(points) - cut
    kept = points[keep[0] : keep[1]]
    return kept if len(kept) > 1 and polyline_length(kept) >= 2 * radius else points


def _junction_cut(q: np.ndarray, centres: np.ndarray, radius: float) -> int:
    """How many points of `q`'s start `cut_junction_ends` cuts (0: none)."""
    arc = arc_lengths(q)
    region = q[: int(np.searchsorted(arc, _JUNCTION_REGION * radius, side="right"))]
    if len(region) < 4:
        return 0
    spacing = max(polyline_length(region) / (len(region) - 1), 1e-12)
    tangent = tangents(region, reach=max(1, int(round(2 * radius / spacing))))

    def crowding(count: int) -> np.ndarray:
        rows = near_box(region[:count], centres, (_JUNCTION_OUTER + 0.1) * radius)
        return _core.crowding(
            np.ascontiguousarray(region[:count]),
            np.ascontiguousarray(tangent[:count]),
            np.ascontiguousarray(np.take(centres, rows, axis=0), np.float32),
            _JUNCTION_SLAB * radius,
            _JUNCTION_INNER * radius,
            _JUNCTION_OUTER * radius,
        )

    # each averaged with its neighbours; past the end, as with none around (so the last two must be
    # clearly crowded: with the end's own value repeated past it, the guitar's front foot's rod ended
    # 6 R short of its path at the leg it meets). Most ends are free: their first few tell at once.
    tip = int(np.searchsorted(arc, _JUNCTION_FREE_TIP * radius, side="right"))
    near = np.convolve(crowding(min(tip + 1, len(region))), np.ones(3) / 3, mode="same")[:tip]
    if (near < _JUNCTION_CROWDED).all():
        return 0
    crowded = np.convolve(crowding(len(region)), np.ones(3) / 3, mode="same") >= _JUNCTION_CROWDED
    # the crowded run at the end, or just inward of a free tip; it must end before the region does
    # (a part crowded all along, a sprinkle on its icing, has no line of its own to judge its end by)
    first = int(np.argmax(crowded))
    if crowded[first:].all():
        return 0
    run = first + int(np.argmin(crowded[first:]))
    inner = int(np.searchsorted(arc, arc[run] + _JUNCTION_BODY * radius))
    if inner >= len(q):
        return 0
    direction = q[run] - q[inner]
    direction /= max(float(np.linalg.norm(direction)), 1e-30)
    if first > 0:  # a free tip past the crowded run: cut only if it turns off (a stalk past a node)
        heading = q[0] - q[tip]
        if float(heading @ direction) > np.cos(np.radians(_JUNCTION_TURN)) * float(np.linalg.norm(heading)):
            return 0
    offset = q[: run + 1] - q[run]
    off = np.linalg.norm(offset - (offset @ direction)[:, None] * direction, axis=1)
    stray = np.flatnonzero(off > _JUNCTION_OFF * radius)
    if len(stray) == 0:
        return 0
    cut = int(stray[-1]) + 1  # the innermost point that strays goes, and all outward of it
    return cut if arc[cut] <= _JUNCTION_DEEPEST * radius else 0


def _uncornered(points: np.ndarray, radius: float) -> np.ndarray:
    """`points` cut at each end's sharpest corner within `_CORNER_REACH` radii of it, if one turns
    by over `_CORNER_DEG`: a hook too long for the 1.5 R chord of `_unhooked` (a leg's end run onto
    the other leg where they meet, a foot's onto the leg)."""
    keep = [0, len(points)]
    if len(points) < 2 or polyline_length(points) < _CORNER_LEAST * radius:
        return points
    for end in (0, 1):
        q = points if end == 0 else points[::-1]
        arc = arc_lengths(q) / radius
        at = np.arange(1.5, _CORNER_REACH + 1e-9, 0.25)
        at = at[at <= arc[-1] - (_CORNER_LEAST - _CORNER_REACH)]
        corner, before, after = (
            np.searchsorted(arc, a) for a in (at, np.maximum(at - _CORNER_BEFORE, 0), at + _CORNER_AFTER)
        )
        inward, outward = q[corner] - q[before], q[after] - q[corner]
        norms = np.linalg.norm(inward, axis=1) * np.linalg.norm(outward, axis=1)
        cosine = np.sum(inward * outward, axis=1) / np.where(norms > 0, norms, np.inf)
        sharp = (norms > 0) & (cosine < np.cos(np.radians(_CORNER_DEG)))
        if sharp.any():
            cut = int(corner[np.flatnonzero(sharp)[np.argmin(cosine[sharp])]])
            keep[end] = cut if end == 0 else len(points) - cut
    return points[keep[0] : keep[1]]


def bridge_detours(
    points: np.ndarray, radius: float, uv: np.ndarray, radius_px: np.ndarray, centres: np.ndarray | None = None
) -> np.ndarray:
    """Bridge the detours of the axis (docs/extraction.md, "Polyline", **Detours**): stretches of at
    most `_DETOUR_SPAN` radii that leave their chord and come back, either in depth (by more than
    `_DETOUR_DEPTH` radii, staying within `_DETOUR_SCREEN` radii of the chord on screen: the path
    climbed onto a leaf in front of the part, or dropped behind it) or doubling back (an arc at
    least `_DETOUR_BACK_RATIO` times the chord, leaving it by more than `_DETOUR_BACK` radii: the
    path ran out onto a side branch or a leaf at a node and back). A part seldom does either within
    a few radii. The points of each go onto its chord, spaced as they were along the arc. Stretches
    within `_DETOUR_END` radii of an end are left to `cut_hooked_ends`. The search (in Rust) takes
    points about R apart.

    With `centres`, then the longer detours in depth (up to `_BEHIND_SPAN` radii, within
    `_BEHIND_SCREEN` of the chord on screen) over which the part runs on behind what the path
    climbed onto: its Gaussians lie along the chord, and the axis left them (`_part_runs_behind`;
    docs/extraction.md, "Polyline", **Behind a leaf**).

    Then the bumps: stretches of at most `_BUMP_SPAN` radii leaving their chord by more than
    `_BUMP_OFF` radii where the axis runs within `_BUMP_ANGLE` degrees of that chord over
    `_BUMP_LEAD` radii on both sides (the path ran onto a leaf pair's stalks at a node and back).

    Args:
        points: (M, 3) axis points in order, about R/2 apart.
        radius: R, the object's radius.
        uv: (M, 2) the points projected into the stroke's camera (pixels).
        radius_px: (M,) R in pixels at each point's depth.
        centres: (N, 3) the part's Gaussian centres around the axis (those the recentring read), or
            None (no pass behind a leaf).

    Returns:
        (M, 3) float64.
    """
    points = np.array(points, np.float64, order="C")
    if len(points) < 3 or not polyline_length(points) > 0:
        return points
    uv = np.ascontiguousarray(uv, np.float64)
    radius_px = np.ascontiguousarray(radius_px, np.float64)
    every = _about_radius_apart(points, radius)
    limits = (_DETOUR_SPAN, _DETOUR_DEPTH, _DETOUR_SCREEN, _DETOUR_BACK_RATIO, _DETOUR_BACK, _DETOUR_END)
    _onto_chords(points, every[_core.detours(points[every], uv[every], radius_px[every], radius, *limits)])
    if centres is not None and len(centres):
        every = _about_radius_apart(points, radius)
        limits = (_BEHIND_SPAN, _DETOUR_DEPTH, _BEHIND_SCREEN, _NEVER, _NEVER, _DETOUR_END)
        longer = every[_core.detours(points[every], uv[every], radius_px[every], radius, *limits)]
        _onto_chords(points, longer[_part_runs_behind(points, longer, centres, radius)])
    every = _about_radius_apart(points, radius)
    bumps = _core.bumps(
        np.ascontiguousarray(points[every]), radius, _BUMP_SPAN, _BUMP_OFF, _BUMP_ANGLE, _BUMP_LEAD, _BUMP_END
    )
    _onto_chords(points, every[bumps])
    return points


def _part_runs_behind(points: np.ndarray, stretches: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Per stretch (i, j) of `points`: whether the part's Gaussians run along its chord and the axis
    over it leaves them (docs/extraction.md, "Polyline", **Behind a leaf**)."""
    keep = np.zeros(len(stretches), bool)
    step = max(polyline_length(points) / max(len(points) - 1, 1), 1e-12)
    around = max(1, int(round(_BEHIND_AROUND * radius / step)))
    for k, (i, j) in enumerate(stretches):
        lo, hi = max(i - around, 0), min(j + around, len(points) - 1)
        samples = max(2, int(np.ceil(np.linalg.norm(points[j] - points[i]) / (radius / 2))) + 1)
        chord = points[i] + np.linspace(0.0, 1.0, samples)[:, None] * (points[j] - points[i])
        region = points[lo : hi + 1]
        near = cKDTree(np.take(centres, near_box(region, centres, radius), axis=0).astype(np.float64))
        count = near.query_ball_point(np.vstack([region, chord]), radius, return_length=True)
        on_axis, on_chord = count[: len(region)], count[len(region) :]
        beside = np.concatenate([on_axis[: i - lo], on_axis[j - lo + 1 :]])
        if len(beside) == 0:
            continue
        typical = float(np.median(beside))
        keep[k] = on_chord.min() >= _BEHIND_CHORD * typical > 0 and on_axis[i - lo : j - lo + 1].min() < (
            _BEHIND_GAP * typical
        )
    return keep


def _about_radius_apart(points: np.ndarray, radius: float) -> np.ndarray:
    """Every k-th point's index, k chosen so that they lie about R apart (a detour or bump is
    several radii long: a quarter of the work of points R / 2 apart)."""
    length = polyline_length(points)
    return np.arange(0, len(points), max(1, min(round(radius * (len(points) - 1) / length), len(points))))


def _onto_chords(points: np.ndarray, stretches: np.ndarray) -> None:
    """Put the points inside each stretch (i, j) onto its chord, spaced as they were along the arc
    (in place)."""
    arc = arc_lengths(points)
    for i, j in stretches:
        along = (arc[i : j + 1] - arc[i]) / (arc[j] - arc[i])
        points[i + 1 : j] = points[i] + along[1:-1, None] * (points[j] - points[i])


def _unhooked(points: np.ndarray, radius: float) -> np.ndarray:
    """`points` less the first `_HOOK_REACH` radii of each end that hooks, up to `_HOOK_CUTS` times."""
    for _ in range(_HOOK_CUTS):
        kept = _hook_cut(points, radius)
        if len(kept) == len(points):
            break
        points = kept
    return points


def _hook_cut(points: np.ndarray, radius: float) -> np.ndarray:
    """`points` less the first `_HOOK_REACH` radii of each end that hooks (one cut an end)."""
    keep = [0, len(points)]
    length = polyline_length(points)
    if length < (_HOOK_REACH + _HOOK_AXIS_LEAST) * radius:
        return points
    for end in (0, 1):
        q = points if end == 0 else points[::-1]
        arc = arc_lengths(q)
        cut = int(np.searchsorted(arc, _HOOK_REACH * radius))
        # a sprinkle's axis is shorter than _HOOK_INWARD: the rest of it is the axis (its hooks
        # were left alone, and a jittered stroke's rod hooked 1.85 R off at an end)
        inner = min(int(np.searchsorted(arc, _HOOK_INWARD * radius)), len(q) - 1)
        chord, axis = q[cut] - q[0], q[inner] - q[cut]
        norms = float(np.linalg.norm(chord) * np.linalg.norm(axis))
        if norms > 0 and chord @ axis < np.cos(np.radians(_HOOK_DEG)) * norms:
            keep[end] = cut if end == 0 else len(points) - cut
    kept = points[keep[0] : keep[1]]
    return kept if len(kept) > 1 and polyline_length(kept) >= _HOOK_KEEP * radius else points


def _third_difference_gram(n: int) -> np.ndarray:
    """D^T D for the (n - 3, n) third-difference matrix D, as the (4, n) upper banded form of
    `scipy.linalg.solveh_banded` (row 3 the main diagonal, row 3 - k the k-th superdiagonal)."""
    stencil = np.array([-1.0, 3.0, -3.0, 1.0])
    banded = np.zeros((4, n))
    # each row r of D adds stencil[a] * stencil[a + k] at (r + a, r + a + k), that is at column
    # r + a + k of the k-th superdiagonal
    for k in range(4):
        for a in range(4 - k):
            banded[3 - k, a + k : a + k + n - 3] += stencil[a] * stencil[a + k]
    return banded


def near_box(polyline: np.ndarray, centres: np.ndarray, margin: float) -> np.ndarray:
    """Rows of `centres` (N, 3) float32 inside the polyline's bounding box grown by `margin` (a cheap
    pre-filter; one parallel pass in Rust, as scenes hold millions of centres)."""
    low = np.asarray(polyline, np.float64).min(axis=0) - margin
    high = np.asarray(polyline, np.float64).max(axis=0) + margin
    # float32 bounds rounded outwards, so that no centre inside the float64 box is missed
    low32 = np.nextafter(low.astype(np.float32), np.float32(-np.inf))
    high32 = np.nextafter(high.astype(np.float32), np.float32(np.inf))
    return _core.rows_in_box(np.ascontiguousarray(centres, np.float32), _triple(low32), _triple(high32))


def _triple(v: np.ndarray) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])


def laplacian_smooth(points: np.ndarray, iterations: int, weight: float = 0.5) -> np.ndarray:
    """Laplacian smoothing with the ends fixed: x_i += weight * ((x_{i-1} + x_{i+1}) / 2 - x_i)."""
    out = np.asarray(points, np.float64).copy()
    for _ in range(iterations):
        if len(out) < 3:
            break
        out[1:-1] += weight * (0.5 * (out[:-2] + out[2:]) - out[1:-1])
    return out


def arc_lengths(points: np.ndarray) -> np.ndarray:
    """(M,) float64 the arc length at each point of a polyline (0 at the first)."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(np.asarray(points, np.float64), axis=0), axis=1))])


def point_at(points: np.ndarray, arc: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points at arc lengths `s` along the polyline `points` (any dimension) whose arc lengths are
    `arc` (linear interpolation)."""
    return np.stack([np.interp(s, arc, points[:, k]) for k in range(points.shape[1])], axis=1)


_NEAREST_CHUNK = 512  # points per block in the point-to-segment search


def nearest_on_polyline(points: np.ndarray, polyline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each of `points` to `polyline` (any dimension) and the arc length of the
    nearest point on it."""
    starts, ends = polyline[:-1], polyline[1:]
    edges = ends - starts
    lengths2 = np.einsum("ij,ij->i", edges, edges)
    safe = np.where(lengths2 > 0, lengths2, 1.0)
    arc = arc_lengths(polyline)
    seg_len = np.sqrt(lengths2)
    distance = np.empty(len(points))
    where = np.empty(len(points))
    for lo in range(0, len(points), _NEAREST_CHUNK):
        block = points[lo : lo + _NEAREST_CHUNK]
        rel = block[:, None, :] - starts[None, :, :]
        t = np.clip(np.einsum("pmk,mk->pm", rel, edges) / safe, 0.0, 1.0)
        t = np.where(lengths2 > 0, t, 0.0)
        diff = rel - t[:, :, None] * edges[None, :, :]
        d2 = np.einsum("pmk,pmk->pm", diff, diff)
        best = np.argmin(d2, axis=1)
        rows = np.arange(len(block))
        distance[lo : lo + _NEAREST_CHUNK] = np.sqrt(d2[rows, best])
        where[lo : lo + _NEAREST_CHUNK] = arc[best] + t[rows, best] * seg_len[best]
    return distance, where


def in_plane(xy: np.ndarray) -> np.ndarray:
    """(N, 2) pixel coordinates as (N, 3) float32 points at z = 0, for the Rust point-to-polyline
    search on screen (`_core.nearest_on_polyline`)."""
    return np.ascontiguousarray(np.column_stack([xy, np.zeros(len(xy))]), np.float32)


def polyline_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def default_edge_length(length: float, radius: float) -> float:
    """Edge length from the object: about the radius, but between length/150 and length/8."""
    return float(min(max(radius, length / 150), length / 8))


def resample(points: np.ndarray, edge_length: float) -> np.ndarray:
    """Resample a polyline at uniform arc length; the ends are kept.

    Args:
        points: (M, 3).
        edge_length: target spacing; the actual spacing is length / round(length / edge_length).

    Returns:
        (K, 3) float64 with K >= 2.
    """
    points = np.asarray(points, np.float64)
    arc = arc_lengths(points)
    edges = max(1, int(round(arc[-1] / edge_length))) if edge_length > 0 else 1
    s = np.linspace(0.0, arc[-1], edges + 1)
    return np.stack([np.interp(s, arc, points[:, k]) for k in range(3)], axis=1)


def _f32(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float32)
