"""The in-memory Gaussian scene: activated arrays, validated once on construction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core
from .errors import SceneFormatError

# Unit quaternions are checked to this tolerance; loaders normalise before constructing.
QUAT_NORM_TOLERANCE = 1e-3

SH_C0 = 0.28209479177387814  # the degree-0 SH basis constant: rgb = 0.5 + SH_C0 * dc


def sh_coefficient_count(degree: int) -> int:
    """Number of SH coefficients per colour channel for `degree` (0..3): (degree + 1)^2."""
    return (degree + 1) ** 2


@dataclass(frozen=True, eq=False)
class GaussianScene:
    """A 3D Gaussian Splatting scene with activated values (see docs/conventions.md).

    Attributes:
        means: (N, 3) float32 centres in world units.
        scales: (N, 3) float32 standard deviations along the local axes, linear and > 0.
        quats: (N, 4) float32 unit rotations, w first.
        opacities: (N,) float32 in [0, 1].
        sh: (N, K, 3) float32 spherical-harmonic coefficients per RGB channel, K = (d + 1)^2;
            sh[:, 0] is the DC term (rgb = 0.5 + SH_C0 * sh[:, 0]).
        sort_offsets: None, or (N, 3) float32: where each Gaussian sorts when rendered, from its
            mean in its own axes (docs/rendering.md, "Sort points"). The pieces of a split needle
            sort where their parent's centre is (`subdivide.split`). Scene files do not keep it.

    Arrays are stored C-contiguous float32; construction converts and validates them and raises
    `SceneFormatError` naming the field and the first bad row.
    """

    means: np.ndarray
    scales: np.ndarray
    quats: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    sort_offsets: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = _as_rows(self, "means", 3)
        _as_rows(self, "scales", 3, n)
        _as_rows(self, "quats", 4, n)
        opacities = _as_float32(self, "opacities")
        if opacities.shape != (n,):
            raise SceneFormatError(f"opacities: expected shape ({n},), got {opacities.shape}")
        sh = _as_float32(self, "sh")
        if sh.ndim != 3 or sh.shape[0] != n or sh.shape[2] != 3 or sh.shape[1] not in (1, 4, 9, 16):
            raise SceneFormatError(f"sh: expected shape ({n}, K, 3) with K in 1, 4, 9, 16, got {sh.shape}")
        # One pass in Rust over all arrays; rows are looked for only when something is off.
        fields = ("means", "scales", "quats", "opacities", "sh")
        finite, scale_min, (opacity_min, opacity_max), (quat_min, quat_max) = _core.scene_summary(
            *(getattr(self, name) for name in fields)
        )
        for name, ok in zip(fields, finite, strict=True):
            if not ok:
                rows = getattr(self, name).reshape(n, -1)
                _first_bad(name, ~np.isfinite(rows).all(axis=1), "NaN or infinite value")
        if self.sort_offsets is not None:
            _as_rows(self, "sort_offsets", 3, n)
            _first_bad("sort_offsets", ~np.isfinite(self.sort_offsets).all(axis=1), "NaN or infinite value")
        if n and scale_min <= 0:
            _first_bad("scales", ~(self.scales > 0).all(axis=1), "scales must be > 0")
        if n and (opacity_min < 0 or opacity_max > 1):
            _first_bad("opacities", ~((self.opacities >= 0) & (self.opacities <= 1)), "opacity must be in [0, 1]")
        if n and (quat_min < (1 - QUAT_NORM_TOLERANCE) ** 2 or quat_max > (1 + QUAT_NORM_TOLERANCE) ** 2):
            norms = np.sqrt(np.einsum("ij,ij->i", self.quats, self.quats))
            _first_bad("quats", norms == 0, "zero quaternion")
            _first_bad("quats", np.abs(norms - 1) > QUAT_NORM_TOLERANCE, "quaternion is not unit length")

    def __len__(self) -> int:
        return int(self.means.shape[0])

    def __repr__(self) -> str:
        return f"GaussianScene({len(self)} Gaussians, SH degree {self.sh_degree})"

    @property
    def sh_degree(self) -> int:
        """Spherical-harmonic degree d (0..3)."""
        return int(round(np.sqrt(self.sh.shape[1]))) - 1

    @property
    def colors(self) -> np.ndarray:
        """(N, 3) float32 view-independent colour from the DC term, clipped to [0, 1]."""
        return np.clip(0.5 + SH_C0 * self.sh[:, 0], 0.0, 1.0).astype(np.float32)

    @classmethod
    def from_colors(
        cls,
        means: np.ndarray,
        scales: np.ndarray,
        quats: np.ndarray,
        opacities: np.ndarray,
        colors: np.ndarray,
    ) -> GaussianScene:
        """Build a degree-0 scene from plain RGB colours (N, 3) in [0, 1]."""
        dc = (np.asarray(colors, np.float32) - 0.5) / np.float32(SH_C0)
        return cls(means, scales, quats, opacities, dc.reshape(-1, 1, 3))

    def subset(self, rows: np.ndarray) -> GaussianScene:
        """A new scene with only `rows` (indices or a boolean mask), in that order."""
        offsets = None if self.sort_offsets is None else self.sort_offsets[rows]
        return GaussianScene(
            self.means[rows], self.scales[rows], self.quats[rows], self.opacities[rows], self.sh[rows], offsets
        )

    def replace(self, **arrays: np.ndarray | None) -> GaussianScene:
        """A new scene with some arrays replaced (the others are shared, not copied)."""
        names = ("means", "scales", "quats", "opacities", "sh", "sort_offsets")
        fields = {name: getattr(self, name) for name in names}
        fields.update(arrays)
        return GaussianScene(**fields)


def _as_float32(scene: GaussianScene, name: str) -> np.ndarray:
    value = getattr(scene, name)
    try:
        array = np.ascontiguousarray(value, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise SceneFormatError(f"{name}: cannot convert to a float32 array ({exc})") from None
    object.__setattr__(scene, name, array)  # frozen dataclass: normalise once, here
    return array


def _as_rows(scene: GaussianScene, name: str, width: int, n: int | None = None) -> int:
    array = _as_float32(scene, name)
    if array.ndim != 2 or array.shape[1] != width or (n is not None and array.shape[0] != n):
        want = f"({'N' if n is None else n}, {width})"
        raise SceneFormatError(f"{name}: expected shape {want}, got {array.shape}")
    return int(array.shape[0])


def _first_bad(name: str, bad_rows: np.ndarray | np.bool_, what: str) -> None:
    bad_rows = np.asarray(bad_rows)
    if bad_rows.any():
        row = int(np.argmax(bad_rows))
        raise SceneFormatError(f"{name}: {what} in row {row} ({int(bad_rows.sum())} bad rows)")
