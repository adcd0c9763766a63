"""Type stubs for the compiled extension `sketchrodgs._core`."""

from typing import Any

import numpy as np
import numpy.typing as npt

__version__: str

class SketchRodGSError(ValueError): ...
class PathNotFoundError(SketchRodGSError): ...
class SimulationError(SketchRodGSError): ...

def trace_stroke(
    index: npt.NDArray[np.int32],
    depth: npt.NDArray[np.float32],
    centres: npt.NDArray[np.float32],
    stroke: npt.NDArray[np.float32],
    radius: float,
    stroke_weight: float = 1.0,
    band_px: float = 0.0,
    cover_px: float = 10.0,
) -> dict[str, object]: ...
def nearest_on_polyline(
    polyline: npt.NDArray[np.float32], points: npt.NDArray[np.float32], reach: float
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float32], npt.NDArray[np.float32]]: ...
def cross_section_centroids(
    axis: npt.NDArray[np.float64],
    tangents: npt.NDArray[np.float64],
    points: npt.NDArray[np.float32],
    nearest_vertex: npt.NDArray[np.int32],
    half_width: float,
    reach: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint32]]: ...
def rasterize(
    means: npt.NDArray[np.float32],
    scales: npt.NDArray[np.float32],
    quats: npt.NDArray[np.float32],
    opacities: npt.NDArray[np.float32],
    sh: npt.NDArray[np.float32],
    world_to_camera: npt.NDArray[np.float64],
    width: int,
    height: int,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    index_only: bool = False,
) -> dict[str, Any]: ...
def num_threads() -> int: ...
def _reset_pool_after_fork() -> None: ...
