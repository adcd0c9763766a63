"""Rendering only the band around a stroke (docs/rendering.md, "Rendering part of the image").

The sketch reads K, Z and where alpha reaches 0.5 (`solid`), near the stroke only.
`PartialRender` renders the 16x16 tiles within reach of the stroke, lets the path search record
every read outside them, and renders those tiles too when it did; the search then runs again.
The final search has read rendered pixels only, and rendered tiles equal a full render's
exactly, so the rod is the one a full render gives, at a fraction of the cost on a large scene.
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .render import SOLID_OUTPUTS, TILE_SIZE, RenderResult, render, tile_grid
from .scene import GaussianScene

# Tiles are taken within the band plus this many pixels of the stroke: the search smooths the
# stroke (its samples move a few pixels), and its width walks cross the object past the band.
# Every later render makes one more pass over the whole scene, which at capture size costs more
# than these tiles: with 64 px, 28 % of real strokes need no second render (1 % with 16 px).
MARGIN_PX = 64.0


def band_tiles(camera: Camera, stroke: np.ndarray, reach_px: float) -> np.ndarray:
    """(rows, cols) bool: the tiles with a pixel within `reach_px` of the stroke polyline."""
    rows, cols = tile_grid(camera)
    y, x = np.mgrid[0:rows, 0:cols]
    centres = np.stack([(x.ravel() + 0.5) * TILE_SIZE, (y.ravel() + 0.5) * TILE_SIZE], axis=1)
    points = np.asarray(stroke, np.float64)
    nearest = np.full(len(centres), np.inf)
    for a, b in zip(points[:-1], points[1:]) if len(points) > 1 else [(points[0], points[0])]:
        ab = b - a
        t = np.clip((centres - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        nearest = np.minimum(nearest, np.linalg.norm(centres - (a + t[:, None] * ab), axis=1))
    # a tile's pixels lie within half a diagonal of its centre
    return (nearest <= reach_px + TILE_SIZE / np.sqrt(2)).reshape(rows, cols)


class PartialRender:
    """Render of K, Z and solid (`outputs=SOLID_OUTPUTS`) of some tiles of `camera`'s image, grown on
    demand.

    Attributes:
        tiles: (rows, cols) bool, the tiles rendered so far.
        result: the render (background, index -1, outside `tiles`).
        renders: how many renders it took.
    """

    def __init__(self, scene: GaussianScene, camera: Camera, tiles: np.ndarray):
        self.scene, self.camera = scene, camera
        self.tiles = np.ascontiguousarray(tiles, bool)
        self.result = render(scene, camera, outputs=SOLID_OUTPUTS, tiles=self.tiles)
        self.renders = 1

    def missed(self) -> np.ndarray:
        """A fresh (rows, cols) record for the search to mark the tiles it read but we lack."""
        return np.zeros_like(self.tiles)

    def add(self, missed: np.ndarray) -> None:
        """Render the tiles of `missed` and merge them into `result`. A width walk that leaves the
        rendered tiles walks on to its end, so `missed` holds all it can read; only where the
        search then goes elsewhere (1 of 117 real strokes) does it ask again."""
        new = missed & ~self.tiles
        if not new.any():
            return
        part = render(self.scene, self.camera, outputs=SOLID_OUTPUTS, tiles=new)
        pixels = np.kron(new, np.ones((TILE_SIZE, TILE_SIZE), bool))[: self.camera.height, : self.camera.width]
        merged = {name: getattr(self.result, name).copy() for name in ("index", "index_depth", "solid")}
        for name, image in merged.items():
            image[pixels] = getattr(part, name)[pixels]
        self.tiles |= new
        self.renders += 1
        self.result = RenderResult(
            rgb=None,
            depth=None,
            alpha=None,
            index=merged["index"],
            index_depth=merged["index_depth"],
            solid=merged["solid"],
            n_visible=self.result.n_visible + part.n_visible,
            n_tile_pairs=self.result.n_tile_pairs + part.n_tile_pairs,
        )
