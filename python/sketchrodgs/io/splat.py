"""antimatter15 `.splat`: headerless 32-byte records (RASTER.md 2.2)."""

from __future__ import annotations

import os

import numpy as np

from ..atomic import atomic_open
from ..errors import SceneFormatError
from ..scene import SH_C0, GaussianScene
from ._quantized import BLOCK, blocks

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])
_OPAQUE = np.dtype([("position", "V12"), ("scale", "V12"), ("rgb", "V3"), ("alpha", "V1"), ("rotation", "V4")])


def read_splat(path: str | os.PathLike[str]) -> GaussianScene:
    """Read a `.splat` file. Colours become a degree-0 SH scene; rotations are renormalised.

    The file is read a block of records at a time into one reused buffer and decoded while the
    block is in the CPU cache (a whole-file buffer costs more in fresh pages than the decoding).
    """
    try:
        with open(path, "rb") as stream:
            size = os.fstat(stream.fileno()).st_size
            if size == 0:
                raise SceneFormatError(f"{path}: empty .splat file")
            if size % RECORD.itemsize:
                raise SceneFormatError(
                    f"{path}: size {size} bytes is not a multiple of the 32-byte .splat record (truncated?)"
                )
            decoder = _SplatDecoder(size // RECORD.itemsize, str(path))
            buffer = np.empty(BLOCK * RECORD.itemsize, dtype=np.uint8)
            for start, stop in blocks(decoder.n):
                chunk = buffer[: (stop - start) * RECORD.itemsize]
                if stream.readinto(memoryview(chunk)) != len(chunk):
                    raise SceneFormatError(f"{path}: file shrank while being read")
                decoder.decode(chunk.view(_OPAQUE), start)
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    return decoder.scene()


def decode_splat(records: np.ndarray, source: str) -> GaussianScene:
    """Turn `.splat` records (an array of RECORD) into a scene; `source` names the data in errors."""
    decoder = _SplatDecoder(len(records), source)
    fields = np.ascontiguousarray(records).view(_OPAQUE)
    for start, stop in blocks(decoder.n):
        decoder.decode(fields[start:stop], start)
    return decoder.scene()


class _SplatDecoder:
    """Fills the scene arrays from consecutive blocks of records."""

    def __init__(self, n: int, source: str) -> None:
        self.n, self.source = n, source
        self.means = np.empty((n, 3), dtype=np.float32)
        self.scales = np.empty((n, 3), dtype=np.float32)
        self.quats = np.empty((n, 4), dtype=np.float32)
        self.dc = np.empty((n, 1, 3), dtype=np.float32)
        self.opacities = np.empty(n, dtype=np.float32)

    def decode(self, fields: np.ndarray, start: int) -> None:
        """Decode `fields` (records viewed as _OPAQUE) into rows start..start + len(fields)."""
        stop = start + len(fields)
        # Copy each field as one opaque item per record (much faster than a strided float copy).
        np.copyto(self.means[start:stop].view(_OPAQUE["position"]).reshape(-1), fields["position"])
        np.copyto(self.scales[start:stop].view(_OPAQUE["scale"]).reshape(-1), fields["scale"])
        # q = (u8 - 128) / 128, normalised; the 1/128 cancels in the normalisation.
        q = self.quats[start:stop]
        q[...] = np.ascontiguousarray(fields["rotation"]).view(np.uint8).reshape(-1, 4)
        q -= np.float32(128)
        w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        squared = w * w + x * x + y * y + z * z
        zero = squared == 0
        if zero.any():
            raise SceneFormatError(f"{self.source}: rotation: zero quaternion in record {start + int(np.argmax(zero))}")
        q *= (np.float32(1) / np.sqrt(squared))[:, None]
        # DC term of colour c = u8 / 255: (c - 0.5) / SH_C0
        d = self.dc[start:stop, 0]
        d[...] = np.ascontiguousarray(fields["rgb"]).view(np.uint8).reshape(-1, 3)
        d /= np.float32(255)
        d -= np.float32(0.5)
        d /= np.float32(SH_C0)
        alpha = np.ascontiguousarray(fields["alpha"]).view(np.uint8)
        np.divide(alpha, np.float32(255), out=self.opacities[start:stop], dtype=np.float32)

    def scene(self) -> GaussianScene:
        try:
            return GaussianScene(self.means, self.scales, self.quats, self.opacities, self.dc)
        except SceneFormatError as exc:
            raise SceneFormatError(f"{self.source}: {exc}") from None


def write_splat(scene: GaussianScene, path: str | os.PathLike[str]) -> None:
    """Write `scene` as `.splat` in row order (lossy: 8-bit colour/opacity/rotation, DC colour only)."""
    records = np.empty(len(scene), dtype=RECORD)
    records["position"] = scene.means
    records["scale"] = scene.scales
    rgb = 0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64)
    records["rgba"][:, :3] = np.clip(np.rint(rgb * 255), 0, 255)
    records["rgba"][:, 3] = np.clip(np.rint(scene.opacities.astype(np.float64) * 255), 0, 255)
    records["rotation"] = np.clip(np.rint(scene.quats.astype(np.float64) * 128 + 128), 0, 255)
    with atomic_open(path) as stream:
        stream.write(records.tobytes())
