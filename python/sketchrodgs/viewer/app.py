"""The interactive viewer: a viser page driven by the CPU pipeline.

Modes (the panel's "Mode" buttons):

- View: orbit, pan, zoom (viser's camera controls).
- Sketch: an invisible box around camera and scene (opacity 0, back faces) catches left drags, so
  a drag draws a stroke instead of orbiting. At the end of the stroke the rod under it is
  extracted from a render of the client's camera at the working width (a worker thread), drawn
  (polyline, segmented Gaussians), and its Gaussians move to their own splat nodes.
- Play: each rod's vertices are draggable handles; dragging one grabs that vertex (its target is
  the pointer on the camera-facing plane through the handle), letting go releases it. A
  simulation thread steps the rods, skins and pushes every frame (`simulation.py`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any, Literal

import numpy as np
import viser

from ..camera import Camera
from ..errors import SketchRodGSError
from ..extract import Extraction
from ..images import save_png
from ..io import save_scene
from ..rod import RodParams
from ..scene import GaussianScene
from .camera import DEFAULT_WORKING_WIDTH, camera_from_viser, viser_view
from .display import SPLAT_UPDATES, SceneDisplay
from .panel import MODES, NO_ROD, Panel
from .rods import RodEntry, RodSet
from .simulation import SimulationLoop
from .sketch import Stroke, extract

logger = logging.getLogger("sketchrodgs")

UP_DIRECTIONS = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}
# Up to this many Gaussians the rods' Gaussians are re-sent exactly every frame; above it they
# move as per-segment nodes, so that the browser need not re-merge a large scene 60 times a
# second (measured in benches/bench_viewer.py).
AUTO_EXACT_LIMIT = 50_000
STATUS_INTERVAL = 0.5  # seconds between timing updates in the panel
SketchUpdate = Literal["auto", "exact", "segments"]


class ViewerApp:
    """A viewer session on one scene; the server runs from construction until `close`.

    Args:
        scene: the scene.
        host: interface to listen on (127.0.0.1: this machine only).
        port: port (viser picks the next free one if taken; see `port`).
        rods: extractions to start with (e.g. from `load_rod`).
        params: rod material (default `RodParams()`; the radius comes from each extraction).
        clamp_ends: clamp both ends of every rod.
        up: the scene's up direction ("+x" ... "-z"); -y for COLMAP-derived captures.
        camera: the view browsers open with (default: the first rod's camera, else framing the scene).
        output_dir: where exports, rod files and screenshots go.
        fps: simulation frames per second.
        splat_update: how rods' Gaussians are sent each frame ("exact", "segments", or "auto":
            exact up to AUTO_EXACT_LIMIT Gaussians).
        working_width: width in pixels of the render a stroke is traced on.
    """

    def __init__(
        self,
        scene: GaussianScene,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        rods: Sequence[Extraction] = (),
        params: RodParams | None = None,
        clamp_ends: bool = True,
        up: str = "-y",
        camera: Camera | None = None,
        output_dir: str | Path = ".",
        fps: float = 60.0,
        splat_update: SketchUpdate = "auto",
        working_width: int = DEFAULT_WORKING_WIDTH,
    ) -> None:
        if up not in UP_DIRECTIONS:
            raise SketchRodGSError(f"up: expected one of {', '.join(UP_DIRECTIONS)}, got {up!r}")
        if splat_update == "auto":
            splat_update = "exact" if len(scene) <= AUTO_EXACT_LIMIT else "segments"
        if splat_update not in SPLAT_UPDATES:
            raise SketchRodGSError(f"splat update: expected auto, exact or segments, got {splat_update!r}")
        if not (math.isfinite(fps) and fps > 0):
            raise SketchRodGSError(f"fps: must be > 0, got {fps}")
        self.scene = scene
        self.up = np.array(UP_DIRECTIONS[up])
        self.output_dir = Path(output_dir)
        self.splat_update = splat_update
        self.mode = "View"
        self.last_extraction: Extraction | None = None
        self.last_error: str | None = None
        self.extractions = 0  # strokes that made a rod
        self._stroke: Stroke | None = None
        self._stroke_depth = 0.0
        self._grab_offsets: dict[int, np.ndarray] = {}
        self._status_lock = threading.Lock()
        self._last_timing_update = 0.0
        self._screenshots = 0
        lo, hi = (scene.means.min(axis=0), scene.means.max(axis=0)) if len(scene) else (np.zeros(3), np.ones(3))
        self._centre = (lo.astype(np.float64) + hi) / 2
        self._extent = max(float(np.linalg.norm(hi - lo)), 1e-6)

        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        try:
            self.server.gui.configure_theme(control_width="medium", show_share_button=False)
            self.server.scene.set_up_direction(tuple(self.up))
            self.server.scene.world_axes.visible = False
            # moving Gaussians by segment poses needs no per-frame skinning (exports skin on demand)
            self.rods = RodSet(scene, params or RodParams(), clamp_ends, skin_each_frame=splat_update == "exact")
            self.display = SceneDisplay(self.server, scene, splat_update, self._on_handle_drag)
            self.display.show_scene(np.empty(0, np.int64))
            self.panel = Panel(self.server.gui, self.rods.params, clamp_ends, working_width)
            self._wire_panel()
            self._box = self.server.scene.add_box(
                "/sketch/surface",
                color=(255, 255, 255),
                dimensions=(1.0, 1.0, 1.0),
                opacity=0.0,
                side="back",
                cast_shadow=False,
                receive_shadow=False,
                visible=False,
            )
            self._box.on_drag("left")(self._on_sketch_drag)
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sketchrodgs-extract")
            for extraction in rods:
                self.add_extraction(extraction)
            self._set_initial_camera(camera or (rods[0].camera if rods else None))
            self.loop = SimulationLoop(self.rods, self.display, fps, on_frame=self._frame_done)
            self.loop.start()
        except BaseException:
            self.server.stop()
            raise
        self._set_status(
            f"{len(scene):,} Gaussians ({self.splat_update} rod updates). Choose Sketch and drag along a slender part."
        )

    # ----- lifetime -----

    @property
    def host(self) -> str:
        return self.server.get_host()

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def close(self) -> None:
        """Stop the simulation, the extraction worker and the server."""
        self.loop.stop()
        self._worker.shutdown(wait=False, cancel_futures=True)
        self.server.stop()

    def __enter__(self) -> ViewerApp:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----- modes -----

    def set_mode(self, mode: str) -> None:
        """Switch to "View", "Sketch" or "Play"."""
        if mode not in MODES:
            raise SketchRodGSError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
        if mode != "Play":
            for rod_id in list(self._grab_offsets):
                self.rods.release(rod_id)
            self._grab_offsets.clear()
        if mode == "Sketch":
            self._place_sketch_box()
        else:
            self.display.clear_stroke()
        self._box.visible = mode == "Sketch"
        self.display.set_visibility(handles=mode == "Play", segmented=mode == "Sketch")
        self.mode = mode
        self.panel.mode_text.content = self.panel.mode_markdown(mode)

    def _place_sketch_box(self) -> None:
        """Size the invisible box to hold the scene and every client's camera, with room to spare."""
        reach = self._extent
        for client in self.server.get_clients().values():
            try:
                reach = max(reach, float(np.linalg.norm(client.camera.position - self._centre)))
            except AssertionError:  # that client has not reported its camera yet
                continue
        self._box.position = tuple(self._centre)
        self._box.dimensions = (20 * reach,) * 3

    # ----- sketch -----

    async def _on_sketch_drag(self, event: Any) -> None:
        # async: drag phases then arrive in order (viser awaits async callbacks on its loop)
        if self.mode != "Sketch":
            return
        if event.phase == "start":
            cam = event.client.camera
            width = int(self.panel.working_width.value)
            self._stroke = Stroke(camera_from_viser(cam.wxyz, cam.position, cam.fov, cam.aspect, width))
            # draw the stroke halfway to the orbit centre: in front of what is looked at (viser washes
            # out lines very close to the camera)
            self._stroke_depth = max(2 * cam.near, 0.5 * float(np.linalg.norm(cam.look_at - cam.position)))
            self._stroke.add(event.start_screen_pos)
        stroke = self._stroke
        if stroke is None:
            return
        stroke.add(event.end_screen_pos)
        self.display.show_stroke(stroke.world_points(self._stroke_depth))
        if event.phase == "end":
            self._stroke = None
            self._worker.submit(self._extract, stroke)

    def _extract(self, stroke: Stroke) -> RodEntry | None:
        clock = time.perf_counter()
        try:
            extraction = extract(self.rods.deformed_scene(), stroke, self.panel.sketch_settings())
            entry = self.add_extraction(extraction)
        except SketchRodGSError as exc:
            self.last_error = str(exc)
            self.display.show_stroke(stroke.world_points(self._stroke_depth), failed=True)
            self._set_status(f"No rod: {exc}")
            return None
        except Exception as exc:  # keep the viewer alive; say what happened
            logger.exception("extraction failed")
            self.last_error = f"{type(exc).__name__}: {exc}"
            self._set_status(f"Extraction failed: {self.last_error}")
            return None
        seconds = time.perf_counter() - clock
        self.last_error = None
        self.last_extraction = extraction
        self.extractions += 1
        self._set_status(
            f"Rod {entry.id}: {len(extraction.polyline)} vertices, {len(entry.gaussian_ids):,} Gaussians, "
            f"R = {extraction.radius:.4g}, stroke covered {100 * extraction.coverage:.0f} %, "
            f"{1e3 * seconds:.0f} ms ({', '.join(f'{k} {1e3 * v:.0f}' for k, v in extraction.timings.items())} ms). "
            "Play to pull it."
        )
        return entry

    def sketch(self, stroke: Stroke) -> Future[RodEntry | None]:
        """Extract the rod under `stroke` as if it had been drawn (on the extraction worker)."""
        return self._worker.submit(self._extract, stroke)

    # ----- rods -----

    def add_extraction(self, extraction: Extraction) -> RodEntry:
        """Add a rod (its Gaussians leave the scene node for the rod's own)."""
        with self.rods.lock:
            entry = self.rods.add(extraction)
            with self.server.atomic():
                self.display.set_scene(self.rods.scene)
                self.display.show_scene(self.rods.off_scene_node())
                self.display.add_rod(entry)
        self._refresh_rod_list(select=entry.id)
        return entry

    def remove_rod(self, rod_id: int) -> None:
        with self.rods.lock:
            self.rods.remove(rod_id)
            self._grab_offsets.pop(rod_id, None)
            with self.server.atomic():
                self.display.set_scene(self.rods.scene)
                self.display.remove_rod(rod_id)
                self.display.show_scene(self.rods.off_scene_node())
        self._refresh_rod_list()

    def remove_all(self) -> None:
        for entry in self.rods.entries:
            self.remove_rod(entry.id)

    def reset(self) -> None:
        """Every rod back to rest."""
        with self.rods.lock:
            self._grab_offsets.clear()
            self.rods.reset()
            self._rebuild_display()

    def _rebuild_display(self) -> None:
        """Every node again, after the rods were rebuilt from the input scene (the rows of split
        needles may have changed). Hold `rods.lock`."""
        with self.server.atomic():
            self.display.set_scene(self.rods.scene)
            for rod_id in self.display.rod_ids():
                self.display.remove_rod(rod_id)
            for entry in self.rods.entries:
                self.display.add_rod(entry)
            self.display.show_scene(self.rods.off_scene_node())
        self.display.push(self.rods)

    def _refresh_rod_list(self, select: int | None = None) -> None:
        names = tuple(f"rod {e.id}" for e in self.rods.entries) or (NO_ROD,)
        self.panel.rod.options = names
        if select is not None:
            self.panel.rod.value = f"rod {select}"  # type: ignore[misc]  # viser's dropdown value is settable
        elif self.panel.rod.value not in names:
            self.panel.rod.value = names[-1]  # type: ignore[misc]

    async def _on_handle_drag(self, rod_id: int, event: Any) -> None:
        vertex = event.instance_index
        if self.mode != "Play" or vertex is None:
            return
        target = np.asarray(event.end_position, np.float64)
        try:
            if event.phase == "start":
                entry = self.rods.get(rod_id)
                if entry.rod.boundaries[vertex] != "free":
                    self._set_status(f"Rod {rod_id}: vertex {vertex} is clamped (untick Clamp ends to move the ends)")
                    return
                # keep the grabbed point where the pointer took it, not the vertex under the pointer
                offset = np.asarray(entry.rod.positions[vertex]) - np.asarray(event.start_position, np.float64)
                self._grab_offsets[rod_id] = offset
                self.rods.grab(rod_id, vertex, target + offset)
            elif rod_id in self._grab_offsets:
                self.rods.move_grab(rod_id, target + self._grab_offsets[rod_id])
                if event.phase == "end":
                    self.rods.release(rod_id)
                    self._grab_offsets.pop(rod_id, None)
        except SketchRodGSError as exc:  # the rod went away mid-drag
            self._grab_offsets.pop(rod_id, None)
            self._set_status(f"Rod {rod_id}: {exc}")

    # ----- exports -----

    def export_ply(self, path: str | Path | None = None) -> Path:
        """Write the deformed scene (exact skinning) as INRIA .ply."""
        target = Path(path) if path is not None else self.output_dir / "deformed.ply"
        target.parent.mkdir(parents=True, exist_ok=True)
        save_scene(self.rods.export_scene(), target)
        return target

    def save_rods(self, directory: str | Path | None = None) -> list[Path]:
        """Write each rod as rod JSON (`rod_<id>.json`, with its material); returns the paths."""
        folder = Path(directory) if directory is not None else self.output_dir
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for entry in self.rods.entries:
            path = folder / f"rod_{entry.id}.json"
            entry.extraction.save(path, material=entry.rod.params.to_dict())
            paths.append(path)
        return paths

    def screenshot(self, client: Any = None, path: str | Path | None = None, timeout: float = 30.0) -> Path:
        """Ask a browser (the first connected when None) for its current view and write it as PNG."""
        if client is None:
            clients = list(self.server.get_clients().values())
            if not clients:
                raise SketchRodGSError("screenshot: no browser is connected")
            client = clients[0]
        height = min(int(client.camera.image_height), 2160)
        width = min(int(client.camera.image_width), 3840)
        image = client.get_render(height=height, width=width, timeout=timeout)
        if path is None:
            self._screenshots += 1
            path = self.output_dir / f"screenshot_{self._screenshots:03d}.png"
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        save_png(target, np.ascontiguousarray(image[..., :3]))
        return target

    # ----- panel -----

    def _wire_panel(self) -> None:
        panel = self.panel

        @panel.mode.on_click
        async def _(event: Any) -> None:
            self.set_mode(event.target.value)

        @panel.auto_radius.on_update
        async def _(event: Any) -> None:
            panel.radius.disabled = bool(panel.auto_radius.value)

        def material_changed(event: Any) -> None:
            with self.rods.lock:
                self._grab_offsets.clear()
                self.rods.set_params(panel.rod_params(-self.up))
                self._rebuild_display()
            self._set_status("Material changed: the rods restarted from rest.")

        for widget in panel.material_inputs():
            widget.on_update(material_changed)

        @panel.clamp_ends.on_update
        def _(event: Any) -> None:
            self.rods.set_clamp_ends(bool(panel.clamp_ends.value))

        @panel.remove_rod.on_click
        def _(event: Any) -> None:
            value = str(panel.rod.value)
            if value != NO_ROD:
                self.remove_rod(int(value.removeprefix("rod ")))

        panel.reset.on_click(lambda event: self.reset())
        panel.remove_all.on_click(lambda event: self.remove_all())

        def exporting(what: str, action: Any) -> Any:
            def run(event: Any) -> None:
                try:
                    result = action(event)
                except (SketchRodGSError, OSError, TimeoutError, RuntimeError) as exc:
                    self._set_status(f"{what} failed: {exc}")
                    return
                self._set_status(f"{what}: {result}")

            return run

        panel.export_ply.on_click(exporting("Deformed scene written", lambda e: self.export_ply()))
        panel.save_rods.on_click(
            exporting("Rods written", lambda e: ", ".join(str(p) for p in self.save_rods()) or "no rods to save")
        )
        panel.screenshot.on_click(exporting("Screenshot written", lambda e: self.screenshot(e.client)))

    def _set_status(self, text: str) -> None:
        with self._status_lock:
            self.panel.status.content = text

    def _frame_done(self, timings: dict[str, float]) -> None:
        now = time.perf_counter()
        if now - self._last_timing_update < STATUS_INTERVAL:
            return
        self._last_timing_update = now
        bound = int(sum(len(e.gaussian_ids) for e in self.rods.entries))
        self.panel.timings.content = (
            f"**Frame** ({bound:,} rod Gaussians, {self.splat_update}, mean of the last "
            f"{min(self.loop.timings.count, 60)}): {self.loop.timings.summary()}"
        )

    # ----- camera -----

    def _set_initial_camera(self, camera: Camera | None) -> None:
        if camera is not None:
            forward = camera.camera_to_world[:3, 2]
            distance = float(np.dot(self._centre - camera.center, forward))
            view = viser_view(camera, distance if distance > 0 else max(self._extent / 2, 1e-3))
            self.server.initial_camera.fov = view.fov_y
        else:
            # look across the scene along an axis perpendicular to up, from 1.2 extents away
            axis = np.array([0.0, 0.0, 1.0]) if abs(self.up[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
            eye = self._centre - 1.2 * max(self._extent, 1e-3) * axis
            view = viser_view(Camera.look_at(eye, self._centre, up=self.up), float(1.2 * max(self._extent, 1e-3)))
        self.server.initial_camera.position = view.position
        self.server.initial_camera.look_at = view.look_at
        self.server.initial_camera.up = view.up
