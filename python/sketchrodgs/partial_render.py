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
from .errors import SketchRodGSError
from .render import SOLID_OUTPUTS, TILE_SIZE, RenderResult, render, render_behind, tile_grid
from .scene import GaussianScene

# Tiles are taken within the band plus this many pixels of the stroke: the search smooths the
# stroke (its samples move a few pixels), and its width walks cross the object past the band.
# Every later render makes one more pass over the whole scene, which at capture size costs more
# than these tiles: with 64 px, 28 % of real strokes need no second render (1 % with 16 px).
MARGIN_PX = 64.0
# Layers rendered behind the front (docs/extraction.md, "What lies behind"): a stem behind two
# leaves is the third layer; each layer lies this many pixels' world size behind the last.
BEHIND_LAYERS = 3
GAP_PX = 24.0


def band_tiles(camera: Camera, stroke: np.ndarray, reach_px: float) -> np.ndarray:
    """(rows, cols) bool: the tiles with a pixel within `reach_px` of the stroke polyline."""
    rows, cols = tile_grid(camera)
    y, x = np.mgrid[0:rows, 0:cols]
    centres = np.stack([(x.ravel() + 0.5) * TILE_SIZE, (y.ravel() + 0.5) * TILE_SIZE], axis=1)
    points = np.asarray(stroke, np.float64)
    a, b = (points[:-1], points[1:]) if len(points) > 1 else (points, points)
    ab = b - a
    length2 = np.maximum((ab * ab).sum(axis=1), 1e-12)
    nearest = np.full(len(centres), np.inf)
    for start in range(0, len(a), 64):  # segments in blocks: (tiles x 64) at a time
        rel = centres[:, None, :] - a[None, start : start + 64]
        t = np.clip((rel * ab[None, start : start + 64]).sum(axis=2) / length2[start : start + 64], 0.0, 1.0)
        gap = rel - t[..., None] * ab[None, start : start + 64]
        nearest = np.minimum(nearest, np.sqrt((gap * gap).sum(axis=2)).min(axis=1))
    # a tile's pixels lie within half a diagonal of its centre
    return (nearest <= reach_px + TILE_SIZE / np.sqrt(2)).reshape(rows, cols)


class PartialRender:
    """Render of K, Z and solid (`outputs=SOLID_OUTPUTS`) of some tiles of `camera`'s image, and
    when asked, of the depth layers behind them (`render_behind`); both grown by the tiles asked for.

    Attributes:
        tiles: (rows, cols) bool, the tiles where `result` and `behind` are rendered (with a front
            given and no layers behind yet, every tile).
        result: the render (background, index -1, outside `tiles`); the `front` given, if one was.
        behind: the layers behind `result`, front to back (index -1 outside `tiles`); none until
            `add_behind`.
        renders: how many renders it took.
    """

    def __init__(
        self, scene: GaussianScene, camera: Camera, tiles: np.ndarray | None, front: RenderResult | None = None
    ):
        """Render `tiles`, or take the `front` given (then `tiles` may be None)."""
        self.scene, self.camera, self.front = scene, camera, front
        self.behind: list[RenderResult] = []
        self._stacked: tuple[list[RenderResult], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        if front is not None:
            self.tiles = np.ones(tile_grid(camera), bool)
            self.result, self.renders = front, 0
        else:
            if tiles is None:
                raise SketchRodGSError("PartialRender: give the tiles to render, or the front")
            self.tiles = np.ascontiguousarray(tiles, bool)
            self.result, self.renders = render(scene, camera, outputs=SOLID_OUTPUTS, tiles=self.tiles), 1

    def add_behind(self, count: int, tiles: np.ndarray) -> None:
        """Render `count` layers behind the front (each `GAP_PX` pixels' world size behind the
        last) of the rendered tiles; with a front given, of `tiles`, which then become the rendered
        tiles."""
        if self.front is not None:
            self.tiles = np.ascontiguousarray(tiles, bool)
        self.behind = self._behind(self.result, count, self.tiles)
        self.renders += 1

    def _behind(self, front: RenderResult, count: int, tiles: np.ndarray) -> list[RenderResult]:
        step = np.float32(1.0 + GAP_PX / self.camera.fx)
        near = np.where(front.index_image >= 0, front.index_depth_image * step, np.float32(np.inf)).astype(np.float32)
        return render_behind(self.scene, self.camera, near, count, gap_px=GAP_PX, tiles=tiles)

    def missed(self) -> np.ndarray:
        """A fresh (rows, cols) record for the search to mark the tiles it read but we lack."""
        return np.zeros_like(self.tiles)

    def add(self, missed: np.ndarray) -> None:
        """Render the tiles of `missed` and merge them into `result` (unless it was given) and
        `behind`. A width walk that leaves the rendered tiles walks on to its end, so `missed` holds
        all it can read; only where the search then goes elsewhere (1 of 117 real strokes) does it
        ask again."""
        new = missed & ~self.tiles
        if not new.any():
            return
        pixels = np.kron(new, np.ones((TILE_SIZE, TILE_SIZE), bool))[: self.camera.height, : self.camera.width]
        if self.front is None:
            self.result = _merged(
                self.result, render(self.scene, self.camera, outputs=SOLID_OUTPUTS, tiles=new), pixels
            )
        if self.behind:
            parts = self._behind(self.result, len(self.behind), new)
            self.behind = [_merged(old, part, pixels) for old, part in zip(self.behind, parts)]
        self.tiles |= new
        self.renders += 1

    def behind_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The layers behind as the path search takes them: index (L, H, W) int32, index depth
        and solid (1 or 0) float32; None without layers. Stacked once per change of the layers."""
        if not self.behind:
            return None
        if self._stacked is None or self._stacked[0] is not self.behind:
            index = np.stack([layer.index_image for layer in self.behind]).astype(np.int32, copy=False)
            depth = np.stack([layer.index_depth_image for layer in self.behind]).astype(np.float32, copy=False)
            solid = np.stack([layer.is_solid() for layer in self.behind]).astype(np.float32)
            self._stacked = (self.behind, (index, depth, solid))
        return self._stacked[1]


def _merged(old: RenderResult, part: RenderResult, pixels: np.ndarray) -> RenderResult:
    """`old` with `part`'s K, Z and solid at `pixels`."""
    merged = {name: getattr(old, name).copy() for name in ("index", "index_depth")}
    merged["solid"] = old.is_solid().copy()
    for name, image in merged.items():
        image[pixels] = (part.is_solid() if name == "solid" else getattr(part, name))[pixels]
    return RenderResult(
        rgb=None,
        depth=None,
        alpha=None,
        index=merged["index"],
        index_depth=merged["index_depth"],
        solid=merged["solid"],
        n_visible=old.n_visible + part.n_visible,
        n_tile_pairs=old.n_tile_pairs + part.n_tile_pairs,
    )
