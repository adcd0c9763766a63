"""Type stubs for the compiled extension `sketchrodgs._core`."""

from typing import Any, final

import numpy as np
import numpy.typing as npt
from typing_extensions import Self, disjoint_base

__version__: str

class SketchRodGSError(ValueError): ...

class PathNotFoundError(SketchRodGSError):
    # set by extract_rod on the errors it raises (what was found, for drawing it)
    stroke: npt.NDArray[np.float32]
    pixel_path: list[npt.NDArray[np.int64]]
    lost_at: list[tuple[int, int]]

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
    focal_px: float = 0.0,
    alpha: npt.NDArray[np.float32] | None = None,
    rendered: npt.NDArray[np.bool_] | None = None,
    missed: npt.NDArray[np.bool_] | None = None,
    behind: tuple[npt.NDArray[np.int32], npt.NDArray[np.float32], npt.NDArray[np.float32]] | None = None,
    colours: tuple[npt.NDArray[np.uint32], npt.NDArray[np.float32]] | None = None,
) -> Trace: ...

@final
class TracePiece:
    @property
    def pixels(self) -> npt.NDArray[np.uint32]: ...
    @property
    def pixel_ids(self) -> npt.NDArray[np.uint32]: ...
    @property
    def gaussian_ids(self) -> npt.NDArray[np.uint32]: ...
    @property
    def reached_goal(self) -> bool: ...
    @property
    def lost_pixel(self) -> tuple[int, int] | None: ...
    @property
    def lost_progress(self) -> float | None: ...

@final
class Trace:
    @property
    def pieces(self) -> list[TracePiece]: ...
    @property
    def clean_stroke(self) -> npt.NDArray[np.float32]: ...
    @property
    def coverage(self) -> float: ...
    @property
    def wants_behind(self) -> bool: ...
    @property
    def colours(self) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None: ...

def shown_ids(
    images: list[npt.NDArray[np.int32]], low: tuple[int, int], high: tuple[int, int], count: int
) -> npt.NDArray[np.uint32]: ...
def forward_along_stroke(
    points: npt.NDArray[np.float32], radius_px: npt.NDArray[np.float32], stroke: npt.NDArray[np.float32]
) -> npt.NDArray[np.bool_]: ...
def estimate_radius(
    index: npt.NDArray[np.int32],
    depth: npt.NDArray[np.float32],
    alpha: npt.NDArray[np.float32],
    stroke: npt.NDArray[np.float32],
    focal_px: float,
    band_px: float = 0.0,
    rendered: npt.NDArray[np.bool_] | None = None,
    missed: npt.NDArray[np.bool_] | None = None,
    behind: tuple[npt.NDArray[np.int32], npt.NDArray[np.float32], npt.NDArray[np.float32]] | None = None,
    colours: tuple[npt.NDArray[np.uint32], npt.NDArray[np.float32]] | None = None,
) -> tuple[float, bool]: ...
def nearest_on_polyline(
    polyline: npt.NDArray[np.float32], points: npt.NDArray[np.float32], reach: float
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float32], npt.NDArray[np.float32]]: ...
def continuation(
    points: npt.NDArray[np.float32],
    seeds: npt.NDArray[np.int64],
    vertex: tuple[float, float, float],
    outward: tuple[float, float, float],
    size: float,
    link: float,
) -> npt.NDArray[np.int64]: ...
def median_neighbour_distance(points: npt.NDArray[np.float32], k: int, samples: int) -> float | None: ...
def small_clusters(
    points: npt.NDArray[np.float32], link: float, seeds: npt.NDArray[np.int64], size: float
) -> npt.NDArray[np.bool_]: ...
def clusters_inside(
    points: npt.NDArray[np.float32], link: float, seeds: npt.NDArray[np.int64], inside: npt.NDArray[np.bool_]
) -> npt.NDArray[np.int64]: ...
def detours(
    points: npt.NDArray[np.float64],
    uv: npt.NDArray[np.float64],
    radius_px: npt.NDArray[np.float64],
    radius: float,
    span: float,
    depth: float,
    screen: float,
    back_ratio: float,
    back: float,
    end: float,
) -> npt.NDArray[np.int64]: ...
def bumps(
    points: npt.NDArray[np.float64],
    radius: float,
    span: float,
    off: float,
    angle_deg: float,
    lead: float,
    end: float,
) -> npt.NDArray[np.int64]: ...
def cross_section_centroids(
    axis: npt.NDArray[np.float64],
    tangents: npt.NDArray[np.float64],
    points: npt.NDArray[np.float32],
    nearest_vertex: npt.NDArray[np.int32],
    half_width: float,
    wide_half_width: float,
    reach: float,
    reach_scale: npt.NDArray[np.float64] | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint32]]: ...
def crowding(
    axis: npt.NDArray[np.float64],
    tangents: npt.NDArray[np.float64],
    points: npt.NDArray[np.float32],
    half_width: float,
    inner: float,
    outer: float,
) -> npt.NDArray[np.float64]: ...
def max_alpha(
    means: npt.NDArray[np.float32],
    scales: npt.NDArray[np.float32],
    quats: npt.NDArray[np.float32],
    opacities: npt.NDArray[np.float32],
    rows: npt.NDArray[np.int64],
    origin: tuple[float, float, float] | list[float],
    spacing: float,
    dims: tuple[int, int, int] | list[int],
) -> npt.NDArray[np.float32]: ...
def max_alpha_along_edges(
    means: npt.NDArray[np.float32],
    scales: npt.NDArray[np.float32],
    quats: npt.NDArray[np.float32],
    opacities: npt.NDArray[np.float32],
    rows: npt.NDArray[np.int64],
    origin: tuple[float, float, float] | list[float],
    spacing: float,
    dims: tuple[int, int, int] | list[int],
    edges: npt.NDArray[np.int64],
    samples: int,
) -> npt.NDArray[np.float32]: ...
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
    background: tuple[float, float, float] = ...,
    mode: str = "all",
    tiles: npt.NDArray[np.bool_] | None = None,
    sh_rows: npt.NDArray[np.uint32] | None = None,
    sort_offsets: npt.NDArray[np.float32] | None = None,
    near_plane: float = ...,
) -> Rendered: ...
def rasterize_behind(
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
    near: npt.NDArray[np.float32],
    count: int,
    gap_px: float,
    tiles: npt.NDArray[np.bool_] | None = None,
    sh_rows: npt.NDArray[np.uint32] | None = None,
    sort_offsets: npt.NDArray[np.float32] | None = None,
    near_plane: float = ...,
) -> list[Rendered]: ...

@final
class Rendered:
    @property
    def rgb(self) -> npt.NDArray[np.float32] | None: ...
    @property
    def alpha(self) -> npt.NDArray[np.float32]: ...
    @property
    def depth(self) -> npt.NDArray[np.float32] | None: ...
    @property
    def index(self) -> npt.NDArray[np.int32] | None: ...
    @property
    def index_depth(self) -> npt.NDArray[np.float32] | None: ...
    @property
    def project_s(self) -> float: ...
    @property
    def sort_s(self) -> float: ...
    @property
    def composite_s(self) -> float: ...
    @property
    def n_visible(self) -> int: ...
    @property
    def n_tile_pairs(self) -> int: ...

@final
class RetainedRender:
    def __new__(
        cls,
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
        moving: npt.NDArray[np.int64],
        background: tuple[float, float, float] = ...,
        mode: str = "all",
        sh_rows: npt.NDArray[np.uint32] | None = None,
        sort_offsets: npt.NDArray[np.float32] | None = None,
        near_plane: float = ...,
    ) -> RetainedRender: ...
    def frame(
        self, means: npt.NDArray[np.float32], scales: npt.NDArray[np.float32], quats: npt.NDArray[np.float32]
    ) -> Rendered: ...

def release_render_buffers() -> None: ...
def rows_in_box(
    points: npt.NDArray[np.float32], low: tuple[float, float, float], high: tuple[float, float, float]
) -> npt.NDArray[np.int64]: ...
def gather_columns(table: npt.NDArray[np.float32], columns: list[int], out: npt.NDArray[np.float32]) -> None: ...
def num_threads() -> int: ...
def _reset_pool_after_fork() -> None: ...

@final
class RodWorld:
    """Several discrete elastic rods stepped together; each is a `Rod` handle (see sketchrodgs.rod)."""

    def __init__(self) -> None: ...
    def __len__(self) -> int: ...
    def remove(self, rod: Rod) -> None: ...
    def solver(self) -> dict[str, Any]: ...
    def set_solver(
        self, tolerance: float, max_iterations: int, max_halvings: int, max_static_iterations: int
    ) -> None: ...
    def step(self, dt: float, count: int = 1) -> list[tuple[int, int, int, bool]]: ...
    def set_field(
        self, values: npt.NDArray[np.float32] | None, origin: tuple[float, float, float], spacing: float
    ) -> None: ...
    def has_field(self) -> bool: ...
    def contact(self) -> tuple[bool, bool, float]: ...
    def set_contact(self, scene: bool, rods: bool, friction: float) -> None: ...

@disjoint_base
class Rod:
    """A discrete elastic rod in a `RodWorld` (the base of `sketchrodgs.rod.Rod`)."""

    def __new__(
        cls,
        world: RodWorld,
        polyline: npt.ArrayLike,
        radius: float,
        youngs_modulus: float,
        shear_modulus: float | None,
        poisson_ratio: float,
        density: float,
        damping: float,
        gravity: tuple[float, float, float],
    ) -> Self: ...
    def __len__(self) -> int: ...
    @property
    def num_vertices(self) -> int: ...
    @property
    def index(self) -> int: ...
    def clamp(self, vertex: int) -> None: ...
    def pin(self, vertex: int, position: npt.ArrayLike | None = None) -> None: ...
    def free(self, vertex: int) -> None: ...
    def set_boundary(self, vertex: int, kind: str) -> None: ...
    @property
    def boundaries(self) -> list[str]: ...
    def move_clamp(
        self, vertex: int, rotation: npt.ArrayLike | None = None, translation: npt.ArrayLike | None = None
    ) -> None: ...
    def clamp_torque(self, vertex: int) -> float: ...
    def grab(self, vertex: int, target: npt.ArrayLike) -> None: ...
    def move_grab(self, target: npt.ArrayLike) -> None: ...
    def release(self) -> None: ...
    @property
    def grabbed(self) -> tuple[int, npt.NDArray[np.float64]] | None: ...
    def transform(self, rotation: npt.ArrayLike | None = None, translation: npt.ArrayLike | None = None) -> None: ...
    def set_positions(self, positions: npt.ArrayLike) -> None: ...
    def set_velocities(self, velocities: npt.ArrayLike) -> None: ...
    def _solve_static(self) -> tuple[int, bool, float]: ...
    def _hold_under_gravity(self) -> tuple[int, float]: ...
    def _energy(self) -> dict[str, float]: ...
    def _material(self) -> dict[str, Any]: ...
    @property
    def positions(self) -> npt.NDArray[np.float64]: ...
    @property
    def velocities(self) -> npt.NDArray[np.float64]: ...
    @property
    def rest_positions(self) -> npt.NDArray[np.float64]: ...
    @property
    def rest_lengths(self) -> npt.NDArray[np.float64]: ...
    @property
    def masses(self) -> npt.NDArray[np.float64]: ...
    @property
    def twist(self) -> npt.NDArray[np.float64]: ...
    @property
    def strain(self) -> npt.NDArray[np.float64]: ...
    def twisting_moment(self) -> npt.NDArray[np.float64]: ...
    @property
    def edge_frames(self) -> npt.NDArray[np.float64]: ...
    @property
    def vertex_frames(self) -> npt.NDArray[np.float64]: ...
    @property
    def edge_quats(self) -> npt.NDArray[np.float64]: ...
    @property
    def vertex_quats(self) -> npt.NDArray[np.float64]: ...
    def forces(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...

def default_rod_params() -> dict[str, Any]: ...
def default_solver_settings() -> dict[str, Any]: ...
def segment_and_bind(
    polyline: npt.NDArray[np.float64],
    arc: npt.NDArray[np.float64],
    length: float,
    means: npt.NDArray[np.float32],
    radius: float,
    grow: float,
    link_spacings: float,
    link_min: float,
    link_max: float,
    attach_size: float | None,
    end_margin: float,
    colours: npt.NDArray[np.float32] | None = None,
    attach_size_fewer: float | None = None,
) -> tuple[
    npt.NDArray[np.int64],
    npt.NDArray[np.int32],
    npt.NDArray[np.float32],
    npt.NDArray[np.float32],
    npt.NDArray[np.float32],
    npt.NDArray[np.bool_],
    tuple[list[float], list[float]] | None,
]: ...
def skin_scatter(
    rest: npt.NDArray[np.float32],
    deformed: npt.NDArray[np.float32],
    rest_frames: npt.NDArray[np.float64],
    frames: npt.NDArray[np.float64],
    segment: npt.NDArray[np.int32],
    t: npt.NDArray[np.float32],
    offset: npt.NDArray[np.float32],
    rest_quats: npt.NDArray[np.float32],
    rest_scales: npt.NDArray[np.float32],
    weight: npt.NDArray[np.float32],
    ids: npt.NDArray[np.int64],
    means: npt.NDArray[np.float32],
    quats: npt.NDArray[np.float32],
    scales: npt.NDArray[np.float32],
) -> None: ...

_F32 = npt.NDArray[np.float32]
# means (N, 3), scales (N, 3), quats (N, 4), opacities (N,), sh (N, K, 3), filled by the decoders
_SceneArrays = tuple[_F32, _F32, _F32, _F32, _F32]

def gunzip_into(raw: npt.NDArray[np.uint8], out: npt.NDArray[np.uint8]) -> tuple[int, bool] | None: ...
def decode_spz(
    payload: npt.NDArray[np.uint8], version: int, sh_bytes_per_splat: int, fractional_bits: int, out: _SceneArrays
) -> None: ...
def decode_compressed_ply(
    bounds: npt.NDArray[np.float64], packed: npt.NDArray[np.uint8], sh_rest: npt.NDArray[np.uint8], out: _SceneArrays
) -> None: ...
def decode_splat(records: npt.NDArray[np.uint8], out: _SceneArrays) -> None: ...
def scene_summary(
    means: _F32, scales: _F32, quats: _F32, opacities: _F32, sh: _F32
) -> tuple[list[bool], float, tuple[float, float], tuple[float, float]]: ...
def encode_png(rgb: npt.NDArray[np.uint8], level: int = 1) -> bytes: ...
