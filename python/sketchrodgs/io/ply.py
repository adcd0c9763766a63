"""INRIA 3DGS `point_cloud.ply` (docs/conventions.md): read with plyfile, write in the reference layout."""

from __future__ import annotations

import os
import re

import numpy as np
import plyfile

from .. import _core
from ..atomic import atomic_open
from ..errors import SceneFormatError
from ..scene import GaussianScene, sh_coefficient_count
from .ply_header import HEADER_LIMIT, check_header

REQUIRED = (
    "x",
    "y",
    "z",
    "f_dc_0",
    "f_dc_1",
    "f_dc_2",
    "opacity",
    "scale_0",
    "scale_1",
    "scale_2",
    "rot_0",
    "rot_1",
    "rot_2",
    "rot_3",
)
_REST_COUNT_TO_DEGREE = {3 * (sh_coefficient_count(d) - 1): d for d in range(4)}
# Opacity is stored as a logit; 0 and 1 would be infinite, so they are pulled this far inside.
_OPACITY_EPS = 1e-7
_UNIT_NORM_SLACK = 2.0**-21  # a few float32 ulps around 1


def reference_property_names(sh_degree: int) -> list[str]:
    """Vertex property names in the order the reference 3DGS `save_ply` writes them."""
    rest = 3 * (sh_coefficient_count(sh_degree) - 1)
    return (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(rest)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )


def read_ply(path: str | os.PathLike[str]) -> GaussianScene:
    """Read an INRIA 3DGS `.ply` (binary little/big endian or ASCII) into an activated scene.

    Scales are exponentiated, opacities passed through the sigmoid and rotations normalised
    (`rot_0` is w). Extra properties (normals, `transform`, ...) are ignored.
    """
    check_header(path)
    fast = _float_vertex_table(path)
    if fast is not None:
        names, gather = fast
        columns = {name: i for i, name in enumerate(names)}
    else:
        try:
            data = plyfile.PlyData.read(os.fspath(path))
        except Exception as exc:  # plyfile raises many types for bad bytes; name the file instead
            raise SceneFormatError(f"{path}: malformed PLY ({type(exc).__name__}: {exc})") from None
        _check_body(path, data)
        elements = [element.name for element in data.elements]
        if "chunk" in elements:  # PlayCanvas compressed PLY
            from .compressed_ply import decode_compressed_ply

            return decode_compressed_ply(data, os.fspath(path))
        if "vertex" not in elements:
            raise SceneFormatError(f"{path}: no 'vertex' element (elements: {', '.join(elements) or 'none'})")
        vertex = data["vertex"]
        if vertex.count == 0:
            raise SceneFormatError(f"{path}: the 'vertex' element has no rows")
        columns = {prop.name: i for i, prop in enumerate(vertex.properties)}

        def gather(*wanted: list[int]) -> list[np.ndarray]:
            return [_gather_float32(vertex, w) for w in wanted]

    missing = [name for name in REQUIRED if name not in columns]
    if missing:
        raise SceneFormatError(f"{path}: missing vertex properties {', '.join(missing)}")
    rest = sorted((name for name in columns if name.startswith("f_rest_")), key=_suffix)
    if len(rest) not in _REST_COUNT_TO_DEGREE or [_suffix(n) for n in rest] != list(range(len(rest))):
        raise SceneFormatError(
            f"{path}: f_rest_* must be f_rest_0..f_rest_(n-1) with n in 0, 9, 24, 45; found {len(rest)}"
        )
    k = sh_coefficient_count(_REST_COUNT_TO_DEGREE[len(rest)])
    # f_rest is channel-major: f_rest_{c*(K-1)+j} is basis j+1 of channel c.
    sh_names = [[f"f_dc_{c}" for c in range(3)]]
    sh_names += [[f"f_rest_{c * (k - 1) + j}" for c in range(3)] for j in range(k - 1)]
    geometry = ["x", "y", "z", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", "opacity"]
    try:
        # Two gathers, so that sh lands in its own contiguous array with no further copy.
        values, sh = gather([columns[name] for name in geometry], [columns[name] for row in sh_names for name in row])
    except (ValueError, TypeError) as exc:
        raise SceneFormatError(f"{path}: vertex properties are not numeric ({exc})") from None
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        scales = np.exp(values[:, 3:6])
        quats = values[:, 6:10]
        norms = np.linalg.norm(quats, axis=1, keepdims=True)
        # Rows already unit to float32 rounding are kept as stored, so a saved file reloads bit-identical.
        norms[np.abs(norms - 1) <= _UNIT_NORM_SLACK] = 1
        quats = quats / np.maximum(norms, np.float32(1e-12))
        opacities = 1.0 / (1.0 + np.exp(-values[:, 10]))
    try:
        return GaussianScene(values[:, 0:3], scales, quats, opacities, sh.reshape(len(sh), k, 3))
    except SceneFormatError as exc:
        raise SceneFormatError(f"{path}: {exc}") from None


def write_ply(scene: GaussianScene, path: str | os.PathLike[str]) -> None:
    """Write `scene` as a binary little-endian INRIA `.ply` with properties in the reference order.

    Values are stored raw as 3DGS training stores them (log scale, logit opacity); opacities of
    exactly 0 or 1 are moved 1e-7 inside so their logit stays finite.
    """
    n, k, sh = len(scene), scene.sh.shape[1], scene.row_sh()
    names = reference_property_names(scene.sh_degree)
    table = np.zeros((n, len(names)), dtype=np.float32)
    table[:, 0:3] = scene.means
    table[:, 6:9] = sh[:, 0]
    # channel-major f_rest: (N, K-1, 3) -> (N, 3, K-1) -> flat
    table[:, 9 : 9 + 3 * (k - 1)] = sh[:, 1:].transpose(0, 2, 1).reshape(n, -1)
    tail = 9 + 3 * (k - 1)
    opacity = np.clip(scene.opacities.astype(np.float64), _OPACITY_EPS, 1 - _OPACITY_EPS)
    table[:, tail] = np.log(opacity / (1 - opacity))
    table[:, tail + 1 : tail + 4] = np.log(scene.scales.astype(np.float64))
    table[:, tail + 4 : tail + 8] = scene.quats
    records = table.view(np.dtype([(name, "<f4") for name in names])).reshape(n)
    element = plyfile.PlyElement.describe(records, "vertex")
    with atomic_open(path) as stream:
        plyfile.PlyData([element], text=False, byte_order="<").write(stream)


def _suffix(name: str) -> int:
    match = re.fullmatch(r"f_rest_(\d+)", name)
    return int(match.group(1)) if match else -1


def _gather_float32(vertex: plyfile.PlyElement, columns: list[int]) -> np.ndarray:
    """(N, len(columns)) float32 of the chosen properties, in one copy when all share a dtype."""
    records = vertex.data
    dtypes = {records.dtype[i] for i in range(len(records.dtype))}
    if len(dtypes) == 1 and records.dtype.itemsize == len(records.dtype) * next(iter(dtypes)).itemsize:
        table = records.view(next(iter(dtypes))).reshape(len(records), -1)
        return np.ascontiguousarray(table[:, columns], dtype=np.float32)
    names = records.dtype.names or ()
    return np.stack([records[names[i]].astype(np.float32) for i in columns], axis=1)


# Rows read at a time by the float-table reader: bounds its buffer (16 MB at SH degree 3).
_ROWS_PER_READ = 1 << 16
_FLOAT_TYPES = {b"float", b"float32"}


def _float_vertex_table(path: str | os.PathLike[str]):
    """The common 3DGS layout, read without holding the file in memory: a binary PLY whose only
    element is `vertex` with float32 properties. Returns (property names, gather) where
    `gather(columns_a, columns_b, ...)` reads the file once, in blocks of rows, into one float32
    array per column list; None for any other layout (plyfile then reads it)."""
    with open(path, "rb") as stream:
        head = stream.read(HEADER_LIMIT)
        size = os.fstat(stream.fileno()).st_size
    end = head.find(b"end_header\n")
    lines = head[:end].split(b"\n")
    formats = {b"format binary_little_endian 1.0": "<f4", b"format binary_big_endian 1.0": ">f4"}
    dtype = next((formats[line.strip()] for line in lines if line.strip() in formats), None)
    elements = [line.split() for line in lines if line.startswith(b"element ")]
    properties = [line.split() for line in lines if line.startswith(b"property ")]
    if end < 0 or dtype is None or len(elements) != 1 or elements[0][1:2] != [b"vertex"] or not properties:
        return None
    if len(elements[0]) != 3 or not elements[0][2].isdigit():
        return None  # plyfile names what is wrong
    if any(len(p) != 3 or p[1] not in _FLOAT_TYPES for p in properties):
        return None
    count, width = int(elements[0][2]), len(properties)
    names = [p[2].decode("ascii", errors="replace") for p in properties]
    start = end + len(b"end_header\n")
    body = size - start
    if count == 0:
        raise SceneFormatError(f"{path}: the 'vertex' element has no rows")
    if body != count * width * 4:
        raise SceneFormatError(
            f"{path}: the header says {count} vertex rows of {width * 4} bytes ({count * width * 4} bytes), "
            f"but {body} bytes follow it ({'truncated' if body < count * width * 4 else 'data past the last row'})"
        )

    def gather(*wanted: list[int]) -> list[np.ndarray]:
        outputs = [np.empty((count, len(w)), np.float32) for w in wanted]
        buffer = np.empty(min(count, _ROWS_PER_READ) * width, np.dtype(dtype))
        with open(path, "rb") as stream:
            stream.seek(start)
            for row in range(0, count, _ROWS_PER_READ):
                rows = min(_ROWS_PER_READ, count - row)
                block = buffer[: rows * width]
                if stream.readinto(block.data.cast("B")) != block.nbytes:
                    raise SceneFormatError(f"{path}: file ended inside vertex row {row}")
                table = block.reshape(rows, width)
                if not table.dtype.isnative:
                    table = table.astype(np.float32)
                for out, w in zip(outputs, wanted):
                    # in Rust, row by row while it is in cache (a NumPy gather goes column by column)
                    _core.gather_columns(table, w, out[row : row + rows])
        return outputs

    return names, gather


def _check_body(path: str | os.PathLike[str], data: plyfile.PlyData) -> None:
    """What plyfile lets pass: rows past the header's counts, and an ASCII file cut inside a number."""
    with open(path, "rb") as stream:
        head = stream.read(HEADER_LIMIT)
        size = os.fstat(stream.fileno()).st_size
        end = head.find(b"end_header")
        start = head.index(b"\n", end) + 1 if end >= 0 and b"\n" in head[end:] else size
        body = b""
        if data.text:  # only an ASCII body is read again (its rows are counted); a binary one is measured
            stream.seek(start)
            body = stream.read()
    if data.text:
        if body and not body[-1:].isspace():
            raise SceneFormatError(
                f"{path}: the file ends inside a value (truncated): '{body[-20:].decode(errors='replace')}'"
            )
        rows = sum(1 for line in body.splitlines() if line.strip())
        expected = sum(element.count for element in data.elements)
        if rows > expected:
            raise SceneFormatError(
                f"{path}: {rows} rows of data but the header declares {expected} (its counts are below the data)"
            )
        return
    sizes = [
        [
            0 if isinstance(prop, plyfile.PlyListProperty) else np.dtype(prop.val_dtype).itemsize
            for prop in element.properties
        ]
        for element in data.elements
    ]
    if all(all(sizes_) for sizes_ in sizes):  # fixed-size rows only
        expected = sum(element.count * sum(row) for element, row in zip(data.elements, sizes))
        if size - start > expected:
            raise SceneFormatError(
                f"{path}: {size - start - expected} bytes after the last row the header declares "
                "(its counts are below the data)"
            )
