"""sketchrodgs: sketch a stroke over a slender object in a 3D Gaussian Splatting scene, extract it
as a discrete elastic rod, pull it and let go. Runs on the CPU.

The public API lives here; see README.md for a tour.
"""

from __future__ import annotations

import os

from . import _core, data
from ._core import __version__
from .camera import Camera, load_cameras
from .errors import (
    CameraError,
    PathNotFoundError,
    SceneFormatError,
    SimulationError,
    SketchRodGSError,
)
from .extract import Extraction, extract_rod
from .io import load_scene, save_scene
from .render import RenderResult, render
from .rig import Rig
from .rod import Rod, RodParams, World
from .scene import GaussianScene
from .skin import BoundRod, skin

# A forked child has none of the worker threads of the parent's pool; it builds its own.
os.register_at_fork(after_in_child=_core._reset_pool_after_fork)

__all__ = [
    "BoundRod",
    "Camera",
    "CameraError",
    "Extraction",
    "GaussianScene",
    "PathNotFoundError",
    "RenderResult",
    "Rig",
    "Rod",
    "RodParams",
    "SceneFormatError",
    "SimulationError",
    "SketchRodGSError",
    "World",
    "__version__",
    "data",
    "extract_rod",
    "load_cameras",
    "load_scene",
    "render",
    "save_scene",
    "skin",
]
