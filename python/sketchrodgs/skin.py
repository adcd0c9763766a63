"""Skinning (docs/deformation.md): the bound Gaussians follow their rod.

Each bound Gaussian follows the transform of its binding point on the rod: its centre is the
deformed point at (segment, t) plus the blended rotation of the rod's vertex frames applied to its
rest offset, its orientation turns by the same rotation, and its covariance stretches along the rod
with the segment's stretch. A weight below 1 (near a clamped end, where the motion eases in)
takes that fraction of the motion. Unbound Gaussians never move. The per-Gaussian work runs in
Rust (`sketchrodgs-skin`).

A `Rig` prepares a scene for its rods: it splits the needle Gaussians of each rod along its axis
(`subdivide`) and binds the pieces, so the scene it skins has more rows than the input; its
`source` maps each row back to the input scene's row.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from . import _core
from . import subdivide as sd
from .errors import SketchRodGSError
from .extract import Extraction
from .rod import Rod
from .scene import GaussianScene
from .polyline import near_box
from .segment import Binding

# Clamped ends ease in over this many R (`Rig.build`).
DEFAULT_END_RAMP = 1.5
# A static needle that runs along the part for this share of its length is split, and its pieces
# in the part follow the rod (a guitar string whose centre is on the body: left whole it stayed
# behind as a line when the neck bent; taking every piece tore the leaves of a plant).
REACH_IN_SHARE = 0.5


@dataclass(frozen=True, eq=False)
class BoundRod:
    """One rod's Gaussians, bound at rest.

    Attributes:
        gaussian_ids: (G,) int64 scene rows that follow the rod.
        segment: (G,) int32 rod segment of each.
        t: (G,) float32 parameter on the segment.
        offset: (G, 3) float32 rest offset from the rod (world axes at rest).
        weight: (G,) float32 share of the rod's motion each takes (0..1).
        attached: (G,) bool rides rigidly with an attached part (docs/deformation.md).
        rest_quats: (G, 4) float32 the Gaussians' rotations at rest (w, x, y, z).
        rest_scales: (G, 3) float32 their scales at rest.
        rest_positions: (M, 3) float32 the rod's vertices at rest.
        rest_frames: (M, 3, 3) float64 the rod's vertex frames at rest.
    """

    gaussian_ids: np.ndarray
    segment: np.ndarray
    t: np.ndarray
    offset: np.ndarray
    weight: np.ndarray
    attached: np.ndarray
    rest_quats: np.ndarray
    rest_scales: np.ndarray
    rest_positions: np.ndarray
    rest_frames: np.ndarray

    @classmethod
    def from_binding(cls, scene: GaussianScene, binding: Binding, rod: Rod, weight: np.ndarray | None = None) -> BoundRod:
        """Bind `binding`'s Gaussians (rows of `scene`) to `rod`, which must be at rest, each
        taking `weight` of the motion (default all of it)."""
        ids = binding.gaussian_ids
        if len(ids) and (ids.min() < 0 or ids.max() >= len(scene)):
            raise SketchRodGSError(f"binding refers to Gaussian {int(ids.max())} but the scene has {len(scene)}")
        if len(binding.segment) and binding.segment.max() >= rod.num_vertices - 1:
            raise SketchRodGSError(f"binding refers to segment {int(binding.segment.max())} "
                                   f"but the rod has {rod.num_vertices - 1}")
        return cls(
            np.ascontiguousarray(ids, np.int64),
            np.ascontiguousarray(binding.segment, np.int32),
            np.ascontiguousarray(binding.t, np.float32),
            np.ascontiguousarray(binding.offset, np.float32),
            np.ones(len(ids), np.float32) if weight is None else np.ascontiguousarray(weight, np.float32),
            np.asarray(binding.attached, bool),
            np.ascontiguousarray(scene.quats[ids], np.float32),
            np.ascontiguousarray(scene.scales[ids], np.float32),
            np.ascontiguousarray(rod.positions, np.float32),
            np.array(rod.vertex_frames, np.float64),
        )

    @classmethod
    def from_extraction(cls, scene: GaussianScene, extraction: Extraction, rod: Rod) -> BoundRod:
        """Bind `extraction`'s Gaussians (no subdivision; see `Rig`) to `rod`, at rest in the
        extraction's polyline."""
        if rod.num_vertices != len(extraction.polyline):
            raise SketchRodGSError(
                f"rod has {rod.num_vertices} vertices but the extraction's polyline {len(extraction.polyline)}"
            )
        return cls.from_binding(scene, extraction.binding, rod)


@dataclass(frozen=True, eq=False)
class Rig:
    """A scene prepared for its rods: needles split, every rod's Gaussians bound.

    Attributes:
        scene: the scene at rest with the split Gaussians: the input's rows first (a split
            Gaussian's row holds its first piece), then the other pieces.
        source: (N',) int64 the input scene's row each row of `scene` comes from.
        bound: one `BoundRod` per rod, rows of `scene`.
    """

    scene: GaussianScene
    source: np.ndarray
    bound: list[BoundRod]

    @classmethod
    def build(cls, scene: GaussianScene, extractions: Sequence[Extraction], rods: Sequence[Rod],
              subdivide: bool = True, end_ramp: float = DEFAULT_END_RAMP) -> Rig:
        """Bind each extraction's Gaussians to its rod (at rest in the extraction's polyline).

        Args:
            subdivide: split needles first (docs/deformation.md, "Subdivision").
            end_ramp: within this many R of a clamped end (clamped when the rig is built), the
                Gaussians take a share of the motion that rises smoothly from 0 at the end: a
                clamp holds the rod's last frame, so the rod bends hardest there, and the part's
                skin would shear off what the end is joined to.
        """
        if len(extractions) != len(rods):
            raise SketchRodGSError(f"{len(extractions)} extractions but {len(rods)} rods")
        source = np.arange(len(scene), dtype=np.int64)
        bound = []
        for k, (extraction, rod) in enumerate(zip(extractions, rods)):
            if rod.num_vertices != len(extraction.polyline):
                raise SketchRodGSError(f"rod {k} has {rod.num_vertices} vertices but its extraction's "
                                       f"polyline {len(extraction.polyline)}")
            b = extraction.binding
            if len(b.gaussian_ids) and b.gaussian_ids.max() >= len(source):
                raise SketchRodGSError(f"rod {k}: binds Gaussian {int(b.gaussian_ids.max())} "
                                       f"but the scene has {len(source)}")
            b = _expand(b, source)  # pieces an earlier rod split
            if subdivide:
                scene, source, b = _split_needles(scene, source, b, extraction)
            bound.append(BoundRod.from_binding(scene, b, rod, clamped_end_weights(b, rod, extraction, end_ramp)))
        return cls(scene, source, bound)

    def skinned(self, rods: Sequence[Rod]) -> GaussianScene:
        """The rig's scene with every rod's Gaussians moved with their rod."""
        means, quats, scales = self.scene.means.copy(), self.scene.quats.copy(), self.scene.scales.copy()
        skin_into(means, quats, scales, self.bound, rods)
        return self.scene.replace(means=means, quats=quats, scales=scales)


def clamped_end_weights(binding: Binding, rod: Rod, extraction: Extraction, ramp: float = DEFAULT_END_RAMP) -> np.ndarray:
    """(G,) the share of the motion each bound Gaussian takes: 1, eased to 0 within `ramp` R of
    the ends of `rod` that are clamped now (see `Rig.build`)."""
    kinds = rod.boundaries
    ends = [k for k, end in ((0, 0), (1, -1)) if kinds[end] == "clamped"]
    weight = np.ones(len(binding.segment))
    if not ends or ramp <= 0 or len(binding.segment) == 0:
        return weight
    polyline = np.asarray(extraction.polyline, np.float64)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))])
    at = arc[binding.segment] + binding.t * (arc[binding.segment + 1] - arc[binding.segment])
    for end in ends:
        s = np.clip((at if end == 0 else arc[-1] - at) / (ramp * extraction.radius), 0.0, 1.0)
        weight = weight * s * s * (3 - 2 * s)  # smoothstep: no kink where the ramp meets the rest
    return weight


def _rebind(binding: Binding, rows: np.ndarray, means: np.ndarray, polyline: np.ndarray) -> Binding:
    """`binding` with each of its `rows` bound again at its own centre: a part row at its nearest
    point on the polyline, an attached row at its parent's point, with its own offset."""
    polyline = np.asarray(polyline, np.float64)
    segment, t = binding.segment.copy(), binding.t.copy()
    own = rows[~binding.attached[rows]]
    if len(own):
        centres = np.ascontiguousarray(means[binding.gaussian_ids[own]], np.float32)
        # every centre is within its distance to the first vertex of the polyline
        reach = float(np.linalg.norm(centres - polyline[0], axis=1).max()) * 1.001 + 1e-9
        segment[own], t[own], _ = _core.nearest_on_polyline(polyline.astype(np.float32), centres, reach)
    a = polyline[segment]
    rest_points = a + t[:, None].astype(np.float64) * (polyline[segment + 1] - a)
    offset = (means[binding.gaussian_ids] - rest_points).astype(np.float32)
    return Binding(binding.gaussian_ids, segment, t, offset, binding.distance, binding.attached)


def _expand(binding: Binding, source: np.ndarray) -> Binding:
    """A binding of input rows, extended to the pieces an earlier rod split them into."""
    if len(source) == len(np.unique(source)) or len(binding.gaussian_ids) == 0:
        return binding
    order = np.argsort(binding.gaussian_ids)
    position = np.searchsorted(binding.gaussian_ids[order], source)
    position = np.minimum(position, len(order) - 1)
    hit = binding.gaussian_ids[order][position] == source
    rows = np.flatnonzero(hit)
    parent = order[position[hit]]
    b = binding.take(parent)
    return Binding(rows.astype(np.int64), b.segment, b.t, b.offset, b.distance, b.attached)


def _split_needles(scene: GaussianScene, source: np.ndarray, binding: Binding, extraction: Extraction):
    """Split the needles among `binding`'s part rows, and the static needles that reach into the
    part (a guitar string whose centre lies on the body, beyond the neck's end); the pieces are
    bound anew, a static needle's pieces all joining the binding (those past the rod's end move
    with the end; leaving them would tear the needle where it leaves the part)."""
    polyline = np.asarray(extraction.polyline, np.float64)
    directions = np.diff(polyline, axis=0)
    directions /= np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), 1e-30)
    part = np.flatnonzero(~binding.attached)
    reach = float(binding.distance[part].max()) if len(part) else extraction.radius
    straddling, straddling_segment = _reaching_in(scene, binding, polyline, reach, extraction.edge_length,
                                                  extraction.radius)
    rows = np.concatenate([binding.gaussian_ids[part], straddling])
    tangents = directions[np.concatenate([binding.segment[part], straddling_segment])]
    counts = sd.piece_counts(scene, rows, tangents, extraction.edge_length)
    if not (counts > 1).any():
        return scene, source, binding
    first = len(scene)
    scene, new_source, piece_rows = sd.split(scene, rows, counts)
    source = np.concatenate([source, source[new_source[first:]]])
    # the appended pieces of bound Gaussians take their parent's binding entry...
    where = {int(g): i for i, g in enumerate(binding.gaussian_ids)}
    appended = np.arange(first, len(scene), dtype=np.int64)
    of_bound = np.array([int(g) in where for g in new_source[first:]], bool)
    parents = np.array([where[int(g)] for g in new_source[first:][of_bound]], np.int64)
    extra = binding.take(parents)
    fields = ("segment", "t", "offset", "distance", "attached")
    binding = Binding(np.concatenate([binding.gaussian_ids, appended[of_bound]]),
                      *(np.concatenate([getattr(binding, f), getattr(extra, f)]) for f in fields))
    # ...and a static needle's pieces join it where they lie in the part (bound by `_rebind`)
    static_pieces = np.concatenate([straddling, appended[~of_bound]])
    seg, t, _ = _core.nearest_on_polyline(polyline.astype(np.float32), scene.means[static_pieces], reach)
    static_pieces = static_pieces[(seg >= 0) & ~_past_an_end(seg, t, len(polyline))]
    count = len(static_pieces)
    joined = Binding(static_pieces, np.zeros(count, np.int32), np.zeros(count, np.float32),
                     np.zeros((count, 3), np.float32), np.zeros(count, np.float32), np.zeros(count, bool))
    binding = Binding(*(np.concatenate([getattr(binding, f), getattr(joined, f)]) for f in ("gaussian_ids",) + fields))
    pieces = np.flatnonzero(np.isin(binding.gaussian_ids, piece_rows))
    return scene, source, _rebind(binding, pieces, scene.means, polyline)


def _past_an_end(segment: np.ndarray, t: np.ndarray, vertices: int) -> np.ndarray:
    """Whether each nearest point is a rod end (the point lies past it)."""
    return ((segment == 0) & (t <= 0)) | ((segment == vertices - 2) & (t >= 1))


def _reaching_in(scene: GaussianScene, binding: Binding, polyline: np.ndarray, reach: float, edge_length: float,
                 radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Unbound Gaussians whose major axis runs within `reach` of the rod (not past its ends) for at
    least an edge and for at least REACH_IN_SHARE of their 3-sigma length; and for each a segment
    it runs along. (Needles of a leaf that only touch a stem stay with the leaf.)"""
    longest = scene.scales.max(axis=1)
    rows = near_box(polyline, scene.means, reach + 3 * float(longest.max(initial=0.0)))
    rows = rows[(6 * longest[rows] > edge_length) & ~np.isin(rows, binding.gaussian_ids)]
    if len(rows) == 0:
        return rows, rows.astype(np.int32)
    axes = Rotation.from_quat(scene.quats[rows][:, [1, 2, 3, 0]].astype(np.float64)).as_matrix()
    major = np.argmax(scene.scales[rows], axis=1)
    tip = axes[np.arange(len(rows)), :, major] * (3 * longest[rows])[:, None]
    steps = np.linspace(-1.0, 1.0, 13)
    inside = np.zeros((len(steps), len(rows)), bool)
    nearest = np.zeros((len(steps), len(rows)), np.int32)
    for k, f in enumerate(steps):
        points = (scene.means[rows] + f * tip).astype(np.float32)
        seg, t, _ = _core.nearest_on_polyline(polyline.astype(np.float32), points, reach)
        inside[k], nearest[k] = (seg >= 0) & ~_past_an_end(seg, t, len(polyline)), seg
    length_inside = inside.sum(axis=0) / (len(steps) - 1) * 6 * longest[rows]
    keep = (length_inside >= edge_length) & (length_inside >= REACH_IN_SHARE * 6 * longest[rows])
    first_inside = np.argmax(inside[:, keep], axis=0)
    return rows[keep], np.maximum(nearest[:, keep][first_inside, np.arange(int(keep.sum()))], 0)


def matrices_to_quats(matrices: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotation matrices -> (M, 4) unit quaternions w, x, y, z (Shepperd's method)."""
    m = np.asarray(matrices, np.float64)
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    q = np.empty((len(m), 4))
    # pick the largest of w, x, y, z to divide by, for accuracy
    case = np.argmax(np.stack([trace, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1), axis=1)
    for k in range(4):
        r = m[case == k]
        if k == 0:
            s = 2 * np.sqrt(np.maximum(1 + r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2], 1e-300))
            q[case == k] = np.stack([s / 4, (r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                                     (r[:, 1, 0] - r[:, 0, 1]) / s], axis=1)
        else:
            i, j, l = k - 1, k % 3, (k + 1) % 3
            s = 2 * np.sqrt(np.maximum(1 + r[:, i, i] - r[:, j, j] - r[:, l, l], 1e-300))
            qv = np.empty((len(r), 4))
            qv[:, 0] = (r[:, l, j] - r[:, j, l]) / s
            qv[:, 1 + i] = s / 4
            qv[:, 1 + j] = (r[:, j, i] + r[:, i, j]) / s
            qv[:, 1 + l] = (r[:, l, i] + r[:, i, l]) / s
            q[case == k] = qv
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def vertex_rotations(rod: Rod, rest_frames: np.ndarray) -> np.ndarray:
    """(M, 4) float32 rotations (w, x, y, z) that carry each rest vertex frame to its frame now."""
    now = np.asarray(rod.vertex_frames, np.float64)
    return matrices_to_quats(now @ np.transpose(rest_frames, (0, 2, 1))).astype(np.float32)


def skin_into(means: np.ndarray, quats: np.ndarray, scales: np.ndarray, bound: Sequence[BoundRod],
              rods: Sequence[Rod]) -> None:
    """Overwrite the bound rows of `means` (N, 3), `quats` (N, 4) and `scales` (N, 3) (float32,
    C-contiguous) with their skinned values; other rows are untouched. The fast path for
    interactive use.

    A Gaussian bound to several rods follows the last of them.
    """
    if len(bound) != len(rods):
        raise SketchRodGSError(f"{len(bound)} bound rods but {len(rods)} rods")
    for b, rod in zip(bound, rods):
        deformed = np.ascontiguousarray(rod.positions, np.float32)
        _core.skin_scatter(b.rest_positions, deformed, vertex_rotations(rod, b.rest_frames), b.segment, b.t, b.offset,
                           b.rest_quats, b.rest_scales, b.weight, b.gaussian_ids, means, quats, scales)


def skin(
    scene: GaussianScene,
    bound: BoundRod | Sequence[BoundRod],
    rods: Rod | Sequence[Rod],
) -> GaussianScene:
    """A new scene with the bound Gaussians moved with their rods; `scene` is not modified.

    Args:
        scene: the scene at rest the rods were bound to (a `Rig`'s scene, for split needles).
        bound: per rod, its `BoundRod`.
        rods: the rods in their current state, in the same order.
    """
    bound = [bound] if isinstance(bound, BoundRod) else list(bound)
    rods = [rods] if isinstance(rods, Rod) else list(rods)
    means, quats, scales = scene.means.copy(), scene.quats.copy(), scene.scales.copy()
    skin_into(means, quats, scales, bound, rods)
    return scene.replace(means=means, quats=quats, scales=scales)
