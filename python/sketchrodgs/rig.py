"""A scene prepared for its rods (docs/deformation.md, "Subdivision", "Separation" and
"Skinning"): the needle Gaussians of each rod split along it (`subdivide`), the part's shell
trimmed where it parts from what it touches (`separation`), every rod's Gaussians bound
(`skin.BoundRod`), and their motion eased in at clamped ends. The rig's scene has more rows than
the input; `source` maps each row back to the input scene's row.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from . import _core
from . import subdivide as sd
from .errors import SketchRodGSError
from .polyline import arc_lengths, near_box
from .rod import Rod
from .rod_file import Extraction
from .scene import GaussianScene
from .segment import Binding, check_rows, past_an_end, point_at
from .separation import trim_shell
from .skin import BoundRod, skin_into

# Clamped ends ease in over this many R (`Rig.build`).
DEFAULT_END_RAMP = 1.5
# A static needle that runs along the part for this share of its length is split, and its pieces
# in the part follow the rod (a guitar string whose centre is on the body: left whole it stayed
# behind as a line when the neck bent; taking every piece tore the leaves of a plant).
REACH_IN_SHARE = 0.5
# Edges of a static needle's length from which it is split (it runs in the part for one at least).
STRADDLING_SPLIT_FROM = 1.0


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
    def build(
        cls,
        scene: GaussianScene,
        extractions: Sequence[Extraction],
        rods: Sequence[Rod],
        subdivide: bool = True,
        end_ramp: float = DEFAULT_END_RAMP,
        taken: np.ndarray | None = None,
        separate: bool = True,
    ) -> Rig:
        """Bind each extraction's Gaussians to its rod (at rest in the extraction's polyline).

        Args:
            subdivide: split needles first (docs/deformation.md, "Subdivision").
            end_ramp: within this many R of a clamped end (clamped when the rig is built), the
                Gaussians take a share of the motion that rises smoothly from 0 at the end: a
                clamp holds the rod's last frame, so the rod bends hardest there, and the part's
                skin would shear off what the end is joined to.
            taken: (N,) bool rows that belong elsewhere (another rod's, in the viewer): never
                split or bound here.
            separate: trim the part's shell where it parts from what it touches, by the cut
                that splits the fewest close pairs, each counted by the share of the motion it
                takes (`separation.trim_shell`, with the `end_ramp` weights).
        """
        if len(extractions) != len(rods):
            raise SketchRodGSError(f"{len(extractions)} extractions but {len(rods)} rods")
        inputs = len(scene)
        source = np.arange(inputs, dtype=np.int64)
        bound: list[BoundRod] = []
        for k, (extraction, rod) in enumerate(zip(extractions, rods)):
            if rod.num_vertices != len(extraction.polyline):
                raise SketchRodGSError(
                    f"rod {k} has {rod.num_vertices} vertices but its extraction's polyline {len(extraction.polyline)}"
                )
            b = extraction.binding
            check_rows(b.gaussian_ids, inputs, f"rod {k}")
            b = _expand(b, source, scene.means, extraction.polyline)  # pieces an earlier rod split
            if subdivide:
                # what an earlier rod bound keeps its geometry: that rod's binding refers to it
                fixed = np.zeros(len(scene), bool)
                for earlier in bound:
                    fixed[earlier.gaussian_ids] = True
                if taken is not None:
                    fixed[: len(taken)] |= taken
                scene, source, b = _split_needles(scene, source, b, extraction, fixed)
            if separate:
                b = trim_shell(scene.means, b, extraction.radius, clamped_end_weights(b, rod, extraction, end_ramp))
            bound.append(BoundRod.from_binding(scene, b, rod, clamped_end_weights(b, rod, extraction, end_ramp)))
        return cls(scene, source, bound)

    def skinned(self, rods: Sequence[Rod]) -> GaussianScene:
        """The rig's scene with every rod's Gaussians moved with their rod."""
        means, quats, scales = self.scene.means.copy(), self.scene.quats.copy(), self.scene.scales.copy()
        skin_into(means, quats, scales, self.bound, rods)
        return self.scene.replace(means=means, quats=quats, scales=scales)


def clamped_end_weights(
    binding: Binding | BoundRod, rod: Rod, extraction: Extraction, ramp: float = DEFAULT_END_RAMP
) -> np.ndarray:
    """(G,) the share of the motion each bound Gaussian (its `segment` and `t`) takes: 1, eased to
    0 within `ramp` R of the ends of `rod` that are clamped now (see `Rig.build`)."""
    kinds = rod.boundaries
    ends = [k for k, end in ((0, 0), (1, -1)) if kinds[end] == "clamped"]
    weight = np.ones(len(binding.segment))
    if not ends or ramp <= 0 or len(binding.segment) == 0:
        return weight
    polyline = np.asarray(extraction.polyline, np.float64)
    arc = arc_lengths(polyline)
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
    offset = (means[binding.gaussian_ids] - point_at(polyline, segment, t)).astype(np.float32)
    return Binding(binding.gaussian_ids, segment, t, offset, binding.distance, binding.attached)


def _entries_of(ids: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of `rows`: whether it is among `ids` (unique), and the position there if so."""
    if len(ids) == 0:
        return np.zeros(len(rows), bool), np.zeros(0, np.int64)
    order = np.argsort(ids)
    position = np.minimum(np.searchsorted(ids[order], rows), len(ids) - 1)
    hit = ids[order][position] == rows
    return hit, order[position[hit]]


def _expand(binding: Binding, source: np.ndarray, means: np.ndarray, polyline: np.ndarray) -> Binding:
    """A binding of input rows, extended to the pieces an earlier rod split them into; those
    pieces (the parent's own row included, which now holds a piece) are bound at their centres."""
    counts = np.bincount(source)
    if (counts <= 1).all() or len(binding.gaussian_ids) == 0:
        return binding
    hit, entries = _entries_of(binding.gaussian_ids, source)
    rows = np.flatnonzero(hit)
    b = binding.take(entries)
    expanded = Binding(rows.astype(np.int64), b.segment, b.t, b.offset, b.distance, b.attached)
    return _rebind(expanded, np.flatnonzero(counts[source[rows]] > 1), means, polyline)


def _split_needles(
    scene: GaussianScene, source: np.ndarray, binding: Binding, extraction: Extraction, taken: np.ndarray | None = None
):
    """Split the needles among `binding`'s part rows (not `taken` ones), and the static needles
    that reach into the part (a guitar string whose centre lies on the body, beyond the neck's
    end). Every piece is bound anew; of a static needle, the pieces that lie in the part join the
    binding and the others stay."""
    polyline = np.asarray(extraction.polyline, np.float64)
    directions = np.diff(polyline, axis=0)
    directions /= np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), 1e-30)
    part = np.flatnonzero(~binding.attached)
    reach = float(binding.distance[part].max()) if len(part) else extraction.radius
    if taken is not None:
        part = part[~taken[binding.gaussian_ids[part]]]  # bound elsewhere: not split again
    straddling, straddling_segment = _reaching_in(scene, binding, polyline, reach, extraction.edge_length)
    if taken is not None:
        free = ~taken[straddling]
        straddling, straddling_segment = straddling[free], straddling_segment[free]
    rows = np.concatenate([binding.gaussian_ids[part], straddling])
    tangents = directions[np.concatenate([binding.segment[part], straddling_segment])]
    # a static needle is split from one edge in the part: whole, it would stay behind there
    split_from = np.r_[np.full(len(part), sd.SPLIT_FROM), np.full(len(straddling), STRADDLING_SPLIT_FROM)]
    counts = sd.piece_counts(scene, rows, tangents, extraction.edge_length, split_from)
    if not (counts > 1).any():
        return scene, source, binding
    first = len(scene)
    scene, new_source, piece_rows = sd.split(scene, rows, counts)
    source = np.concatenate([source, source[new_source[first:]]])
    # the appended pieces of bound Gaussians take their parent's binding entry...
    appended = np.arange(first, len(scene), dtype=np.int64)
    of_bound, parents = _entries_of(binding.gaussian_ids, new_source[first:])
    extra = binding.take(parents)
    binding = binding.extend(
        Binding(appended[of_bound], extra.segment, extra.t, extra.offset, extra.distance, extra.attached)
    )
    # ...and a static needle's pieces join it where they lie in the part (bound by `_rebind`)
    static_pieces = np.concatenate([straddling, appended[~of_bound]])
    seg, t, _ = _core.nearest_on_polyline(polyline.astype(np.float32), scene.means[static_pieces], reach)
    static_pieces = static_pieces[(seg >= 0) & ~past_an_end(seg, t, len(polyline))]
    count = len(static_pieces)
    joined = Binding(
        static_pieces,
        np.zeros(count, np.int32),
        np.zeros(count, np.float32),
        np.zeros((count, 3), np.float32),
        np.zeros(count, np.float32),
        np.zeros(count, bool),
    )
    binding = binding.extend(joined)
    pieces = np.flatnonzero(np.isin(binding.gaussian_ids, piece_rows))
    return scene, source, _rebind(binding, pieces, scene.means, polyline)


def _reaching_in(
    scene: GaussianScene, binding: Binding, polyline: np.ndarray, reach: float, edge_length: float
) -> tuple[np.ndarray, np.ndarray]:
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
        inside[k], nearest[k] = (seg >= 0) & ~past_an_end(seg, t, len(polyline)), seg
    length_inside = inside.sum(axis=0) / (len(steps) - 1) * 6 * longest[rows]
    keep = (length_inside >= edge_length) & (length_inside >= REACH_IN_SHARE * 6 * longest[rows])
    first_inside = np.argmax(inside[:, keep], axis=0)
    return rows[keep], np.maximum(nearest[:, keep][first_inside, np.arange(int(keep.sum()))], 0)
