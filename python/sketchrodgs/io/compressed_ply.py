"""PlayCanvas / SuperSplat compressed `.ply` (as written by SuperSplat and splat-transform).

Splats come in chunks of 256 in file order. Element `chunk` holds per-chunk float bounds:
min/max of x, y, z, of the log scales, and (in newer files) of the colours r, g, b. Element
`vertex` packs each splat into four uint32 values:

- `packed_position`: x, y, z as 11, 10, 11-bit unsigned fractions (x in the top bits) between the
  chunk's min and max;
- `packed_rotation`: bits 30-31 the index (in rot_0..rot_3 = w, x, y, z order) of the largest
  component, then the other three, each 10 bits mapping [0, 1023] to [-1/sqrt(2), 1/sqrt(2)], the
  first of them in the highest bits;
- `packed_scale`: log scales, 11/10/11 bits, between the chunk's min and max scale;
- `packed_color`: r, g, b, a bytes (r in the top byte). RGB is the colour 0.5 + SH_C0 * f_dc, a
  fraction between the chunk's min and max colour when the chunk has them, else itself; a is the
  opacity after the sigmoid.

An optional element `sh` holds uchar `f_rest_0..f_rest_{n-1}` (n = 9, 24 or 45, channel-major
like the INRIA PLY); byte b stands for 8 * ((b + 0.5) / 256 - 0.5), with 0 and 255 meaning -4
and 4. Axes are those of the INRIA PLY (the writers convert to them), so nothing is flipped.

plyfile maps the file and checks its structure; the splats are decoded in Rust
(`sketchrodgs-formats`), a block of whole chunks per core.
"""

from __future__ import annotations

import math
import os

import numpy as np
import plyfile

from .. import _core
from ..errors import SceneFormatError
from ..scene import GaussianScene, sh_coefficient_count
from ._quantized import empty_scene_arrays
from .ply_header import check_header

CHUNK_SIZE = 256
CHUNK_BOUNDS = (
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
)
CHUNK_COLOR_BOUNDS = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
_REST_COUNT_TO_DEGREE = {3 * (sh_coefficient_count(d) - 1): d for d in (1, 2, 3)}

_PACKED_RECORD = np.dtype([(name, "<u4") for name in PACKED])


def read_compressed_ply(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a compressed `.ply` into an activated scene.

    Raises:
        SceneFormatError: the file is unreadable, not a compressed PLY, or its element counts or
            properties disagree with the format.
    """
    check_header(path)  # the INRIA reader's guard against counts larger than the file
    try:
        data = plyfile.PlyData.read(os.fspath(path))
    except Exception as exc:  # plyfile raises many types for bad bytes; name the file instead
        raise SceneFormatError(f"{path}: malformed PLY ({type(exc).__name__}: {exc})") from None
    return decode_compressed_ply(data, os.fspath(path))


def decode_compressed_ply(data: plyfile.PlyData, source: str) -> GaussianScene:
    """Decode a parsed compressed PLY; `source` names it in errors."""
    elements = {element.name: element for element in data.elements}
    for name in ("chunk", "vertex"):
        if name not in elements:
            raise SceneFormatError(f"{source}: compressed PLY without a '{name}' element")
    chunk, vertex = elements["chunk"], elements["vertex"]
    n = vertex.count
    if n == 0:
        raise SceneFormatError(f"{source}: the 'vertex' element has no rows")
    chunks = math.ceil(n / CHUNK_SIZE)
    if chunk.count != chunks:
        raise SceneFormatError(
            f"{source}: {chunk.count} chunk rows for {n} splats (expected {chunks}: one per {CHUNK_SIZE} splats)"
        )
    chunk_names = {prop.name for prop in chunk.properties}
    has_colors = all(name in chunk_names for name in CHUNK_COLOR_BOUNDS)
    bounds = _columns(chunk, CHUNK_BOUNDS + (CHUNK_COLOR_BOUNDS if has_colors else ()), "f", source)
    packed = _packed(vertex, source)
    k = 1
    rest = np.empty((n, 0), dtype=np.uint8)
    if "sh" in elements:
        rest = _sh_bytes(elements["sh"], n, source)
        k = rest.shape[1] // 3 + 1
    arrays = empty_scene_arrays(n, k)
    _core.decode_compressed_ply(np.stack(list(bounds.values()), axis=1), packed, rest, arrays)
    try:
        return GaussianScene(*arrays)
    except SceneFormatError as exc:
        raise SceneFormatError(f"{source}: {exc}") from None


def _packed(vertex: plyfile.PlyElement, source: str) -> np.ndarray:
    """(N, 16) uint8: per splat position, rotation, scale and colour as little-endian uint32. A view of
    the mapped file when its rows are exactly these four, else a converted copy."""
    if vertex.data.dtype == _PACKED_RECORD:
        return vertex.data.view(np.uint8).reshape(-1, 16)
    columns = _columns(vertex, PACKED, "u", source)
    return np.stack([columns[name] for name in PACKED], axis=1).astype("<u4", copy=False).view(np.uint8)


def _columns(element: plyfile.PlyElement, names: tuple[str, ...], kind: str, source: str) -> dict[str, np.ndarray]:
    """The named properties: float64 copies for kind "f", uint32 (views where possible) for "u"."""
    present = {prop.name for prop in element.properties}
    missing = [name for name in names if name not in present]
    if missing:
        raise SceneFormatError(f"{source}: compressed PLY '{element.name}' element lacks {', '.join(missing)}")
    columns = {}
    for name in names:
        values = element.data[name]
        if kind == "u" and values.dtype.kind not in "ui":
            raise SceneFormatError(f"{source}: compressed PLY property {name} must be an integer, not {values.dtype}")
        if kind == "f" and values.dtype.kind not in "uif":
            raise SceneFormatError(f"{source}: compressed PLY property {name} must be a number, not {values.dtype}")
        if kind == "f":
            columns[name] = values.astype(np.float64)
        else:  # as uint32, converted only where the file stores another integer type
            columns[name] = values if values.dtype == np.dtype("<u4") else values.astype(np.uint32)
    return columns


def _sh_bytes(element: plyfile.PlyElement, n: int, source: str) -> np.ndarray:
    """(n, 3 * (K - 1)) uint8 of the `sh` element's f_rest_* columns in numeric order."""
    names = [prop.name for prop in element.properties]
    count = len(names)
    expected = [f"f_rest_{i}" for i in range(count)]
    if count not in _REST_COUNT_TO_DEGREE or sorted(names) != sorted(expected):
        raise SceneFormatError(
            f"{source}: compressed PLY 'sh' element must hold f_rest_0..f_rest_(n-1) with n in 9, 24, 45; "
            f"found {count} properties"
        )
    if element.count != n:
        raise SceneFormatError(f"{source}: compressed PLY 'sh' element has {element.count} rows for {n} splats")
    records = element.data
    if all(records.dtype[name] == np.uint8 for name in expected) and records.dtype.itemsize == count:
        table = records.view(np.uint8).reshape(n, count)
        order = [names.index(name) for name in expected]
        return table if order == list(range(count)) else np.ascontiguousarray(table[:, order])
    for name in expected:
        if records.dtype[name].kind not in "ui":
            raise SceneFormatError(f"{source}: compressed PLY property sh.{name} must be an integer")
    return np.stack([np.clip(records[name], 0, 255).astype(np.uint8) for name in expected], axis=1)
