"""Skinning (paper: linear blend skinning with frames from the rod; DESIGN.md "Skinning").

Each bound Gaussian follows the rigid transform of its binding point on the rod: its centre is the
deformed point at (segment, t) plus the blended rotation of the rod's vertex frames applied to its
rest offset, and its orientation turns by the same rotation. Unbound Gaussians never move.
The per-Gaussian work runs in Rust (`sketchrodgs-skin`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import _core
from .errors import SketchRodGSError
from .extract import Extraction
from .rod import Rod
from .scene import GaussianScene


@dataclass(frozen=True, eq=False)
class BoundRod:
    """One rod's Gaussians, bound at rest.

    Attributes:
        gaussian_ids: (G,) int64 scene rows that follow the rod.
        segment: (G,) int32 rod segment of each.
        t: (G,) float32 parameter on the segment.
        offset: (G, 3) float32 rest offset from the rod (world axes at rest).
        rest_quats: (G, 4) float32 the Gaussians' rotations at rest (w, x, y, z).
        rest_frames: (M, 3, 3) float64 the rod's vertex frames at rest.
    """

    gaussian_ids: np.ndarray
    segment: np.ndarray
    t: np.ndarray
    offset: np.ndarray
    rest_quats: np.ndarray
    rest_frames: np.ndarray

    @classmethod
    def from_extraction(cls, scene: GaussianScene, extraction: Extraction, rod: Rod) -> BoundRod:
        """Bind `extraction`'s Gaussians to `rod`, which must be at rest in the extraction's polyline."""
        if rod.num_vertices != len(extraction.polyline):
            raise SketchRodGSError(
                f"rod has {rod.num_vertices} vertices but the extraction's polyline {len(extraction.polyline)}"
            )
        b = extraction.binding
        return cls(
            np.ascontiguousarray(b.gaussian_ids, np.int64),
            np.ascontiguousarray(b.segment, np.int32),
            np.ascontiguousarray(b.t, np.float32),
            np.ascontiguousarray(b.offset, np.float32),
            np.ascontiguousarray(scene.quats[b.gaussian_ids], np.float32),
            np.array(rod.vertex_frames, np.float64),
        )


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


def skin_into(means: np.ndarray, quats: np.ndarray, bound: Sequence[BoundRod], rods: Sequence[Rod]) -> None:
    """Overwrite the bound rows of `means` (N, 3) and `quats` (N, 4) (float32, C-contiguous) with
    their skinned values; other rows are untouched. The fast path for interactive use.

    A Gaussian bound to several rods follows the last of them.
    """
    if len(bound) != len(rods):
        raise SketchRodGSError(f"{len(bound)} bound rods but {len(rods)} rods")
    for b, rod in zip(bound, rods):
        deformed = np.ascontiguousarray(rod.positions, np.float32)
        _core.skin_scatter(deformed, vertex_rotations(rod, b.rest_frames), b.segment, b.t, b.offset, b.rest_quats,
                           b.gaussian_ids, means, quats)


def skin(
    scene: GaussianScene,
    bound: BoundRod | Extraction | Sequence[BoundRod | Extraction],
    rods: Rod | Sequence[Rod],
) -> GaussianScene:
    """A new scene with the bound Gaussians moved with their rods; `scene` is not modified.

    Args:
        scene: the scene at rest.
        bound: per rod, its `BoundRod`, or the `Extraction` it was built from (its rest frames are
            then those of a rod built on the extraction's polyline).
        rods: the rods in their current state, in the same order.
    """
    bound = [bound] if isinstance(bound, (BoundRod, Extraction)) else list(bound)
    rods = [rods] if isinstance(rods, Rod) else list(rods)
    bound = [
        BoundRod.from_extraction(scene, b, Rod(b.polyline, params=rod.params)) if isinstance(b, Extraction) else b
        for b, rod in zip(bound, rods)
    ]
    means, quats = scene.means.copy(), scene.quats.copy()
    skin_into(means, quats, bound, rods)
    return scene.replace(means=means, quats=quats)
