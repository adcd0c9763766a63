"""What every browser is sent: the scene drawn at rest, and per rod its splats, polyline, handles
and bound-Gaussian dots.

The scene node tree (each tab shows or hides the `/overlay`, `/overlay/bound` and `/play`
branches for itself, see `tabs.py`):

    /scene/<chunk>                  the Gaussians of no rod, in spatial chunks (`scene_chunks.py`)
    /rods/<id>/...                  a rod's Gaussians (below)
    /overlay/rod_<id>/polyline      the rod's axis (Sketch and Play)
    /overlay/bound/rod_<id>         dots on its Gaussians, the tint showing what is bound
    /play/rod_<id>/handles          a ball per grabbable vertex (Play)

viser merges every splat node into one buffer on the client and rebuilds it whenever any node's
Gaussians change, so per-frame updates of a rod's Gaussians cost the browser work in proportion to
the whole scene. Two ways to move a rod's Gaussians each frame:

- "exact": one splat node per rod whose buffer is re-sent every frame (what `set_gaussians` sends,
  packed here without its (N, 3, 3) detour), skinned exactly as the exports are: 32 bytes a
  Gaussian a frame, and the browser re-merges the whole scene each time.
- "segments": one splat node per rod segment, holding the segment's Gaussians in its rest frame;
  a frame only moves the nodes (a pose per segment: about 2 kB a frame with the handles and the
  polyline; no re-merge). Gaussians follow their segment rigidly instead of the blend of its two
  vertex frames, a small difference at the joints of a strongly bent rod.

benches/bench_viewer.py measures both.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import viser

from ..camera import Camera
from ..images import POLYLINE_COLOUR, SEGMENT_COLOUR
from ..scene import GaussianScene
from ..skin import matrices_to_quats
from .rods import RodEntry, RodSet
from .scene_chunks import SceneChunks
from .splats import SplatArrays, SplatPacker, covariance_triu, splat_unit

SplatUpdate = Literal["exact", "segments"]
SPLAT_UPDATES = ("exact", "segments")
# Handles are thin: a ball of half the rod's radius lets the rod's Gaussians show around it, kept
# between HANDLE_PIXELS (to be grabbed) in the view of the last tab that entered Play or moved
# there (or entered Sketch while no tab played).
HANDLE_RADII = 0.5
HANDLE_PIXELS = (4.0, 9.0)
# The splats hide what lies inside the part (viser draws them over meshes nearer the axis), so the
# balls and the rod's line sit this many R in front of the axis towards that tab's camera (a ball
# also by its own radius): on the part as seen, in front of its surface Gaussians, whose visible
# half-width is R and whose footprint reaches about 1.5 R.
SHOWN_LIFT_RADII = 1.5
HANDLE_GAP = 3.0  # handle radii between the balls shown (a vertex closer to the last one has none)
HANDLE_OPACITY = 0.8
HANDLE_COLOUR = (90, 200, 255)
CLAMPED_COLOUR = (150, 150, 150)
PINNED_COLOUR = (170, 90, 230)
GRABBED_COLOUR = (255, 140, 0)
MAX_DOTS = 1500  # bound-Gaussian dots per rod (a tint, not a census: 9 bytes a dot a moving frame)
DOT_RADII = 0.2  # dot size in rod radii

POSE_TOLERANCE = 1e-7  # relative to the rod's length (and radians): smaller pose changes are not sent
HandleEvent = Callable[[int, int, Any], Any]  # (rod id, vertex, viser event) -> None or a coroutine


def _icosphere() -> tuple[np.ndarray, np.ndarray]:
    import trimesh  # a viser dependency

    mesh = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint32)


def polyline_segments(points: np.ndarray) -> np.ndarray:
    """(M, 3) polyline -> (M-1, 2, 3) float32 line segments."""
    p = np.asarray(points, np.float32)
    return np.ascontiguousarray(np.stack([p[:-1], p[1:]], axis=1))


def handle_radii(rest: np.ndarray, radius: float, camera: Camera | None) -> tuple[np.ndarray, np.ndarray]:
    """Which vertices of a rod get a handle, and how large: ((H,) vertices, (H,) float32 radii).

    `HANDLE_RADII` R, kept within `HANDLE_PIXELS` in `camera`'s view; a vertex closer than
    `HANDLE_GAP` radii to the last one with a handle has none, except the ends (which show how the
    rod is held), so that the balls do not hide the rod."""
    rest = np.asarray(rest, np.float64)
    radii = np.full(len(rest), HANDLE_RADII * radius)
    if camera is not None:
        depth = np.maximum(camera.project(rest)[1], 1e-9)
        pixel = depth / camera.fy  # world size of one pixel at each vertex
        radii = np.clip(radii, HANDLE_PIXELS[0] * pixel, HANDLE_PIXELS[1] * pixel)
    shown = [0]
    for v in range(1, len(rest)):
        if np.linalg.norm(rest[v] - rest[shown[-1]]) >= HANDLE_GAP * max(radii[v], radii[shown[-1]]):
            shown.append(v)
        elif v == len(rest) - 1 and len(shown) > 1:
            shown[-1] = v  # the end keeps its handle; the interior vertex crowding it gives it up
        elif v == len(rest) - 1:
            shown.append(v)
    vertices = np.array(shown, np.int64)
    return vertices, radii[vertices].astype(np.float32)


def towards_camera(points: np.ndarray, lift: np.ndarray | float, camera: Camera | None) -> np.ndarray:
    """`points` (N, 3) moved `lift` (scalar or (N,)) along their rays towards `camera`'s centre
    (at most half way there): they draw where they were, in front of what surrounds them. Without a
    camera they stay."""
    points = np.asarray(points, np.float64)
    if camera is None or len(points) == 0:
        return points.astype(np.float32)
    ray = camera.center[None, :] - points
    distance = np.maximum(np.linalg.norm(ray, axis=1), 1e-12)
    step = np.minimum(np.broadcast_to(np.asarray(lift, np.float64), distance.shape), 0.5 * distance)
    return (points + ray * (step / distance)[:, None]).astype(np.float32)


@dataclass
class RodNodes:
    """The scene nodes of one rod."""

    splats: list[Any]
    segments: list[int]  # for "segments": the rod segment of each splat node
    packer: SplatPacker
    sent_poses: np.ndarray  # for "segments": (S, 7) wxyz + position last sent per node
    polyline: Any
    handles: Any
    dots: Any
    dot_rows: np.ndarray  # rows of the rod's binding the dots sit on
    dot_centre: np.ndarray  # (3,) the dots node's position (the dots are sent relative to it)
    handle_vertices: np.ndarray  # the vertex of each handle
    handle_radii: np.ndarray
    colours: np.ndarray = field(default_factory=lambda: np.empty((0, 3), np.uint8))
    dots_stale: bool = False


class SceneDisplay:
    """The scene nodes of a viewer session (shared by every browser).

    Args:
        server: the viser server.
        scene: the scene at rest.
        update: how rods' Gaussians move each frame ("exact" or "segments", see the module).
        on_handle_drag: called with (rod id, vertex, event) when a rod's handle is dragged.
        on_handle_click: called with (rod id, vertex, event) when a rod's handle is clicked.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        scene: GaussianScene,
        update: SplatUpdate,
        on_handle_drag: HandleEvent,
        on_handle_click: HandleEvent | None = None,
    ) -> None:
        if update not in SPLAT_UPDATES:
            raise ValueError(f"splat update: expected one of {SPLAT_UPDATES}, got {update!r}")
        self.server = server
        self.splats = SplatArrays.from_scene(scene)
        self.unit = splat_unit(scene.scales)  # every splat node has this scale (see splats.py)
        self.update = update
        self.chunks = SceneChunks(server, self.unit)
        self._on_handle_drag = on_handle_drag
        self._on_handle_click = on_handle_click
        self._rods: dict[int, RodNodes] = {}
        self._sphere = _icosphere()
        self._handle_camera: Camera | None = None
        self.dots_wanted = True  # some tab shows the dots: keep them moving with the rods
        self.sent_gaussians = 0  # Gaussians sent by the last `sync` (chunks and new rods)

    # ----- the scene and its rods -----

    def sync(self, rods: RodSet) -> int:
        """Make the nodes match `rods` (call with `rods.lock` held, after adding or removing rods):
        the chunks whose rows changed, and the nodes of rods added or removed. Returns the number
        of Gaussians sent."""
        with self.server.atomic():
            self.splats = self.splats.updated(rods.scene, changed := rods.take_changed_rows())
            sent = self.chunks.update(self.splats, rods.static_rows(), changed)
            current = {entry.id: entry for entry in rods.entries}
            for rod_id in [r for r in self._rods if r not in current]:
                self._remove_rod(rod_id)
            for rod_id, entry in current.items():
                if rod_id not in self._rods:
                    self._add_rod(entry)
                    sent += len(entry.gaussian_ids)
        self.sent_gaussians = sent
        return sent

    def rod_ids(self) -> list[int]:
        return list(self._rods)

    def _add_rod(self, entry: RodEntry) -> None:
        """Create the nodes of a rod (at rest)."""
        ids = entry.gaussian_ids
        splats, segments = [], []
        base = f"/rods/{entry.id}"
        part = self.splats.subset(ids)
        rest = np.asarray(entry.rod.rest_positions, np.float64)
        if self.update == "exact":
            local = part.in_unit(self.unit)
            splats.append(
                self.server.scene.add_gaussian_splats(
                    f"{base}/splats", local.centers, local.covariances, local.rgbs, local.opacities, scale=self.unit
                )
            )
        else:
            for j in np.unique(entry.bound.segment):
                # each node holds its Gaussians relative to the segment's first vertex at rest
                piece = part.subset(np.flatnonzero(entry.bound.segment == j)).in_unit(self.unit, rest[j])
                splats.append(
                    self.server.scene.add_gaussian_splats(
                        f"{base}/segment_{j}",
                        piece.centers,
                        piece.covariances,
                        piece.rgbs,
                        piece.opacities,
                        scale=self.unit,
                        position=rest[j],
                    )
                )
                segments.append(int(j))
        positions = np.asarray(entry.rod.positions, np.float32)
        polyline = self.server.scene.add_line_segments(
            f"/overlay/rod_{entry.id}/polyline",
            polyline_segments(self._shown_line(entry, positions)),
            POLYLINE_COLOUR,
            thickness=2.0,
            thickness_units="screen",
        )
        dot_rows = np.arange(len(ids))[:: max(1, -(-len(ids) // MAX_DOTS))]
        centre = rest.mean(axis=0)
        dots = self.server.scene.add_point_cloud(
            f"/overlay/bound/rod_{entry.id}",
            (part.centers[dot_rows] - centre).astype(np.float16),
            SEGMENT_COLOUR,
            point_size=max(DOT_RADII * entry.extraction.radius, 1e-6),
            point_shape="circle",
            position=centre,
        )
        vertices, radii = handle_radii(rest, entry.extraction.radius, self._handle_camera)
        colours = self._handle_colours(entry, None)
        handles = self._add_handles(
            entry.id, self._ball_centres(entry, positions, vertices, radii), vertices, radii, colours
        )
        poses = np.zeros((len(segments), 7))
        poses[:, 0] = 1.0
        poses[:, 4:] = rest[segments]
        packer = SplatPacker(part.rgbs, part.opacities)
        self._rods[entry.id] = RodNodes(
            splats, segments, packer, poses, polyline, handles, dots, dot_rows, centre, vertices, radii, colours
        )

    def _shown_line(self, entry: RodEntry, positions: np.ndarray) -> np.ndarray:
        """The rod's vertices where its line is drawn: in front of its axis (`SHOWN_LIFT_RADII`)."""
        return towards_camera(positions, SHOWN_LIFT_RADII * entry.extraction.radius, self._handle_camera)

    def _ball_centres(
        self, entry: RodEntry, positions: np.ndarray, vertices: np.ndarray, radii: np.ndarray
    ) -> np.ndarray:
        """Where the balls of `vertices` (radii `radii`) are drawn: in front of the axis by
        `SHOWN_LIFT_RADII` R and their own radius."""
        lift = SHOWN_LIFT_RADII * entry.extraction.radius + np.asarray(radii, np.float64)
        return towards_camera(positions[vertices], lift, self._handle_camera)

    def _add_handles(
        self, rod_id: int, centres: np.ndarray, vertices: np.ndarray, radii: np.ndarray, colours: np.ndarray
    ) -> Any:
        mesh_vertices, faces = self._sphere
        handles = self.server.scene.add_batched_meshes_simple(
            f"/play/rod_{rod_id}/handles",
            mesh_vertices,
            faces,
            batched_wxyzs=np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (len(vertices), 1)),
            batched_positions=centres,
            batched_scales=radii,
            batched_colors=colours[vertices],
            batched_opacities=np.full(len(vertices), HANDLE_OPACITY, np.float32),
            opacity=1.0,
            cast_shadow=False,
            receive_shadow=False,
        )

        def forward(callback: HandleEvent) -> Callable[[Any], Any]:
            async def call(event: Any) -> None:
                if event.instance_index is None:
                    return
                result = callback(rod_id, int(vertices[event.instance_index]), event)
                if hasattr(result, "__await__"):
                    await result

            return call

        handles.on_drag("left")(forward(self._on_handle_drag))
        if self._on_handle_click is not None:
            handles.on_click(forward(self._on_handle_click))
        return handles

    def _remove_rod(self, rod_id: int) -> None:
        nodes = self._rods.pop(rod_id)
        for node in [*nodes.splats, nodes.polyline, nodes.dots, nodes.handles]:
            node.remove()

    # ----- handles -----

    def size_handles(self, rods: RodSet, camera: Camera) -> None:
        """Size the handles for `camera`'s view (see `handle_radii`), and place them and the rods'
        lines in front of the axes for it (`towards_camera`; call with `rods.lock` held)."""
        self._handle_camera = camera
        for entry in rods.entries:
            nodes = self._rods.get(entry.id)
            if nodes is None:
                continue
            vertices, radii = handle_radii(entry.rod.rest_positions, entry.extraction.radius, camera)
            positions = np.asarray(entry.rod.positions, np.float64)
            nodes.polyline.points = polyline_segments(self._shown_line(entry, positions))  # lifted for this view
            if np.array_equal(vertices, nodes.handle_vertices):
                if not np.allclose(radii, nodes.handle_radii, rtol=0.05, atol=0.0):
                    nodes.handles.batched_scales = radii
                    nodes.handle_radii = radii
                nodes.handles.batched_positions = self._ball_centres(entry, positions, vertices, nodes.handle_radii)
                continue
            nodes.handles.remove()  # another number of balls: a new node
            centres = self._ball_centres(entry, positions, vertices, radii)
            nodes.handles = self._add_handles(entry.id, centres, vertices, radii, nodes.colours)
            nodes.handle_vertices, nodes.handle_radii = vertices, radii

    def shown_handles(self, rod_id: int) -> np.ndarray:
        """Vertices of rod `rod_id` that have a handle now."""
        return self._rods[rod_id].handle_vertices.copy()

    # ----- each frame -----

    def push(self, rods: RodSet) -> dict[str, float]:
        """Send every rod's current state (call with `rods.lock` held); returns seconds spent."""
        clock = time.perf_counter()
        grabbed = rods.grabbed()
        with self.server.atomic():
            for entry in rods.entries:
                nodes = self._rods.get(entry.id)
                if nodes is None:
                    continue
                positions = np.asarray(entry.rod.positions, np.float32)
                rotations = entry.edge_rotations()
                if self.update == "exact":
                    ids = entry.gaussian_ids
                    unit = np.float32(self.unit)
                    nodes.splats[0].buffer = nodes.packer.pack(
                        rods.means[ids] / unit, covariance_triu(rods.scales[ids] / unit, rods.quats[ids])
                    )
                else:
                    poses = np.concatenate([matrices_to_quats(rotations), positions[:-1].astype(np.float64)], axis=1)[
                        nodes.segments
                    ]
                    # setting a pose costs tens of microseconds in viser: send only the ones that moved
                    moved = np.abs(poses - nodes.sent_poses).max(axis=1) > POSE_TOLERANCE * max(entry.length, 1e-12)
                    for k in np.flatnonzero(moved):
                        nodes.splats[k].wxyz = poses[k, :4]
                        nodes.splats[k].position = poses[k, 4:]
                    nodes.sent_poses[moved] = poses[moved]
                nodes.dots_stale = True
                if self.dots_wanted:
                    self._move_dots(entry, nodes, rods, rotations, positions)
                nodes.polyline.points = polyline_segments(self._shown_line(entry, positions))
                nodes.handles.batched_positions = self._ball_centres(
                    entry, positions, nodes.handle_vertices, nodes.handle_radii
                )
                colours = self._handle_colours(entry, grabbed.get(entry.id))
                if not np.array_equal(colours, nodes.colours):
                    nodes.handles.batched_colors = colours[nodes.handle_vertices]
                    nodes.colours = colours
        return {"push": time.perf_counter() - clock}

    def show_dots(self, rods: RodSet, wanted: bool) -> None:
        """Keep the dots moving with the rods or not (when no tab shows them); brings them up to
        date when they are wanted again."""
        self.dots_wanted = wanted
        if not wanted:
            return
        with rods.lock, self.server.atomic():
            for entry in rods.entries:
                nodes = self._rods.get(entry.id)
                if nodes is not None and nodes.dots_stale:
                    positions = np.asarray(entry.rod.positions, np.float32)
                    self._move_dots(entry, nodes, rods, entry.edge_rotations(), positions)

    def _move_dots(
        self, entry: RodEntry, nodes: RodNodes, rods: RodSet, rotations: np.ndarray, positions: np.ndarray
    ) -> None:
        rows = nodes.dot_rows
        if self.update == "exact":
            means, _, _ = rods.skinned()
            world = means[entry.gaussian_ids[rows]].astype(np.float64)
        else:  # rigidly with their segment, as the splat nodes move
            segment = entry.bound.segment[rows]
            rest = np.asarray(entry.rod.rest_positions, np.float64)
            local = rods.scene.means[entry.gaussian_ids[rows]].astype(np.float64) - rest[segment]
            world = np.einsum("kij,kj->ki", rotations[segment], local) + positions[segment]
        nodes.dots.points = (world - nodes.dot_centre).astype(np.float16)
        nodes.dots_stale = False

    @staticmethod
    def _handle_colours(entry: RodEntry, grabbed: int | None) -> np.ndarray:
        kinds = entry.rod.boundaries
        palette = {"free": HANDLE_COLOUR, "clamped": CLAMPED_COLOUR, "pinned": PINNED_COLOUR}
        colours = np.array([palette.get(k, HANDLE_COLOUR) for k in kinds], np.uint8)
        if grabbed is not None:
            colours[grabbed] = GRABBED_COLOUR
        return colours
