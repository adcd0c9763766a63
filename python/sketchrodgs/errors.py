"""The exceptions sketchrodgs raises. All subclass `ValueError`.

The base classes are defined in the compiled core so that Rust and Python raise the same types.
"""

from __future__ import annotations

from ._core import PathNotFoundError, SimulationError, SketchRodGSError

__all__ = [
    "CameraError",
    "PathNotFoundError",
    "SceneFormatError",
    "SimulationError",
    "SketchRodGSError",
]


class SceneFormatError(SketchRodGSError):
    """A scene file or scene array is malformed. The message names the file or field."""


class CameraError(SketchRodGSError):
    """A camera is degenerate or a camera file is malformed."""
