"""Frames to a video file: MP4 through imageio-ffmpeg (its wheel carries ffmpeg), GIF through Pillow."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from .atomic import atomic_open
from .errors import SketchRodGSError


def write_video(path: str | os.PathLike[str], frames: Sequence[np.ndarray], fps: float) -> None:
    """Write (H, W, 3) uint8 frames as `.mp4` (H.264) or `.gif`, chosen by the name's suffix."""
    suffix = Path(path).suffix.lower()
    if not frames:
        raise SketchRodGSError(f"{path}: no frames to write")
    if suffix == ".gif":
        images = [Image.fromarray(f) for f in frames]
        with atomic_open(path) as stream:
            images[0].save(
                stream, format="GIF", save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0
            )
    elif suffix == ".mp4":
        import imageio.v2 as imageio

        # ffmpeg needs a real file name: write beside the target, then rename into place
        target = Path(path)
        temporary = target.with_name(f".{target.name}.part.mp4")
        try:
            # H.264 wants even sizes; pad by repeating the last row/column when needed
            height, width = frames[0].shape[:2]
            pad = ((0, height % 2), (0, width % 2), (0, 0))
            with imageio.get_writer(
                temporary, fps=fps, codec="libx264", quality=7, macro_block_size=1, ffmpeg_log_level="error"
            ) as writer:
                for frame in frames:
                    writer.append_data(np.pad(frame, pad, mode="edge"))  # type: ignore[attr-defined]  # imageio v2 writer
            os.replace(temporary, target)
        finally:
            temporary.unlink(missing_ok=True)
    else:
        raise SketchRodGSError(f"{path}: cannot write '{suffix}' videos (use .mp4 or .gif)")
