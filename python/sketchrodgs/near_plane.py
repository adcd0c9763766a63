"""The rasteriser's near plane: Gaussians at camera z <= 0.2 are culled, as in the reference 3DGS
(docs/rendering.md, "Near plane"). A close-up of a small scene can lose all of it.

`render_near` renders with another near plane without a change to the rasteriser: a render is
unchanged when the scene and the camera's position are scaled together (projection, EWA
footprint and SH direction are all scale-free) except for that fixed cull, so scaling by
NEAR_PLANE / near moves it to `near`. Depths are scaled back.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from .camera import Camera
from .errors import SketchRodGSError
from .render import RenderResult, render
from .scene import GaussianScene

NEAR_PLANE = 0.2  # rust/sketchrodgs-raster NEAR_PLANE


def render_near(scene: GaussianScene, camera: Camera, near: float = NEAR_PLANE, **options: Any) -> RenderResult:
    """`render(scene, camera, **options)` with Gaussians culled at camera z <= `near`."""
    if not (math.isfinite(near) and near > 0):
        raise SketchRodGSError(f"near: must be a number > 0, got {near}")
    if near == NEAR_PLANE:
        return render(scene, camera, **options)
    scale = NEAR_PLANE / near
    scaled = scene.replace(means=scene.means * np.float32(scale), scales=scene.scales * np.float32(scale))
    if not (np.isfinite(scaled.means).all() and np.isfinite(scaled.scales).all()):
        raise SketchRodGSError(f"near: {near:g} is too small for this scene's coordinates")
    matrix = camera.world_to_camera.copy()
    matrix[:3, 3] *= scale
    result = render(scaled, dataclasses.replace(camera, world_to_camera=matrix), **options)
    depths = {
        k: getattr(result, k) / np.float32(scale) for k in ("depth", "index_depth") if getattr(result, k) is not None
    }
    return dataclasses.replace(result, **depths)


def why_nothing_is_visible(scene: GaussianScene, camera: Camera, near: float = NEAR_PLANE) -> str:
    """Why a render of `scene` shows nothing, for people (call it when no pixel is covered)."""
    uv, depth = camera.project(scene.means)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
    too_near = int((inside & (depth <= near)).sum())
    if too_near and not (inside & (depth > near)).any():
        closest = float(depth[inside & (depth > 0)].min(initial=near))
        return (
            f"nothing is visible: the {too_near:,} Gaussians in view are nearer to the camera than the near "
            f"plane ({near:g}); give --near below {closest:.3g}, or move the camera back"
        )
    if not (depth > 0).any():
        return "nothing is visible: the whole scene is behind the camera"
    if not inside.any():
        return "nothing is visible: the camera looks away from the scene (`sketchrodgs camera` frames it)"
    return "nothing is visible: the Gaussians in view are too faint or too small to cover a pixel"
