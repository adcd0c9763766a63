"""Test-side encoders for SPZ and the PlayCanvas compressed PLY, written from the format
descriptions (nianticlabs/spz README and `packGaussians`; splat-transform's compressed-chunk
writer), not from our decoders. They quantise activated scene arrays the way the reference
writers do, so that decoding what they write must give the values back within each format's
quantisation step. They also expose the container pieces, so tests can build broken files.
"""

from __future__ import annotations

import gzip
import math
import struct

import numpy as np
import zstandard

SH_C0 = 0.28209479177387814
SPZ_COLOR_SCALE = 0.15
SPZ_SH_DIM = {0: 0, 1: 3, 2: 8, 3: 15, 4: 24}


def _to_u8(values: np.ndarray) -> np.ndarray:
    """round-half-away then clamp to a byte, like the reference `toUint8` (std::round)."""
    values = np.asarray(values, dtype=np.float64)
    return np.clip(np.sign(values) * np.floor(np.abs(values) + 0.5), 0, 255).astype(np.uint8)


# ---- SPZ ----------------------------------------------------------------------------------------


def spz_blocks(
    means: np.ndarray,
    scales: np.ndarray,
    quats: np.ndarray,
    opacities: np.ndarray,
    sh: np.ndarray,
    version: int,
    fractional_bits: int = 12,
    sh_bits: tuple[int, int] = (8, 8),
) -> list[bytes]:
    """The six attribute blocks (positions, alphas, colours, scales, rotations, SH) of `version`.

    Inputs are activated: scales linear, quats (N, 4) w first, opacities in [0, 1], sh (N, K, 3)
    with sh[:, 0] the DC term. SH rows are coefficient-major with RGB inner, as SPZ stores them.
    `sh_bits` are the bits kept of the degree-1 and of the higher SH bytes; the reference writer
    keeps (5, 4) by default, rounding each byte to a multiple of 2^(8 - bits).
    """
    n = len(means)
    fixed = np.rint(np.asarray(means, np.float64) * (1 << fractional_bits)).astype(np.int64)
    fixed &= 0xFFFFFF  # 24-bit two's complement
    positions = np.stack([fixed & 0xFF, (fixed >> 8) & 0xFF, (fixed >> 16) & 0xFF], axis=-1).astype(np.uint8)
    alphas = _to_u8(np.asarray(opacities, np.float64) * 255)
    colors = _to_u8(np.asarray(sh[:, 0], np.float64) * (SPZ_COLOR_SCALE * 255) + 0.5 * 255)
    log_scales = _to_u8((np.log(np.asarray(scales, np.float64)) + 10) * 16)
    # The reference works in x, y, z, w order.
    q = np.asarray(quats, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    xyzw = np.concatenate([q[:, 1:], q[:, :1]], axis=1)
    if version == 2:
        sign = np.where(xyzw[:, 3:] < 0, -1.0, 1.0)
        rotations = _to_u8(xyzw[:, :3] * sign * 127.5 + 127.5)
    else:
        largest = np.argmax(np.abs(xyzw), axis=1)  # first of equal magnitudes, like the reference
        negate = np.take_along_axis(xyzw, largest[:, None], axis=1)[:, 0] < 0
        word = largest.astype(np.uint32)
        for k in range(4):  # components other than the largest, first one ends in the highest bits
            negbit = ((xyzw[:, k] < 0) != negate).astype(np.uint32)
            magnitude = np.floor(511 * (np.abs(xyzw[:, k]) / math.sqrt(0.5)) + 0.5).astype(np.uint32)
            word = np.where(largest == k, word, (word << 10) | (negbit << 9) | magnitude)
        rotations = word.astype("<u4").view(np.uint8).reshape(n, 4)
    rest = np.rint(np.asarray(sh[:, 1:], np.float64) * 128 + 128)
    for band, bits in ((slice(0, 3), sh_bits[0]), (slice(3, None), sh_bits[1])):
        bucket = 1 << (8 - bits)
        rest[:, band] = np.floor((rest[:, band] + bucket / 2) / bucket) * bucket
    sh_bytes = np.clip(rest, 0, 255).astype(np.uint8)
    return [a.tobytes() for a in (positions, alphas, colors, log_scales, rotations, sh_bytes)]


def spz_gzip(
    blocks: list[bytes],
    count: int,
    sh_degree: int,
    version: int,
    fractional_bits: int = 12,
    flags: int = 0,
    extensions: bytes = b"",
    magic: bytes = b"NGSP",
) -> bytes:
    """A version 2/3 file: gzip(16-byte header + extension records + blocks)."""
    header = struct.pack("<4sIIBBBB", magic, version, count, sh_degree, fractional_bits, flags, 0)
    return gzip.compress(header + extensions + b"".join(blocks))


def spz_v4(
    blocks: list[bytes],
    count: int,
    sh_degree: int,
    fractional_bits: int = 12,
    flags: int = 0,
    extensions: bytes = b"",
    frames: list[bytes] | None = None,
    sizes: list[int] | None = None,
    stream_count: int | None = None,
    version: int = 4,
) -> bytes:
    """A version 4 file: 32-byte header, extension records, table of contents, zstd streams.

    Empty blocks are left out, as the reference writer does. `frames` replaces the compressed
    streams and `sizes` the uncompressed sizes in the table of contents (for broken files).
    """
    stored = [block for block in blocks if block]
    if frames is None:
        frames = [zstandard.ZstdCompressor(level=3).compress(block) for block in stored]
    if sizes is None:
        sizes = [len(block) for block in stored]
    count_of_streams = len(frames) if stream_count is None else stream_count
    toc_offset = 32 + len(extensions)
    header = struct.pack(
        "<4sIIBBBBI12x", b"NGSP", version, count, sh_degree, fractional_bits, flags, count_of_streams, toc_offset
    )
    toc = b"".join(struct.pack("<QQ", len(frame), size) for frame, size in zip(frames, sizes, strict=True))
    return header + extensions + toc + b"".join(frames)


def encode_spz(
    means, scales, quats, opacities, sh, version: int = 4, fractional_bits: int = 12, sh_bits: tuple[int, int] = (8, 8)
) -> bytes:
    """A whole `.spz` file of `version` (2, 3 or 4) for the given activated arrays."""
    sh = np.asarray(sh)
    degree = {1: 0, 4: 1, 9: 2, 16: 3, 25: 4}[sh.shape[1]]
    blocks = spz_blocks(means, scales, quats, opacities, sh, version, fractional_bits, sh_bits)
    if version == 4:
        return spz_v4(blocks, len(means), degree, fractional_bits)
    return spz_gzip(blocks, len(means), degree, version, fractional_bits)


# ---- PlayCanvas compressed PLY ------------------------------------------------------------------

CHUNK = 256
CHUNK_PROPERTIES = [
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
]
CHUNK_COLOR_PROPERTIES = ["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"]


def _normalize(values: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    span = high - low
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(span < 1e-5, 0.0, (values - low) / np.where(span == 0, 1, span))
    return np.where(values <= low, 0.0, np.where(values >= high, 1.0, t))


def _pack_unorm(values: np.ndarray, bits: int) -> np.ndarray:
    top = (1 << bits) - 1
    return np.clip(np.floor(values * top + 0.5), 0, top).astype(np.uint32)


def encode_compressed_ply(
    means,
    scales,
    quats,
    opacities,
    sh,
    chunk_colors: bool = True,
    chunk_rows: int | None = None,
    sh_rows: int | None = None,
) -> bytes:
    """A compressed `.ply` in the layout splat-transform writes (file order kept, no sorting).

    `chunk_colors=False` writes the older 12-property chunks whose colours are stored directly.
    `chunk_rows` / `sh_rows` override the element counts written in the header (for broken files).
    """
    n = len(means)
    chunks = -(-n // CHUNK)
    pad = chunks * CHUNK - n

    def padded(values: np.ndarray) -> np.ndarray:  # the writer repeats the last splat
        values = np.asarray(values, np.float64)
        return np.concatenate([values, np.repeat(values[-1:], pad, axis=0)]).reshape(chunks, CHUNK, *values.shape[1:])

    position, log_scale = padded(means), padded(np.log(np.asarray(scales, np.float64)))
    rgb = padded(np.asarray(sh[:, 0], np.float64) * SH_C0 + 0.5)
    pos_lo, pos_hi = position.min(axis=1, keepdims=True), position.max(axis=1, keepdims=True)
    scale_lo = np.clip(log_scale.min(axis=1, keepdims=True), -20, 20)
    scale_hi = np.clip(log_scale.max(axis=1, keepdims=True), -20, 20)
    rgb_lo, rgb_hi = rgb.min(axis=1, keepdims=True), rgb.max(axis=1, keepdims=True)

    def pack_111011(values: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        t = _normalize(values, low, high)
        return (_pack_unorm(t[..., 0], 11) << 21) | (_pack_unorm(t[..., 1], 10) << 11) | _pack_unorm(t[..., 2], 11)

    packed_position = pack_111011(position, pos_lo, pos_hi)
    packed_scale = pack_111011(log_scale, scale_lo, scale_hi)
    color_t = _normalize(rgb, rgb_lo, rgb_hi) if chunk_colors else rgb
    alpha = padded(np.asarray(opacities, np.float64))
    packed_color = (
        (_pack_unorm(color_t[..., 0], 8) << 24)
        | (_pack_unorm(color_t[..., 1], 8) << 16)
        | (_pack_unorm(color_t[..., 2], 8) << 8)
        | _pack_unorm(alpha, 8)
    )
    q = padded(np.asarray(quats, np.float64))
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    largest = np.argmax(np.abs(q), axis=-1)  # first of equal magnitudes, like the writer's reduce
    q = np.where(np.take_along_axis(q, largest[..., None], axis=-1) < 0, -q, q)
    packed_rotation = largest.astype(np.uint32)
    for k in range(4):
        part = _pack_unorm(q[..., k] * (math.sqrt(2) * 0.5) + 0.5, 10)
        packed_rotation = np.where(largest == k, packed_rotation, (packed_rotation << 10) | part)

    chunk_table = [pos_lo[:, 0], pos_hi[:, 0], scale_lo[:, 0], scale_hi[:, 0]]
    chunk_names = list(CHUNK_PROPERTIES)
    if chunk_colors:
        chunk_table += [rgb_lo[:, 0], rgb_hi[:, 0]]
        chunk_names += CHUNK_COLOR_PROPERTIES
    chunk_data = np.concatenate(chunk_table, axis=1).astype("<f4")
    if chunk_rows is not None:  # as many rows as the header claims, so the file itself parses
        chunk_data = np.resize(chunk_data, (chunk_rows, chunk_data.shape[1]))
    vertex = np.stack(
        [a.reshape(-1)[:n] for a in (packed_position, packed_rotation, packed_scale, packed_color)], axis=1
    ).astype("<u4")
    rest_count = 3 * (sh.shape[1] - 1)
    lines = [
        "ply",
        "format binary_little_endian 1.0",
        "comment test encoder",
        f"element chunk {chunks if chunk_rows is None else chunk_rows}",
    ]
    lines += [f"property float {name}" for name in chunk_names]
    lines += [f"element vertex {n}"]
    lines += [f"property uint packed_{name}" for name in ("position", "rotation", "scale", "color")]
    body = chunk_data.tobytes() + vertex.tobytes()
    if rest_count:
        lines += [f"element sh {n if sh_rows is None else sh_rows}"]
        lines += [f"property uchar f_rest_{i}" for i in range(rest_count)]
        # channel-major like the INRIA PLY: f_rest_{c*(K-1)+j} = sh[:, j+1, c]
        rest = np.asarray(sh[:, 1:], np.float64).transpose(0, 2, 1).reshape(n, rest_count)
        rest_bytes = np.clip(np.trunc((rest / 8 + 0.5) * 256), 0, 255).astype(np.uint8)
        if sh_rows is not None:
            rest_bytes = np.resize(rest_bytes, (sh_rows, rest_count))
        body += rest_bytes.tobytes()
    return ("\n".join(lines) + "\nend_header\n").encode() + body
