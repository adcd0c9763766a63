"""Sketch to rod: from one stroke on a view, the 3D polyline of the slender object under it and the
Gaussians that belong to it (paper: Path Optimization, Occlusion, Post Process; docs/extraction.md).
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
from scipy.ndimage import median_filter
from scipy.spatial import cKDTree

from . import _core, near_plane
from . import polyline as pl
from . import segment as sg
from .camera import Camera
from .errors import PathNotFoundError, SketchRodGSError
from .partial_render import BEHIND_LAYERS, MARGIN_PX, PartialRender, band_tiles
from .render import TILE_SIZE, RenderResult, tile_grid
from .render import render as render_scene
from .rod import MAX_ROD_VERTICES
from .rod_file import Extraction
from .scene import GaussianScene
from .scene_identity import SceneIdentity
from .working_view import WORKING_WIDTH, WorkingView

DEFAULT_SMOOTHING = 1.0  # radii (polyline.smooth_axis)
MAX_SMOOTHING = 100.0  # far past any use: the axis is a straight line long before
_SMALLEST = float(np.finfo(np.float32).tiny)  # lengths go to Rust as float32
_LARGEST = float(np.finfo(np.float32).max)
# A path Gaussian's centre must project within this many pixels, or radii, of the path; within
# the wider reach where the nearer keeps fewer than half of what that would (`_near_the_path`).
_NEAR_PIXEL_PX = 3.0
_NEAR_PIXEL_RADII = 1.0
_NEAR_PIXEL_RADII_WIDE = 2.0
# Path pixels whose Gaussian lies farther than the wider reach get the Gaussian that owns them
# without it, at most this many times over (`_past_far_owners`).
_FAR_OWNER_ROUNDS = 2
# The depth gap between surfaces is 3 R, but at least this many pixels' world size (the search's,
# GAP_FLOOR_PX in rust/sketchrodgs-path/src/lib.rs; docs/extraction.md, "Stroke clean-up").
_GAP_FLOOR_PX = 8.0
# Where the part is outlined by background, its recentring reaches no further than its visible
# half-width allows, but not under this share of the usual reach (a dark edge that blends into
# the background narrows what shows).
OUTLINED_FLOOR = 0.4


def extract_rod(
    scene: GaussianScene,
    camera: Camera,
    stroke: np.ndarray,
    radius: float | None = None,
    *,
    alpha: float = 1.0,
    band_px: float | None = None,
    edge_length: float | None = None,
    smoothing: float = DEFAULT_SMOOTHING,
    segment_scale: float = sg.DEFAULT_GROW,
    attach: bool = True,
    attach_size: float | None = None,
    recentre: bool = True,
    render: RenderResult | None = None,
    working_width: int | None = WORKING_WIDTH,
) -> Extraction:
    """Extract the slender object under `stroke`.

    Args:
        scene: the scene.
        camera: the camera the stroke was drawn in.
        stroke: (S, 2) stroke points in continuous pixel coordinates of `camera`.
        radius: R, the object's radius in world units. When None it is estimated from the object's
            visible width across the stroke (`estimate_radius`).
        alpha: weight of the stroke-distance term of the path cost (paper Eq. 1; the term is in
            units of a pixel's world size, so that the scene's units do not matter:
            docs/extraction.md, "Search").
        band_px: half-width of the band around the stroke (default 1 % of the image width, or 1.25 R
            in pixels at the stroke's depth where that is wider).
        edge_length: polyline spacing (default from R and the object's length).
        smoothing: how smooth the axis is, in radii (`polyline.smooth_axis`): bends shorter than
            about 2 pi `smoothing` R are smoothed out; 0 keeps the recentred points as they are.
        segment_scale: the part's cross-section reaches `segment_scale * R` from the axis (grown
            from the axis over neighbouring Gaussians; docs/deformation.md, "Segmentation").
        attach: small parts attached to the part (a leaf, a tag) ride rigidly with the rod.
        attach_size: the largest attached part, in world units (default
            `segment.default_attach_size`, and `segment.default_attach_size_fewer` for a part with
            no more Gaussians than the rod's own; docs/deformation.md, "Segmentation").
        recentre: move the visible surface points onto the axis (our addition; the paper keeps them).
        render: a render of `scene` by `camera` with `index`, `index_depth` and `alpha` (made if
            None; without alpha, widths are measured on the index image alone).
        working_width: a view of another width is traced on a copy scaled to this width, so that
            the rod does not depend on the resolution (docs/extraction.md, "Resolution"); None
            traces every view at its own size.

    The stroke may overshoot the object at either end (it is trimmed to where it meets the object it
    follows), pass over occluders (skipped by depth) and be drawn in either direction (the same rod).

    Raises:
        PathNotFoundError: the stroke misses the object or the path is too short to make a rod. The
            error carries `stroke`, `pixel_path` (what was found) and `lost_at` for drawing it.
        SketchRodGSError: bad arguments (the message names which).
    """
    stroke = _check_stroke(stroke)
    for name, value in (("alpha", alpha), ("segment_scale", segment_scale)):
        if not np.isfinite(value) or value < 0:
            raise SketchRodGSError(f"{name}: must be finite and >= 0, got {value}")
    if radius is not None and not (np.isfinite(radius) and _SMALLEST <= radius <= _LARGEST):
        raise SketchRodGSError(f"radius: must be finite and within float32's {_SMALLEST:g}..{_LARGEST:g}, got {radius}")
    if band_px is not None and not (np.isfinite(band_px) and 0 < band_px <= _LARGEST):
        raise SketchRodGSError(f"band_px: must be finite, > 0 and within float32's range, got {band_px}")
    if attach_size is not None and not (np.isfinite(attach_size) and attach_size > 0):
        raise SketchRodGSError(f"attach_size: must be finite and > 0, got {attach_size}")
    if edge_length is not None and not (np.isfinite(edge_length) and edge_length > 0):
        raise SketchRodGSError(f"edge_length: must be finite and > 0, got {edge_length}")
    if (
        isinstance(smoothing, bool)
        or not isinstance(smoothing, (int, float, np.integer, np.floating))
        or not 0 <= smoothing <= MAX_SMOOTHING
    ):
        raise SketchRodGSError(f"smoothing: must be a number of radii in 0..{MAX_SMOOTHING:g}, got {smoothing!r}")

    if working_width is not None and not (isinstance(working_width, (int, np.integer)) and working_width >= 16):
        raise SketchRodGSError(f"working_width: must be a whole number of pixels >= 16, or None, got {working_width!r}")
    if render is not None:
        _check_render_size(render, camera)
    view = WorkingView.of(camera, working_width)
    try:
        extraction = _extract(
            scene,
            view.work,
            view.points_to_work(stroke),
            radius,
            alpha=alpha,
            band_px=None if band_px is None else band_px * view.scale[0],
            edge_length=edge_length,
            smoothing=smoothing,
            segment_scale=segment_scale,
            attach=attach,
            attach_size=attach_size,
            recentre=recentre,
            render=None if view.scaled else render,
        )
    except PathNotFoundError as err:
        raise view.failure_to_user(err, stroke) from None
    return view.extraction_to_user(extraction, stroke)


def _extract(
    scene: GaussianScene,
    camera: Camera,
    stroke: np.ndarray,
    radius: float | None,
    *,
    alpha: float,
    band_px: float | None,
    edge_length: float | None,
    smoothing: float,
    segment_scale: float,
    attach: bool,
    attach_size: float | None,
    recentre: bool,
    render: RenderResult | None,
) -> Extraction:
    """`extract_rod` on arguments checked, in the view it traces (`WorkingView.work`)."""
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    given = render is not None
    # The band's tiles (unless the render was given), and where the search asks for them, the
    # layers behind them.
    band = band_px if band_px is not None else 0.01 * camera.width

    def band_of_stroke() -> np.ndarray:  # computed only when needed: ~7 ms for a long stroke
        return band_tiles(camera, stroke, band + MARGIN_PX)

    partial = PartialRender(scene, camera, None if given else band_of_stroke(), front=render)
    render_s = time.perf_counter() - clock
    layered = False
    front: _Traced | None = None  # the last whole trace over the front alone
    while True:
        # The search records what it read outside the rendered tiles; those tiles are then
        # rendered and the search runs again (partial_render.py). A search that could run behind
        # what lies in front of the object asks for the layers behind; it then runs again with them.
        missed = partial.missed()
        try:
            found = _trace(scene, camera, partial, stroke, radius, alpha, band_px, timings, missed)
        except PathNotFoundError:
            if missed.any():
                found = None
            elif layered and front is not None:
                found = front  # the layers behind lost the part: keep what the front alone found
            else:
                raise
        clock = time.perf_counter()
        if missed.any():
            partial.add(missed)
        elif found is not None and found.wants_behind and not layered:
            front = found
            partial.add_behind(BEHIND_LAYERS, band_of_stroke())
            layered = True
        else:
            break
        render_s += time.perf_counter() - clock
    if partial.renders:
        timings["render"] = render_s
    assert found is not None  # (the loop ends on a trace, or raises)
    rod_points = found.rod_points(scene, camera)
    if rod_points is None and front is not None and found is not front:
        # A part lying on a surface can be taken for a leaf in front of what lies behind it: where the
        # chain behind then makes no rod, the front's does (docs/extraction.md, "What lies behind").
        front_points = front.rod_points(scene, camera)
        if front_points is not None:
            found, rod_points = front, front_points
    radius, estimated, _, trace, pixel_path, path_ids, points = found
    flip = _flipped(stroke)
    pieces = trace.pieces

    clock = time.perf_counter()
    if rod_points is None:
        length = pl.polyline_length(points) if len(points) > 1 else 0.0
        path_px = sum(len(p.pixels) for p in pieces)
        # a long path on under two of the part's Gaussians ran over what the part lies on or
        # touches, one big Gaussian owning its pixels: the stroke lay along the part's edge
        # (docs/real_captures.md, "Drawn along an edge")
        what = (
            f"draw the stroke along the object's middle, not its edge (the path ran {path_px} px over what it lies on)"
            if len(path_ids) < 2 and path_px >= _EDGE_PATH_PX
            else "draw the stroke along more of the object, or give a smaller --radius"
        )
        raise _failure(
            f"the path under the stroke is too short for a rod ({len(path_ids)} Gaussians, {length:.3g} long, "
            f"radius {radius:.3g}): {what}",
            stroke,
            pixel_path,
            pieces,
        )
    points = rod_points
    # Recentre on a uniform sampling at half the radius, smooth, bridge detours, cut hooked ends
    # and ends turning off at a junction, resample to the edge length.
    _check_vertex_count("radius", pl.polyline_length(points), radius / 2, radius, 4 * MAX_ROD_VERTICES)
    points = pl.resample(points, radius / 2)
    if recentre:
        # on a surface of another colour, the axis is the part's Gaussians' only (`_of_the_part`)
        part = _of_the_part(pl.near_box(points, scene.means, 2.5 * radius), scene, trace.colours)
        nearby = np.take(scene.means, part, axis=0)  # faster than `means[part]` (docs/extraction.md, "Speed")
        scale = _outlined_scale(points, camera, partial, radius, stroke, band + MARGIN_PX)
        points = pl.recentre(points, nearby, radius, scale)
    points = pl.smooth_axis(points, radius, smoothing)
    points = pl.bridge_detours(points, radius, *_on_screen(camera, points, radius)[::2], nearby if recentre else None)
    points = pl.cut_hooked_ends(points, radius)
    if recentre:
        points = pl.cut_junction_ends(points, nearby, radius)
    length = pl.polyline_length(points)
    spacing = edge_length if edge_length is not None else pl.default_edge_length(length, radius)
    _check_vertex_count("edge_length", length, spacing, spacing, MAX_ROD_VERTICES)
    polyline = pl.resample(points, spacing)
    crossing = _turn_from_stroke(camera, polyline, stroke, radius)
    if crossing > _CROSSING_DEG:
        raise _failure(
            f"the rod found runs across the stroke ({crossing:.0f} degrees from it), not along it: the part "
            "may be hidden there by a leaf or body, or the stroke may run over two parts; draw the stroke "
            "along where the part is seen",
            stroke,
            pixel_path,
            pieces,
        )
    if flip:
        polyline, path_ids = polyline[::-1].copy(), path_ids[::-1].copy()
    timings["polyline"] = time.perf_counter() - clock

    clock = time.perf_counter()
    binding = sg.segment_and_bind(polyline, scene, radius, grow=segment_scale, attach=attach, attach_size=attach_size)
    timings["segment_bind"] = time.perf_counter() - clock
    # every piece but the last ends at a gap, in either direction, so the flags need no reversal
    reached = [bool(p.reached_goal) for p in pieces]
    return Extraction(
        polyline=polyline.astype(np.float32),
        radius=float(radius),
        edge_length=float(spacing),
        pixel_path=pixel_path,
        path_gaussian_ids=path_ids,
        gaussian_ids=binding.gaussian_ids,
        binding=binding,
        coverage=float(trace.coverage),
        pieces_reached_goal=reached,
        camera=camera,
        stroke=stroke,
        radius_estimated=estimated,
        timings=timings,
        rendered_tiles=None if given else float(partial.tiles.mean()),
        scene_identity=SceneIdentity.of(scene),
    )


def _line_over_path_pixels(
    points: np.ndarray, scene: GaussianScene, camera: Camera, pieces: list[_core.TracePiece], path_ids: np.ndarray
) -> np.ndarray:
    """The line fitted to the path's pixels that show one of the path's Gaussians `path_ids`, each
    pixel unprojected at its Gaussian's depth, over their extent, in the direction of `points` (the
    centres): where 2-3 big Gaussians draw a sprinkle, their centres span less than the part does
    on screen (docs/extraction.md, "Polyline, segmentation, binding")."""
    pixels = np.concatenate([p.pixels.astype(np.int64) for p in pieces])
    ids = np.concatenate([p.pixel_ids.astype(np.int64) for p in pieces])
    shown = np.isin(ids, path_ids)
    pixels, ids = pixels[shown], ids[shown]
    if len(pixels) < 2:
        return points
    unprojected = camera.unproject(pixels + 0.5, camera.project(np.take(scene.means, ids, axis=0))[1])
    middle = unprojected.mean(axis=0)
    direction = np.linalg.svd(unprojected - middle, full_matrices=False)[2][0]
    if direction @ (points[-1] - points[0]) < 0:
        direction = -direction
    along = (unprojected - middle) @ direction
    return np.stack([middle + along.min() * direction, middle + along.max() * direction])


# A failed path this many pixels long on under two of the part's Gaussians ran along the part's edge
# (the error says so)
_EDGE_PATH_PX = 20

# A path piece lost where an occluder hides the part may have climbed onto it first: its pixels
# nearer the break than `_BREAK_WINDOW_R[0]` R that lie `_BREAK_AHEAD_R` R in front of the part's
# depth across the gap (from the sides' median depths `_BREAK_WINDOW_R` R from it) are taken off
# (`_off_occluders_at_breaks`).
_BREAK_AHEAD_R = 2.0
_BREAK_WINDOW_R = (3.0, 8.0)


# A rod whose chord on screen, at least two radii long, turns more than this from the stroke's over
# the same stretch does not follow the stroke: it crossed a leaf hiding the part, or two parts
# (docs/extraction.md, "Failures", A rod across its stroke)
_CROSSING_DEG = 40.0


def _turn_from_stroke(camera: Camera, polyline: np.ndarray, stroke: np.ndarray, radius: float) -> float:
    """The angle in degrees between the lines of `polyline`'s chord on screen and of `stroke`'s chord
    between its points nearest the polyline's projected ends; 0 where the polyline's chord is under
    two radii on screen (too short to have a direction) or the stroke's stretch is a point."""
    ends, depth = camera.project(polyline[[0, -1]])
    chord = ends[1] - ends[0]
    radius_px = radius * camera.fx / max(float(np.mean(depth)), 1e-12)
    if not np.linalg.norm(chord) >= 2 * radius_px:
        return 0.0
    # the stroke's points in the image (one far off it, a stray sample the clean-up dropped, would
    # make the nearest-point sums overflow in float32)
    stroke = np.asarray(stroke, np.float64)
    stroke = stroke[((stroke >= 0) & (stroke <= (camera.width, camera.height))).all(axis=1)]
    if len(stroke) < 2:
        return 0.0
    _, at = pl.nearest_on_polyline(ends, stroke)
    over = pl.point_at(stroke, pl.arc_lengths(stroke), at)
    along = over[1] - over[0]
    if not np.linalg.norm(along) > 0:
        return 0.0
    cosine = abs(chord @ along) / (np.linalg.norm(chord) * np.linalg.norm(along))
    return float(np.degrees(np.arccos(min(cosine, 1.0))))


class _Traced(NamedTuple):
    """What `_trace` found."""

    radius: float
    estimated: bool
    wants_behind: bool  # whether the layers behind the front could change it
    trace: _core.Trace
    pixel_path: list[np.ndarray]  # in the user's direction
    path_ids: np.ndarray
    points: np.ndarray  # the path's Gaussians' centres, lightly smoothed

    def rod_points(self, scene: GaussianScene, camera: Camera) -> np.ndarray | None:
        """The points where they make a rod two diameters long, or the line over the path's pixels
        where that is longer (`_line_over_path_pixels`); None where neither does."""
        points, length = self.points, (pl.polyline_length(self.points) if len(self.points) > 1 else 0.0)
        if len(points) >= 2 and length < 2 * self.radius:
            line = _line_over_path_pixels(points, scene, camera, self.trace.pieces, self.path_ids)
            line_length = pl.polyline_length(line)
            if line_length > length:
                points, length = line, line_length
        return points if len(points) >= 2 and length >= 2 * self.radius else None


def _trace(
    scene: GaussianScene,
    camera: Camera,
    partial: PartialRender,
    stroke: np.ndarray,
    radius: float | None,
    alpha: float,
    band_px: float | None,
    timings: dict[str, float],
    missed: np.ndarray,
) -> _Traced:
    """Everything that reads the render: R (estimated when None), the path, its Gaussians in order
    and their centres lightly smoothed."""
    index, depth, opacity, work, flip = _search_inputs(partial.result, stroke)
    focal = float(camera.fx)
    region: dict[str, Any] = {"rendered": partial.tiles, "missed": missed, "behind": partial.behind_arrays()}
    clock = time.perf_counter()
    estimated, estimate_wants = radius is None, False
    shown = [index, *(region["behind"][:1] if region["behind"] else [])]
    colours = _shown_colours(scene, shown, work, _colours_reach(depth, work, radius, focal, band_px))
    if radius is None:
        try:
            radius, estimate_wants = _core.estimate_radius(
                index, depth, opacity, work, focal, float(band_px or 0.0), **region, colours=colours
            )
        except PathNotFoundError as err:
            raise _failure(_with_near_plane_hint(str(err), scene, camera, stroke), stroke, []) from None
        timings["estimate_radius"] = time.perf_counter() - clock
        clock = time.perf_counter()

    def trace_path(radius: float) -> tuple[_core.Trace, list[np.ndarray], np.ndarray, np.ndarray]:
        try:
            trace = _core.trace_stroke(
                index,
                depth,
                scene.means,
                work,
                float(radius),
                float(alpha),
                float(band_px or 0.0),
                focal_px=focal,
                alpha=opacity,
                colours=colours,
                **region,
            )
        except PathNotFoundError as err:
            raise _failure(_with_near_plane_hint(str(err), scene, camera, stroke), stroke, []) from None
        pieces = [p.pixels.astype(np.int64) for p in trace.pieces]
        piece_ids = [p.pixel_ids.astype(np.int64) for p in trace.pieces]
        if len(pieces) > 1:
            depths = [camera.project(np.take(scene.means, i, axis=0))[1] for i in piece_ids]
            pieces, piece_ids = _off_occluders_at_breaks(pieces, piece_ids, depths, float(radius), focal)
        pixel_path = [p[::-1] for p in pieces[::-1]] if flip else pieces
        pixels = np.concatenate(pieces)
        ids = np.concatenate(piece_ids)
        path = cKDTree(pixels + 0.5)  # the pixels' centres, for how far off each Gaussian lies
        ids = _past_far_owners(scene, camera, pixels, ids, path, radius)
        path_ids = _near_the_path(path, ids, scene.means, camera, radius)
        path_ids = _of_the_part(path_ids, scene, trace.colours)
        path_ids = _forward_only(path_ids, scene.means, camera, trace.clean_stroke, radius)
        # The path hops between Gaussians scattered over the surface; a little smoothing takes out
        # the zigzag before the chain is resampled by arc length.
        points = pl.laplacian_smooth(scene.means[path_ids].astype(np.float64), 3)
        return trace, pixel_path, path_ids, points

    def length(points: np.ndarray) -> float:
        return pl.polyline_length(points) if len(points) > 1 else 0.0

    def long_enough(points: np.ndarray, pixel_path: list[np.ndarray], radius: float) -> bool:
        """Whether the path makes a rod two diameters long: its Gaussians' centres, or where the part
        is a few big Gaussians whose centres lie closer together than its ends, its pixels."""
        return length(points) >= 2 * radius or _path_length_on_screen(pixel_path, depth, focal) >= 2 * radius

    trace, pixel_path, path_ids, points = trace_path(radius)
    found = length(points)
    if estimated and found > 0 and not long_enough(points, pixel_path, radius):
        # A rod is at least two diameters long, so an estimate that makes the part shorter than that
        # took in what the part lies on (a sprinkle on the icing): trace again at a quarter its length
        # (docs/extraction.md, "Radius").
        radius = found / 4
        trace, pixel_path, path_ids, points = trace_path(radius)
    if estimated and trace.colours is not None:
        # on a surface of another colour, the part's width is where its colour ends; an answer far
        # off the estimate (a few pixels of the part's colour) or a trace that then fails or is too
        # short for a rod keeps it
        by_colour = _radius_by_colour(scene, index, depth, opacity, trace, focal, radius)
        if by_colour is not None and 0.25 * radius <= by_colour <= 4 * radius:
            try:
                again, again_pixels, again_ids, again_points = trace_path(by_colour)
                if long_enough(again_points, again_pixels, by_colour):
                    trace, pixel_path, path_ids, points = again, again_pixels, again_ids, again_points
                    radius = by_colour
            except PathNotFoundError:
                pass
    timings["path_search"] = time.perf_counter() - clock
    return _Traced(radius, estimated, estimate_wants or trace.wants_behind, trace, pixel_path, path_ids, points)


def _path_length_on_screen(pixel_path: list[np.ndarray], depth: np.ndarray, focal: float) -> float:
    """The pixel path's length in world units at its median depth (its pieces' lengths summed)."""
    pixels = np.concatenate(pixel_path)
    depths = depth[pixels[:, 1], pixels[:, 0]]
    depths = depths[np.isfinite(depths) & (depths > 0)]
    if len(depths) == 0:
        return 0.0
    px = sum(pl.polyline_length(piece.astype(np.float64)) for piece in pixel_path if len(piece) > 1)
    return float(px * np.median(depths) / focal)


def _off_occluders_at_breaks(
    pieces: list[np.ndarray], ids: list[np.ndarray], depth: list[np.ndarray], radius: float, focal: float
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The path's `pieces` (pixels) and their Gaussians `ids`, with each end at a break taken off
    where it climbed onto the occluder that hides the part there (docs/extraction.md, "Piece ends on
    an occluder"): the run of its last pixels before the window whose Gaussians (camera `depth` per
    pixel) lie over `_BREAK_AHEAD_R` R in front of the part's depth across the gap, the line through
    the median depths of both sides over the window, `_BREAK_WINDOW_R` R from the break (R in pixels
    at focal length `focal`)."""
    pieces, ids, depth = list(pieces), list(ids), list(depth)
    for k in range(len(pieces) - 1):
        before, after = depth[k][::-1], depth[k + 1]  # each from the break outwards
        px = radius * focal / float(np.median(np.r_[before, after]))
        near, far = (round(r * px) for r in _BREAK_WINDOW_R)
        if min(len(before), len(after)) < far or far <= near:
            continue
        middle = 0.5 * (near + far)
        gap = float(np.linalg.norm(pieces[k + 1][0] - pieces[k][-1]))
        z_before, z_after = float(np.median(before[near:far])), float(np.median(after[near:far]))
        # the part's depth along the line through the two medians, at x px from the break's near
        # side, is z_before + (x + middle) slope; a pixel over the allowance in front of it climbed
        slope = (z_after - z_before) / (gap + 2 * middle)
        limit = z_before + middle * slope - _BREAK_AHEAD_R * radius
        steps = np.arange(near)
        cut = _leading_run(before[: len(steps)] < limit - steps * slope)
        if cut:
            pieces[k], ids[k], depth[k] = pieces[k][:-cut], ids[k][:-cut], depth[k][:-cut]
        cut = _leading_run(after[: len(steps)] < limit + (gap + steps) * slope)
        if cut:
            pieces[k + 1], ids[k + 1], depth[k + 1] = pieces[k + 1][cut:], ids[k + 1][cut:], depth[k + 1][cut:]
    return pieces, ids


def _leading_run(mask: np.ndarray) -> int:
    """How many of `mask`'s first entries are True."""
    return len(mask) if mask.all() else int(np.argmin(mask))


def _radius_by_colour(
    scene: GaussianScene,
    index: np.ndarray,
    depth: np.ndarray,
    opacity: np.ndarray,
    trace: _core.Trace,
    focal: float,
    radius: float,
) -> float | None:
    """R of a part lying on a surface of another colour (`Trace.colours`), measured from the path:
    from each path pixel, walk both ways across the clean stroke until a pixel shows nothing, a
    Gaussian nearer the surface's colour than the part's (in hue too: `_surface_coloured`), or a
    depth more than the depth gap (`radius`'s) beyond every depth walked (at most 1/8 of the image
    each way); R is the median half-width in world units. The depth ends a walk where the colour
    does not: a dark hook before a dark floor (docs/extraction.md, "A part lying on a surface", Up
    to a depth step). The radius estimate walks from the stroke's samples, which a stroke drawn
    beside the part puts on the surface, and stops by a colour taken under the stroke; the path
    keeps to the part (docs/extraction.md, "A part lying on a surface"). Only the
    path pixels that show a Gaussian of the part's colour are measured from: a stroke drawn on past
    the part's end takes the path over the surface there, and each such pixel measured 0.5 px."""
    pixels = np.concatenate([p.pixels.astype(np.int64) for p in trace.pieces])
    clean = np.asarray(trace.clean_stroke, np.float64)
    if trace.colours is None or len(clean) < 2 or len(pixels) == 0:
        return None
    shown = index[pixels[:, 1], pixels[:, 0]]
    pixels = pixels[(shown >= 0) & _part_coloured(scene.colors_of(np.maximum(shown, 0)), trace.colours)]
    if len(pixels) == 0:
        return None
    normal = _normals_on_screen(clean)
    nearest = np.argmin(((pixels[:, None, :] - clean[None]) ** 2).sum(axis=2), axis=1)
    height, width = index.shape
    steps = np.arange(1, max(width, height) // 8 + 1)
    start = depth[pixels[:, 1], pixels[:, 0]]
    gap = _depth_gap(radius, start, focal)[:, None]
    reach = []
    for sign in (1, -1):
        walk = np.rint(pixels[:, None, :] + sign * steps[None, :, None] * normal[nearest][:, None, :]).astype(np.int64)
        inside = (walk >= 0).all(axis=2) & (walk[..., 0] < width) & (walk[..., 1] < height)
        col, row = np.clip(walk[..., 0], 0, width - 1), np.clip(walk[..., 1], 0, height - 1)
        ids = index[row, col]
        on_surface = _surface_coloured(scene.colors_of(np.maximum(ids, 0).ravel()), trace.colours).reshape(ids.shape)
        stop = ~(inside & (ids >= 0) & (opacity[row, col] >= 0.5)) | on_surface
        # each step against the depths walked before it (only those before the first stop count)
        z = depth[row, col]
        walked = np.concatenate([start[:, None], z[:, :-1]], axis=1)
        stop |= (z < np.minimum.accumulate(walked, axis=1) - gap) | (z > np.maximum.accumulate(walked, axis=1) + gap)
        reach.append(np.where(stop.any(axis=1), np.argmax(stop, axis=1), len(steps)))
    half = 0.5 * (reach[0] + reach[1] + 1) * start / focal
    half = half[np.isfinite(half) & (half > 0)]
    return float(np.median(half)) if len(half) else None


def _with_near_plane_hint(message: str, scene: GaussianScene, camera: Camera, stroke: np.ndarray) -> str:
    """`message`, and where the stroke lies on background only because what it was drawn over is
    nearer than the camera's near plane (a close-up of a small scene), how to see it."""
    if "background" not in message:
        return message
    hint = near_plane.culled_under_stroke(scene, camera, stroke)
    return f"{message}; {hint}" if hint else message


def _colours_reach(
    depth: np.ndarray, stroke: np.ndarray, radius: float | None, focal: float, band_px: float | None
) -> float:
    """How far from the stroke's bounding box, in pixels, the Gaussians' colours are read: the radius
    estimate's width walks reach the band and 1/8 of the image's larger side (radius.rs), the path's
    colour term the band and 5 R across the stroke (search.rs; R in pixels at the nearest depth under
    the stroke), docs/extraction.md, "A part lying on a surface"."""
    height, width = depth.shape
    band = max(band_px or 0.0, 0.01 * width, 2.0)
    if radius is None:
        return band + max(width, height) / 8 + 2
    # (on the image first: a point 1e20 px out has no int64 pixel)
    on_image = (stroke >= 0).all(axis=1) & (stroke[:, 0] < width) & (stroke[:, 1] < height)
    pixels = np.floor(stroke[on_image]).astype(np.int64)
    under = depth[pixels[:, 1], pixels[:, 0]]
    under = under[np.isfinite(under) & (under > 0)]
    radius_px = radius * focal / float(np.min(under)) if len(under) else 0.25 * max(width, height)
    return band + min(5 * radius_px, max(width, height) / 8) + 2


def _shown_colours(
    scene: GaussianScene, index_images: list[np.ndarray], stroke: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """The colours (SH DC term) of the Gaussians that `index_images` ((H, W) or (L, H, W)) show
    within `reach` pixels of `stroke`'s bounding box: (ids ascending, rgb)."""
    height, width = index_images[0].shape
    low = np.clip(np.floor(stroke.min(axis=0) - reach), 0, [width, height]).astype(int)
    high = np.clip(np.ceil(stroke.max(axis=0) + reach) + 1, 0, [width, height]).astype(int)
    ids = _core.shown_ids(index_images, (int(low[0]), int(low[1])), (int(high[0]), int(high[1])), len(scene))
    return ids, scene.colors_of(ids)


def _on_screen(camera: Camera, points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`points` (N, 3) as `camera` sees them: pixels (N, 2), depth (N,), and R in pixels there (N,)."""
    uv, z = camera.project(points)
    return uv, z, radius * camera.fx / np.maximum(z, 1e-12)


def _far_off(
    path: cKDTree, ids: np.ndarray, means: np.ndarray, camera: Camera, radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per Gaussian of `ids`, how far its centre projects from the nearest of the path's pixel
    centres `path`, in pixels (infinite behind the camera), and R in pixels at its depth."""
    uv, z, radius_px = _on_screen(camera, means[ids], radius)
    off_path, _ = path.query(np.where(np.isfinite(uv), uv, -1e9))
    return np.where(z > 0, off_path, np.inf), radius_px


def _past_far_owners(
    scene: GaussianScene,
    camera: Camera,
    pixels: np.ndarray,
    ids: np.ndarray,
    path: cKDTree,
    radius: float,
) -> np.ndarray:
    """The Gaussians `ids` (P,) of the path's `pixels` (P, 2) (their centres in the tree `path`),
    where a pixel's Gaussian lies far off (its centre more than 2 R from every pixel of the path)
    replaced by the Gaussian that owns that pixel without it, where that one lies at the part's
    depth. K is the Gaussian of largest weight: over a sprinkle, a faint icing Gaussian 10 R long,
    its centre 100 px away, can outweigh each of the sprinkle's Gaussians behind it, though the
    pixel shows the sprinkle's blue; the rod then missed the sprinkle's upper half
    (docs/extraction.md, "Gaussians the part hides behind a faint one"). At the part's depth: within
    the depth gap (3 R), plus the lateral distance as in the depth chain, of the Gaussian of the
    nearest pixel along the path whose own is not far off: a leaf's Gaussian is far off too, and
    what it hides is often deeper. `ids` is changed in place."""
    for _ in range(_FAR_OWNER_ROUNDS):
        shown = np.unique(ids)
        off_path, radius_px = _far_off(path, shown, scene.means, camera, radius)
        far = shown[off_path > _NEAR_PIXEL_RADII_WIDE * radius_px]
        owned = np.isin(ids, far)
        at = np.flatnonzero(owned)
        kept = np.flatnonzero(~owned)
        if len(at) < 3 or len(kept) == 0:
            break
        tiles = np.zeros(tile_grid(camera), bool)
        tiles[pixels[at, 1] // TILE_SIZE, pixels[at, 0] // TILE_SIZE] = True
        opacities = scene.opacities.copy()
        opacities[far] = 0.0
        without = render_scene(scene.replace(opacities=opacities), camera, outputs=("index",), tiles=tiles)
        owner = np.asarray(without.index)[pixels[at, 1], pixels[at, 0]].astype(np.int64)
        # the nearest pixel along the path with a Gaussian not far off
        after = np.searchsorted(kept, at)
        before, after = kept[np.maximum(after - 1, 0)], kept[np.minimum(after, len(kept) - 1)]
        reference = np.where(np.abs(at - before) <= np.abs(after - at), before, after)
        _, z_owner = camera.project(scene.means[np.maximum(owner, 0)].astype(np.float64))
        _, z_part = camera.project(scene.means[ids[reference]].astype(np.float64))
        lateral = np.linalg.norm(pixels[at] - pixels[reference], axis=1) * z_part / camera.fx
        same_depth = (owner >= 0) & (np.abs(z_owner - z_part) <= 3 * radius + lateral)
        if not same_depth.any():
            break
        ids[at[same_depth]] = owner[same_depth]
    return ids


def _near_the_path(path: cKDTree, ids: np.ndarray, means: np.ndarray, camera: Camera, radius: float) -> np.ndarray:
    """The Gaussians `ids` of the path's pixels (their centres in the tree `path`) in order, one
    visit each, leaving out those whose centre projects more than R (3 px at least) from every pixel
    of the path: a big Gaussian of what the part touches (the guitar body at a stand's foot, the
    icing under a sprinkle) can own a pixel at the part's edge while its centre lies to the side,
    and would hook the rod's end towards it. A big Gaussian of the part itself (a flat stand leg is
    drawn by a few) has its centre on the path, though far along it from where the path first met
    it. Where that keeps fewer than half the Gaussians within 2 R (a part of few Gaussians, a
    sprinkle seen edge-on), those are kept. None farther is ever kept: over one sprinkle a faint
    icing Gaussian 13 R long owned 101 of the path's 119 pixels, its centre 400 px off, and the rod
    ran there (docs/real_captures.md, "Sprinkles from their colour"); too few left makes the rod too
    short, a clear error."""
    _, first = np.unique(ids, return_index=True)
    ids = ids[np.sort(first)]  # first visit of each Gaussian, in path order
    off_path, radius_px = _far_off(path, ids, means, camera, radius)
    near, wide = (
        off_path <= np.maximum(_NEAR_PIXEL_PX, k * radius_px) for k in (_NEAR_PIXEL_RADII, _NEAR_PIXEL_RADII_WIDE)
    )
    if near.sum() < max(3, 0.5 * wide.sum()):
        near = wide
    return ids[near]


def _normals_on_screen(line: np.ndarray) -> np.ndarray:
    """(M, 2) unit normals of a polyline on screen (M, 2), across its local direction."""
    direction = np.gradient(line, axis=0)
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    return normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)


def _depth_gap(radius: float, depth: np.ndarray, focal: float) -> np.ndarray:
    """The depth gap between surfaces at camera `depth`: 3 R, but at least `_GAP_FLOOR_PX` pixels'
    world size there (as the search's, `depth_gap` in rust/sketchrodgs-path/src/lib.rs)."""
    return np.maximum(3 * radius, _GAP_FLOOR_PX * depth / focal)


def _outlined_scale(
    points: np.ndarray, camera: Camera, partial: PartialRender, radius: float, stroke: np.ndarray, band_px: float
) -> np.ndarray:
    """Per point (M, 3) on the part's surface, how far its recentring may reach, as a share of the
    usual: the part's visible half-width there over R, where it is outlined by background on both
    sides (the walks across the points' direction on screen end on a pixel that shows nothing
    within the first reach, 2.2 R, without a depth step on the way), at least OUTLINED_FLOOR; else
    1. A part thinner than R there (a tapering finger whose R is its thicker arm's) then does not
    take in what lies beside it (docs/extraction.md, "Polyline, segmentation, binding", Outlined
    thinner than R)."""
    result, m = partial.result, len(points)
    scale = np.ones(m)
    if m < 3 or result.index_depth is None:
        return scale
    solid, depth = result.is_solid(), result.index_depth
    height, width = solid.shape
    uv, z = camera.project(points)
    normal = _normals_on_screen(uv)
    px = radius * camera.fx / np.maximum(z, 1e-12)  # R on screen at each point
    reach_px = pl.REACHES[0] * px
    steps = np.arange(1, int(np.ceil(min(reach_px.max(), max(width, height)))) + 1)
    start = np.rint(uv).astype(np.int64)
    inside = (start >= 0).all(axis=1) & (start[:, 0] < width) & (start[:, 1] < height)
    at = np.clip(start, 0, [width - 1, height - 1])
    seen = inside & solid[at[:, 1], at[:, 0]]
    start_depth = depth[at[:, 1], at[:, 0]]
    gap = _depth_gap(radius, start_depth, camera.fx)
    # both walks of every point at once: (2, M, steps, 2) pixels, one side each
    sides = np.array([1.0, -1.0])[:, None, None, None]
    walk = np.rint(uv[None, :, None, :] + sides * steps[None, None, :, None] * normal[None, :, None, :]).astype(
        np.int64
    )
    known = (walk >= 0).all(axis=3) & (walk[..., 0] < width) & (walk[..., 1] < height)
    col, row = np.clip(walk[..., 0], 0, width - 1), np.clip(walk[..., 1], 0, height - 1)
    # Only the stroke's band is known alike to a render of the band and to one of the whole view:
    # a pixel within `band_px` of the stroke lies in a band tile (`band_tiles`), and a walk's k-th
    # pixel lies within k + 1/2 of its start (a pixel more for the float32 distance)
    _, _, off_stroke = _core.nearest_on_polyline(pl.in_plane(stroke), pl.in_plane(uv), band_px)  # inf: further
    room = band_px - off_stroke - 1.5
    known &= steps[None, None, :] <= room[None, :, None]
    shows = solid[row, col]
    stepped = shows & (np.abs(depth[row, col] - start_depth[None, :, None]) > gap[None, :, None])
    within = steps[None, None, :] <= reach_px[None, :, None]
    # the first step that ends a walk: nothing shown (outlined), a depth step, or not known
    ends = ~known | ~shows | stepped | ~within
    first = np.argmax(ends, axis=2)[..., None]
    outlined = ends.any(axis=2) & np.take_along_axis(known & ~shows & within, first, axis=2)[..., 0]
    half = np.where(outlined, steps[first[..., 0]] - 0.5, np.nan)
    both = seen & np.isfinite(half[0]) & np.isfinite(half[1])
    scale[both] = np.clip((half[0][both] + half[1][both]) / 2 / px[both], OUTLINED_FLOOR, 1.0)
    # one walk across a gap in the part, or past its tip, is one point: the median of five
    return median_filter(scale, size=5, mode="nearest")


def _of_the_part(ids: np.ndarray, scene: GaussianScene, colours: tuple | None) -> np.ndarray:
    """The Gaussians `ids` less those of the colour of the surface the part lies on, where the trace
    found one (`Trace.colours`: the part's colour and the surface's). The path keeps to the part's
    pixels, but a large surface Gaussian can own some at its edge; and the recentring's cross-sections
    reach over the surface around the part. All are kept where fewer than 2 would be left."""
    if colours is None or len(ids) == 0:
        return ids
    keep = _part_coloured(scene.colors_of(ids), colours)
    return ids[keep] if keep.sum() >= 2 else ids


def _surface_coloured(rgb: np.ndarray, colours: tuple) -> np.ndarray:
    """Per row of `rgb` (K, 3): whether it is nearer the surface's colour than the part's
    (`Trace.colours`) both in RGB and in hue (each colour over the sum of its channels, 0.1 at
    least, as `width::chroma` in Rust). A part's shaded side is darker, not of another hue: the
    right cradle hook's in az300 lies nearer the dark floor's colour than its own lit grey
    (docs/extraction.md, "A part lying on a surface", Up to a depth step)."""
    hue = [c / np.maximum(c.sum(axis=-1, keepdims=True), 0.1) for c in (rgb, *np.asarray(colours, np.float32))]
    return ~_part_coloured(rgb, colours) & ~_part_coloured(hue[0], (hue[1], hue[2]))


def _part_coloured(rgb: np.ndarray, colours: tuple) -> np.ndarray:
    """Per row of `rgb` (K, 3): whether it is at least as near the part's colour as the surface's
    (`Trace.colours`; as `SurfaceColours::is_surround` in search.rs, negated)."""
    part, surround = (np.asarray(c, np.float32) for c in colours)
    return np.linalg.norm(rgb - part, axis=1) <= np.linalg.norm(rgb - surround, axis=1)


def _forward_only(ids: np.ndarray, means: np.ndarray, camera: Camera, stroke: np.ndarray, radius: float) -> np.ndarray:
    """The path's Gaussians less those that go back along the cleaned stroke: where the path
    doubles back (around a node, at a junction), its Gaussians in visiting order would fold the rod
    onto itself (`_core.forward_along_stroke`)."""
    uv, _, radius_px = _on_screen(camera, means[ids], radius)
    keep = _core.forward_along_stroke(
        np.ascontiguousarray(uv, np.float32), np.ascontiguousarray(radius_px, np.float32), stroke
    )
    return ids[keep]


def _search_inputs(
    render: RenderResult, stroke: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """The arrays the Rust search takes: index, index depth, opacity (1 where the render is solid,
    alpha >= 0.5: all the search asks of alpha), and the stroke in the canonical direction with
    whether it was flipped.
    The search always starts at the stroke end that comes first in (x, y) order, so the result
    does not depend on the direction the stroke was drawn."""
    index = np.ascontiguousarray(render.index_image, np.int32)
    depth = np.ascontiguousarray(render.index_depth_image, np.float32)
    opacity = np.ascontiguousarray(render.is_solid(), np.float32)
    flip = _flipped(stroke)
    work = np.ascontiguousarray(stroke[::-1] if flip else stroke, np.float32)
    return index, depth, opacity, work, flip


def _check_vertex_count(name: str, length: float, spacing: float, value: float, most: int) -> None:
    """Refuse a spacing that would sample the object's `length` into more than `most` points."""
    with np.errstate(over="ignore", divide="ignore"):
        count = np.float64(length) / np.float64(spacing) + 1
    if not count <= most:
        shown = f"{count:,.0f}" if count < 1e12 else f"{count:.3g}"
        raise SketchRodGSError(
            f"{name}: {value:g} would make {shown} vertices along the object ({length:.3g} long); "
            f"at most {most:,}: give a larger {name}"
        )


def _flipped(stroke: np.ndarray) -> bool:
    """Whether the search runs the stroke backwards (it starts at the end first in (x, y) order)."""
    return bool((stroke[-1, 0], stroke[-1, 1]) < (stroke[0, 0], stroke[0, 1]))


def _failure(
    message: str, stroke: np.ndarray, pixel_path: list[np.ndarray], pieces: list[_core.TracePiece] | None = None
) -> PathNotFoundError:
    """A PathNotFoundError that carries what was found, so that callers can draw it: `stroke`,
    `pixel_path` (pieces of (P, 2) col, row) and `lost_at` ((col, row) where the path stopped)."""
    error = PathNotFoundError(message)
    error.stroke = stroke
    error.pixel_path = pixel_path
    lost = [p.lost_pixel for p in pieces or [] if p.lost_pixel is not None]
    error.lost_at = lost
    return error


def _check_render_size(render: RenderResult, camera: Camera) -> None:
    if render.index_image.shape != (camera.height, camera.width):
        raise SketchRodGSError(
            f"render: index image is {render.index_image.shape}, camera is {camera.height}x{camera.width}"
        )


def _check_stroke(stroke: np.ndarray) -> np.ndarray:
    try:
        points = np.asarray(stroke, dtype=np.float64)
    except (TypeError, ValueError):
        raise SketchRodGSError("stroke: expected an (S, 2) array of pixel coordinates") from None
    if points.ndim != 2 or points.shape[1] != 2:
        raise SketchRodGSError(f"stroke: expected shape (S, 2), got {points.shape}")
    if len(points) < 2:
        raise SketchRodGSError(f"stroke: needs at least 2 points, got {len(points)}")
    if not np.isfinite(points).all():
        bad = int(np.argmax(~np.isfinite(points).all(axis=1)))
        raise SketchRodGSError(f"stroke: point {bad} is not finite")
    # the path search reads float32 pixels (a point at 1e300 became infinite there)
    beyond = (np.abs(points) > np.finfo(np.float32).max).any(axis=1)
    if beyond.any():
        bad = int(np.argmax(beyond))
        raise SketchRodGSError(
            f"stroke: point {bad} ({points[bad, 0]:g}, {points[bad, 1]:g}) is beyond float32's range"
        )
    return np.ascontiguousarray(points, np.float32)


def estimate_radius(render: RenderResult, camera: Camera, stroke: np.ndarray, band_px: float | None = None) -> float:
    """R from the object's visible width under `stroke` (docs/extraction.md, "Radius"): half the
    width of the surface across the stroke, where it stays solid (alpha >= 0.5) and its depth does
    not jump, in world units at its depth; the median over the stroke's samples on the object. A
    view of another width is measured scaled to `WORKING_WIDTH`, as `extract_rod` traces it.
    Without the scene it has no colours, which `extract_rod`'s estimate also uses: a part lying on
    a surface at its own depth, and a flat bar whose faces step in depth, measure as they look in
    depth alone (docs/extraction.md, "Radius", A flat bar's faces)."""
    stroke = _check_stroke(stroke)
    _check_render_size(render, camera)
    view = WorkingView.of(camera)
    index, depth, opacity, work, _ = _search_inputs(view.render_to_work(render), view.points_to_work(stroke))
    band = float(band_px or 0.0) * view.scale[0]
    try:
        return float(_core.estimate_radius(index, depth, opacity, work, float(view.work.fx), band)[0])
    except PathNotFoundError as err:
        raise view.failure_to_user(err, stroke) from None
