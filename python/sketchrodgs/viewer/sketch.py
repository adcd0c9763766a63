"""A stroke drawn in the browser, and the rod extracted under it.

The browser sends the pointer about 20 times a second while the left button is held, so the
stroke is the polyline through those samples. The camera is read once, when the stroke starts
(the camera does not move while sketching); extraction renders the scene from it at a working
resolution, whatever the size of the browser's canvas. While it is drawn, the band the path
search looks in is drawn around it (`Stroke.brush`): the brush's width.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera
from ..errors import SketchRodGSError
from ..extract import extract_rod
from ..rod_file import Extraction
from ..scene import GaussianScene
from .camera import screen_to_pixels

# The path search looks this share of the image width either side of the stroke, or 1.25 R where
# that is wider (`extract_rod`'s band_px default).
BAND_SHARE = 0.01
BRUSH_SIDES = 24  # segments of the circle drawn at the pointer


@dataclass(frozen=True)
class SketchSettings:
    """Extraction parameters from the panel.

    Attributes:
        radius: R in scene units, or None to estimate it.
        alpha: weight of the stroke-distance term (paper Eq. 1).
        edge_length: rod edge length in scene units, or None for the default.
        attach: small parts attached to the rod (leaves, a headstock) ride with it
            (docs/deformation.md).
    """

    radius: float | None = None
    alpha: float = 1.0
    edge_length: float | None = None
    attach: bool = True


@dataclass
class Stroke:
    """A stroke being drawn: the camera at its start and the pointer samples.

    Attributes:
        camera: our camera for the client's view, at the working resolution.
        screen: pointer samples, normalised canvas coordinates ((0, 0) top-left, (1, 1) bottom-right).
    """

    camera: Camera
    screen: list[tuple[float, float]] = field(default_factory=list)

    def add(self, position: tuple[float, float] | list[float]) -> None:
        """Append a pointer sample (repeats of the last one are dropped)."""
        point = (float(position[0]), float(position[1]))
        if not np.isfinite(point).all():
            return
        if not self.screen or point != self.screen[-1]:
            self.screen.append(point)

    def pixels(self) -> np.ndarray:
        """(S, 2) float32 the stroke in the camera's continuous pixel coordinates."""
        return screen_to_pixels(np.array(self.screen, np.float64).reshape(-1, 2), self.camera)

    def world_points(self, depth: float) -> np.ndarray:
        """(S, 3) the stroke placed at camera depth `depth` (to draw it in the scene)."""
        return self.camera.unproject(self.pixels(), depth)

    def brush(self, depth: float) -> np.ndarray:
        """(K, 2, 3) line segments at camera depth `depth` outlining the band the path search looks
        in: its two edges along the stroke and a circle of its half-width at the stroke's end."""
        pixels = self.pixels().astype(np.float64)
        half = BAND_SHARE * self.camera.width
        lines = []
        if len(pixels) > 1:
            tangent = np.gradient(pixels, axis=0)
            tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
            normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
            lines += [pixels + half * normal, pixels - half * normal]
        if len(pixels):
            angle = np.linspace(0, 2 * np.pi, BRUSH_SIDES + 1)
            lines.append(pixels[-1] + half * np.stack([np.cos(angle), np.sin(angle)], axis=1))
        segments = [np.stack([line[:-1], line[1:]], axis=1) for line in lines]
        if not segments:
            return np.empty((0, 2, 3), np.float32)
        flat = np.concatenate(segments).reshape(-1, 2)
        return self.camera.unproject(flat, depth).reshape(-1, 2, 3).astype(np.float32)


def extract(scene: GaussianScene, stroke: Stroke, settings: SketchSettings) -> Extraction:
    """Extract the rod under `stroke` in `scene`.

    Raises:
        PathNotFoundError: the stroke misses the object or the path is too short.
        SketchRodGSError: the stroke has fewer than two samples, or bad settings.
    """
    if len(stroke.screen) < 2:
        raise SketchRodGSError("the stroke is a single point: drag across the object")
    # the camera is made at the panel's working width, and traced at it: a user may trade the
    # extraction's detail for its time (docs/viewer.md)
    return extract_rod(
        scene,
        stroke.camera,
        stroke.pixels(),
        settings.radius,
        alpha=settings.alpha,
        edge_length=settings.edge_length,
        attach=settings.attach,
        working_width=stroke.camera.width,
    )
