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
"""

from __future__ import annotations

import math
import os

import numpy as np
import plyfile

from ..errors import SceneFormatError
from ..scene import SH_C0, GaussianScene, sh_coefficient_count
from ._quantized import SmallestThree, block_size, blocks, byte_table, lookup
from .ply import _check_header

CHUNK_SIZE = 256
CHUNK_BOUNDS = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z",
                "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z")
CHUNK_COLOR_BOUNDS = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
_REST_COUNT_TO_DEGREE = {3 * (sh_coefficient_count(d) - 1): d for d in (1, 2, 3)}

_UNIT_8 = np.arange(256, dtype=np.float64) / 255
_UNIT_8_F32 = _UNIT_8.astype(np.float32)
_SH_BYTE = byte_table(lambda b: 8 * (np.where(b == 0, 0, np.where(b == 255, 1, (b + 0.5) / 256)) - 0.5))
_UNIT_10 = np.arange(1024, dtype=np.float64) / 1023
_UNIT_11 = np.arange(2048, dtype=np.float64) / 2047
_ROTATION_10 = ((_UNIT_10 - 0.5) * math.sqrt(2)).astype(np.float32)


def read_compressed_ply(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a compressed `.ply` into an activated scene.

    Raises:
        SceneFormatError: the file is unreadable, not a compressed PLY, or its element counts or
            properties disagree with the format.
    """
    _check_header(path)  # the INRIA reader's guard against counts larger than the file
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
    packed = _columns(vertex, PACKED, "u", source)
    rest = None
    if "sh" in elements:
        rest = _sh_bytes(elements["sh"], n, source)

    means = np.empty((n, 3), dtype=np.float32)
    scales = np.empty((n, 3), dtype=np.float32)
    quats = np.empty((n, 4), dtype=np.float32)
    opacities = np.empty(n, dtype=np.float32)
    k = 1 if rest is None else rest.shape[1] // 3 + 1
    sh = np.empty((n, k, 3), dtype=np.float32)
    smallest_three = SmallestThree(wxyz=(0, 1, 2, 3))  # components in rot_0..rot_3 order
    chunks_per_block = block_size(60 + 12 * k) // CHUNK_SIZE
    fraction = np.zeros(chunks_per_block * CHUNK_SIZE, dtype=np.float64)
    sh_block = np.empty((chunks_per_block * CHUNK_SIZE, k, 3), dtype=np.float32)
    rgb = np.empty((chunks_per_block * CHUNK_SIZE, 3), dtype=np.float32)
    rest_values = np.empty(chunks_per_block * CHUNK_SIZE * 3 * (k - 1), dtype=np.float32)
    # Blocks of whole chunks, so that a chunk's bounds broadcast over its splats when a block is
    # viewed as (chunks, 256); the last chunk is padded, and the padding cut off.
    for first, last in blocks(chunks, chunks_per_block):
        start, stop = first * CHUNK_SIZE, min(n, last * CHUNK_SIZE)
        size = stop - start
        chunk_bounds = {name: values[first:last, None] for name, values in bounds.items()}
        grid = fraction[:(last - first) * CHUNK_SIZE]
        position = packed["packed_position"][start:stop]
        scale = packed["packed_scale"][start:stop]
        for axis, (name, shift, table) in enumerate((("x", 21, _UNIT_11), ("y", 11, _UNIT_10), ("z", 0, _UNIT_11))):
            mask = len(table) - 1
            means[start:stop, axis] = _lerp(chunk_bounds, name, table, (position >> shift) & mask, grid)
            scales[start:stop, axis] = _lerp(chunk_bounds, f"scale_{name}", table, (scale >> shift) & mask, grid)
        color = packed["packed_color"][start:stop]
        colors = rgb[:size]
        for channel, (name, shift) in enumerate((("r", 24), ("g", 16), ("b", 8))):
            byte = (color >> shift) & 0xFF
            if has_colors:
                colors[:, channel] = _lerp(chunk_bounds, name, _UNIT_8, byte, grid)
            else:
                lookup(_UNIT_8_F32, byte, colors[:, channel])
        np.divide(color & 0xFF, np.float32(255), out=opacities[start:stop], dtype=np.float32)
        rows = sh_block[:size]
        np.subtract(colors, np.float32(0.5), out=rows[:, 0])  # rgb = 0.5 + SH_C0 * f_dc
        rows[:, 0] /= np.float32(SH_C0)
        if rest is not None:
            # channel-major: f_rest_{c*(K-1)+j} is basis j+1 of channel c
            values = rest_values[: size * 3 * (k - 1)].reshape(size, 3, k - 1)
            lookup(_SH_BYTE, rest[start:stop].reshape(size, 3, k - 1), values)  # both contiguous: fast
            rows[:, 1:] = values.transpose(0, 2, 1)
        sh[start:stop] = rows
        rotation = packed["packed_rotation"][start:stop]
        stored = smallest_three.stored(size)
        for row, shift in enumerate((20, 10, 0)):
            lookup(_ROTATION_10, (rotation >> shift) & 0x3FF, stored[row])
        smallest_three.finish(rotation >> 30, quats[start:stop])
    with np.errstate(over="ignore"):
        np.exp(scales, out=scales)  # the chunk bounds hold log scales
    try:
        return GaussianScene(means, scales, quats, opacities, sh)
    except SceneFormatError as exc:
        raise SceneFormatError(f"{source}: {exc}") from None


def _lerp(
    bounds: dict[str, np.ndarray], name: str, table: np.ndarray, index: np.ndarray, grid: np.ndarray
) -> np.ndarray:
    """Each chunk's min_<name>..max_<name> at t = table[index], computed as the PlayCanvas decoder
    does (min * (1 - t) + max * t in float64), the chunk bounds broadcast over its 256 splats."""
    size = len(index)
    lookup(table, index, grid[:size])
    t = grid.reshape(-1, CHUNK_SIZE)  # the padding past `size` is cut off below
    low, high = bounds[f"min_{name}"], bounds[f"max_{name}"]
    return (low * (1 - t) + high * t).reshape(-1)[:size]


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
        else:  # read in place (the decoder slices it a block at a time), converted only if needed
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
