"""Sample scenes bundled with the package (licences in LICENSES.md beside this file)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from ..errors import SketchRodGSError

# name -> (file, one-line description)
SAMPLES = {
    "ring": ("ring_10k.splat", "open split ring (a tube on an elliptical centre line), 10k splats, CC0-1.0"),
}


def sample(name: str = "ring") -> Path:
    """Path of a bundled sample scene (see `SAMPLES` for the names)."""
    if name not in SAMPLES:
        raise SketchRodGSError(f"no sample named {name!r} (samples: {', '.join(SAMPLES)})")
    return Path(str(resources.files(__name__).joinpath(SAMPLES[name][0])))
