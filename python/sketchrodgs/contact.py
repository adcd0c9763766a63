"""The static scene as rods feel it (docs/contact.md): a signed distance field of the scene's
solid parts, built from its Gaussians around the rods' reach, for `World.set_scene_field`.

1. A grid over the rods' rest box, grown by half the longest rod (a clamped rod's middle moves
   about that far at most) and a few radii, at half the smallest radius per cell, coarser where
   that would pass `MAX_CELLS`.
2. Per cell, the largest opacity any unbound Gaussian reaches at its centre (`_core.max_alpha`,
   in Rust); cells where it reaches `SOLID_ALPHA` are solid.
3. The rods' own place at rest is carved out (cells within `CARVE_RADII` radii of a rest
   polyline): what a rod touches at rest, where it joins the scene, does not push it.
4. Hollow insides are filled: captures are shells of surface Gaussians, and a rod pushed into an
   object must meet its inside as solid too. Non-solid cells that do not connect to the grid's
   border are solid.
5. The signed distance, negative inside, in scene units: next to the boundary from where alpha
   crosses `SOLID_ALPHA` along the grid lines between nodes (sampled `EDGE_SAMPLES` times along
   each line that crosses, in Rust), further away by Euclidean distance transforms (scipy) to
   those nodes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from . import _core
from .polyline import polyline_length
from .scene import GaussianScene

SOLID_ALPHA = 0.5
MAX_CELLS = 2_000_000
CARVE_RADII = 2.0
REACH_SHARE = 0.5
MARGIN_RADII = 4.0
# Where the boundary crosses a grid line, the Gaussians' alpha is sampled this many times along it:
# interpolated linearly between two nodes a cell (about a radius) apart, the crossing was off by
# up to 0.07 R, and a rod sank that far into a slab (docs/contact.md).
EDGE_SAMPLES = 8


@dataclass(frozen=True)
class SceneField:
    """A signed distance field of a scene's solid parts.

    Attributes:
        values: (nz, ny, nx) float32 signed distance [scene units] at the nodes, negative inside.
        origin: (3,) float64 the node (0, 0, 0).
        spacing: distance between nodes.
        solid: (nz, ny, nx) bool, the solid cells it was made from (for pictures and tests).
    """

    values: np.ndarray
    origin: np.ndarray
    spacing: float
    solid: np.ndarray

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance at `points` (N, 3), +inf outside the grid: the cubic B-spline of the node
        values, as the rod solver samples it (docs/contact.md)."""
        g = (np.asarray(points, np.float64) - self.origin) / self.spacing
        shape = np.array(self.values.shape[::-1])  # nx, ny, nz
        inside = np.all((g >= 0) & (g <= shape - 1), axis=1)
        out = np.full(len(g), np.inf)
        if inside.any():
            coords = g[inside][:, ::-1].T  # z, y, x order for map_coordinates
            out[inside] = ndimage.map_coordinates(self.values, coords, order=3, mode="nearest", prefilter=False)
        return out


def scene_field(
    scene: GaussianScene,
    polylines: Sequence[np.ndarray],
    radii: Sequence[float],
    exclude: np.ndarray | None = None,
) -> SceneField | None:
    """The solid parts of `scene` around rods at rest on `polylines` (each (M, 3)) of `radii`,
    leaving out the Gaussians of rows `exclude` (the rods' own). None where nothing there is solid.
    """
    rest = [np.asarray(p, np.float64) for p in polylines]
    radius = float(min(radii))
    reach = REACH_SHARE * max(polyline_length(p) for p in rest) + MARGIN_RADII * float(max(radii))
    low = np.min([p.min(axis=0) for p in rest], axis=0) - reach
    high = np.max([p.max(axis=0) for p in rest], axis=0) + reach
    spacing = max(radius / 2, float(np.prod(high - low) / MAX_CELLS) ** (1 / 3))
    dims = np.maximum(np.ceil((high - low) / spacing).astype(int) + 1, 2)
    keep = np.ones(len(scene), bool)
    if exclude is not None and len(exclude):
        keep[np.asarray(exclude, np.int64)] = False
    # Gaussians whose centre lies within the grid grown by a few of their own sizes
    grow = 3.0 * float(np.max(scene.scales)) if len(scene) else 0.0
    rows = _core.rows_in_box(
        scene.means, tuple((low - grow).astype(np.float32)), tuple((high + grow).astype(np.float32))
    )
    rows = rows[keep[rows]]
    if len(rows) == 0:
        return None
    # the rows in place: no copy of the scene's arrays
    means, scales = np.ascontiguousarray(scene.means), np.ascontiguousarray(scene.scales)
    quats, opacities = np.ascontiguousarray(scene.quats), np.ascontiguousarray(scene.opacities)
    rows = rows.astype(np.int64)
    origin, cells = [float(v) for v in low], [int(v) for v in dims]
    alpha = _core.max_alpha(means, scales, quats, opacities, rows, origin, float(spacing), cells)
    alpha = alpha.reshape(dims[2], dims[1], dims[0])
    solid = alpha >= SOLID_ALPHA
    carved = _carved(rest, radii, low, spacing, dims)
    solid &= ~carved
    if not solid.any():
        return None
    # hollow insides: non-solid regions not connected to the grid's border
    labels, _ = ndimage.label(~solid)
    border = np.unique(
        np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(), labels[:, :, [0, -1]].ravel()])
    )
    enclosed = ~solid & ~np.isin(labels, border[border > 0]) & ~carved
    solid |= enclosed

    def along_edges(edges: np.ndarray) -> np.ndarray:
        return _core.max_alpha_along_edges(
            means, scales, quats, opacities, rows, origin, float(spacing), cells, edges, EDGE_SAMPLES
        )

    values = (_signed_distance(alpha, solid, along_edges) * spacing).astype(np.float32)
    return SceneField(values, low.astype(np.float64), float(spacing), solid)


def _signed_distance(
    alpha: np.ndarray, solid: np.ndarray, along_edges: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """(nz, ny, nx) signed distance in cells to the boundary of `solid`, negative inside, placed
    between nodes where the Gaussians' alpha crosses SOLID_ALPHA (a cell is about a radius: half a
    cell of error would sink a rod half a radius into a table).

    Nodes next to the boundary take the distance to the plane through its crossings on the grid
    lines around them (axis intercepts d_x, d_y, d_z: 1 / sqrt(sum 1 / d^2)). Each node takes the
    crossing nearest it on a line, found by `along_edges` ((E, 4) node i, j, k and axis ->
    (E, EDGE_SAMPLES + 1) alpha along the line); a line next to a carved or filled node, which
    alpha does not describe, crosses half-way. Every other node adds its distance to the nearest
    such node of its side (Euclidean distance transforms).
    """
    described = solid == (alpha >= SOLID_ALPHA)
    inverse = np.zeros(alpha.shape, np.float32)  # sum over axes of 1 / (intercept in cells)^2
    for axis in range(3):
        first = [slice(None)] * 3
        second = [slice(None)] * 3
        first[axis], second[axis] = slice(None, -1), slice(1, None)
        a, b = tuple(first), tuple(second)
        crossing = solid[a] != solid[b]
        # how far the crossing nearest each node lies from it, in cells
        from_a = np.full(crossing.shape, 0.5, np.float64)
        from_b = from_a.copy()
        lines = crossing & described[a] & described[b]
        if lines.any():
            nodes = np.argwhere(lines)  # (k, j, i) of node a
            edges = np.ascontiguousarray(np.column_stack([nodes[:, ::-1], np.full(len(nodes), 2 - axis)]), np.int64)
            from_a[lines], from_b[lines] = _nearest_crossings(along_edges(edges), solid[a][lines])
        nearest = np.zeros(alpha.shape, np.float32)  # the nearest crossing along this axis, either side
        nearest[a] = np.where(crossing, 1 / np.maximum(from_a, 1e-3) ** 2, 0.0)
        nearest[b] = np.maximum(nearest[b], np.where(crossing, 1 / np.maximum(from_b, 1e-3) ** 2, 0.0))
        inverse += nearest
    band = inverse > 0
    near = np.zeros(alpha.shape, np.float32)
    near[band] = 1 / np.sqrt(inverse[band])
    out = np.empty(alpha.shape, np.float32)
    for side, sign in ((~solid, 1.0), (solid, -1.0)):
        seeds = band & side
        if not seeds.any():
            out[side] = sign * np.inf
            continue
        gap, (iz, iy, ix) = ndimage.distance_transform_edt(~seeds, return_indices=True)
        out[side] = sign * (gap + near[iz, iy, ix])[side]
    return out


def _nearest_crossings(profile: np.ndarray, start_solid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From (E, S + 1) alpha sampled along grid lines from node a to node b, one of them solid
    (`start_solid`: node a): how far (in cells) the crossing of SOLID_ALPHA nearest node a lies
    from it, and the one nearest node b from b, each interpolated between the two samples around
    it.

    A Gaussian thinner than a cell makes the node nearest its centre solid though its alpha there
    is lower. Where the line meets it, its crossings are still found along the line; where the
    line does not, the solid node is where it ends (distance 0 from that node), not half-way to
    the next."""
    samples = profile.shape[1] - 1
    inside = profile >= SOLID_ALPHA
    crosses = inside.any(axis=1) & ~inside.all(axis=1)
    flips = inside[:, 1:] != inside[:, :-1]  # (E, S): the crossing lies between samples s and s + 1
    first = np.argmax(flips, axis=1)
    last = samples - 1 - np.argmax(flips[:, ::-1], axis=1)

    def at(s: np.ndarray) -> np.ndarray:
        rows = np.arange(len(profile))
        low, high = profile[rows, s], profile[rows, s + 1]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # lines that do not cross
            part = np.clip((SOLID_ALPHA - low) / (high - low), 0.0, 1.0)
        return (s + np.nan_to_num(part, nan=0.5)) / samples

    # nothing on the line reaches SOLID_ALPHA: the solid node holds a thin Gaussian's centre
    at_a = np.where(start_solid, 0.0, 1.0)
    return np.where(crosses, at(first), at_a), np.where(crosses, 1 - at(last), 1 - at_a)


def _carved(
    rest: list[np.ndarray], radii: Sequence[float], low: np.ndarray, spacing: float, dims: np.ndarray
) -> np.ndarray:
    """(nz, ny, nx) the cells within CARVE_RADII radii of a rest polyline."""
    carved = np.zeros((dims[2], dims[1], dims[0]), bool)
    for polyline, r in zip(rest, radii):
        reach = CARVE_RADII * float(r) + spacing
        lo = np.maximum(np.floor((polyline.min(axis=0) - reach - low) / spacing).astype(int), 0)
        hi = np.minimum(np.ceil((polyline.max(axis=0) + reach - low) / spacing).astype(int) + 1, dims)
        z, y, x = np.mgrid[lo[2] : hi[2], lo[1] : hi[1], lo[0] : hi[0]]
        centres = (np.stack([x, y, z], axis=-1).reshape(-1, 3) * spacing + low).astype(np.float32)
        _, _, distance = _core.nearest_on_polyline(polyline.astype(np.float32), centres, reach)
        near = (distance <= CARVE_RADII * float(r)).reshape(z.shape)
        carved[lo[2] : hi[2], lo[1] : hi[1], lo[0] : hi[0]] |= near
    return carved
