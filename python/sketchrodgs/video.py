"""Frames to a video file: MP4 through imageio-ffmpeg (its wheel carries ffmpeg), GIF through Pillow.

`VideoWriter` takes the frames one at a time, so that a long or large MP4 never holds its frames
in memory (ten seconds of 1920x1080 at 30 fps are 1.9 GB of pixels); a GIF keeps its palettised
frames until it is closed. The file appears only when the writer closes without error.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from PIL import Image

from .atomic import atomic_open
from .errors import SketchRodGSError

SUFFIXES = (".mp4", ".gif")


class VideoWriter:
    """Writes (H, W, 3) uint8 frames to `path`, `.mp4` (H.264) or `.gif` by its suffix, at `fps`.

    Use as a context manager (or call `close`, or `abort` on failure): the file is put in place
    when the block ends without error, and nothing is left behind otherwise.
    """

    def __init__(self, path: str | os.PathLike[str], fps: float) -> None:
        self.path = Path(path)
        self.fps = fps
        self.suffix = self.path.suffix.lower()
        if self.suffix not in SUFFIXES:
            raise SketchRodGSError(f"{path}: cannot write '{self.suffix}' videos (use .mp4 or .gif)")
        self.count = 0
        self._gif: list[Image.Image] = []
        self._mp4: Any = None  # the imageio writer, opened with the first frame (its size)
        # ffmpeg needs a real file name: write beside the target, then rename into place
        self._temporary = self.path.with_name(f".{self.path.name}.part.mp4")
        self._pad: tuple[tuple[int, int], ...] = ()

    def append(self, frame: np.ndarray) -> None:
        """Add one frame (the first fixes the size)."""
        if self.suffix == ".gif":
            self._gif.append(Image.fromarray(frame))
        else:
            if self._mp4 is None:
                import imageio.v2 as imageio

                # H.264 wants even sizes; pad by repeating the last row/column when needed
                height, width = frame.shape[:2]
                self._pad = ((0, height % 2), (0, width % 2), (0, 0))
                self._mp4 = imageio.get_writer(
                    self._temporary, fps=self.fps, codec="libx264", quality=7, macro_block_size=1,
                    ffmpeg_log_level="error",
                )  # fmt: skip
            self._mp4.append_data(np.pad(frame, self._pad, mode="edge"))
        self.count += 1

    def close(self) -> None:
        """Finish the file and put it in place."""
        if self.count == 0:
            self.abort()
            raise SketchRodGSError(f"{self.path}: no frames to write")
        if self.suffix == ".gif":
            with atomic_open(self.path) as stream:
                self._gif[0].save(
                    stream,
                    format="GIF",
                    save_all=True,
                    append_images=self._gif[1:],
                    duration=int(round(1000 / self.fps)),
                    loop=0,
                )
            self._gif = []
            return
        try:
            self._mp4.close()
            self._mp4 = None
            os.replace(self._temporary, self.path)
        finally:
            self._temporary.unlink(missing_ok=True)

    def abort(self) -> None:
        """Drop what was written."""
        if self._mp4 is not None:
            try:
                self._mp4.close()
            except Exception:  # noqa: BLE001 - ffmpeg may refuse a half-written file; it goes anyway
                pass
            self._mp4 = None
        self._temporary.unlink(missing_ok=True)
        self._gif = []

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if kind is None:
            self.close()
        else:
            self.abort()


def write_video(path: str | os.PathLike[str], frames: Sequence[np.ndarray], fps: float) -> None:
    """Write (H, W, 3) uint8 frames as `.mp4` (H.264) or `.gif`, chosen by the name's suffix."""
    with VideoWriter(path, fps) as writer:
        for frame in frames:
            writer.append(frame)
