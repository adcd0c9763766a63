"""`sketchrodgs view`: the interactive browser viewer (viser), driven by the CPU pipeline.

Orbit the scene, sketch over a slender part to extract it as a rod, pull a rod vertex and let go.
The page renders the splats on the user's GPU in the browser; extraction, simulation and
skinning run here. See `app.ViewerApp`.
"""

from __future__ import annotations

from .app import ViewerApp
from .camera import camera_from_viser, screen_to_pixels, viser_view

__all__ = ["ViewerApp", "camera_from_viser", "screen_to_pixels", "viser_view"]
