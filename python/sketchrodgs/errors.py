"""The exceptions sketchrodgs raises. All subclass `ValueError`, and all pickle (they cross
`multiprocessing`).

The base classes are defined in the compiled core (`sketchrodgs._core`) so that Rust and Python
raise the same types.
"""

from __future__ import annotations

from ._core import PathNotFoundError, SimulationError, SketchRodGSError

__all__ = [
    "CameraError",
    "PathNotFoundError",
    "SceneFileNotFoundError",
    "SceneFormatError",
    "SimulationError",
    "SketchRodGSError",
]


class SceneFormatError(SketchRodGSError):
    """A scene file or scene array is malformed. The message names the file or field."""


class SceneFileNotFoundError(SceneFormatError, FileNotFoundError):
    """A scene file that does not exist (also a `FileNotFoundError`)."""


class CameraError(SketchRodGSError):
    """A camera is degenerate or a camera file is malformed."""
