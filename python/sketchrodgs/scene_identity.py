"""Which scene a rod belongs to: the Gaussian count and a SHA-256 of the means, stored in the rod
file (docs/rod_file.md, `scene`) so that a rod is not animated on another scene.

A rod's ids are rows of the scene it was extracted from; on another scene of the same size they
would bind unrelated Gaussians without any error. The means identify a scene's rows: they are
float32 in every format, so the identity survives `convert` between .ply and .splat.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from .errors import SketchRodGSError
from .scene import GaussianScene


class SceneIdentity:
    """A scene's Gaussian count and the SHA-256 of its means (float32, C order, little-endian).

    Made from a scene (`of`), the hash is computed when first needed and refers to the scene's
    means array until then (no copy); read from a rod file (`from_dict`), it is the stored one.
    """

    def __init__(self, count: int, means_sha256: str | None = None, means: np.ndarray | None = None) -> None:
        self.count = int(count)
        self._digest = means_sha256
        self._means = means

    @classmethod
    def of(cls, scene: GaussianScene) -> SceneIdentity:
        return cls(len(scene), means=scene.means)

    @property
    def means_sha256(self) -> str:
        if self._digest is None:
            means = np.ascontiguousarray(self._means, dtype="<f4")
            self._digest = hashlib.sha256(means.data).hexdigest()
            self._means = None
        return self._digest

    def matches(self, scene: GaussianScene) -> bool:
        """Whether `scene` is the scene this identifies (the same count and means)."""
        if self._means is not None and self._means is scene.means:
            return True
        return self.count == len(scene) and self.means_sha256 == SceneIdentity.of(scene).means_sha256

    def describe(self) -> str:
        return f"{self.count:,} Gaussians, means sha256 {self.means_sha256[:12]}"

    def to_dict(self) -> dict[str, Any]:
        return {"count": self.count, "means_sha256": self.means_sha256}

    @classmethod
    def from_dict(cls, data: Any, source: str) -> SceneIdentity:
        """Parse the rod file's `scene` field; `source` names it in errors."""
        count = data.get("count") if isinstance(data, dict) else None
        digest = data.get("means_sha256") if isinstance(data, dict) else None
        if not isinstance(count, int) or count < 0 or not isinstance(digest, str) or len(digest) != 64:
            raise SketchRodGSError(f'{source}: scene: expected {{"count": N, "means_sha256": 64 hex digits}}')
        return cls(count, digest.lower())


def check_rod_scene(identity: SceneIdentity | None, scene: GaussianScene, rod: str, scene_name: str) -> None:
    """Refuse a rod extracted from another scene; `rod` and `scene_name` name them in the error.
    Rods without an identity (written before it was recorded) are not checked."""
    if identity is not None and not identity.matches(scene):
        here = SceneIdentity.of(scene)
        raise SketchRodGSError(
            f"{rod}: this rod was extracted from another scene ({identity.describe()}), "
            f"not from {scene_name} ({here.describe()})"
        )
