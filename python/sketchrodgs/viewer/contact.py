"""Rods meet the scene: the distance field of what no rod carries, rebuilt off the GUI thread.

The field (`sketchrodgs.contact.scene_field`, as `Animation` builds it) depends on which Gaussians
the rods carry and where they lie at rest, so it changes whenever a rod is added or removed. It
is built on its own thread: adding a rod does not wait for it. Until the new field is in, the
rods have none (the old one would hold the new rod's own Gaussians as solid and push it out).
"""

from __future__ import annotations

import logging
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from ..contact import scene_field
from .rods import RodSet

logger = logging.getLogger("sketchrodgs")


class SceneContact:
    """Keeps the rods' scene field current.

    Args:
        rods: the rods.

    Attributes:
        built: rod layouts (`RodSet.layout`) whose field was installed, for tests.
    """

    def __init__(self, rods: RodSet) -> None:
        self.rods = rods
        self.built = 0
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sketchrodgs-contact")

    def rebuild(self) -> Future[None]:
        """Drop the field now and build the one of the rods as they are (call after adding or
        removing rods); the future is done once it is in."""
        self.rods.set_scene_field(None)
        return self._worker.submit(self._build)

    def _build(self) -> None:
        with self.rods.lock:
            layout = self.rods.layout
            entries = self.rods.entries
            scene = self.rods.scene
            carried = self.rods.owned_ids()
            hidden = np.flatnonzero(self.rods.hidden)
        if not entries:
            return
        polylines = [np.asarray(e.extraction.polyline, np.float64) for e in entries]
        radii = [e.extraction.radius for e in entries]
        try:
            field = scene_field(scene, polylines, radii, np.concatenate([carried, hidden]))
        except Exception:  # contact is a nicety: a failure must not take the viewer down
            logger.exception("building the scene's contact field failed")
            return
        with self.rods.lock:
            if self.rods.layout == layout:  # no rod came or went meanwhile
                self.rods.set_scene_field(field)
                self.built = layout

    def close(self) -> None:
        self._worker.shutdown(wait=False, cancel_futures=True)
