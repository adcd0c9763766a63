"""Gaussians as viser draws them: centre, 3x3 covariance, RGB and opacity.

viser's splat renderer has no spherical harmonics, so the view-independent (DC) colour is baked
in: `rgb = clip(0.5 + SH_C0 * sh[:, 0], 0, 1)`.

viser stores covariances as float16, whose normal range is 6e-5..65504: a Gaussian 0.005 units
across has a covariance of 2.5e-5, a float16 subnormal (few significant bits, and numpy converts
subnormals about 15 times slower). So splats are sent in a scaled unit: a node with scale `u`
holds centres / u and covariances / u^2, with `u` the scene's median Gaussian size
(`splat_unit`), which centres the scene's covariances on 1 in float16's range.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import GaussianScene


def quats_to_matrices(quats: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions w, x, y, z (normalised here) -> (N, 3, 3) float32 rotation matrices."""
    q = np.asarray(quats, np.float32)
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), np.float32(1e-12))
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty((len(q), 3, 3), np.float32)
    out[:, 0, 0] = 1 - 2 * (y * y + z * z)
    out[:, 0, 1] = 2 * (x * y - w * z)
    out[:, 0, 2] = 2 * (x * z + w * y)
    out[:, 1, 0] = 2 * (x * y + w * z)
    out[:, 1, 1] = 1 - 2 * (x * x + z * z)
    out[:, 1, 2] = 2 * (y * z - w * x)
    out[:, 2, 0] = 2 * (x * z - w * y)
    out[:, 2, 1] = 2 * (y * z + w * x)
    out[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def covariances(scales: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """(N, 3) linear scales and (N, 4) rotations -> (N, 3, 3) float32 covariances R S^2 R^T."""
    r = quats_to_matrices(quats)
    rs = r * np.asarray(scales, np.float32)[:, None, :]  # R S: column j scaled by s_j
    return rs @ np.transpose(rs, (0, 2, 1))


def covariance_triu(scales: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """(N, 6) float32 upper triangle (xx, xy, xz, yy, yz, zz) of R S^2 R^T, the layout viser packs.

    The per-frame path: element-wise over the N Gaussians, no (N, 3, 3) temporaries.
    """
    rs = quats_to_matrices(quats) * np.asarray(scales, np.float32)[:, None, :]  # M = R S
    m = [[rs[:, i, k] for k in range(3)] for i in range(3)]
    out = np.empty((len(rs), 6), np.float32)
    for col, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        out[:, col] = m[i][0] * m[j][0] + m[i][1] * m[j][1] + m[i][2] * m[j][2]
    return out


class SplatPacker:
    """Builds viser's splat buffer (per Gaussian 8 uint32: centre as 3 float32, one reserved word,
    covariance upper triangle as 6 float16, RGBA as 4 uint8) for a fixed set of Gaussians whose
    centres and covariances change; colours and opacities are packed once.

    Args:
        rgbs: (G, 3) float in [0, 1].
        opacities: (G, 1) or (G,) float in [0, 1].
    """

    def __init__(self, rgbs: np.ndarray, opacities: np.ndarray) -> None:
        rgba = np.empty((len(rgbs), 4), np.uint8)
        rgba[:, :3] = np.clip(np.asarray(rgbs, np.float32) * 255.0, 0, 255).astype(np.uint8)
        rgba[:, 3] = np.clip(np.asarray(opacities, np.float32).reshape(-1) * 255.0, 0, 255).astype(np.uint8)
        self._template = np.zeros((len(rgbs), 8), np.uint32)
        self._template[:, 7] = rgba.view(np.uint32)[:, 0]

    def __len__(self) -> int:
        return len(self._template)

    def pack(self, centers: np.ndarray, triu: np.ndarray) -> np.ndarray:
        """(G, 8) uint32 buffer for (G, 3) centres and (G, 6) covariance upper triangles."""
        buffer = self._template.copy()
        buffer[:, 0:3] = np.ascontiguousarray(centers, np.float32).view(np.uint32)
        buffer[:, 4:7] = np.ascontiguousarray(triu, np.float32).astype(np.float16).view(np.uint32)
        return buffer


def splat_unit(scales: np.ndarray) -> float:
    """Length unit for sending splats: the median of the Gaussians' largest scales, raised where
    needed so that the largest covariance stays below float16's maximum (scale / unit <= 255)."""
    s = np.asarray(scales, np.float32)
    if len(s) == 0:
        return 1.0
    largest = s.max(axis=1)
    unit = max(float(np.median(largest)), float(largest.max()) / 255.0)
    return unit if np.isfinite(unit) and unit > 0 else 1.0


@dataclass(frozen=True, eq=False)
class SplatArrays:
    """The arrays `add_gaussian_splats` / `set_gaussians` take.

    Attributes:
        centers: (N, 3) float32.
        covariances: (N, 3, 3) float32.
        rgbs: (N, 3) float32 in [0, 1], the baked DC colour.
        opacities: (N, 1) float32 in [0, 1].
    """

    centers: np.ndarray
    covariances: np.ndarray
    rgbs: np.ndarray
    opacities: np.ndarray

    @classmethod
    def from_scene(cls, scene: GaussianScene) -> SplatArrays:
        """All Gaussians of `scene`."""
        return cls(
            np.ascontiguousarray(scene.means, np.float32),
            covariances(scene.scales, scene.quats),
            np.ascontiguousarray(scene.colors, np.float32),
            np.ascontiguousarray(scene.opacities, np.float32)[:, None],
        )

    def __len__(self) -> int:
        return len(self.centers)

    def updated(self, scene: GaussianScene, rows: np.ndarray) -> SplatArrays:
        """These arrays made current for `scene`, a later state of the scene they were made from:
        `rows` replaced and the rows it has beyond them appended (the rest is not looked at)."""
        old = len(self)
        if old == len(scene) and len(rows) == 0:
            return self
        rows = np.asarray(rows, np.int64)
        changed = SplatArrays.from_scene(scene.subset(np.concatenate([rows, np.arange(old, len(scene))])))
        arrays = []
        for name in ("centers", "covariances", "rgbs", "opacities"):
            values = np.concatenate([getattr(self, name), getattr(changed, name)[len(rows) :]])
            values[rows] = getattr(changed, name)[: len(rows)]
            arrays.append(values)
        return SplatArrays(*arrays)

    def subset(self, rows: np.ndarray) -> SplatArrays:
        rows = np.asarray(rows, np.int64)
        return SplatArrays(self.centers[rows], self.covariances[rows], self.rgbs[rows], self.opacities[rows])

    def in_unit(self, unit: float, origin: np.ndarray | None = None) -> SplatArrays:
        """The same Gaussians in a node of scale `unit` placed at `origin` (default 0)."""
        centers = self.centers if origin is None else self.centers - np.asarray(origin, np.float32)
        return SplatArrays(
            np.ascontiguousarray(centers / np.float32(unit), np.float32),
            self.covariances / np.float32(unit * unit),
            self.rgbs,
            self.opacities,
        )
