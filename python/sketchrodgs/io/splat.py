"""antimatter15 `.splat`: headerless 32-byte records (RASTER.md 2.2)."""

from __future__ import annotations

import os

import numpy as np

from ..atomic import atomic_open
from ..errors import SceneFormatError
from ..scene import SH_C0, GaussianScene

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])


def read_splat(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a `.splat` file. Colours become a degree-0 SH scene; rotations are renormalised."""
    try:
        raw = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    if raw.size == 0:
        raise SceneFormatError(f"{path}: empty .splat file")
    if raw.size % RECORD.itemsize:
        raise SceneFormatError(
            f"{path}: size {raw.size} bytes is not a multiple of the 32-byte .splat record (truncated?)"
        )
    return decode_splat(raw.view(RECORD), str(path))


def decode_splat(records: np.ndarray, source: str) -> GaussianScene:
    """Turn `.splat` records into a scene; `source` names the data in errors."""
    quats = (records["rotation"].astype(np.float32) - 128.0) / 128.0
    norms = np.sqrt(np.einsum("ij,ij->i", quats, quats))[:, None]
    zero = norms[:, 0] == 0
    if zero.any():
        raise SceneFormatError(f"{source}: rotation: zero quaternion in record {int(np.argmax(zero))}")
    rgba = records["rgba"].astype(np.float32) / 255.0
    try:
        return GaussianScene.from_colors(
            records["position"], records["scale"], quats / norms, rgba[:, 3], rgba[:, :3]
        )
    except SceneFormatError as exc:
        raise SceneFormatError(f"{source}: {exc}") from None


def write_splat(scene: GaussianScene, path: str | os.PathLike[str]) -> None:
    """Write `scene` as `.splat` in row order (lossy: 8-bit colour/opacity/rotation, DC colour only)."""
    records = np.empty(len(scene), dtype=RECORD)
    records["position"] = scene.means
    records["scale"] = scene.scales
    rgb = 0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64)
    records["rgba"][:, :3] = np.clip(np.rint(rgb * 255), 0, 255)
    records["rgba"][:, 3] = np.clip(np.rint(scene.opacities.astype(np.float64) * 255), 0, 255)
    records["rotation"] = np.clip(np.rint(scene.quats.astype(np.float64) * 128 + 128), 0, 255)
    with atomic_open(path) as stream:
        stream.write(records.tobytes())
