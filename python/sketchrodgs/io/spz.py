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

The attributes are decompressed a block at a time straight into the decoder, so no stream is
ever held whole and nothing past the size the header declares is ever inflated.
"""

from __future__ import annotations

import logging
import math
import os
import struct
import zlib
from dataclasses import dataclass

import numpy as np
import zstandard

from ..errors import SceneFormatError
from ..scene import GaussianScene, sh_coefficient_count
from ._quantized import SmallestThree, block_size, blocks, byte_table, lookup

logger = logging.getLogger("sketchrodgs")

MAGIC = b"NGSP"
GZIP_MAGIC = b"\x1f\x8b"
COLOR_SCALE = 0.15  # SPZ keeps f_dc as 0.5 + 0.15 * f_dc so that colours a little outside [0, 1] fit
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
_INPUT_PIECE = 1 << 16  # compressed bytes handed to zlib at a time

_DC = byte_table(lambda b: (b / 255 - 0.5) / COLOR_SCALE)
_LOG_SCALE_EXP = byte_table(lambda b: np.exp(b / 16 - 10))
_V2_ROTATION = byte_table(lambda b: b / 127.5 - 1)
# 10-bit smallest-three field: sign bit 9, then a 9-bit magnitude over 1/sqrt(2)
_SMALLEST_THREE = byte_table(lambda f: np.where(f >= 512, -1, 1) * (f % 512) * math.sqrt(0.5) / 511, 1024)


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
    try:
        with open(path, "rb") as stream:
            raw = stream.read()
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    return decode_spz(raw, os.fspath(path))


def decode_spz(raw: bytes, source: str = "<spz>") -> GaussianScene:
    """Decode the bytes of a `.spz` file; `source` names it in errors."""
    try:
        if raw[:4] == MAGIC:
            header, streams = _open_v4(memoryview(raw))
        elif raw[:2] == GZIP_MAGIC:
            header, streams = _open_gzipped(raw)
        else:
            raise SceneFormatError(f"not an SPZ file (starts with {raw[:4]!r}, not gzip or NGSP)")
        return _decode(header, streams)
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
    return SpzHeader(version, count, sh_degree, fractional_bits, flags)


# ---- where the attribute bytes come from --------------------------------------------------------


class _Inflated:
    """The attributes of a version 2/3 file, read in order from its one gzip stream.

    Compressed input is fed in pieces: zlib hands back the unused input as a new bytes object on
    every call, so feeding the whole file would copy it once per block.
    """

    def __init__(self, raw: bytes) -> None:
        self.raw, self.fed = memoryview(raw), 0
        self.inflater = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
        self.header: SpzHeader | None = None
        self.done = 0

    def inflate(self, limit: int) -> bytes:
        """Up to `limit` more bytes; empty only at the end of the stream or of the input."""
        try:
            while True:
                data = self.inflater.unconsumed_tail
                if not data:
                    if self.inflater.eof or self.fed >= len(self.raw):
                        return b""
                    data = self.raw[self.fed:self.fed + _INPUT_PIECE]
                    self.fed += len(data)
                piece = self.inflater.decompress(data, limit)
                if piece or self.inflater.eof:
                    return piece
        except zlib.error as exc:
            raise SceneFormatError(f"corrupt gzip stream ({exc})") from None

    def read(self, limit: int) -> bytes:
        """Up to `limit` bytes, fewer only where the stream or the input ends."""
        pieces, got = [], 0
        while got < limit:
            piece = self.inflate(limit - got)
            if not piece:
                break
            pieces.append(piece)
            got += len(piece)
        return b"".join(pieces)

    def fill(self, name: str, out: np.ndarray) -> None:
        got = 0
        while got < len(out):
            piece = self.inflate(len(out) - got)
            if not piece:
                break
            out[got:got + len(piece)] = np.frombuffer(piece, dtype=np.uint8)
            got += len(piece)
        self.done += got
        if got < len(out) and self.header is not None:
            raise SceneFormatError(
                f"SPZ data ends in the {name} after {self.done:,} of the {self.header.payload_bytes():,} bytes that "
                f"{self.header.count:,} splats need (truncated, or the count disagrees with the data)"
            )

    def close(self) -> None:
        if self.inflate(1) and self.header is not None:
            raise SceneFormatError(
                f"SPZ data continues past the {self.header.payload_bytes():,} bytes that "
                f"{self.header.count:,} splats need (the count disagrees with the data)"
            )
        if not self.inflater.eof:
            raise SceneFormatError("gzip stream is truncated (no end marker)")


class _InMemory:
    """Attributes already inflated (version 2/3 files with extension records)."""

    def __init__(self, data: np.ndarray) -> None:
        self.data, self.done = data, 0

    def fill(self, name: str, out: np.ndarray) -> None:
        out[...] = self.data[self.done:self.done + len(out)]
        self.done += len(out)

    def close(self) -> None:
        pass


class _ZstdStreams:
    """The attributes of a version 4 file, each its own zstd stream of a known size."""

    def __init__(self, raw: memoryview, header: SpzHeader, frames: dict[str, tuple[int, int, int]]) -> None:
        self.raw, self.header, self.frames = raw, header, frames  # name -> (offset, compressed, size)
        self.decompressor = zstandard.ZstdDecompressor()
        self.name: str | None = None
        self.reader: zstandard.ZstdDecompressionReader | None = None
        self.done = 0

    def fill(self, name: str, out: np.ndarray) -> None:
        reader = self.reader
        if name != self.name or reader is None:
            self.close()
            offset, compressed, _ = self.frames[name]
            self.name, self.done = name, 0
            reader = self.reader = self.decompressor.stream_reader(
                self.raw[offset:offset + compressed], read_across_frames=True
            )
        view, got = memoryview(out), 0
        try:
            while got < len(out):
                count = reader.readinto(view[got:])
                if not count:
                    break
                got += count
        except zstandard.ZstdError as exc:
            raise SceneFormatError(f"{name} stream is corrupt ({exc})") from None
        self.done += got
        if got < len(out):
            size = self.frames[name][2]
            raise SceneFormatError(f"{name} stream ends after {self.done:,} of its {size:,} bytes (truncated)")

    def close(self) -> None:
        """Check that the stream just read holds nothing more."""
        if self.reader is None:
            return
        try:
            extra = self.reader.read(1)
        except zstandard.ZstdError as exc:
            raise SceneFormatError(f"{self.name} stream is corrupt ({exc})") from None
        if extra:
            size = self.frames[str(self.name)][2]
            raise SceneFormatError(f"{self.name} stream decompresses past its declared {size:,} bytes")
        self.reader.close()
        self.reader = None


def _open_gzipped(raw: bytes) -> tuple[SpzHeader, _Inflated | _InMemory]:
    """Versions 2 and 3: one gzip stream holding the header and the attributes."""
    stream = _Inflated(raw)
    head = stream.read(LEGACY_HEADER.size)
    if len(head) < LEGACY_HEADER.size:
        raise SceneFormatError(f"gzip stream ends inside the {LEGACY_HEADER.size}-byte SPZ header")
    header = parse_header(*LEGACY_HEADER.unpack(head)[:6])
    if header.version == 4:
        raise SceneFormatError("SPZ version 4 must not be gzipped (corrupt file?)")
    payload = header.payload_bytes()
    if payload > len(raw) * DEFLATE_MAX_RATIO:
        raise SceneFormatError(
            f"header declares {header.count:,} splats ({payload:,} bytes), more than {len(raw):,} gzip bytes can "
            "hold (truncated or corrupt)"
        )
    stream.header = header
    if not header.flags & FLAG_EXTENSIONS:
        return header, stream
    # Extension records sit between the header and the attributes, and no length field says how
    # long they are across versions: inflate everything (to a bound) and take the attributes
    # from the end.
    body = stream.read(payload + MAX_EXTENSION_BYTES + 1)
    if len(body) < payload:
        raise SceneFormatError(
            f"SPZ data holds {len(body):,} bytes after the header but {header.count:,} splats need {payload:,} "
            "(truncated, or the count disagrees with the data)"
        )
    if len(body) - payload > MAX_EXTENSION_BYTES:
        raise SceneFormatError(
            f"SPZ data continues past the {payload:,} bytes that {header.count:,} splats need "
            "(the count disagrees with the data)"
        )
    stream.close()
    return header, _InMemory(np.frombuffer(body, dtype=np.uint8, offset=len(body) - payload))


def _open_v4(raw: memoryview) -> tuple[SpzHeader, _ZstdStreams]:
    """Version 4: a plain header and table of contents, then one zstd stream per attribute."""
    if len(raw) < V4_HEADER.size:
        raise SceneFormatError(f"file ends inside the {V4_HEADER.size}-byte SPZ header ({len(raw)} bytes)")
    *fields, stream_count, toc_offset = V4_HEADER.unpack_from(raw)
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
    frames = {}
    offset = toc_end
    for i, (name, size) in enumerate(expected):
        compressed, uncompressed = TOC_ENTRY.unpack_from(raw, toc_offset + TOC_ENTRY.size * i)
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
        frames[name] = (offset, compressed, size)
        offset += compressed
    return header, _ZstdStreams(raw, header, frames)


# ---- decoding -------------------------------------------------------------------------------------


def _decode(header: SpzHeader, streams: _Inflated | _InMemory | _ZstdStreams) -> GaussianScene:
    """Pull each attribute a block at a time, in file order, and decode it into the scene."""
    n = header.count
    k = sh_coefficient_count(min(header.sh_degree, 3))
    if header.sh_degree == 4:
        logger.warning("SPZ SH degree 4: band 4 dropped (scenes hold degree 3 at most)")
    means = np.empty((n, 3), dtype=np.float32)
    scales = np.empty((n, 3), dtype=np.float32)
    quats = np.empty((n, 4), dtype=np.float32)
    opacities = np.empty(n, dtype=np.float32)
    sh = np.empty((n, k, 3), dtype=np.float32)
    block = block_size(60 + 12 * k)
    sh_row = 3 * SH_DIM[header.sh_degree]
    rotation_bytes = 3 if header.version == 2 else 4
    buffer = np.empty(max(9, sh_row, 1) * block + 1, dtype=np.uint8)  # one reused read buffer

    def read(name: str, width: int, start: int, stop: int) -> np.ndarray:
        out = buffer[: width * (stop - start)]
        streams.fill(name, out)
        return out

    position_scale = np.float32(math.ldexp(1.0, -header.fractional_bits))  # a power of two: exact
    for start, stop in blocks(n, block):
        size = stop - start
        read("positions", 9, start, stop)
        buffer[9 * size] = 0
        # Each 24-bit coordinate is read as the int32 starting at its first byte, then shifted up
        # and back down, which drops the following byte and sign-extends.
        words = np.ndarray((3 * size,), dtype="<i4", buffer=buffer, strides=(3,)) << 8
        words >>= 8
        xyz = means[start:stop].reshape(-1)
        xyz[...] = words  # exact: 24 bits fit a float32
        xyz *= position_scale
    for start, stop in blocks(n, block):
        np.divide(read("alphas", 1, start, stop), np.float32(255), out=opacities[start:stop], dtype=np.float32)
    # With SH, the colours wait (as bytes) for the SH rows, so that each row is written whole.
    colors = np.empty(3 * n, dtype=np.uint8) if k > 1 else None
    for start, stop in blocks(n, block):
        data = read("colors", 3, start, stop)
        if colors is None:
            lookup(_DC, data.reshape(-1, 3), sh[start:stop, 0])
        else:
            colors[3 * start:3 * stop] = data
    for start, stop in blocks(n, block):
        lookup(_LOG_SCALE_EXP, read("scales", 3, start, stop), scales[start:stop].reshape(-1))
    smallest_three = SmallestThree(wxyz=(3, 0, 1, 2))  # SPZ orders components x, y, z, w
    for start, stop in blocks(n, block):
        data = read("rotations", rotation_bytes, start, stop)
        if header.version == 2:
            _rotations_v2(data.reshape(-1, 3), quats[start:stop])
        else:
            packed = data.view("<u4")
            stored = smallest_three.stored(stop - start)
            for row, shift in enumerate((20, 10, 0)):
                lookup(_SMALLEST_THREE, (packed >> shift) & 0x3FF, stored[row])
            smallest_three.finish(packed >> 30, quats[start:stop])
    if sh_row and colors is not None:
        rows_buffer = np.empty((block, k, 3), dtype=np.float32)
        for start, stop in blocks(n, block):
            size = stop - start
            rows = rows_buffer[:size]
            coefficients = read("sh", sh_row, start, stop).reshape(size, sh_row)[:, : 3 * (k - 1)]
            lookup(_DC, colors[3 * start:3 * stop].reshape(size, 3), rows[:, 0])
            # (b - 128) / 128: b ^ 0x80 read as int8 is b - 128, and 1/128 is exact
            centred = (coefficients ^ np.uint8(0x80)).view(np.int8).reshape(size, k - 1, 3)
            np.multiply(centred, np.float32(1 / 128), out=rows[:, 1:], dtype=np.float32)
            sh[start:stop] = rows
    streams.close()
    return GaussianScene(means, scales, quats, opacities, sh)


def _rotations_v2(xyz_bytes: np.ndarray, out: np.ndarray) -> None:
    """x, y, z as u8 (q / 127.5 - 1), w >= 0 rebuilt; renormalised, as |xyz| may exceed 1."""
    xyz = np.empty(xyz_bytes.shape, dtype=np.float32)
    lookup(_V2_ROTATION, xyz_bytes, xyz)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    squared = x * x + y * y + z * z
    out[:, 0] = np.sqrt(np.maximum(np.float32(0), np.float32(1) - squared))
    out[:, 1:] = xyz
    too_long = squared > 1  # then w is 0
    if too_long.any():
        out[too_long] /= np.sqrt(squared[too_long])[:, None]


__all__ = ["SpzHeader", "decode_spz", "read_spz"]
