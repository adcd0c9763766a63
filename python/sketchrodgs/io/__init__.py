"""Scene files: pick the reader from the content, write atomically.

Readers: INRIA 3DGS `.ply` (binary or ASCII, SH degree 0..3) and antimatter15 `.splat`.
Writers: `.ply` (lossless for float32 values) and `.splat` (lossy: 8-bit colour, opacity and
rotation, no SH beyond the DC term).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import SceneFormatError
from ..scene import GaussianScene
from . import ply, splat

__all__ = ["detect_format", "load_scene", "save_scene"]

_READERS = {"ply": ply.read_ply, "splat": splat.read_splat}
_WRITERS = {".ply": ply.write_ply, ".splat": splat.write_splat}


def detect_format(path: str | os.PathLike[str]) -> str:
    """Name of the format of the file at `path` ("ply" or "splat"), judged from its first bytes.

    `.splat` has no magic number, so a file is taken as `.splat` when it is not a PLY and its name
    ends in `.splat`.
    """
    try:
        with open(path, "rb") as stream:
            head = stream.read(4)
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    if head == b"ply\n" or head == b"ply\r":
        return "ply"
    if Path(path).suffix.lower() == ".splat":
        return "splat"
    raise SceneFormatError(f"{path}: unknown scene format (not a PLY file and not named .splat)")


def load_scene(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a scene file (format chosen from its content).

    Raises:
        SceneFormatError: the file is unreadable or malformed; the message names the file and what
            is wrong with it.
    """
    return _READERS[detect_format(path)](path)


def save_scene(scene: GaussianScene, path: str | os.PathLike[str]) -> None:
    """Write `scene` to `path` as INRIA `.ply` or, when the name ends in `.splat`, as `.splat`.

    `.splat` is lossy: colours, opacities and rotations are stored in 8 bits and SH above degree 0 is
    dropped. The file is written to a temporary name and renamed, so a failed write leaves any
    existing file intact.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in _WRITERS:
        raise SceneFormatError(f"{path}: cannot write '{suffix}' files (use .ply or .splat)")
    _WRITERS[suffix](scene, path)
