"""Pictures: 8-bit conversion, PNG and JPEG writing, and overlays of stroke, path and polyline."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from . import _core
from .atomic import atomic_open
from .camera import Camera
from .errors import SketchRodGSError

STROKE_COLOUR = (40, 220, 90)
PATH_COLOUR = (255, 60, 40)
POLYLINE_COLOUR = (60, 140, 255)
SEGMENT_COLOUR = (255, 220, 0)


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) float colour -> uint8, clamped to [0, 1] and rounded (NaN -> 0)."""
    return (np.clip(np.nan_to_num(rgb), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


# Animation frames are written at the fast level: `fdeflate` (Rust `png` crate) writes a 960x540
# frame in 3 ms, where Pillow's zlib took 15 ms at level 1 and 32 ms at level 6, for files of the
# same size (benches/bench_io.py).
FRAME_PNG_LEVEL = 1


def save_png(path: str | os.PathLike[str], image: np.ndarray | Image.Image, compress_level: int = 6) -> None:
    """Write an (H, W, 3) image (uint8, or float in [0, 1]) or a PIL image as an RGB PNG, atomically
    (`compress_level` 0-9 as zlib's: 0 stores, 1 is fast, 9 smallest; encoded in Rust)."""
    if isinstance(compress_level, bool) or not isinstance(compress_level, (int, np.integer)):
        raise SketchRodGSError(f"compress_level: expected an integer 0 to 9, got {compress_level!r}")
    if not 0 <= compress_level <= 9:
        raise SketchRodGSError(f"compress_level: expected an integer 0 to 9, got {compress_level}")
    if isinstance(image, Image.Image):
        pixels = np.asarray(image.convert("RGB"))
    else:
        pixels = image if image.dtype == np.uint8 else to_uint8(image)
    if pixels.ndim != 3 or pixels.shape[2] != 3:
        raise SketchRodGSError(f"image: expected shape (H, W, 3), got {pixels.shape}")
    encoded = _core.encode_png(np.ascontiguousarray(pixels), int(compress_level))
    with atomic_open(path) as stream:
        stream.write(encoded)


JPEG_QUALITY = 95


def save_image(path: str | os.PathLike[str], image: np.ndarray | Image.Image) -> None:
    """Write an image as its name says: JPEG (quality 95) for .jpg or .jpeg, PNG otherwise."""
    if Path(path).suffix.lower() not in (".jpg", ".jpeg"):
        save_png(path, image)
        return
    if not isinstance(image, Image.Image):
        image = Image.fromarray(np.ascontiguousarray(image if image.dtype == np.uint8 else to_uint8(image)), "RGB")
    with atomic_open(path) as stream:
        image.save(stream, format="JPEG", quality=JPEG_QUALITY)


def draw_overlay(
    rgb: np.ndarray,
    camera: Camera,
    stroke: np.ndarray,
    pixel_path: Sequence[np.ndarray] = (),
    polyline: np.ndarray | None = None,
    highlight: np.ndarray | None = None,
    stops: Sequence[tuple[float, float]] = (),
) -> Image.Image:
    """The render with what extraction saw and found drawn on it.

    Args:
        rgb: (H, W, 3) render of `camera`.
        camera: the view.
        stroke: (S, 2) the user's stroke (green).
        pixel_path: pieces of the pixel path, (P, 2) (col, row) each (red).
        polyline: (M, 3) the 3D polyline, projected (blue, with its vertices).
        highlight: (G, 3) points to mark, e.g. the segmented Gaussians' centres (yellow dots).
        stops: (col, row) pixels where the path lost the object (red crosses).
    """
    base = Image.fromarray(to_uint8(rgb) if rgb.dtype != np.uint8 else rgb, "RGB")
    # dim the render so the drawing stands out
    image = Image.blend(base, Image.new("RGB", base.size, (0, 0, 0)), 0.35)
    draw = ImageDraw.Draw(image)
    if highlight is not None and len(highlight):
        uv, depth = camera.project(highlight)
        for u, v in uv[depth > 0]:
            draw.point((float(u), float(v)), fill=SEGMENT_COLOUR)
    draw.line([tuple(map(float, p)) for p in stroke], fill=STROKE_COLOUR, width=3, joint="curve")
    for piece in pixel_path:
        draw.point([(float(c) + 0.5, float(r) + 0.5) for c, r in piece], fill=PATH_COLOUR)
    for c, r in stops:
        x, y = float(c) + 0.5, float(r) + 0.5
        draw.line((x - 6, y - 6, x + 6, y + 6), fill=PATH_COLOUR, width=2)
        draw.line((x - 6, y + 6, x + 6, y - 6), fill=PATH_COLOUR, width=2)
    if polyline is not None and len(polyline) > 1:
        uv, depth = camera.project(polyline)
        visible = [tuple(map(float, p)) for p, z in zip(uv, depth) if z > 0]
        draw.line(visible, fill=POLYLINE_COLOUR, width=2)
        for u, v in visible:
            draw.ellipse((u - 2, v - 2, u + 2, v + 2), outline=POLYLINE_COLOUR)
    return image
