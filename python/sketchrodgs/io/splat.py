"""antimatter15 `.splat`: headerless 32-byte records (docs/conventions.md)."""

from __future__ import annotations

import os

import numpy as np

from .. import _core
from ..atomic import atomic_open
from ..errors import SceneFormatError
from ..scene import SH_C0, GaussianScene
from ._quantized import empty_scene_arrays, map_file

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])


def read_splat(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a `.splat` file. Colours become a degree-0 SH scene; rotations are renormalised."""
    raw = map_file(path)
    if len(raw) == 0:
        raise SceneFormatError(f"{path}: empty .splat file")
    if len(raw) % RECORD.itemsize:
        raise SceneFormatError(
            f"{path}: size {len(raw)} bytes is not a multiple of the 32-byte .splat record (truncated?)"
        )
    return decode_splat(raw, os.fspath(path))


def decode_splat(records: np.ndarray, source: str) -> GaussianScene:
    """Turn `.splat` records (RECORD, or their bytes) into a scene; `source` names the data in errors."""
    raw = np.ascontiguousarray(records).view(np.uint8).reshape(-1)
    arrays = empty_scene_arrays(len(raw) // RECORD.itemsize, 1)
    try:
        _core.decode_splat(raw, arrays)  # in Rust (sketchrodgs-formats), a block of records per core
        return GaussianScene(*arrays)
    except ValueError as exc:  # a zero rotation (from Rust), or what the scene's checks found
        raise SceneFormatError(f"{source}: {exc}") from None


def write_splat(scene: GaussianScene, path: str | os.PathLike[str]) -> None:
    """Write `scene` as `.splat` in row order (lossy: 8-bit colour/opacity/rotation, DC colour only)."""
    records = np.empty(len(scene), dtype=RECORD)
    records["position"] = scene.means
    records["scale"] = scene.scales
    rgb = 0.5 + SH_C0 * scene.row_sh()[:, 0].astype(np.float64)
    records["rgba"][:, :3] = np.clip(np.rint(rgb * 255), 0, 255)
    records["rgba"][:, 3] = np.clip(np.rint(scene.opacities.astype(np.float64) * 255), 0, 255)
    records["rotation"] = np.clip(np.rint(scene.quats.astype(np.float64) * 128 + 128), 0, 255)
    with atomic_open(path) as stream:
        stream.write(records.tobytes())
