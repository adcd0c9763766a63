"""sketchrodgs: sketch a stroke over a slender object in a 3D Gaussian Splatting scene, extract it
as a discrete elastic rod, pull it and let go. Runs on the CPU.

The public API lives here; see README.md for a tour.
"""

from __future__ import annotations

from . import data
from ._core import __version__
from .camera import Camera, load_cameras
from .errors import (
    CameraError,
    PathNotFoundError,
    SceneFormatError,
    SimulationError,
    SketchRodGSError,
)
from .io import load_scene, save_scene
from .scene import GaussianScene

__all__ = [
    "Camera",
    "CameraError",
    "GaussianScene",
    "PathNotFoundError",
    "SceneFormatError",
    "SimulationError",
    "SketchRodGSError",
    "__version__",
    "data",
    "load_cameras",
    "load_scene",
    "save_scene",
]
