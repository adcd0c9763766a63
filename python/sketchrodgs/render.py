"""Render a Gaussian scene for a camera on the CPU (Rust, parallel, the GIL released).

The rasteriser follows the reference 3DGS one exactly (see docs/rendering.md): EWA projection with a
0.3 px low-pass, 3-sigma footprint in 16x16 tiles, SH colour for the direction from the camera
centre, front-to-back blending by camera z with alpha capped at 0.99, contributions below 1/255
skipped and a stop once the transmittance would fall below 1e-4.

Besides colour it returns the index image K (per pixel, the Gaussian with the largest blending
weight alpha_i * T_i, -1 where none) and Z (that Gaussian's camera z), which the sketch uses.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np

from . import _core
from .camera import Camera
from .errors import CameraError, SketchRodGSError
from .scene import GaussianScene

OUTPUT_NAMES = ("rgb", "alpha", "depth", "index", "index_depth", "solid")
# Outputs an index-only render gives (no SH, no colour); without "alpha" it may also stop each
# pixel once its index is decided and its alpha reached 0.5 (docs/rendering.md, "Index and solid only").
INDEX_OUTPUTS = frozenset({"index", "index_depth", "alpha", "solid"})
SOLID_OUTPUTS = frozenset({"index", "index_depth", "solid"})
# Outputs a colour-only render gives: blending does not track each pixel's heaviest Gaussian
# (docs/rendering.md, "Colour only"), what a picture or an animation frame needs.
COLOR_OUTPUTS = frozenset({"rgb", "alpha"})


@dataclass(frozen=True, eq=False)
class RenderResult:
    """The images of one render. Arrays come straight from Rust (no copy).

    Attributes:
        rgb: (H, W, 3) float32 colour including the background, not clamped (SH colours may
            exceed 1); None in index-only mode.
        alpha: (H, W) float32 accumulated opacity 1 - T_final (also in index-only mode).
        depth: (H, W) float32 expected camera z, sum(w_i z_i) / alpha (0 where nothing
            contributes); None in index-only and colour-only mode.
        index: (H, W) int32 row of the Gaussian with the largest alpha_i * T_i (ties go to the
            front-most), -1 where no Gaussian contributes; None in colour-only mode.
        index_depth: (H, W) float32 camera z of that Gaussian (0 where index is -1); None in
            colour-only mode.
        solid: (H, W) bool, alpha >= 0.5: the pixel shows something at least half opaque (None in
            a result made by hand without it: `is_solid` then reads alpha).
        timings: seconds per stage: "project", "sort" (depth sort and tile binning), "composite".
        n_visible: Gaussians that survived culling.
        n_tile_pairs: (tile, Gaussian) pairs binned.
    """

    rgb: np.ndarray | None
    alpha: np.ndarray | None
    depth: np.ndarray | None
    index: np.ndarray | None
    index_depth: np.ndarray | None
    solid: np.ndarray | None = None
    timings: dict[str, float] = field(default_factory=dict)
    n_visible: int = 0
    n_tile_pairs: int = 0

    @classmethod
    def from_core(cls, raw: _core.Rendered, mode: str) -> RenderResult:
        """The result of a core render (`_core.rasterize`, `RetainedRender.frame`) in `mode`; in
        "solid" mode the core's alpha is exact only below 0.5, so only `solid` is kept of it."""
        return cls(rgb=raw.rgb, alpha=None if mode == "solid" else raw.alpha, depth=raw.depth, index=raw.index,
                   index_depth=raw.index_depth, solid=raw.alpha >= 0.5,
                   timings={"project": raw.project_s, "sort": raw.sort_s, "composite": raw.composite_s},
                   n_visible=raw.n_visible, n_tile_pairs=raw.n_tile_pairs)  # fmt: skip

    def is_solid(self) -> np.ndarray:
        """(H, W) bool `solid`; for a result without it, alpha >= 0.5, or where no alpha either,
        every pixel a Gaussian covers."""
        if self.solid is not None:
            return self.solid
        return self.alpha >= 0.5 if self.alpha is not None else self.index_image >= 0

    def covered(self) -> np.ndarray:
        """(H, W) bool: the pixels some Gaussian contributes to (index >= 0, or where a render has
        no index, alpha > 0: the same pixels)."""
        if self.index is not None or self.alpha is None:
            return np.asarray(self.index_image >= 0)
        return np.asarray(self.alpha > 0)

    @property
    def rgb_image(self) -> np.ndarray:
        """`rgb`, or an error where the render has no colour (made with `outputs="index"`)."""
        if self.rgb is None:
            raise SketchRodGSError("this render has no colour (it was made with outputs='index')")
        return self.rgb

    @property
    def index_image(self) -> np.ndarray:
        """`index`, or an error where the render has none (made with `outputs=("rgb", "alpha")`)."""
        return _with_index(self.index)

    @property
    def index_depth_image(self) -> np.ndarray:
        """`index_depth`, or an error where the render has no index image (as `index_image`)."""
        return _with_index(self.index_depth)


def _with_index(image: np.ndarray | None) -> np.ndarray:
    """`image` (the index image or its depth), or the error that the render has none."""
    if image is None:
        raise SketchRodGSError("this render has no index image (it was made for colour only: outputs='all' has it)")
    return image


def render(
    scene: GaussianScene,
    camera: Camera,
    *,
    background: Iterable[float] = (0.0, 0.0, 0.0),
    outputs: str | Iterable[str] = "all",
    tiles: np.ndarray | None = None,
) -> RenderResult:
    """Render `scene` as seen by `camera`, or only some of its 16x16 tiles.

    Args:
        scene: the Gaussians.
        camera: a valid pinhole camera (its constructor has checked size, focal lengths and
            rigidity; the renderer checks again).
        background: RGB colour behind the scene, added as T_final * background.
        outputs: "all"; "index" for only `index`, `index_depth`, `alpha` and `solid` (cheaper: no SH,
            no colour); or an iterable of names from OUTPUT_NAMES. Names all among `index`,
            `index_depth` and `solid` render cheaper still: each pixel stops once its index is
            decided and its alpha reached 0.5, the rest of alpha is not computed (`alpha` None).
            Names among `rgb` and `alpha` render the colour without the index image (blending does
            not track each pixel's heaviest Gaussian): the same rgb and alpha as "all", cheaper.
            Outputs not computed are None.
        tiles: (ceil(H / 16), ceil(W / 16)) bool, the tiles to render (`tile_grid`); each comes out
            exactly as in a full render, the others as background with index -1. Gaussians that
            cannot reach them are skipped before projection, so a narrow band renders quickly.
    Returns:
        A RenderResult. An empty scene, or one entirely behind the camera, renders as the
        background with index -1 everywhere.

    Raises:
        CameraError: `camera` is not a Camera.
        SketchRodGSError: a bad `background` or `outputs`, or arrays the renderer refuses.
    """
    _check_inputs(scene, camera)
    bg = _background(background)
    mode = render_mode(outputs)
    tiles = _check_tiles(tiles, camera)
    raw = _core.rasterize(
        *_core_inputs(scene, camera), background=bg, mode=mode, tiles=tiles, **_core_keywords(scene, camera)
    )
    return RenderResult.from_core(raw, mode)


def render_behind(
    scene: GaussianScene,
    camera: Camera,
    near: np.ndarray,
    count: int,
    *,
    gap_px: float = 8.0,
    tiles: np.ndarray | None = None,
) -> list[RenderResult]:
    """Depth layers of what lies behind `near`, as `render(..., outputs=SOLID_OUTPUTS)` gives
    them (docs/extraction.md, "What lies behind").

    Layer 0 blends at each pixel only the Gaussians deeper than `near` there ((H, W) camera z;
    -inf: all, inf: none); each further layer only those deeper than the last layer's index depth
    plus `gap_px` pixels' world size at that depth. `tiles` as for `render`. The Gaussians are
    projected and sorted once for all `count` layers.
    """
    _check_inputs(scene, camera)
    near = np.asarray(near)
    if near.shape != (camera.height, camera.width) or near.dtype.kind != "f" or np.isnan(near).any():
        raise SketchRodGSError(
            f"near: expected a ({camera.height}, {camera.width}) array of depths, got {near.dtype} {near.shape}"
        )
    if isinstance(count, bool) or not (isinstance(count, (int, np.integer)) and 0 <= count <= 64):
        raise SketchRodGSError(f"count: expected a whole number of layers in 0..64, got {count!r}")
    tiles = _check_tiles(tiles, camera)
    raws = _core.rasterize_behind(*_core_inputs(scene, camera), np.ascontiguousarray(near, np.float32), int(count),
                                  float(gap_px), tiles=tiles, **_core_keywords(scene, camera))  # fmt: skip
    return [RenderResult.from_core(raw, "solid") for raw in raws]


def _check_tiles(tiles: np.ndarray | None, camera: Camera) -> np.ndarray | None:
    """`tiles` as the core takes it: a C-contiguous bool array of the camera's tile grid."""
    if tiles is None:
        return None
    tiles = np.asarray(tiles)
    if tiles.shape != tile_grid(camera) or tiles.dtype.kind not in "bui":
        raise SketchRodGSError(f"tiles: expected a {tile_grid(camera)} bool array, got {tiles.dtype} {tiles.shape}")
    return np.ascontiguousarray(tiles != 0)


def release_buffers() -> None:
    """Free the buffers a full render keeps for the next one (docs/rendering.md, "Buffers kept
    between renders"): about 76 bytes per Gaussian of the largest scene rendered, held so that
    repeated renders skip the system's page faults. The next render allocates afresh."""
    _core.release_render_buffers()


def _check_inputs(scene: GaussianScene, camera: Camera) -> None:
    if not isinstance(scene, GaussianScene):
        raise SketchRodGSError(f"scene: expected a GaussianScene, got {type(scene).__name__}")
    if not isinstance(camera, Camera):
        raise CameraError(f"camera: expected a Camera, got {type(camera).__name__}")


_CoreInputs = tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int, float, float, float, float
]


def _core_inputs(scene: GaussianScene, camera: Camera) -> _CoreInputs:
    """The scene's arrays and the camera as the core's renderers take them."""
    w2c = np.ascontiguousarray(camera.world_to_camera, dtype=np.float64)
    return (scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, w2c, camera.width, camera.height,
            camera.fx, camera.fy, camera.cx, camera.cy)  # fmt: skip


class _CoreKeywords(TypedDict):
    sh_rows: np.ndarray | None
    sort_offsets: np.ndarray | None
    near_plane: float


def _core_keywords(scene: GaussianScene, camera: Camera) -> _CoreKeywords:
    """The scene's optional per-row arrays and the camera's near plane, as the core's renderers
    take them (by keyword)."""
    return {"sh_rows": scene.sh_rows, "sort_offsets": scene.sort_offsets, "near_plane": camera.near}


TILE_SIZE = 16


def tile_grid(camera: Camera) -> tuple[int, int]:
    """(rows, columns) of the camera's 16x16 tiles."""
    return -(-camera.height // TILE_SIZE), -(-camera.width // TILE_SIZE)


def _background(background: Iterable[float]) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in background)
    except (TypeError, ValueError):
        raise SketchRodGSError(f"background: expected 3 numbers, got {background!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise SketchRodGSError(f"background: expected 3 finite numbers, got {background!r}")
    return values  # type: ignore[return-value]


def render_mode(outputs: str | Iterable[str]) -> str:
    """The core's render mode for `outputs`: "all", "index", "solid" or "color"."""
    if outputs in ("all", "index"):
        return outputs  # type: ignore[return-value]
    names = {outputs} if isinstance(outputs, str) else set(outputs)
    unknown = names - set(OUTPUT_NAMES)
    if unknown or not names:
        raise SketchRodGSError(
            f"outputs: expected 'all', 'index' or names from {', '.join(OUTPUT_NAMES)}, got {outputs!r}"
        )
    if names <= SOLID_OUTPUTS:
        return "solid"
    if names <= INDEX_OUTPUTS:
        return "index"
    return "color" if names <= COLOR_OUTPUTS else "all"
