"""The view a sketch is traced on: the user's view, scaled to `WORKING_WIDTH` pixels wide
(docs/extraction.md, "Resolution").

Extraction's rules measure in pixels (the depth gap floor of the width walks, the stroke's
smoothing, the band), and were set on 960x540 views. A pixel's world size halves when the same view
is rendered at twice the width, so at 1920x1080 the width walks split a flat stand leg's depths into
clusters and its radius came out at a third of the 960 px view's. Tracing a larger view on a copy scaled down to 960
pixels wide makes the rod the same at any resolution, and the work that of a 960-pixel view. A
smaller view is traced on a copy scaled up to 960 pixels for the same reason: at 480x270 the
radius estimates of 6 of the real cases' 39 views left 0.7-1.4 x R (none at 960).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from .camera import Camera
from .errors import PathNotFoundError
from .render import RenderResult

if TYPE_CHECKING:
    from .rod_file import Extraction

WORKING_WIDTH = 960


@dataclasses.dataclass(frozen=True)
class WorkingView:
    """The user's `camera` and the `work` camera a sketch is traced on (the same view, `scale`
    times the pixels per unit of image on each axis; (1, 1) where the view is not scaled)."""

    camera: Camera
    work: Camera
    scale: tuple[float, float]

    @classmethod
    def of(cls, camera: Camera, working_width: int | None = WORKING_WIDTH) -> WorkingView:
        """`camera` as it is where it is `working_width` wide (or `working_width` is None), else
        scaled to that width (the height keeps the aspect ratio)."""
        if working_width is None or camera.width == working_width:
            return cls(camera, camera, (1.0, 1.0))
        work = camera.resized(working_width)
        return cls(camera, work, (work.width / camera.width, work.height / camera.height))

    @property
    def scaled(self) -> bool:
        return self.work is not self.camera

    def points_to_work(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) continuous pixel coordinates of the user's view in the working view."""
        return (np.asarray(points, np.float64) * self.scale).astype(np.float32) if self.scaled else points

    def render_to_work(self, render: RenderResult) -> RenderResult:
        """A render of the user's view as the working view samples it: each working pixel takes the
        user's pixel under its centre (the Gaussian shown there, its depth, whether it is solid).
        `extract_rod` renders the working view instead; this is for `extract.estimate_radius`."""
        if not self.scaled:
            return render
        rows = ((np.arange(self.work.height) + 0.5) / self.scale[1]).astype(np.int64)
        cols = ((np.arange(self.work.width) + 0.5) / self.scale[0]).astype(np.int64)
        rows, cols = np.minimum(rows, self.camera.height - 1), np.minimum(cols, self.camera.width - 1)

        def sample(image: np.ndarray | None) -> np.ndarray | None:
            return None if image is None else np.ascontiguousarray(image[rows][:, cols])

        return dataclasses.replace(
            render,
            rgb=sample(render.rgb),
            alpha=sample(render.alpha),
            depth=sample(render.depth),
            index=sample(render.index),
            index_depth=sample(render.index_depth),
            solid=sample(render.solid),
        )

    def path_to_user(self, piece: np.ndarray) -> np.ndarray:
        """A pixel path (P, 2) (col, row) of the working view as an 8-connected path of the user's
        pixels: those under each working pixel's centre and under the line between them."""
        piece = np.asarray(piece, np.int64).reshape(-1, 2)
        if not self.scaled or len(piece) == 0:
            return piece
        centres = (piece + 0.5) / self.scale  # continuous coordinates of the user's view
        steps = np.maximum(np.ceil(np.abs(np.diff(centres, axis=0)).max(axis=1, initial=0.0)), 1).astype(np.int64)
        dense = [centres[:1]]
        for a, b, n in zip(centres[:-1], centres[1:], steps):
            dense.append(a + np.outer(np.arange(1, n + 1) / n, b - a))
        pixels = np.floor(np.concatenate(dense)).astype(np.int64)
        pixels = np.clip(pixels, 0, [self.camera.width - 1, self.camera.height - 1])
        keep = np.r_[True, (np.diff(pixels, axis=0) != 0).any(axis=1)]
        return pixels[keep]

    def failure_to_user(self, error: PathNotFoundError, stroke: np.ndarray) -> PathNotFoundError:
        """`error` of a trace on the working view, told in the user's view: its image size, stroke,
        path so far and where it stopped."""
        if not self.scaled:
            return error
        message = str(error).replace(
            f"{self.work.width}x{self.work.height} image", f"{self.camera.width}x{self.camera.height} image"
        )
        told = PathNotFoundError(message)
        told.stroke = stroke
        told.pixel_path = [self.path_to_user(piece) for piece in getattr(error, "pixel_path", [])]
        told.lost_at = [tuple(self.path_to_user(np.asarray([p]))[0]) for p in getattr(error, "lost_at", [])]
        return told

    def extraction_to_user(self, extraction: Extraction, stroke: np.ndarray) -> Extraction:
        """`extraction` of the working view with the user's camera, stroke and pixel path."""
        if not self.scaled:
            return extraction
        pixel_path = [self.path_to_user(piece) for piece in extraction.pixel_path]
        return dataclasses.replace(extraction, camera=self.camera, stroke=stroke, pixel_path=pixel_path)
