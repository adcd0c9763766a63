"""Segmentation and binding (docs/deformation.md, "Segmentation"): which Gaussians follow a rod,
and where each sits on the rest polyline.

The sets, found over a proximity graph of Gaussian centres (centres closer than the link
distance are neighbours, so a gap in the cloud separates parts):
- the part: grown from the Gaussians within R of the axis over neighbours within `grow * R` of
  the axis and within the rod's extent along it, so that a cross-section that is not round (the
  fretboard edge of a guitar neck) goes whole, and a neighbour across a gap stays; a surface of
  another colour that the part lies on (a floor, a table) is left out where its centres form a
  sheet beside the axis;
- attached parts: what hangs on the part and is small (every piece of it within `attach_size` of
  where it joins, or within `attach_size_fewer` where it holds no more Gaussians than the part; a
  leaf on its petiole, the leaves at a branch tip). Each rides rigidly with the rod point where it
  joins. Large bodies the rod joins (a pot, a trunk, a guitar body) reach further and stay, and so
  does a piece of another slender part that joins the rod (a stand's leg on its foot): where that
  part's Gaussians thin out, a piece of it is a component of its own at the part's link, and it
  would swing off the rest (`_without_pieces_of_other_parts`);
- continuations: what continues the part past an end and fits within `continuation_size` of it
  (the tip of a stem with its leaves, past where the stroke stopped); each rides rigidly with that
  end. A clamped end does not move, so they move only with a free end (`Animation(clamp=...)`);
  what runs on further (the rest of the plant past a stem's base) stays;
- strays: small clusters (at most `STRAY_SIZE` R across) within `STRAY_REACH` R of what moves past
  the rod's ends or of its attached parts, across a gap wider than a link but joined to nothing
  else (the halo of floaters around a guitar's headstock). Left behind, they would hang in the air
  where the part was; each rides with the moving Gaussian nearest it;
- haze: around attached parts, clusters of faint, large Gaussians that lie wholly within
  `HAZE_RADII` R of them (the blur a capture puts around a leaf); left behind, a faint copy of the
  leaf stayed where it had hung. Each rides with the attached Gaussian nearest it;
- specks: such clusters that reach within `SPECK_RADII` R of the axis anywhere along it, inside
  the part's tube but linked to nothing (two opaque Gaussians on a tree tip); bound as the part's
  own Gaussians are.

No band of partly moving Gaussians around the part: where the part has a gap around it there is
nothing to blend with, and where it touches something (a crossing branch) a band 1 R wide made
the tears of a real pull three times as many, and the needles six (docs/deformation.md). Motion
eases in at clamped ends instead (`skin.Rig`).

The work runs in Rust in one call (`sketchrodgs_polyline::segment`, a few ms for a rope of 25k
Gaussians); the NumPy implementation it replaced is the test oracle
(`tests/reference/segment_reference.py`), which it matches to the bit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from . import _core
from .errors import SketchRodGSError
from .polyline import arc_lengths, near_box, polyline_length
from .scene import GaussianScene

# The part's cross-section reaches this many R from the axis. Surface Gaussians sit at about one
# radius from the axis, and on real captures their centres scatter well past the visible
# half-width (the estimated R): at 1.5 R a pulled plant stem left a ghost of itself behind.
DEFAULT_GROW = 2.5
ATTACH_SHARE = 0.5  # attached parts up to this share of the rod's length,
# and between these many R: the bundled plant's leaves reach up to 10.3 R from where they join a
# stem of 20 R, a tree's twigs 9-9.8 R from a branch of 15 R (docs/deformation.md)
ATTACH_MIN, ATTACH_MAX = 12.0, 20.0
# A part that holds no more Gaussians than the rod's own may reach this far: a long stem's leaves
# reach 20-23 R; the pot under a main stem's base (21.5 R from where the stem enters) holds more.
ATTACH_FEWER_MAX = 25.0
CONTINUATION_SHARE = 1.0  # past an end, what fits within the rod's length continues it,
CONTINUATION_MIN, CONTINUATION_MAX = 8.0, 20.0  # and between these many R
CONTINUATION_LINKS = 2.0  # linked at twice the part's link: a leaf's big faint Gaussians sit further apart
END_MARGIN = 3.0  # within this many R of a rod end, only what lies past the end is attached
# Neighbours: centres within LINK_SPACINGS times the part's typical 4th-neighbour spacing, kept
# between LINK_MIN and LINK_MAX radii (real captures range from 0.1 to 0.4 R).
LINK_SPACINGS = 1.5
LINK_MIN, LINK_MAX = 0.2, 0.75
# Strays: clusters of linked unbound Gaussians that come within STRAY_REACH R of a moving one and
# span at most STRAY_SIZE R (a cluster joined to the rest of the scene spans more)...
STRAY_REACH = 1.0
STRAY_SIZE = 2.0
# ... past the rod's ends (within this many R of them along it) and around attached parts.
STRAY_END_RADII = 2.0
# Haze: clusters of unbound Gaussians (linked at the attached parts' link) that come within
# STRAY_REACH R of an attached part and lie wholly within HAZE_RADII R of the attached parts, whose
# Gaussians are faint (mean opacity below HAZE_OPACITY) and mostly larger than HAZE_SCALE R across
# their largest axis: a leaf's blur, 1-2 R off its surface (docs/deformation.md, "Segmentation").
# Opaque or small ones are what the part touches (a guitar body where its neck joins it).
HAZE_RADII = 3.0
HAZE_OPACITY = 0.35
HAZE_SCALE = 1.0
# Specks: such clusters that reach within SPECK_RADII R of the axis anywhere along the rod lie inside
# the part's tube, a piece of its surface the proximity graph did not reach: they ride with it.
SPECK_RADII = 1.5
# A piece of another part: an attached part of at least PIECE_MIN Gaussians shaped as a rod (the
# second principal extent of its centres under PIECE_SHAPE of the first; a leaf is a sheet, 0.55-0.74)
# whose far end (its centres within two links of the farthest from where it joins) comes within
# PIECE_LINKS links of a centre nothing binds: the part it belongs to runs on there. A whole twig
# ends free and rides along (docs/deformation.md, "Segmentation", A piece of another part).
PIECE_MIN = 20
PIECE_SHAPE = 0.4
PIECE_LINKS = 2.0


def default_attach_size(length: float, radius: float) -> float:
    """Attached parts up to half the rod's length, between 12 R and 20 R, ride with the rod (a leaf
    on a stem is a third of the stem or more, and a short stroke's leaves are as large as a long
    one's; the body a part joins is longer than the part; the cap keeps the search around a long
    rope small)."""
    return float(np.clip(ATTACH_SHARE * length, ATTACH_MIN * radius, ATTACH_MAX * radius))


def default_attach_size_fewer(length: float, radius: float) -> float:
    """Attached parts that hold no more Gaussians than the rod's own part reach up to half the
    rod's length, between 12 R and 25 R: a leaf on a long stem (docs/deformation.md,
    "Segmentation")."""
    return float(np.clip(ATTACH_SHARE * length, ATTACH_MIN * radius, ATTACH_FEWER_MAX * radius))


def default_continuation_size(length: float, radius: float) -> float:
    """What continues a part past an end rides with it up to the rod's length from the end,
    between 8 R and 20 R (a stem's tip with its leaves; the rest of a plant past a stem's base
    reaches further)."""
    return float(np.clip(CONTINUATION_SHARE * length, CONTINUATION_MIN * radius, CONTINUATION_MAX * radius))


@dataclass(frozen=True, eq=False)
class Binding:
    """Where each Gaussian that follows a rod sits on the rest polyline.

    Attributes:
        gaussian_ids: (G,) int64 rows of the scene.
        segment: (G,) int32 polyline segment index i (between vertices i and i + 1).
        t: (G,) float32 parameter on that segment, in [0, 1].
        offset: (G, 3) float32 centre minus the rest point at (segment, t), in world axes at rest.
        distance: (G,) float32 distance from the centre to the rest polyline.
        attached: (G,) bool rides rigidly with the point where its attached part joins the rod
            (not with its own nearest point; such Gaussians are never subdivided).
    """

    gaussian_ids: np.ndarray
    segment: np.ndarray
    t: np.ndarray
    offset: np.ndarray
    distance: np.ndarray
    attached: np.ndarray

    def take(self, rows: np.ndarray) -> Binding:
        """The binding of a subset (rows index this binding)."""
        return Binding(*(getattr(self, f)[rows] for f in Binding.__dataclass_fields__))

    def extend(self, other: Binding) -> Binding:
        """This binding followed by `other`'s entries."""
        return Binding(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in Binding.__dataclass_fields__))


def check_rows(ids: np.ndarray, count: int | None, what: str) -> None:
    """Raise SketchRodGSError, starting with `what`, naming the first of `ids` that is not a row of
    a scene of `count` Gaussians (None: of any size), or the first row bound twice. A negative id
    would bind a row counted from the end without a word."""
    ids = np.asarray(ids)
    if len(ids) == 0:
        return
    outside = (ids < 0) if count is None else (ids < 0) | (ids >= count)
    if outside.any():
        rows = "rows are >= 0" if count is None else f"the scene has {count}"
        raise SketchRodGSError(f"{what}: binds Gaussian {int(ids[np.argmax(outside)])} but {rows}")
    ordered = np.sort(ids)
    repeated = ordered[1:] == ordered[:-1]
    if repeated.any():
        raise SketchRodGSError(f"{what}: binds Gaussian {int(ordered[1:][np.argmax(repeated)])} twice")


def segment_and_bind(
    polyline: np.ndarray,
    scene: GaussianScene,
    radius: float,
    *,
    grow: float = DEFAULT_GROW,
    attach: bool = True,
    attach_size: float | None = None,
) -> Binding:
    """The Gaussians that follow the rod on `polyline`, bound (see the module docstring).

    Args:
        polyline: (M, 3) rest polyline, M >= 2.
        scene: the scene (its centres are read).
        radius: R.
        grow: the part's cross-section reaches `grow * R` from the axis.
        attach: let small attached parts and strays ride with the rod.
        attach_size: the largest attached part (default `default_attach_size`, and
            `default_attach_size_fewer` for one that holds no more Gaussians than the part), and when
            given the largest continuation past an end too (default `default_continuation_size`).
    """
    polyline = np.ascontiguousarray(polyline, np.float64)
    length = polyline_length(polyline)
    # a size given bounds what continues the part past its ends too, and every attached part
    continuation_size = default_continuation_size(length, radius) if attach_size is None else attach_size
    attach_size_fewer = default_attach_size_fewer(length, radius) if attach_size is None else attach_size
    if attach_size is None:
        attach_size = default_attach_size(length, radius)
    # Every step below reads the centres within its own reach of the rod: cut the scene to all of
    # their reaches once (each step's own cut is then a pass over thousands, not millions).
    rows = near_box(polyline, scene.means, _reach(radius, grow, attach_size_fewer, continuation_size))
    # np.take: NumPy gathers the rows of an (N, 3) array 4 times faster than `means[rows]` does
    # (0.08 against 0.35 ms for 26,000 rows; docs/extraction.md, "Speed")
    means, colours = _f32(np.take(scene.means, rows, axis=0)), scene.colors_of(rows)
    binding, surface = _part_and_attached(
        polyline,
        means,
        radius,
        grow=grow,
        attach_size=attach_size if attach else None,
        attach_size_fewer=attach_size_fewer,
        colours=colours,
    )
    if attach:
        binding = _without_pieces_of_other_parts(binding, polyline, means, radius)
        # a surface left out of the part does not continue it past an end either (a rope's tip
        # past the stroke lies on the floor, joined to all of it)
        bound = _Bound.of(binding, polyline, len(means))
        binding = _with_continuations(binding, bound, polyline, means, radius, continuation_size, colours, surface)
        binding = _with_strays(binding, bound, polyline, means, radius, attach_size)
        binding = _with_haze(binding, polyline, means, radius, scene, rows)
        binding = _with_specks(binding, polyline, means, radius, colours, surface)
    return replace(binding, gaussian_ids=rows[binding.gaussian_ids])


def _without_pieces_of_other_parts(binding: Binding, polyline: np.ndarray, means: np.ndarray, radius: float) -> Binding:
    """`binding` less the attached parts that are pieces of another part (`PIECE_SHAPE`). An
    attached part is the Gaussians bound where it joins: the Rust step binds each of a part's
    Gaussians at the one point where the part touches the rod."""
    attached = np.flatnonzero(binding.attached)
    if len(attached) < PIECE_MIN:
        return binding
    link = _link(np.take(means, binding.gaussian_ids[~binding.attached], axis=0), radius)
    reach = PIECE_LINKS * link
    t_bits = np.ascontiguousarray(binding.t[attached], np.float32).view(np.uint32)
    joins = binding.segment[attached].astype(np.int64) << 32 | t_bits
    _, part_of, counts = np.unique(joins, return_inverse=True, return_counts=True)
    taken = np.zeros(len(means), bool)
    taken[binding.gaussian_ids] = True
    dropped = np.zeros(len(binding.attached), bool)
    for k in np.flatnonzero(counts >= PIECE_MIN):
        rows = attached[part_of == k]
        centres = np.take(means, binding.gaussian_ids[rows], axis=0).astype(np.float64)
        spread = centres - centres.mean(axis=0)
        extents = np.sqrt(np.maximum(np.linalg.eigvalsh(spread.T @ spread / len(spread)), 0.0))  # ascending
        if extents[1] > PIECE_SHAPE * extents[2]:
            continue
        where = point_at(polyline, binding.segment[rows[:1]], binding.t[rows[:1]])[0]
        far = np.linalg.norm(centres - where, axis=1)
        end = centres[far >= far.max() - 2 * link]
        # the box around the far end a little wider than the reach (the box is float32), then the distances
        pad = 1.001 * reach
        near = _core.rows_in_box(means, tuple(end.min(axis=0) - pad), tuple(end.max(axis=0) + pad))
        free = near[~taken[near]]
        if len(free) and np.isfinite(cKDTree(end).query(means[free], distance_upper_bound=reach)[0]).any():
            dropped[rows] = True
    return binding.take(np.flatnonzero(~dropped)) if dropped.any() else binding


def _reach(radius: float, grow: float, attach_size: float, continuation_size: float) -> float:
    """How far from the rod's polyline `segment_and_bind` may read a centre (a bound above each
    step's own reach): the part and its attached parts with their two links, or a continuation
    past an end with its link, and around either the strays' search."""
    link = LINK_MAX * radius
    moving = max(grow * radius + attach_size + 2 * link, continuation_size + CONTINUATION_LINKS * link)
    strays = max(STRAY_REACH * radius + min(STRAY_SIZE * radius, attach_size), HAZE_RADII * radius)
    return 1.01 * (moving + strays + link)


def part_and_attached(
    polyline: np.ndarray,
    scene: GaussianScene,
    radius: float,
    *,
    grow: float,
    attach_size: float | None,
    attach_size_fewer: float | None = None,
) -> Binding:
    """The part and its attached parts (None: none; `attach_size_fewer` None: `attach_size`), in
    one Rust call, without the strays: the step that `tests/reference/segment_reference.py`
    matches to the bit."""
    return _part_and_attached(
        polyline, _f32(scene.means), radius, grow=grow, attach_size=attach_size, attach_size_fewer=attach_size_fewer
    )[0]


def _part_and_attached(
    polyline: np.ndarray,
    means: np.ndarray,
    radius: float,
    *,
    grow: float,
    attach_size: float | None,
    attach_size_fewer: float | None = None,
    colours: np.ndarray | None = None,
) -> tuple[Binding, tuple[np.ndarray, np.ndarray] | None]:
    """`part_and_attached` over the centres `means` (N, 3) float32 (ids index them); with their
    `colours` (N, 3) float32, a surface of another colour under the part is left out of it, and
    (the part's colour, the surface's) is returned with the binding (else None)."""
    polyline = np.ascontiguousarray(polyline, np.float64)
    # The arc lengths and the length as NumPy sums them: the decisions near the rod's ends compare
    # with them to the bit.
    ids, segment, t, offset, distance, attached, surface = _core.segment_and_bind(
        polyline,
        arc_lengths(polyline),
        polyline_length(polyline),
        means,
        float(radius),
        float(grow),
        LINK_SPACINGS,
        LINK_MIN,
        LINK_MAX,
        None if attach_size is None else float(attach_size),
        END_MARGIN,
        colours,
        None if attach_size_fewer is None else float(attach_size_fewer),
    )
    colours_told = None if surface is None else (np.asarray(surface[0], np.float32), np.asarray(surface[1], np.float32))
    return Binding(ids, segment, t, offset, distance, attached), colours_told


def _nearer_second(colours: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Per row of `colours` (N, 3): nearer `second` than `first` (the rule of the Rust
    `Surface::has`)."""
    return np.linalg.norm(colours - second, axis=1) < np.linalg.norm(colours - first, axis=1)


@dataclass
class _Bound:
    """What the part and its attached parts took, as the continuations and the strays read it."""

    along: np.ndarray
    """(G,) float64 how far along the rod each of their G entries is bound (entries added after
    them, the continuations', are attached)."""
    length: float
    """The rod's length as `along` reaches it (the last cumulative arc length)."""
    taken: np.ndarray
    """Per row of the centres read: bound so far (the continuations add theirs)."""

    @classmethod
    def of(cls, binding: Binding, polyline: np.ndarray, rows: int) -> _Bound:
        arc = arc_lengths(polyline)
        along = arc[binding.segment] + binding.t * (arc[binding.segment + 1] - arc[binding.segment])
        taken = np.zeros(rows, bool)
        taken[binding.gaussian_ids] = True
        return cls(along, float(arc[-1]), taken)


def _with_strays(
    binding: Binding,
    bound: _Bound,
    polyline: np.ndarray,
    means: np.ndarray,
    radius: float,
    attach_size: float,
) -> Binding:
    """`binding` and the strays around it (see the module docstring; no larger than
    `attach_size` either), each bound as an attached Gaussian at the `(segment, t)` of the moving
    Gaussian nearest it, with its own offset."""
    # Along the rod the part's own reach (`grow` R) takes its halo; strays hang past the rod's ends
    # and around attached parts, so only the Gaussians there are searched around.
    along, count = bound.along, len(bound.along)
    start, end = np.zeros(len(binding.attached), bool), np.zeros(len(binding.attached), bool)
    start[:count] = along <= STRAY_END_RADII * radius
    end[:count] = along >= bound.length - STRAY_END_RADII * radius
    searched = np.flatnonzero(binding.attached | start | end)  # entries of the binding
    if len(searched) < 5:
        return binding
    moving32 = np.take(means, binding.gaussian_ids[searched], axis=0)
    moving = moving32.astype(np.float64)
    moving_tree = cKDTree(moving, balanced_tree=False, compact_nodes=False)
    link = _link(moving32, radius)
    reach, size = STRAY_REACH * radius, min(STRAY_SIZE * radius, attach_size)
    # unbound Gaussians near what moves, and as far again as a stray cluster may reach (its whole
    # cluster then lies in this region, unless it runs on further: then it is too large anyway)
    region = reach + size + link
    # one pass over the scene for the box around all of them, then the boxes around each end and
    # the attached parts apart (the one box around a long rope would hold all of it)
    rows = near_box(moving, means, region)
    centres = np.take(means, rows, axis=0)
    inside = np.zeros(len(rows), bool)
    for group in (binding.attached, start & ~binding.attached, end & ~binding.attached):
        if group.any():
            points = means[binding.gaussian_ids[group]].astype(np.float64)
            low, high = points.min(axis=0) - region, points.max(axis=0) + region
            inside |= ((centres >= low) & (centres <= high)).all(axis=1)
    rows = rows[inside & ~bound.taken[rows]]
    if len(rows) == 0:
        return binding
    points = np.take(means, rows, axis=0).astype(np.float64)
    to_moving, nearest = moving_tree.query(points, distance_upper_bound=region)
    inside = np.isfinite(to_moving)
    rows, points, to_moving, nearest = rows[inside], points[inside], to_moving[inside], nearest[inside]
    if not (to_moving <= reach).any():
        return binding
    # clusters of linked Gaussians; one goes when it comes within `reach` of what moves and is no
    # larger than `size` (one that runs on into the scene is larger, and is not searched whole)
    seeds = np.flatnonzero(to_moving <= reach)
    goes = _core.small_clusters(_f32(points), link, seeds, size)
    if not goes.any():
        return binding
    stray_rows = rows[goes]
    # each rides with the searched Gaussian nearest it
    joined = searched[nearest[goes]]
    segment, t = binding.segment[joined], binding.t[joined]
    centre = means[stray_rows].astype(np.float64)
    # no stray lies further from the axis than what moves, and a region more
    farthest = float(binding.distance.max()) + region
    _, _, distance = _core.nearest_on_polyline(_f32(polyline), _f32(centre), farthest)
    return binding.extend(_bound_at(stray_rows, polyline, segment, t, centre, distance, attached=True))


def _with_haze(
    binding: Binding, polyline: np.ndarray, means: np.ndarray, radius: float, scene: GaussianScene, rows: np.ndarray
) -> Binding:
    """`binding` and the haze around its attached parts (see HAZE_RADII), each bound as an attached
    Gaussian at the `(segment, t)` of the attached Gaussian nearest it, with its own offset. `means`
    (float32) are the centres of the scene's `rows`, which the binding's ids index."""
    attached = binding.gaussian_ids[binding.attached]
    if len(attached) < 5:
        return binding
    points32 = np.take(means, attached, axis=0)
    link = _link(points32, radius)
    shell = HAZE_RADII * radius
    # the unbound centres within the shell and a link more (a cluster that runs on past the shell
    # shows it there)
    near = near_box(points32, means, shell + link)
    taken = np.zeros(len(means), bool)
    taken[binding.gaussian_ids] = True
    near = near[~taken[near]]
    centres = np.take(means, near, axis=0)
    kept = _in_cells_around(centres, points32, shell + link)
    near, centres = near[kept], centres[kept]
    if len(near) == 0:
        return binding
    to_attached, nearest = cKDTree(points32.astype(np.float64)).query(
        centres.astype(np.float64), distance_upper_bound=shell + link
    )
    within = np.isfinite(to_attached)
    near, centres, to_attached, nearest = near[within], centres[within], to_attached[within], nearest[within]
    seeds = np.flatnonzero(to_attached <= STRAY_REACH * radius)
    if len(seeds) == 0:
        return binding
    cluster = _core.clusters_inside(centres, link, seeds, to_attached <= shell)
    found = cluster >= 0
    if not found.any():
        return binding
    near, centres, nearest, cluster = near[found], centres[found], nearest[found], cluster[found]
    # faint and large: the cluster's mean opacity, and the share of its Gaussians larger than R
    scene_rows = rows[near]
    opacity = np.take(scene.opacities, scene_rows).astype(np.float64)
    large = np.take(scene.scales, scene_rows, axis=0).max(axis=1) > HAZE_SCALE * radius
    count = np.bincount(cluster)
    faint = np.bincount(cluster, weights=opacity) < HAZE_OPACITY * count
    mostly_large = 2 * np.bincount(cluster, weights=large.astype(np.float64)) > count
    goes = (faint & mostly_large)[cluster]
    if not goes.any():
        return binding
    haze, joined = near[goes], np.flatnonzero(binding.attached)[nearest[goes]]
    centre = centres[goes].astype(np.float64)
    farthest = float(binding.distance.max()) + shell + link
    _, _, distance = _core.nearest_on_polyline(_f32(polyline), _f32(centre), farthest)
    return binding.extend(
        _bound_at(haze, polyline, binding.segment[joined], binding.t[joined], centre, distance, attached=True)
    )


def _in_cells_around(centres: np.ndarray, points: np.ndarray, reach: float) -> np.ndarray:
    """Per row of `centres` (N, 3), whether it lies in a cell of a grid `reach` wide that holds one
    of `points` (M, 3) or touches one that does: every centre within `reach` of a point among them,
    and few others (a cheap filter before the exact distances: a k-d tree query of 33,000 centres
    around the main stem's 11,500 attached Gaussians took 22 ms, 1,640 of them within reach)."""
    points = np.asarray(points, np.float64)
    # cells at least `reach` wide, and at most 2^20 along any axis, so that a key fits in 63 bits
    width = max(reach, float(np.ptp(points, axis=0).max()) / 2**20)
    cell = np.floor(points / width).astype(np.int64)
    base = cell.min(axis=0) - 1  # a cell of margin on every side: a neighbour's key never wraps
    size = cell.max(axis=0) - base + 2
    stride = np.array([size[1] * size[2], size[2], 1])
    steps = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) @ stride
    occupied = np.unique((cell - base) @ stride)
    around = np.unique(occupied[:, None] + steps[None])
    at = np.floor(np.asarray(centres, np.float64) / width).astype(np.int64) - base
    inside = ((at >= 0) & (at < size)).all(axis=1)
    found = np.zeros(len(centres), bool)
    found[inside] = np.isin(at[inside] @ stride, around)
    return found


def _with_specks(
    binding: Binding,
    polyline: np.ndarray,
    means: np.ndarray,
    radius: float,
    colours: np.ndarray,
    surface: tuple[np.ndarray, np.ndarray] | None,
) -> Binding:
    """`binding` and the specks inside the part's tube: clusters of unbound Gaussians (linked as the
    strays are) that reach within `SPECK_RADII` R of the axis anywhere along it and span at most
    `STRAY_SIZE` R, each bound as the part's own Gaussians are, at its nearest point on the axis
    (not attached: the separation cut may still leave it). Where the part lies on a `surface` of
    another colour, rows of its colour are not specks (docs/deformation.md, "Segmentation")."""
    taken = np.zeros(len(means), bool)
    taken[binding.gaussian_ids] = True

    def unbound_near(margin: float) -> np.ndarray:
        rows = near_box(polyline, means, margin)
        rows = rows[~taken[rows]]
        return rows if surface is None else rows[~_nearer_second(colours[rows], *surface)]

    # the seeds first (most rods have none), then what their clusters may reach
    reach = SPECK_RADII * radius
    near = unbound_near(reach)
    _, _, distance = _core.nearest_on_polyline(_f32(polyline), _f32(np.take(means, near, axis=0)), reach)
    near = near[distance <= reach]
    if len(near) == 0:
        return binding
    link = _link(np.take(means, binding.gaussian_ids, axis=0), radius)
    size = STRAY_SIZE * radius
    rows = unbound_near(reach + size + link)
    points = _f32(np.take(means, rows, axis=0))
    seeds = np.flatnonzero(np.isin(rows, near))
    goes = _core.small_clusters(points, link, seeds.astype(np.int64), size)
    if not goes.any():
        return binding
    speck_rows = rows[goes]
    centre = means[speck_rows].astype(np.float64)
    segment, t, distance = _core.nearest_on_polyline(_f32(polyline), _f32(centre), SPECK_RADII * radius + size)
    return binding.extend(_bound_at(speck_rows, polyline, segment, t, centre, distance, attached=False))


def _bound_at(
    rows: np.ndarray,
    polyline: np.ndarray,
    segment: np.ndarray,
    t: np.ndarray,
    centre: np.ndarray,
    distance: np.ndarray,
    *,
    attached: bool,
) -> Binding:
    """The binding of `rows` (centres `centre`, float64) at `(segment, t)` on `polyline`, each with
    its own offset from there and its `distance` from the axis."""
    return Binding(
        rows.astype(np.int64),
        segment.astype(np.int32),
        t.astype(np.float32),
        (centre - point_at(polyline, segment, t)).astype(np.float32),
        distance.astype(np.float32),
        np.full(len(rows), attached),
    )


def _link(centres: np.ndarray, radius: float) -> float:
    """The part's link, as the segmentation takes it: 1.5 times the typical 4th-neighbour spacing
    of `centres` (N, 3) float32 (the median over every N // 500-th), within LINK_MIN..LINK_MAX R."""
    spacing = _core.median_neighbour_distance(_f32(centres), 4, 500)
    if spacing is None:  # too few to tell: the longest link
        return LINK_MAX * radius
    return float(np.clip(LINK_SPACINGS * spacing, LINK_MIN * radius, LINK_MAX * radius))


def _with_continuations(
    binding: Binding,
    bound: _Bound,
    polyline: np.ndarray,
    means: np.ndarray,
    radius: float,
    size: float,
    colours: np.ndarray,
    surface: tuple[np.ndarray, np.ndarray] | None,
) -> Binding:
    """`binding` and what continues the part past each end (see the module docstring), each bound
    as an attached Gaussian at that end, with its own offset. Where the part lies on a `surface` of
    another colour ((the part's colour, the surface's), None if not), rows whose `colours` are
    nearer the surface's do not continue it (judged for the rows near the ends only: over all the
    rows around a rope by a pole, 1.5 ms). `bound.taken` gains the continuations' rows."""
    along = bound.along
    # the part's Gaussians within END_MARGIN R of each end: what a continuation touches
    ends = [
        ~binding.attached & (along <= END_MARGIN * radius),
        ~binding.attached & (along >= bound.length - END_MARGIN * radius),
    ]
    near_ends = ends[0] | ends[1]
    if near_ends.sum() < 5:
        return binding
    # the link from the part's spacing there (the part is sampled alike all along)
    link = CONTINUATION_LINKS * _link(np.take(means, binding.gaussian_ids[near_ends], axis=0), radius)
    # the centres not bound yet within reach of an end: a continuation and a link more (the box
    # around each end apart: the one box around both held most of a long rod's surroundings, and
    # the distances to each end over it took 1.3 ms on the bundled plant)
    region = size + link
    vertices = polyline[[0, -1]]
    found: list[Binding] = []

    for end, at_end in enumerate(ends):
        if not at_end.any():
            continue
        vertex = vertices[end]
        outward = polyline[0] - polyline[1] if end == 0 else polyline[-1] - polyline[-2]
        outward = outward / max(float(np.linalg.norm(outward)), 1e-30)
        rows = _core.rows_in_box(means, tuple(vertex - region), tuple(vertex + region))
        rows = rows[~bound.taken[rows]]
        if surface is not None:
            rows = rows[~_nearer_second(colours[rows], *surface)]
        from_vertex = np.linalg.norm(np.take(means, rows, axis=0) - vertex, axis=1)
        close = from_vertex <= region
        rows, from_vertex = rows[close], from_vertex[close]
        # seeds: the centres linked to the end's part, which lies within its reach of the vertex
        end_part = means[binding.gaussian_ids[at_end]]
        near = np.flatnonzero(from_vertex <= float(np.linalg.norm(end_part - vertex, axis=1).max()) + link)
        if len(near) == 0:
            continue
        touching, _ = cKDTree(end_part).query(means[rows[near]], distance_upper_bound=link * (1 + 1e-6))
        seeds = near[np.isfinite(touching)].astype(np.int64)
        if len(seeds) == 0:
            continue
        points = np.take(means, rows, axis=0)
        goes = _core.continuation(points, seeds, tuple(vertex), tuple(outward), float(size), float(link))
        if len(goes) == 0:
            continue
        count = len(goes)
        bound.taken[rows[goes]] = True
        segment = np.full(count, 0 if end == 0 else len(polyline) - 2, np.int32)
        t = np.full(count, 0.0 if end == 0 else 1.0, np.float32)
        centre = points[goes].astype(np.float64)
        _, _, distance = _core.nearest_on_polyline(_f32(polyline), _f32(centre), region + radius)
        found.append(
            Binding(
                rows[goes].astype(np.int64),
                segment,
                t,
                (centre - point_at(polyline, segment, t)).astype(np.float32),
                distance.astype(np.float32),
                np.ones(count, bool),
            )
        )
    for continuation in found:
        binding = binding.extend(continuation)
    return binding


def which_end(segment: np.ndarray, t: np.ndarray, vertices: int) -> np.ndarray:
    """Per nearest point `(segment, t)` on a polyline of `vertices`: 0 where the point lies past
    its start, 1 past its end, -1 beside it."""
    start = (segment == 0) & (t <= 0)
    end = (segment == vertices - 2) & (t >= 1)
    return np.where(start, 0, np.where(end, 1, -1))


def past_an_end(segment: np.ndarray, t: np.ndarray, vertices: int) -> np.ndarray:
    """Whether each nearest point is a rod end (the point lies past it)."""
    return which_end(segment, t, vertices) >= 0


def point_at(polyline: np.ndarray, segment: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(G, 3) float64 the points at `(segment, t)` on `polyline`."""
    a = polyline[segment]
    return a + np.asarray(t, np.float64)[:, None] * (polyline[segment + 1] - a)


def _f32(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float32)
