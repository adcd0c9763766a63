"""Skinning (docs/deformation.md): the bound Gaussians follow their rod.

Each bound Gaussian follows the transform of its binding point on the rod: its centre is the
deformed point at (segment, t) plus the blended rotation of the rod's vertex frames applied to its
rest offset, its orientation turns by the same rotation, and its covariance stretches along the rod
with the segment's stretch. A weight below 1 (near a clamped end, where the motion eases in)
takes that fraction of the motion. Unbound Gaussians never move. The per-Gaussian work runs in
Rust (`sketchrodgs-skin`).

`rig.Rig` prepares a scene for its rods (needles split, motion eased at clamped ends) and holds
their `BoundRod`s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import _core
from .errors import SketchRodGSError
from .rod import Rod
from .rod_file import Extraction
from .scene import GaussianScene
from .segment import Binding, check_rows


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
        rest_frames: (M, 4) float64 the rod's vertex frames at rest, as unit quaternions w, x, y, z.
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
    def from_binding(
        cls, scene: GaussianScene, binding: Binding, rod: Rod, weight: np.ndarray | None = None
    ) -> BoundRod:
        """Bind `binding`'s Gaussians (rows of `scene`) to `rod`, which must be at rest, each
        taking `weight` of the motion (default all of it)."""
        ids = binding.gaussian_ids
        check_rows(ids, len(scene), "binding")
        if len(binding.segment) and binding.segment.max() >= rod.num_vertices - 1:
            raise SketchRodGSError(
                f"binding refers to segment {int(binding.segment.max())} but the rod has {rod.num_vertices - 1}"
            )
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
            np.array(rod.vertex_quats, np.float64),
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
            q[case == k] = np.stack(
                [s / 4, (r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s, (r[:, 1, 0] - r[:, 0, 1]) / s],
                axis=1,
            )
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


def skin_into(
    means: np.ndarray, quats: np.ndarray, scales: np.ndarray, bound: Sequence[BoundRod], rods: Sequence[Rod]
) -> None:
    """Overwrite the bound rows of `means` (N, 3), `quats` (N, 4) and `scales` (N, 3) (float32,
    C-contiguous) with their skinned values; other rows are untouched. The fast path for
    interactive use.

    A Gaussian bound to several rods follows the last of them.
    """
    if len(bound) != len(rods):
        raise SketchRodGSError(f"{len(bound)} bound rods but {len(rods)} rods")
    for b, rod in zip(bound, rods):
        deformed = np.ascontiguousarray(rod.positions, np.float32)
        _core.skin_scatter(
            b.rest_positions,
            deformed,
            b.rest_frames,
            np.ascontiguousarray(rod.vertex_quats, np.float64),
            b.segment,
            b.t,
            b.offset,
            b.rest_quats,
            b.rest_scales,
            b.weight,
            b.gaussian_ids,
            means,
            quats,
            scales,
        )


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
