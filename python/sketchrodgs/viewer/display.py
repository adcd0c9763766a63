"""What the browser shows: the scene's splats, and per rod its splats, polyline, handles and
segmented Gaussians; the stroke being drawn.

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

benches/bench_viewer.py measures both. The scene node holds the Gaussians of no rod; it is rebuilt
when a rod is added or removed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import viser

from ..images import POLYLINE_COLOUR, SEGMENT_COLOUR, STROKE_COLOUR
from ..scene import GaussianScene
from ..skin import matrices_to_quats
from .rods import RodEntry, RodSet
from .splats import SplatArrays, SplatPacker, covariance_triu, splat_unit

SplatUpdate = Literal["exact", "segments"]
SPLAT_UPDATES = ("exact", "segments")
HANDLE_SCALE = 1.15  # handle radius in rod radii: poking out of the tube (the splats hide what is inside)
HANDLE_OPACITY = 0.45  # see-through, so the tube stays visible under its handles
HANDLE_COLOUR = (90, 200, 255)
CLAMPED_COLOUR = (150, 150, 150)
GRABBED_COLOUR = (255, 140, 0)
FAILED_STROKE_COLOUR = (230, 40, 40)

POSE_TOLERANCE = 1e-7  # relative to the rod's length (and radians): smaller pose changes are not sent
HandleDrag = Callable[[int, Any], Any]  # (rod id, viser drag event) -> None or a coroutine


def _icosphere() -> tuple[np.ndarray, np.ndarray]:
    import trimesh  # a viser dependency

    mesh = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint32)


def polyline_segments(points: np.ndarray) -> np.ndarray:
    """(M, 3) polyline -> (M-1, 2, 3) float32 line segments."""
    p = np.asarray(points, np.float32)
    return np.ascontiguousarray(np.stack([p[:-1], p[1:]], axis=1))


@dataclass
class RodNodes:
    """The scene nodes of one rod."""

    splats: list[Any]
    segments: list[int]  # for "segments": the rod segment of each splat node
    part: SplatArrays  # the rod's Gaussians at rest
    packer: SplatPacker
    sent_poses: np.ndarray  # for "segments": (S, 7) wxyz + position last sent per node
    polyline: Any
    handles: Any
    segmented: Any
    colours: np.ndarray = field(default_factory=lambda: np.empty((0, 3), np.uint8))


class SceneDisplay:
    """The scene nodes of a viewer session.

    Args:
        server: the viser server.
        scene: the scene at rest.
        update: how rods' Gaussians move each frame ("exact" or "segments", see the module).
        on_handle_drag: called with (rod id, event) when a rod's handle is dragged.
    """

    def __init__(
        self, server: viser.ViserServer, scene: GaussianScene, update: SplatUpdate, on_handle_drag: HandleDrag
    ) -> None:
        if update not in SPLAT_UPDATES:
            raise ValueError(f"splat update: expected one of {SPLAT_UPDATES}, got {update!r}")
        self.server = server
        self.splats = SplatArrays.from_scene(scene)
        self._scene = scene
        self.unit = splat_unit(scene.scales)  # every splat node has this scale (see splats.py)
        self.update = update
        self._on_handle_drag = on_handle_drag
        self._scene_node: Any = None
        self._rods: dict[int, RodNodes] = {}
        self._stroke: Any = None
        self._stroke_failed = False
        self._stroke_lock = threading.Lock()  # the event loop draws it, the extraction worker recolours it
        self._sphere = _icosphere()
        self.show_handles = False
        self.show_segmented = False

    # ----- the scene -----

    def set_scene(self, scene: GaussianScene) -> None:
        """The scene the nodes are made from, when rods change it (split needles are appended)."""
        if scene is not self._scene:
            self.splats = SplatArrays.from_scene(scene)
            self._scene = scene

    def show_scene(self, owned: np.ndarray) -> float:
        """(Re)send the scene node without the Gaussians in `owned`; returns seconds spent."""
        clock = time.perf_counter()
        keep = np.ones(len(self.splats), bool)
        keep[owned] = False
        part = (self.splats if keep.all() else self.splats.subset(np.flatnonzero(keep))).in_unit(self.unit)
        self._scene_node = self.server.scene.add_gaussian_splats(
            "/scene", part.centers, part.covariances, part.rgbs, part.opacities, scale=self.unit
        )
        return time.perf_counter() - clock

    # ----- rods -----

    def add_rod(self, entry: RodEntry) -> None:
        """Create the nodes of a rod (at rest)."""
        ids = entry.gaussian_ids
        splats, segments = [], []
        base = f"/rods/{entry.id}"
        part = self.splats.subset(ids)
        if self.update == "exact":
            local = part.in_unit(self.unit)
            splats.append(
                self.server.scene.add_gaussian_splats(
                    f"{base}/splats", local.centers, local.covariances, local.rgbs, local.opacities, scale=self.unit
                )
            )
        else:
            rest = np.asarray(entry.rod.rest_positions, np.float64)
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
            f"{base}/polyline", polyline_segments(positions), POLYLINE_COLOUR, thickness=3.0, thickness_units="screen"
        )
        count = len(positions)
        colours = self._handle_colours(entry, None)
        vertices, faces = self._sphere
        handles = self.server.scene.add_batched_meshes_simple(
            f"{base}/handles",
            vertices,
            faces,
            batched_wxyzs=np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (count, 1)),
            batched_positions=positions,
            batched_scales=np.full(count, HANDLE_SCALE * entry.extraction.radius, np.float32),
            batched_colors=colours,
            batched_opacities=self._handle_opacities(colours),
            opacity=1.0,
            cast_shadow=False,
            receive_shadow=False,
            visible=self.show_handles,
        )
        rod_id = entry.id

        async def dragged(event: Any) -> None:
            result = self._on_handle_drag(rod_id, event)
            if hasattr(result, "__await__"):
                await result

        handles.on_drag("left")(dragged)
        segmented = self.server.scene.add_point_cloud(
            f"{base}/segmented",
            self.splats.centers[ids],
            SEGMENT_COLOUR,
            point_size=max(entry.extraction.radius * 0.15, 1e-6),
            point_shape="circle",
            visible=self.show_segmented,
        )
        poses = np.zeros((len(segments), 7))
        poses[:, 0] = 1.0
        poses[:, 4:] = np.asarray(entry.rod.rest_positions, np.float64)[segments]
        self._rods[entry.id] = RodNodes(
            splats, segments, part, SplatPacker(part.rgbs, part.opacities), poses, polyline, handles, segmented, colours
        )

    def remove_rod(self, rod_id: int) -> None:
        nodes = self._rods.pop(rod_id, None)
        if nodes is None:
            return
        for node in [*nodes.splats, nodes.polyline, nodes.handles, nodes.segmented]:
            node.remove()

    def rod_ids(self) -> list[int]:
        return list(self._rods)

    def set_visibility(self, handles: bool, segmented: bool) -> None:
        self.show_handles, self.show_segmented = handles, segmented
        for nodes in list(self._rods.values()):  # a rod may be added meanwhile (extraction worker)
            nodes.handles.visible = handles
            nodes.segmented.visible = segmented

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
                if self.update == "exact":
                    ids = entry.gaussian_ids
                    unit = np.float32(self.unit)
                    nodes.splats[0].buffer = nodes.packer.pack(
                        rods.means[ids] / unit, covariance_triu(rods.scales[ids] / unit, rods.quats[ids])
                    )
                else:
                    poses = np.concatenate(
                        [matrices_to_quats(entry.edge_rotations()), np.asarray(entry.rod.positions, np.float64)[:-1]],
                        axis=1,
                    )[nodes.segments]
                    # setting a pose costs tens of microseconds in viser: send only the ones that moved
                    moved = np.abs(poses - nodes.sent_poses).max(axis=1) > POSE_TOLERANCE * max(entry.length, 1e-12)
                    for k in np.flatnonzero(moved):
                        nodes.splats[k].wxyz = poses[k, :4]
                        nodes.splats[k].position = poses[k, 4:]
                    nodes.sent_poses[moved] = poses[moved]
                nodes.polyline.points = polyline_segments(positions)
                nodes.handles.batched_positions = positions
                colours = self._handle_colours(entry, grabbed.get(entry.id))
                if not np.array_equal(colours, nodes.colours):
                    nodes.handles.batched_colors = colours
                    nodes.handles.batched_opacities = self._handle_opacities(colours)
                    nodes.colours = colours
        return {"push": time.perf_counter() - clock}

    @staticmethod
    def _handle_opacities(colours: np.ndarray) -> np.ndarray:
        grabbed = (colours == np.array(GRABBED_COLOUR, np.uint8)).all(axis=1)
        return np.where(grabbed, 0.9, HANDLE_OPACITY).astype(np.float32)

    @staticmethod
    def _handle_colours(entry: RodEntry, grabbed: int | None) -> np.ndarray:
        kinds = entry.rod.boundaries
        colours = np.array([CLAMPED_COLOUR if k != "free" else HANDLE_COLOUR for k in kinds], np.uint8)
        if grabbed is not None:
            colours[grabbed] = GRABBED_COLOUR
        return colours

    # ----- the stroke -----

    def show_stroke(self, points: np.ndarray, failed: bool = False) -> None:
        """Draw the stroke through (S, 3) world points (placed in front of what the camera looks at)."""
        if len(points) < 2:
            return
        segments = polyline_segments(points)
        with self._stroke_lock:
            if self._stroke is None or failed != self._stroke_failed:
                # a new node for a new colour: assigning per-vertex colours to a line node greys it
                # out in viser 1.1, so the colour is only ever given at creation
                if self._stroke is not None:
                    self._stroke.remove()
                self._stroke = self.server.scene.add_line_segments(
                    "/sketch/stroke",
                    segments,
                    FAILED_STROKE_COLOUR if failed else STROKE_COLOUR,
                    thickness=3.0,
                    thickness_units="screen",
                )
                self._stroke_failed = failed
            else:
                self._stroke.points = segments

    def clear_stroke(self) -> None:
        with self._stroke_lock:
            if self._stroke is not None:
                self._stroke.remove()
                self._stroke = None
