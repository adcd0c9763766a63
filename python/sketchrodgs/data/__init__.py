"""Sample scenes bundled with the package (licences in LICENSES.md beside this file).

Some samples come with a view and a stroke on a slender part, ready for `extract_rod`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import SketchRodGSError

if TYPE_CHECKING:  # imported when used: the command line lists the samples without numpy
    import numpy as np

    from ..camera import Camera


@dataclass(frozen=True)
class Sample:
    file: str
    description: str
    camera: str | None = None  # our camera JSON beside the scene
    stroke: str | None = None  # stroke JSON in that camera's pixels


SAMPLES = {
    "plant": Sample(
        "plant.splat",
        "real phone capture of a potted houseplant, 113,648 splats, CC-BY-4.0 Marcel Padilla",
        "plant_camera.json",
        "plant_stroke.json",
    ),
    "ring": Sample("ring_10k.splat", "open split ring (a tube on an elliptical centre line), 10k splats, CC0-1.0"),
}


def _entry(name: str) -> Sample:
    if name not in SAMPLES:
        raise SketchRodGSError(f"no sample named {name!r} (samples: {', '.join(SAMPLES)})")
    return SAMPLES[name]


def _path(file: str) -> Path:
    return Path(str(resources.files(__name__).joinpath(file)))


def sample(name: str = "ring") -> Path:
    """Path of a bundled sample scene (see `SAMPLES` for the names)."""
    return _path(_entry(name).file)


def sample_camera(name: str) -> Camera:
    """The prepared view of a sample."""
    from ..camera import Camera

    entry = _entry(name)
    if entry.camera is None:
        raise SketchRodGSError(f"sample {name!r} has no prepared view")
    return Camera.from_dict(json.loads(_path(entry.camera).read_text()), entry.camera)


def sample_stroke(name: str) -> np.ndarray:
    """(S, 2) the prepared stroke of a sample, in pixels of `sample_camera(name)`."""
    import numpy as np

    entry = _entry(name)
    if entry.stroke is None:
        raise SketchRodGSError(f"sample {name!r} has no prepared stroke")
    return np.asarray(json.loads(_path(entry.stroke).read_text())["points"], np.float64)


def contact_push() -> dict[str, Any]:
    """The prepared push of `sketchrodgs demo --contact` (plant_contact.json): the plant's left side
    stem, its `camera` and `stroke`, `radius`, `clamp`, the `grab`bed vertex, the `drag` in that
    camera's pixels and the `show_camera` it is seen from."""
    return dict(json.loads(_path("plant_contact.json").read_text()))
