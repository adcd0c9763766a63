"""sketchrodgs: sketch a stroke over a slender object in a 3D Gaussian Splatting scene, extract it
as a discrete elastic rod, pull it and let go. Runs on the CPU.

The public API lives here; see README.md for a tour. Names are imported when first used, so that
`import sketchrodgs` (and the command line's `--version` and `--help`) start fast.
"""

from __future__ import annotations

import importlib
import os
import sys
import types
from typing import TYPE_CHECKING, Any

from . import _core
from ._core import __version__

# A forked child has none of the worker threads of the parent's pool; it builds its own.
os.register_at_fork(after_in_child=_core._reset_pool_after_fork)

# public name -> the module that defines it
_EXPORTS = {
    "BoundRod": "skin",
    "Camera": "camera",
    "CameraError": "errors",
    "Extraction": "rod_file",
    "GaussianScene": "scene",
    "PathNotFoundError": "errors",
    "RenderResult": "render",
    "Rig": "rig",
    "Rod": "rod",
    "RodParams": "rod",
    "SceneFormatError": "errors",
    "SimulationError": "errors",
    "SketchRodGSError": "errors",
    "World": "rod",
    "extract_rod": "extract",
    "load_cameras": "camera",
    "load_rod": "rod_file",
    "load_scene": "io",
    "render": "render",
    "save_scene": "io",
    "skin": "skin",
}

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
    "load_rod",
    "load_scene",
    "render",
    "save_scene",
    "skin",
]


# Functions named like the module that defines them. Importing `sketchrodgs.render` binds the
# module as the package's attribute `render`; the package keeps the function there instead.
_FUNCTIONS_OVER_MODULES = {"render", "skin"}


class _Package(types.ModuleType):
    def __setattr__(self, name: str, value: Any) -> None:
        if name in _FUNCTIONS_OVER_MODULES and isinstance(value, types.ModuleType):
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def __getattr__(name: str) -> Any:
    if name == "data":
        return importlib.import_module(".data", __name__)
    if name not in _EXPORTS:
        raise AttributeError(f"module 'sketchrodgs' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


if TYPE_CHECKING:
    from . import data
    from .camera import Camera, load_cameras
    from .errors import CameraError, PathNotFoundError, SceneFormatError, SimulationError, SketchRodGSError
    from .extract import extract_rod
    from .io import load_scene, save_scene
    from .render import RenderResult, render
    from .rig import Rig
    from .rod import Rod, RodParams, World
    from .rod_file import Extraction, load_rod
    from .scene import GaussianScene
    from .skin import BoundRod, skin
