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
        sh_rows: None, or (N,) uint32: the row of `sh`, then a table of any number of rows, each
            Gaussian takes its coefficients from. The pieces of a split needle share their
            parent's (`subdivide.split`), so a split scene does not copy the SH of the whole
            scene. `row_sh()` gives the (N, K, 3) coefficients per Gaussian either way.

    Arrays are stored C-contiguous float32; construction converts and validates them and raises
    `SceneFormatError` naming the field and the first bad row.
    """

    means: np.ndarray
    scales: np.ndarray
    quats: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    sort_offsets: np.ndarray | None = None
    sh_rows: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = _as_rows(self, "means", 3)
        _as_rows(self, "scales", 3, n)
        _as_rows(self, "quats", 4, n)
        opacities = _as_float32(self, "opacities")
        if opacities.shape != (n,):
            raise SceneFormatError(f"opacities: expected shape ({n},), got {opacities.shape}")
        sh = _as_float32(self, "sh")
        rows = "M" if self.sh_rows is not None else n
        if sh.ndim != 3 or sh.shape[2] != 3 or sh.shape[1] not in (1, 4, 9, 16) or rows not in ("M", sh.shape[0]):
            raise SceneFormatError(f"sh: expected shape ({rows}, K, 3) with K in 1, 4, 9, 16, got {sh.shape}")
        if self.sh_rows is not None:
            _check_sh_rows(self, n, sh.shape[0])
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
        return self.colors_of(slice(None))

    def colors_of(self, rows: np.ndarray | slice) -> np.ndarray:
        """`colors` of the Gaussians `rows` only, (len(rows), 3) float32."""
        if isinstance(rows, slice):
            dc = self.sh[rows, 0] if self.sh_rows is None else self.sh[self.sh_rows[rows], 0]
        else:
            # whole rows, then their DC term: np.take copies a strided input whole first, and
            # `sh[:, 0]` of an SH-3 scene is strided (22 ms at 2.27 M Gaussians, for any number of
            # rows; docs/extraction.md, "Speed")
            dc = np.take(self.sh, rows if self.sh_rows is None else self.sh_rows[rows], axis=0)[:, 0]
        return np.clip(0.5 + SH_C0 * dc, 0.0, 1.0).astype(np.float32)

    def row_sh(self) -> np.ndarray:
        """(N, K, 3) float32 the SH coefficients of each Gaussian (a copy where rows share them)."""
        return self.sh if self.sh_rows is None else self.sh[self.sh_rows]

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
        if self.sh_rows is None:
            sh, sh_rows = self.sh[rows], None
        else:  # the rows keep sharing the table
            sh, sh_rows = self.sh, self.sh_rows[rows]
        return GaussianScene(
            self.means[rows], self.scales[rows], self.quats[rows], self.opacities[rows], sh, offsets, sh_rows
        )

    def replace(self, **arrays: np.ndarray | None) -> GaussianScene:
        """A new scene with some arrays replaced (the others are shared, not copied). A new `sh`
        without `sh_rows` is one row per Gaussian."""
        names = ("means", "scales", "quats", "opacities", "sh", "sort_offsets", "sh_rows")
        fields = {name: getattr(self, name) for name in names}
        if "sh" in arrays and "sh_rows" not in arrays:
            fields["sh_rows"] = None
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


def _check_sh_rows(scene: GaussianScene, n: int, table_rows: int) -> None:
    rows = np.asarray(scene.sh_rows)
    if rows.shape != (n,) or rows.dtype.kind not in "iu":
        raise SceneFormatError(f"sh_rows: expected ({n},) integers, got shape {rows.shape} of {rows.dtype}")
    _first_bad("sh_rows", (rows < 0) | (rows >= table_rows), f"row outside the {table_rows} rows of sh")
    object.__setattr__(scene, "sh_rows", np.ascontiguousarray(rows, dtype=np.uint32))


def _first_bad(name: str, bad_rows: np.ndarray | np.bool_, what: str) -> None:
    bad_rows = np.asarray(bad_rows)
    if bad_rows.any():
        row = int(np.argmax(bad_rows))
        raise SceneFormatError(f"{name}: {what} in row {row} ({int(bad_rows.sum())} bad rows)")
