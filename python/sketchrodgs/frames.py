"""Rendering the frames of an animation (docs/rendering.md, "Frames of an animation").

Between frames only the rods' Gaussians move. `FrameRenderer` projects, sorts and bins the rest of
the scene once; each frame it projects the moving Gaussians and re-blends only the tiles they
touch now or touched in the frame before. Every frame equals `render` of the same scene exactly.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from . import _core
from .camera import Camera
from .errors import SketchRodGSError
from .render import RenderResult, _background, _check_inputs, _core_inputs, _core_keywords, render_mode
from .scene import GaussianScene


class FrameRenderer:
    """Renders `scene` with its rows `moving` moved, frame after frame, for one camera.

    Args:
        scene: the scene at rest; only `moving` rows may differ in the scenes given to `render`,
            and only in their means, quats and scales (what skinning changes).
        camera: the camera of every frame.
        moving: the rows that may move (e.g. `Animation.moving_rows`).
        background, outputs: as for `render`.
    """

    def __init__(
        self,
        scene: GaussianScene,
        camera: Camera,
        moving: np.ndarray,
        *,
        background: Iterable[float] = (0.0, 0.0, 0.0),
        outputs: str | Iterable[str] = "all",
    ):
        _check_inputs(scene, camera)
        self.size = len(scene)
        self.camera = camera
        self.mode = render_mode(outputs)
        self._retained = _core.RetainedRender(
            *_core_inputs(scene, camera),
            np.ascontiguousarray(moving, np.int64),
            background=_background(background),
            mode=self.mode,
            **_core_keywords(scene, camera),
        )

    def render(self, scene: GaussianScene) -> RenderResult:
        """The frame of `scene` (the scene at rest with the moving rows moved)."""
        if len(scene) != self.size:
            raise SketchRodGSError(f"scene: has {len(scene)} Gaussians, the renderer was made for {self.size}")
        return self.frame(scene.means, scene.scales, scene.quats)

    def frame(self, means: np.ndarray, scales: np.ndarray, quats: np.ndarray) -> RenderResult:
        """The frame with the moving rows of these whole-scene arrays (float32, C-contiguous; e.g.
        `Animation.means`, `.scales`, `.quats`, read in place without a copy)."""
        for name, array, width in (("means", means, 3), ("scales", scales, 3), ("quats", quats, 4)):
            if array.shape != (self.size, width):
                raise SketchRodGSError(f"{name}: expected shape ({self.size}, {width}), got {array.shape}")
        raw = self._retained.frame(
            np.ascontiguousarray(means, np.float32),
            np.ascontiguousarray(scales, np.float32),
            np.ascontiguousarray(quats, np.float32),
        )
        return RenderResult.from_core(raw, self.mode)
