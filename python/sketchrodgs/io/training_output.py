"""3DGS training output folders, accepted wherever a scene file is.

The reference trainer (graphdeco-inria/gaussian-splatting) writes
`OUT/point_cloud/iteration_<N>/point_cloud.ply` at each saved iteration and `OUT/cameras.json`
with the training cameras; the scene is the highest iteration's point cloud.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..errors import SceneFileNotFoundError

CAMERAS_FILE = "cameras.json"
_ITERATION = re.compile(r"iteration_(\d+)")


def scene_file(path: str | os.PathLike[str]) -> Path:
    """The scene file `path` stands for: itself, or the latest point cloud of a training folder."""
    path = Path(path)
    if not path.is_dir():
        return path
    iterations = [
        (int(match.group(1)), folder / "point_cloud.ply")
        for folder in (path / "point_cloud").glob("iteration_*")
        if (match := _ITERATION.fullmatch(folder.name)) and (folder / "point_cloud.ply").is_file()
    ]
    if not iterations:
        raise SceneFileNotFoundError(
            f"{path}: a folder, but not a 3DGS training output (no point_cloud/iteration_N/point_cloud.ply in it)"
        )
    return max(iterations)[1]


def training_cameras(path: str | os.PathLike[str]) -> Path | None:
    """The `cameras.json` of a training folder `path`; None for a file or a folder without one."""
    cameras = Path(path) / CAMERAS_FILE
    return cameras if Path(path).is_dir() and cameras.is_file() else None
