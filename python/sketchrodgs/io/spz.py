"""Niantic `.spz` (nianticlabs/spz), versions 2 to 4.

Layout: a header, then six attribute blocks, each for all splats in turn: positions (3 x 24-bit
signed fixed point, `fractionalBits` fractional bits), alphas (u8, sigmoid already applied),
colours (3 x u8 holding 0.5 + 0.15 * f_dc), scales (3 x u8 holding (log scale + 10) * 16),
rotations, spherical harmonics (u8 holding 128 + 128 * coefficient; per splat coefficient-major,
RGB inner, degree 1..4).

- Versions 2 and 3 gzip the whole thing; the 16-byte header is `NGSP`, version, count (u32),
  SH degree, fractional bits, flags, reserved (u8). Flag 2 means extension records follow the
  header inside the stream.
- Version 4 is not gzipped: a 32-byte header (`NGSP`, version, count, SH degree, fractional bits,
  flags, stream count (u8), table-of-contents offset (u32), 12 reserved bytes), optional extension
  records, the table of contents ((compressed, uncompressed) u64 pairs), then each non-empty
  block as its own zstd stream.
- Rotations: version 2 stores x, y, z as u8 (q / 127.5 - 1) with w >= 0 rebuilt; versions 3 and
  4 store the "smallest three" in a little-endian u32: bits 30-31 the index (in x, y, z, w order)
  of the largest component, then 10 bits per other component (9-bit magnitude over 1/sqrt(2) and a
  sign bit), the first of them in the highest bits.

Axes: SPZ nominally stores RUB axes (OpenGL: y up, z backwards), while INRIA `.ply` files are
usually RDF (OpenCV: y down). The reference loader converts only when asked for a target system;
we load the values as stored, like its default (no conversion), so a scene reads with the same
numbers every tool shows for the file (the biker test file, for one, stands head up along +y).
To get RDF axes, negate y and z of the means, the y and z quaternion components, and the SH
coefficients whose basis function changes sign under (y, z) -> (-y, -z).

Extensions (vendor records) are skipped. SH degree 4 is read and its band 4 dropped (the scene
holds degree 3 at most). The antialiasing flag is ignored.

The attributes are inflated into one buffer of the size the header declares (gzip by libdeflate,
in a part per core for big streams; zstd by `zstandard`), so nothing past it is ever inflated,
and decoded in Rust (`sketchrodgs-formats`), a block of splats per core.
"""

from __future__ import annotations

import logging
import os
import struct
import zlib
from dataclasses import dataclass

import numpy as np
import zstandard

from .. import _core
from ..errors import SceneFormatError
from ..scene import GaussianScene, sh_coefficient_count
from ._quantized import empty_scene_arrays, map_file

logger = logging.getLogger("sketchrodgs")
MAX_FRACTIONAL_BITS = 24

MAGIC = b"NGSP"
GZIP_MAGIC = b"\x1f\x8b"
FLAG_EXTENSIONS = 0x2
LEGACY_HEADER = struct.Struct("<4sIIBBBB")  # versions 2, 3 (inside the gzip stream)
V4_HEADER = struct.Struct("<4sIIBBBBI12x")  # version 4
TOC_ENTRY = struct.Struct("<QQ")
SUPPORTED_VERSIONS = (2, 3, 4)
# SH coefficients per channel beyond the DC term, by degree (SPZ allows degree 4).
SH_DIM = {0: 0, 1: 3, 2: 8, 3: 15, 4: 24}
STREAM_NAMES = ("positions", "alphas", "colors", "scales", "rotations", "sh")
# Extension records in a gzip stream have no length field we can trust across versions; we skip
# whatever lies between the header and the attributes, up to this much.
MAX_EXTENSION_BYTES = 1 << 20
# The reference loader refuses more splats than this; it also caps what a forged count can make us
# allocate (a zstd or gzip bomb can only fill what the count declares).
MAX_SPLATS = 10_000_000
# Bomb guards: no deflate stream expands more than 1032:1, and no zstd stream more than an RLE
# block does (4 bytes to 128 KiB). A declared size beyond these cannot be real.
DEFLATE_MAX_RATIO = 1032
ZSTD_MAX_RATIO = 1 << 15
_ZSTD_FRAME_SLACK = 1 << 17
_HEADER_PIECE = 1 << 12  # compressed bytes inflated to read a gzipped header


@dataclass(frozen=True)
class SpzHeader:
    """The header fields the decoder uses."""

    version: int
    count: int
    sh_degree: int
    fractional_bits: int
    flags: int

    def stream_sizes(self) -> list[tuple[str, int]]:
        """(name, bytes) of each attribute block in file order."""
        n = self.count
        rotation_bytes = 3 if self.version == 2 else 4
        sizes = (9 * n, n, 3 * n, 3 * n, rotation_bytes * n, 3 * SH_DIM[self.sh_degree] * n)
        return list(zip(STREAM_NAMES, sizes, strict=True))

    def payload_bytes(self) -> int:
        return sum(size for _, size in self.stream_sizes())


def read_spz(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a `.spz` file (version 2, 3 or 4) into an activated scene.

    Raises:
        SceneFormatError: the file is unreadable, truncated, of another version, its counts
            disagree with its data, or a stream would decompress past its declared size.
    """
    return decode_spz(map_file(path), os.fspath(path))


def decode_spz(raw: bytes | np.ndarray, source: str = "<spz>") -> GaussianScene:
    """Decode the bytes of a `.spz` file (bytes or a uint8 array); `source` names it in errors."""
    raw = np.frombuffer(raw, dtype=np.uint8) if not isinstance(raw, np.ndarray) else raw
    start = raw[:4].tobytes()
    try:
        if start == MAGIC:
            header, payload = _inflate_v4(raw)
        elif start[:2] == GZIP_MAGIC:
            header, payload = _inflate_gzipped(raw, source)
        else:
            raise SceneFormatError(f"not an SPZ file (starts with {start!r}, not gzip or NGSP)")
        return _decode(header, payload)
    except SceneFormatError as exc:
        raise SceneFormatError(f"{source}: {exc}") from None


def parse_header(magic: bytes, version: int, count: int, sh_degree: int, fractional_bits: int, flags: int) -> SpzHeader:
    """Check the header fields common to all versions (magic, version, count, SH degree)."""
    if magic != MAGIC:
        raise SceneFormatError(f"bad SPZ magic {magic!r} (expected {MAGIC!r})")
    if version not in SUPPORTED_VERSIONS:
        hint = " (version 1 stored float16 positions and was never released)" if version == 1 else ""
        raise SceneFormatError(f"unsupported SPZ version {version}{hint}; supported: 2, 3, 4")
    if count == 0:
        raise SceneFormatError("the SPZ header declares 0 splats")
    if count > MAX_SPLATS:
        raise SceneFormatError(
            f"the SPZ header declares {count:,} splats, more than the {MAX_SPLATS:,} the reference SPZ loader "
            "accepts (corrupt file?)"
        )
    if sh_degree not in SH_DIM:
        raise SceneFormatError(f"unsupported SH degree {sh_degree} (SPZ allows 0 to 4)")
    if fractional_bits > MAX_FRACTIONAL_BITS:
        # positions are 24-bit fixed point: more fractional bits than that put every one near 0
        raise SceneFormatError(
            f"fractionalBits {fractional_bits}: positions are 24-bit fixed point, so at most {MAX_FRACTIONAL_BITS} "
            "(the reference writer uses 12)"
        )
    return SpzHeader(version, count, sh_degree, fractional_bits, flags)


# ---- inflating the attributes ---------------------------------------------------------------------


def _inflate_gzipped(raw: np.ndarray, source: str) -> tuple[SpzHeader, np.ndarray]:
    """Versions 2 and 3: one gzip stream holding the header and the attributes. Bytes after the
    gzip member are ignored, as gzip ignores them, with a warning."""
    header = _gzipped_header(raw)
    payload = header.payload_bytes()
    if payload > len(raw) * DEFLATE_MAX_RATIO:
        raise SceneFormatError(
            f"header declares {header.count:,} splats ({payload:,} bytes), more than {len(raw):,} gzip bytes can "
            "hold (truncated or corrupt)"
        )
    # Extension records sit between the header and the attributes, and no length field says how
    # long they are across versions: leave room for them (to a bound) and take the attributes
    # from the end.
    room = MAX_EXTENSION_BYTES if header.flags & FLAG_EXTENSIONS else 0
    inflated = np.empty(LEGACY_HEADER.size + payload + room, dtype=np.uint8)
    try:
        result = _core.gunzip_into(raw, inflated)
    except ValueError as exc:
        raise SceneFormatError(str(exc)) from None
    if result is None:
        raise SceneFormatError(
            f"SPZ data continues past the {payload:,} bytes that {header.count:,} splats need "
            "(the count disagrees with the data)"
        )
    written, trailing = result
    if trailing:
        logger.warning("%s: the file continues after its gzip member; the extra bytes were ignored", source)
    body = written - LEGACY_HEADER.size
    if body < payload:
        inside = _stream_at(header, body)
        raise SceneFormatError(
            f"SPZ data ends in the {inside} after {body:,} of the {payload:,} bytes that {header.count:,} splats "
            "need (truncated, or the count disagrees with the data)"
        )
    return header, inflated[written - payload : written]


def _gzipped_header(raw: np.ndarray) -> SpzHeader:
    """The SPZ header at the start of the gzip stream, inflated on its own."""
    inflater = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
    head, fed = b"", 0
    try:
        while len(head) < LEGACY_HEADER.size and not inflater.eof:
            piece = inflater.unconsumed_tail
            if not piece:
                if fed >= len(raw):
                    break
                piece, fed = raw[fed : fed + _HEADER_PIECE].tobytes(), fed + _HEADER_PIECE
            head += inflater.decompress(piece, LEGACY_HEADER.size - len(head))
    except zlib.error as exc:
        raise SceneFormatError(f"corrupt gzip stream ({exc})") from None
    if len(head) < LEGACY_HEADER.size:
        raise SceneFormatError(f"gzip stream ends inside the {LEGACY_HEADER.size}-byte SPZ header")
    header = parse_header(*LEGACY_HEADER.unpack(head)[:6])
    if header.version == 4:
        raise SceneFormatError("SPZ version 4 must not be gzipped (corrupt file?)")
    return header


def _stream_at(header: SpzHeader, offset: int) -> str:
    """Name of the attribute block holding payload byte `offset`."""
    for name, size in header.stream_sizes():
        if offset < size:
            return name
        offset -= size
    return STREAM_NAMES[-1]


def _inflate_v4(raw: np.ndarray) -> tuple[SpzHeader, np.ndarray]:
    """Version 4: a plain header and table of contents, then one zstd stream per attribute."""
    if len(raw) < V4_HEADER.size:
        raise SceneFormatError(f"file ends inside the {V4_HEADER.size}-byte SPZ header ({len(raw)} bytes)")
    *fields, stream_count, toc_offset = V4_HEADER.unpack_from(raw.data)
    header = parse_header(*fields)
    if header.version != 4:
        raise SceneFormatError(f"SPZ version {header.version} must be gzipped, but the file starts with NGSP")
    expected = [(name, size) for name, size in header.stream_sizes() if size]
    if stream_count != len(expected):
        raise SceneFormatError(
            f"header lists {stream_count} streams; SH degree {header.sh_degree} needs {len(expected)}"
        )
    toc_end = toc_offset + TOC_ENTRY.size * stream_count
    if toc_offset < V4_HEADER.size or toc_end > len(raw):
        raise SceneFormatError(f"table of contents at byte {toc_offset} lies outside the {len(raw)}-byte file")
    frames = []
    offset = toc_end
    for i, (name, size) in enumerate(expected):
        compressed, uncompressed = TOC_ENTRY.unpack_from(raw.data, toc_offset + TOC_ENTRY.size * i)
        if uncompressed != size:
            raise SceneFormatError(
                f"{name} stream holds {uncompressed:,} bytes but {header.count:,} splats need {size:,} "
                "(the count disagrees with the data)"
            )
        if offset + compressed > len(raw):
            raise SceneFormatError(
                f"{name} stream ({compressed:,} bytes at {offset:,}) runs past the end of the {len(raw):,}-byte "
                "file (truncated)"
            )
        if size > compressed * ZSTD_MAX_RATIO + _ZSTD_FRAME_SLACK:
            raise SceneFormatError(f"{name} stream of {compressed:,} bytes cannot expand to {size:,} bytes")
        frames.append((name, raw[offset : offset + compressed], size))
        offset += compressed
    payload = np.empty(header.payload_bytes(), dtype=np.uint8)
    done = 0
    for name, frame, size in frames:
        _unzstd_into(name, frame, payload[done : done + size])
        done += size
    return header, payload


def _unzstd_into(name: str, frame: np.ndarray, out: np.ndarray) -> None:
    """Decompress the zstd stream `frame` into exactly `out`, or say why it does not fit."""
    reader = zstandard.ZstdDecompressor().stream_reader(frame.data, read_across_frames=True)
    view, got = out.data, 0
    try:
        while got < len(out):
            count = reader.readinto(view[got:])
            if not count:
                raise SceneFormatError(f"{name} stream ends after {got:,} of its {len(out):,} bytes (truncated)")
            got += count
        if reader.read(1):
            raise SceneFormatError(f"{name} stream decompresses past its declared {len(out):,} bytes")
    except zstandard.ZstdError as exc:
        raise SceneFormatError(f"{name} stream is corrupt ({exc})") from None


# ---- decoding -------------------------------------------------------------------------------------


def _decode(header: SpzHeader, payload: np.ndarray) -> GaussianScene:
    """Decode the attribute blocks (`payload`, in file order) into a scene."""
    if header.sh_degree == 4:
        logger.warning("SPZ SH degree 4: band 4 dropped (scenes hold degree 3 at most)")
    arrays = empty_scene_arrays(header.count, sh_coefficient_count(min(header.sh_degree, 3)))
    sh_bytes_per_splat = 3 * SH_DIM[header.sh_degree]
    _core.decode_spz(payload, header.version, sh_bytes_per_splat, header.fractional_bits, arrays)
    return GaussianScene(*arrays)


__all__ = ["SpzHeader", "decode_spz", "read_spz"]
