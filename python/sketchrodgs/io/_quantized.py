"""Pieces shared by the quantised scene formats (`.splat`, SPZ, compressed PLY)."""

from __future__ import annotations

import mmap
import os

import numpy as np

from ..errors import SceneFormatError


def map_file(path: str | os.PathLike[str]) -> np.ndarray:
    """The bytes of the file at `path` as a read-only uint8 array backed by a memory map.

    Mapping rather than reading saves a copy of the file and, on this kind of VM, the page faults
    of a fresh buffer (about a sixth of a 1M-splat SPZ load).
    """
    try:
        with open(path, "rb") as stream:
            if os.fstat(stream.fileno()).st_size == 0:
                return np.empty(0, dtype=np.uint8)
            mapped = mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    return np.frombuffer(mapped, dtype=np.uint8)


def empty_scene_arrays(n: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Uninitialised float32 means (n, 3), scales (n, 3), quats (n, 4), opacities (n,), sh (n, k, 3)
    for a decoder to fill (numpy asks the kernel for huge pages for big arrays: fewer page faults)."""
    return (
        np.empty((n, 3), dtype=np.float32),
        np.empty((n, 3), dtype=np.float32),
        np.empty((n, 4), dtype=np.float32),
        np.empty(n, dtype=np.float32),
        np.empty((n, k, 3), dtype=np.float32),
    )
