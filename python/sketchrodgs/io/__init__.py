"""Scene files: pick the reader from the content, write atomically.

Readers: INRIA 3DGS `.ply` (binary or ASCII, SH degree 0..3), the PlayCanvas/SuperSplat
compressed `.ply`, antimatter15 `.splat` and Niantic `.spz` (versions 2 to 4).
Writers: `.ply` (lossless for float32 values) and `.splat` (lossy: 8-bit colour, opacity and
rotation, no SH beyond the DC term). A 3DGS training output folder stands for its latest point
cloud (`training_output.py`).
"""

from __future__ import annotations

import os
import zlib
from pathlib import Path

from ..errors import SceneFileNotFoundError, SceneFormatError, SketchRodGSError
from ..scene import GaussianScene
from . import compressed_ply, ply, splat, spz
from .training_output import scene_file, training_cameras

__all__ = ["FORMAT_NAMES", "detect_format", "format_up", "load_scene", "save_scene", "scene_file", "training_cameras"]

_READERS = {
    "ply": ply.read_ply,
    "compressed-ply": compressed_ply.read_compressed_ply,
    "splat": splat.read_splat,
    "spz": spz.read_spz,
}
# What each format name returned by detect_format stands for, for people.
FORMAT_NAMES = {
    "ply": "INRIA 3DGS PLY",
    "compressed-ply": "PlayCanvas compressed PLY",
    "splat": "antimatter15 .splat",
    "spz": "Niantic SPZ",
}
_HEAD_BYTES = 1 << 16  # enough for any PLY header we read, and for a gzip header
_WRITERS = {".ply": ply.write_ply, ".splat": splat.write_splat}


# Formats whose specification fixes the axes: SPZ stores right-up-back (RUB, as OpenGL and
# three.js; Niantic's spz README, "Coordinate System"), so +y is up. PLY and .splat files carry
# whatever their trainer used (COLMAP's y-down for most captures): they say nothing.
_FORMAT_UP = {"spz": ("+y", "the SPZ convention (right-up-back)")}


def format_up(path: str | os.PathLike[str]) -> tuple[str, str] | None:
    """(up axis, why) where the format of the scene file at `path` fixes its axes, else None
    (also for a file that cannot be read: loading it reports that)."""
    try:
        return _FORMAT_UP.get(detect_format(path))
    except SketchRodGSError:
        return None


def detect_format(path: str | os.PathLike[str]) -> str:
    """Name of the format of the file at `path`, judged from its first bytes (see FORMAT_NAMES).

    A PLY header with a `chunk` element is a compressed PLY; gzip data or `NGSP` is SPZ. `.splat`
    has no magic number, so a file is taken as `.splat` when it is none of these and its name
    ends in `.splat`. A 3DGS training output folder is judged by its latest point cloud.
    """
    path = scene_file(path)
    try:
        with open(path, "rb") as stream:
            head = stream.read(_HEAD_BYTES)
    except FileNotFoundError:
        raise SceneFileNotFoundError(f"{path}: no such file") from None
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    if head[:4] in (b"ply\n", b"ply\r"):
        end = head.find(b"end_header")
        lines = head[: end if end >= 0 else len(head)].splitlines()
        return "compressed-ply" if any(line.split()[:2] == [b"element", b"chunk"] for line in lines) else "ply"
    if head[:4] == spz.MAGIC or _gzipped_spz(head):
        return "spz"
    if Path(path).suffix.lower() == ".splat":
        return "splat"
    raise SceneFormatError(f"{path}: unknown scene format (not PLY, not SPZ, and not named .splat)")


def _gzipped_spz(head: bytes) -> bool:
    """Whether `head` starts a gzip stream whose content starts with the SPZ magic.

    Looking inside keeps a `.splat` whose first float happens to begin with the gzip bytes a
    `.splat`.
    """
    if head[:2] != spz.GZIP_MAGIC:
        return False
    try:
        return zlib.decompressobj(wbits=16 + zlib.MAX_WBITS).decompress(head, len(spz.MAGIC)) == spz.MAGIC
    except zlib.error:
        return False


def load_scene(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a scene file (format chosen from its content), or the latest point cloud of a 3DGS
    training output folder (`point_cloud/iteration_<highest>/point_cloud.ply`).

    Raises:
        SceneFormatError: the file is unreadable or malformed; the message names the file and what
            is wrong with it.
    """
    path = scene_file(path)
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
