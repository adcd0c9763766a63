"""Why a render shows nothing. The rasteriser culls Gaussians at camera z <= the camera's near
plane (`Camera.near`, by default the reference 3DGS's 0.2 whatever the scene's units), so a
close-up of a small scene can lose all of it (docs/rendering.md, "Near plane").
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .scene import GaussianScene


def why_nothing_is_visible(scene: GaussianScene, camera: Camera) -> str:
    """Why a render of `scene` by `camera` shows nothing, for people (call it when no pixel is
    covered)."""
    near = camera.near
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


def culled_under_stroke(scene: GaussianScene, camera: Camera, stroke: np.ndarray, reach_px: float = 10.0) -> str | None:
    """Where Gaussians nearer than the near plane project within `reach_px` of the stroke's box (the
    stroke lay on background: what the user drew over was culled), what to do about it; else None."""
    uv, depth = camera.project(scene.means)
    points = np.asarray(stroke, np.float64).reshape(-1, 2)
    low, high = points.min(axis=0) - reach_px, points.max(axis=0) + reach_px
    culled = np.all((uv >= low) & (uv <= high), axis=1) & (depth > 0) & (depth <= camera.near)
    if not culled.any():
        return None
    closest = float(depth[culled].min())
    return (
        f"what it was drawn over is nearer to the camera than the near plane ({camera.near:g}): "
        f"give --near below {closest:.3g} (the camera's `near`), or move the camera back"
    )
