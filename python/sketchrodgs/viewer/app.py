"""The interactive viewer: a viser page driven by the CPU pipeline.

Each browser tab has its own mode (`tabs.py`): View (orbit, pan, zoom), Sketch (a left drag draws
a stroke; the rod under it is extracted from a render of the tab's camera at the working width, on
a worker thread) and Play (drag a rod's ball to grab that vertex, let go to release it; click a
ball to pin it). A simulation thread steps the rods, skins and pushes every frame
(`simulation.py`). Rod operations (extract, remove, clamps, pins, material) can be undone
(`history.py`); results and errors are notifications on the tab concerned (`feedback.py`); only
pages of allowed origins may connect (`origin.py`).
"""

from __future__ import annotations

import dataclasses
import io
import logging
import math
import threading
import time
import zipfile
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any, Literal

import numpy as np
import viser

from ..camera import Camera
from ..errors import SketchRodGSError
from ..framing import AXES, frame_scene
from ..images import save_png
from ..io import save_scene
from ..rod_file import Extraction
from ..scene import GaussianScene
from .camera import DEFAULT_WORKING_WIDTH, ViserView, framing_view, viser_view
from .contact import SceneContact
from .display import SPLAT_UPDATES, SceneDisplay
from .feedback import Feedback, Kind, Notice, describe_failure
from .history import History, Step
from .material import CLAMPS, Clamp, Material
from .origin import OriginGuard, allowed_origins
from .panel import CAMERA_VIEWS, CLAMP_LABELS, NO_ROD, Panel, clamp_of
from .rods import RodEntry, RodSet
from .simulation import SimulationLoop
from .sketch import Stroke, extract
from .tabs import MODES, Tab, Tabs

logger = logging.getLogger("sketchrodgs")

# Up to this many Gaussians the rods' Gaussians are re-sent exactly every frame; above it they
# move as per-segment nodes, so that the browser need not re-merge a large scene 60 times a
# second (measured in benches/bench_viewer.py).
AUTO_EXACT_LIMIT = 50_000
TIMINGS_INTERVAL = 0.5  # seconds between timing updates in the panel
PRESET_ORBITS = {"Front": (0.0, 0.0), "Side": (90.0, 0.0), "Top": (0.0, 89.0)}  # azimuth, elevation
SketchUpdate = Literal["auto", "exact", "segments"]


class ViewerApp:
    """A viewer session on one scene; the server runs from construction until `close`.

    Args:
        scene: the scene.
        host: interface to listen on (127.0.0.1: this machine only).
        port: port (viser picks the next free one if taken; see `port`).
        rods: extractions to start with (e.g. from `load_rod`).
        material: how the rods swing (default `Material()`: a 0.5 s swing; the radius comes from
            each extraction, and each rod's stiffness from its size and the swing period).
        clamp: how new rods are held: "both" ends, "start", "end" or "none".
        up: the scene's up direction ("+x" ... "-z"); -y for COLMAP-derived captures.
        camera: the view browsers open with (default: the first rod's camera, else framing the scene).
        output_dir: where exports are written (they are also downloaded by the browser).
        fps: simulation frames per second.
        splat_update: how rods' Gaussians are sent each frame ("exact", "segments", or "auto":
            exact up to AUTO_EXACT_LIMIT Gaussians).
        working_width: width in pixels of the render a stroke is traced on.
        allow_origins: origins of pages other than the viewer's own that may connect
            (`origin.py`), e.g. "http://myhost:8080".
        contact: rods keep out of the scene's solid parts and of each other (`contact.py`).
        friction: Coulomb friction of the rods against the scene.
    """

    def __init__(
        self,
        scene: GaussianScene,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        rods: Sequence[Extraction] = (),
        material: Material | None = None,
        clamp: Clamp = "both",
        up: str = "-y",
        camera: Camera | None = None,
        output_dir: str | Path = ".",
        fps: float = 60.0,
        splat_update: SketchUpdate = "auto",
        working_width: int = DEFAULT_WORKING_WIDTH,
        allow_origins: Sequence[str] = (),
        contact: bool = True,
        friction: float = 0.0,
    ) -> None:
        if up not in AXES:
            raise SketchRodGSError(f"up: expected one of {', '.join(AXES)}, got {up!r}")
        if splat_update == "auto":
            splat_update = "exact" if len(scene) <= AUTO_EXACT_LIMIT else "segments"
        if splat_update not in SPLAT_UPDATES:
            raise SketchRodGSError(f"splat update: expected auto, exact or segments, got {splat_update!r}")
        if not (math.isfinite(fps) and fps > 0):
            raise SketchRodGSError(f"fps: must be > 0, got {fps}")
        if clamp not in CLAMPS:
            raise SketchRodGSError(f"clamp: expected one of {', '.join(CLAMPS)}, got {clamp!r}")
        self.scene = scene
        self.up = np.array(AXES[up])
        self.output_dir = Path(output_dir)
        self.splat_update = splat_update
        self.last_extraction: Extraction | None = None
        self.last_error: str | None = None
        self.extractions = 0  # strokes that made a rod
        self._grabs: dict[int, np.ndarray] = {}  # rod id -> offset from the pointer to the grabbed vertex
        self._panel_lock = threading.RLock()
        self._last_timings = 0.0
        self._screenshots = 0
        lo, hi = (scene.means.min(axis=0), scene.means.max(axis=0)) if len(scene) else (np.zeros(3), np.ones(3))
        self._centre = (lo.astype(np.float64) + hi) / 2
        self._extent = max(float(np.linalg.norm(hi - lo)), 1e-6)

        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        try:
            # before anything is in the scene: a page of another origin gets nothing
            self.origins = OriginGuard(self.server, allowed_origins(host, self.server.get_port(), allow_origins))
            gui = self.server.gui
            gui.configure_theme(control_width="small", show_share_button=False)
            gui.main_panel.dock_right()
            self.server.scene.set_up_direction(tuple(self.up))
            self.server.scene.world_axes.visible = False
            for branch in ("/overlay", "/overlay/bound", "/play"):  # each tab shows or hides these
                self.server.scene.add_frame(branch, show_axes=False)
            material = material or Material()
            self.panel = Panel(gui, material, working_width, len(scene))
            self.feedback = Feedback(self.server)
            self.history = History()
            # moving Gaussians by segment poses needs no per-frame skinning (exports skin on demand)
            self.rods = RodSet(scene, material, clamp, skin_each_frame=splat_update == "exact")
            self.contact = SceneContact(self.rods)
            self.display = SceneDisplay(self.server, scene, splat_update, self._on_handle_drag, self._on_handle_click)
            with self.rods.lock:
                self.display.sync(self.rods)  # the scene, sent once
            self.panel.scene_loaded()
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sketchrodgs-extract")
            for extraction in rods:
                self.add_extraction(extraction, record=False)
            self._start_view = self._set_initial_camera(camera or (rods[0].camera if rods else None))
            self._wire_panel()
            self.panel.friction.value = friction  # type: ignore[misc]  # viser's values are settable
            self.set_contact(contact, friction)
            self.tabs = Tabs(self.server, self._make_tab)
            self.loop = SimulationLoop(self.rods, self.display, fps, on_frame=self._frame_done)
            self.loop.start()
        except BaseException:
            self.server.stop()
            raise

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
        self.contact.close()
        self.server.stop()

    def __enter__(self) -> ViewerApp:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----- tabs and modes -----

    def _make_tab(self, client: Any) -> Tab:
        return Tab(
            client,
            self.panel.view_folder,
            (self._centre, self._extent),
            on_change=self._tab_changed,
            on_stroke=self._stroke_drawn,
            on_view=self._size_handles,
            working_width=lambda: int(self.panel.working_width.value),
        )

    def set_mode(self, mode: str, client: Any = None) -> None:
        """Switch `client`'s tab (every tab when None) to "View", "Sketch" or "Play"."""
        if mode not in MODES:
            raise SketchRodGSError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
        for tab in self.tabs.all() if client is None else [t for t in [self.tabs.of(client)] if t]:
            tab.set_mode(mode)

    def mode_of(self, client: Any) -> str | None:
        """The mode of `client`'s tab (None when it is not connected)."""
        tab = self.tabs.of(client)
        return tab.mode if tab is not None else None

    def _tab_changed(self, tab: Tab) -> None:
        if tab.mode != "Play":  # what this tab held is let go
            for rod_id in list(self._grabs):
                self._grabs.pop(rod_id, None)
                self.rods.release(rod_id)
        self.display.show_dots(self.rods, any(t.shows_dots for t in self.tabs.all()))
        # the balls are for a tab in Play; the rod's line shows in Sketch too, so a tab entering
        # Sketch places it for its view while no tab plays
        if tab.mode == "Play" or (tab.mode == "Sketch" and all(t.mode != "Play" for t in self.tabs.all())):
            self._size_handles(tab)

    def _size_handles(self, tab: Tab) -> None:
        camera = tab.camera()
        if camera is not None:
            with self.rods.lock:
                self.display.size_handles(self.rods, camera)

    def act(self, action: str, client: Any = None) -> None:
        """Do what a keyboard shortcut names (`panel.SHORTCUTS`) for `client`'s tab."""
        tab = self.tabs.of(client)
        if action in MODES:
            self.set_mode(action, client)
        elif action == "Undo":
            self.undo(client)
        elif action == "Redo":
            self.redo(client)
        elif action == "Frame":
            self.frame_rod(client)
        elif action == "Start":
            self.show_view("Start", client)
        elif action == "Handles" and tab is not None:
            tab.set_toggles(handles=not tab.show_handles)
        elif action == "Bound" and tab is not None:
            tab.set_toggles(bound=not tab.show_bound)
        elif action == "Reset":
            self.reset()
        elif action == "Remove":
            entry = self.selected_rod()
            if entry is None:
                self.feedback.notify(client, "info", "No rod to remove", "Sketch over a slender part to make one.")
            else:
                self.remove_rod(entry.id, client=client)

    # ----- sketch -----

    def _stroke_drawn(self, tab: Tab, stroke: Stroke) -> None:
        notice = self.feedback.notify(tab.client, "busy", "Extracting the rod…", "Following your stroke in the scene.")
        self._worker.submit(self._extract, stroke, tab, notice)

    def sketch(self, stroke: Stroke) -> Future[RodEntry | None]:
        """Extract the rod under `stroke` as if it had been drawn (on the extraction worker); the
        result is shown on every tab."""
        return self._worker.submit(self._extract, stroke)

    def _extract(self, stroke: Stroke, tab: Tab | None = None, notice: Notice | None = None) -> RodEntry | None:
        clock = time.perf_counter()
        try:
            extraction = extract(self.rods.deformed_scene(), stroke, self.panel.sketch_settings())
            entry = self.add_extraction(extraction)
        except Exception as exc:  # keep the viewer alive; say what happened
            if not isinstance(exc, SketchRodGSError):
                logger.exception("extraction failed")
            self.last_error = describe_failure(exc)
            if tab is not None:
                tab.show_stroke(stroke, failed=True)
            self._say(tab, notice, "error", "No rod", self.last_error)
            return None
        seconds = time.perf_counter() - clock
        self.last_error = None
        self.last_extraction = extraction
        self.extractions += 1
        if tab is not None:
            tab.clear_stroke()
        self._say(
            tab,
            notice,
            "done",
            f"Rod {entry.id}",
            f"{len(entry.gaussian_ids):,} Gaussians follow it ({seconds:.1f} s). Press Play (3) to pull it.",
        )
        logger.info("rod %d extracted in %.0f ms: %s", entry.id, 1e3 * seconds, extraction.timings)
        return entry

    def _say(self, tab: Tab | None, notice: Notice | None, kind: Kind, title: str, body: str) -> None:
        if notice is not None:
            self.feedback.update(notice, kind, title, body)
        else:
            self.feedback.notify(tab.client if tab is not None else None, kind, title, body)

    # ----- rod operations (each can be undone) -----

    def add_extraction(
        self,
        extraction: Extraction,
        rod_id: int | None = None,
        clamp: Clamp | None = None,
        pins: Sequence[int] = (),
        record: bool = True,
    ) -> RodEntry:
        """Add a rod (its Gaussians leave the scene's chunks for the rod's own nodes).

        Raises:
            RodRefused: it repeats a rod, or no Gaussian would follow it.
        """
        with self.rods.lock:
            entry = self.rods.add(extraction, rod_id, clamp, pins)
            self.display.sync(self.rods)
            self.contact.rebuild()
        if record:
            added = entry
            self.history.record(
                Step(
                    f"rod {added.id}",
                    undo=lambda: self.remove_rod(added.id, record=False),
                    redo=lambda: self._put_back(added),
                )
            )
        self._refresh_panel(select=entry.id)
        return entry

    def _put_back(self, entry: RodEntry) -> None:
        self.add_extraction(entry.extraction, entry.id, entry.clamp, sorted(entry.pins), record=False)

    def remove_rod(self, rod_id: int, record: bool = True, client: Any = None) -> RodEntry:
        """Remove a rod: its Gaussians go back to the scene at rest."""
        with self.rods.lock:
            self._grabs.pop(rod_id, None)
            entry = self.rods.remove(rod_id)
            self.display.sync(self.rods)
            self.contact.rebuild()
        if record:
            self.history.record(
                Step(
                    f"removal of rod {rod_id}",
                    undo=lambda: self._put_back(entry),
                    redo=lambda: self.remove_rod(rod_id, record=False),
                )
            )
            self.feedback.notify(client, "info", f"Rod {rod_id} removed", "Undo (Ctrl+Z) brings it back.")
        self._refresh_panel()
        return entry

    def remove_all(self, client: Any = None) -> None:
        with self.rods.lock:
            self._grabs.clear()
            removed = self.rods.clear()
            self.display.sync(self.rods)
            self.contact.rebuild()
        if removed:

            def put_back() -> None:
                for entry in removed:
                    self._put_back(entry)

            def remove_again() -> None:
                for entry in removed:
                    self.remove_rod(entry.id, record=False)

            self.history.record(Step("removal of every rod", undo=put_back, redo=remove_again))
            self.feedback.notify(client, "info", f"{len(removed)} rod(s) removed", "Undo (Ctrl+Z) brings them back.")
        self._refresh_panel()

    def set_material(self, material: Material, record: bool = True) -> None:
        """New material for every rod; they restart from rest."""
        with self.rods.lock:
            before = self.rods.material
            self._grabs.clear()
            self.rods.set_material(material)
        if record:

            def apply(m: Material) -> None:
                self.set_material(m, record=False)
                self.panel.show_material(m)

            self.history.record(
                Step("material change", undo=lambda: apply(before), redo=lambda: apply(material), merge="material")
            )
        self._refresh_panel()

    def set_clamp(self, rod_id: int, clamp: Clamp, record: bool = True) -> None:
        """Hold rod `rod_id` at both ends, one end or none (it restarts from rest)."""
        with self.rods.lock:
            before = self.rods.get(rod_id).clamp
            self._grabs.pop(rod_id, None)
            self.rods.set_clamp(rod_id, clamp)
        if record:
            self.history.record(
                Step(
                    f"rod {rod_id} held at {CLAMP_LABELS[clamp]}",
                    undo=lambda: self.set_clamp(rod_id, before, record=False),
                    redo=lambda: self.set_clamp(rod_id, clamp, record=False),
                )
            )
        self._refresh_panel()

    def set_pinned(self, rod_id: int, vertex: int, pinned: bool, record: bool = True) -> None:
        """Pin a vertex where it is, or free it."""
        with self.rods.lock:
            if self._grabs and self.rods.grabbed().get(rod_id) == vertex:
                self._grabs.pop(rod_id, None)
            self.rods.set_pinned(rod_id, vertex, pinned)
        if record:
            what = "pin" if pinned else "release"
            self.history.record(
                Step(
                    f"{what} of point {vertex} of rod {rod_id}",
                    undo=lambda: self.set_pinned(rod_id, vertex, not pinned, record=False),
                    redo=lambda: self.set_pinned(rod_id, vertex, pinned, record=False),
                )
            )

    def set_contact(self, on: bool, friction: float = 0.0) -> None:
        """Rods keep out of the scene's solid parts and of each other, or pass through."""
        self.rods.set_contact(on, friction)
        self.panel.friction.disabled = not on
        if bool(self.panel.contact.value) != on:
            self.panel.contact.value = on  # type: ignore[misc]  # viser's values are settable

    def reset(self) -> None:
        """Every rod back to rest."""
        with self.rods.lock:
            self._grabs.clear()
            self.rods.reset()

    def undo(self, client: Any = None) -> Step | None:
        """Undo the last rod operation; says what on `client`'s tab (every tab when None)."""
        return self._step(self.history.undo, "Undone", "Nothing to undo", client)

    def redo(self, client: Any = None) -> Step | None:
        return self._step(self.history.redo, "Redone", "Nothing to redo", client)

    def _step(self, action: Any, done: str, nothing: str, client: Any) -> Step | None:
        try:
            step = action()
        except SketchRodGSError as exc:
            self.feedback.notify(client, "error", f"Could not {done.lower()[:-1]}", describe_failure(exc))
            return None
        finally:
            self._refresh_panel()
        if step is None:
            self.feedback.notify(client, "info", nothing)
        else:
            self.feedback.notify(client, "info", f"{done}: {step.label}")
        return step

    # ----- grabbing and pinning -----

    async def _on_handle_drag(self, rod_id: int, vertex: int, event: Any) -> None:
        tab = self.tabs.of(event.client)
        if tab is None or tab.mode != "Play":
            return
        target = np.asarray(event.end_position, np.float64)
        try:
            if event.phase == "start":
                entry = self.rods.get(rod_id)
                kind = entry.rod.boundaries[vertex]
                if kind != "free":
                    self.feedback.notify(event.client, "info", *self._held_message(kind))
                    return
                # keep the grabbed point where the pointer took it, not the vertex under the pointer
                offset = np.asarray(entry.rod.positions[vertex]) - np.asarray(event.start_position, np.float64)
                self._grabs[rod_id] = offset
                self.rods.grab(rod_id, vertex, target + offset)
            elif rod_id in self._grabs:
                self.rods.move_grab(rod_id, target + self._grabs[rod_id])
                if event.phase == "end":
                    self.rods.release(rod_id)
                    self._grabs.pop(rod_id, None)
        except SketchRodGSError as exc:  # the rod went away mid-drag
            self._grabs.pop(rod_id, None)
            self.feedback.notify(event.client, "error", f"Rod {rod_id}", describe_failure(exc))

    @staticmethod
    def _held_message(kind: str) -> tuple[str, str]:
        if kind == "clamped":
            return "This end is held", "Choose another 'Held at' under Rods to move it."
        return "This point is pinned", "Click it to free it."

    async def _on_handle_click(self, rod_id: int, vertex: int, event: Any) -> None:
        tab = self.tabs.of(event.client)
        if tab is None or tab.mode != "Play":
            return
        try:
            kind = self.rods.get(rod_id).rod.boundaries[vertex]
            if kind == "clamped":
                self.feedback.notify(event.client, "info", *self._held_message(kind))
                return
            self.set_pinned(rod_id, vertex, kind == "free")
        except SketchRodGSError as exc:
            self.feedback.notify(event.client, "error", f"Rod {rod_id}", describe_failure(exc))
            return
        if kind == "free":
            self.feedback.notify(
                event.client, "info", "Pinned", "That point stays where it is; click it again to free it."
            )
        else:
            self.feedback.notify(event.client, "info", "Freed", "That point moves again.")

    # ----- camera -----

    def frame_rod(self, client: Any, rod_id: int | None = None) -> None:
        """Turn `client`'s view to show the rod (the selected one when None) whole."""
        tab = self.tabs.of(client)
        entry = self.selected_rod() if rod_id is None else self.rods.get(rod_id)
        if entry is None:
            self.feedback.notify(client, "info", "No rod to frame", "Sketch over a slender part to make one.")
            return
        camera = tab.camera() if tab is not None else None
        if camera is None:
            return
        view = framing_view(np.asarray(entry.rod.positions), entry.extraction.radius, camera, self.up)
        self._look(client, view)

    def show_view(self, name: str, client: Any) -> None:
        """Show `client` the view the page opened with ("Start"), or the scene from the "Front",
        "Side" or "Top"."""
        if name not in CAMERA_VIEWS:
            raise SketchRodGSError(f"view: expected one of {', '.join(CAMERA_VIEWS)}, got {name!r}")
        if name == "Start":
            self._look(client, self._start_view)
            return
        tab = self.tabs.of(client)
        camera = tab.camera() if tab is not None else None
        if camera is None:
            return
        framed = frame_scene(
            self.scene,
            self.up,
            PRESET_ORBITS[name],
            width=camera.width,
            height=camera.height,
            fov_y_deg=camera.fov_y_deg,
        )
        # it looks at the middle of the scene without its floaters: orbit about a point on that line
        forward = framed.camera_to_world[:3, 2]
        distance = float(np.dot(self._centre - framed.center, forward))
        self._look(client, viser_view(framed, distance if distance > 0 else self._extent))

    def _look(self, client: Any, view: ViserView) -> None:
        if client is None:
            return
        with client.atomic():
            client.camera.fov = view.fov_y
            client.camera.up_direction = view.up
            client.camera.look_at = view.look_at
            client.camera.position = view.position

    def _set_initial_camera(self, camera: Camera | None) -> ViserView:
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
            view = dataclasses.replace(view, fov_y=float(self.server.initial_camera.fov))
        self.server.initial_camera.position = view.position
        self.server.initial_camera.look_at = view.look_at
        self.server.initial_camera.up = view.up
        return view

    # ----- exports -----

    def export_ply(self, path: str | Path | None = None) -> Path:
        """Write the deformed scene (exact skinning) as INRIA .ply."""
        target = Path(path) if path is not None else self.output_dir / "deformed.ply"
        target.parent.mkdir(parents=True, exist_ok=True)
        save_scene(self.rods.export_scene(), target)
        return target

    def save_rods(self, directory: str | Path | None = None) -> list[Path]:
        """Write each rod as rod JSON (`rod_<id>.json` and its bindings, with its material);
        returns the JSON paths."""
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

    def _download(self, client: Any, what: str, make: Any) -> None:
        """Write an export with `make() -> (file name, bytes, where written)` and send it to
        `client`'s browser as a download."""
        notice = self.feedback.notify(client, "busy", f"Preparing {what}…")
        try:
            name, data, written = make()
        except (SketchRodGSError, OSError, TimeoutError, RuntimeError) as exc:
            self.feedback.update(notice, "error", f"No {what}", describe_failure(exc))
            return
        if client is not None:
            client.send_file_download(name, data, save_immediately=True)
        self.feedback.update(notice, "done", f"{name} downloaded ({_size(len(data))})", f"Also written to {written}.")

    def _ply_download(self) -> tuple[str, bytes, str]:
        path = self.export_ply()
        return path.name, path.read_bytes(), str(path)

    def _rods_download(self) -> tuple[str, bytes, str]:
        paths = self.save_rods()
        if not paths:
            raise SketchRodGSError("there are no rods to save yet")
        buffer = io.BytesIO()
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
            for path in paths:
                for part in sorted(path.parent.glob(path.stem + ".*")):
                    archive.write(part, part.name)
        return "rods.zip", buffer.getvalue(), str(self.output_dir)

    def _screenshot_download(self, client: Any) -> tuple[str, bytes, str]:
        path = self.screenshot(client)
        return path.name, path.read_bytes(), str(path)

    # ----- panel -----

    def selected_rod(self) -> RodEntry | None:
        value = str(self.panel.rod.value)
        if value == NO_ROD:
            return None
        try:
            return self.rods.get(int(value.removeprefix("rod ")))
        except (SketchRodGSError, ValueError):
            return None

    def _wire_panel(self) -> None:
        panel = self.panel

        @panel.auto_radius.on_update
        def _(event: Any) -> None:
            panel.radius.disabled = bool(panel.auto_radius.value)

        def material_changed(event: Any) -> None:
            if event.client is None:  # set by the app (an undo), not by the user
                return
            density = self.rods.material.density
            self.set_material(panel.material(-self.up, density))
            self.feedback.notify(event.client, "info", "Material changed", "The rods restarted from rest.")

        for widget in panel.material_inputs():
            widget.on_update(material_changed)

        def contact_changed(event: Any) -> None:
            self.set_contact(bool(panel.contact.value), float(panel.friction.value))

        panel.contact.on_update(contact_changed)
        panel.friction.on_update(contact_changed)
        panel.rod.on_update(lambda event: self._refresh_panel())

        @panel.clamp.on_update
        def _(event: Any) -> None:
            entry = self.selected_rod()
            if event.client is None or entry is None:
                return
            clamp = clamp_of(str(panel.clamp.value))
            if clamp != entry.clamp:
                self.set_clamp(entry.id, clamp)

        panel.frame.on_click(lambda event: self.frame_rod(event.client))
        panel.remove_rod.on_click(lambda event: self.act("Remove", event.client))
        panel.reset.on_click(lambda event: self.reset())
        panel.remove_all.on_click(lambda event: self.remove_all(event.client))

        @panel.undo.on_click
        def _(event: Any) -> None:
            self.undo(event.client)

        @panel.redo.on_click
        def _(event: Any) -> None:
            self.redo(event.client)

        panel.camera.on_click(lambda event: self.show_view(str(event.target.value), event.client))
        panel.export_ply.on_click(lambda event: self._download(event.client, "the deformed scene", self._ply_download))
        panel.save_rods.on_click(lambda event: self._download(event.client, "the rods", self._rods_download))
        panel.screenshot.on_click(
            lambda event: self._download(event.client, "a screenshot", lambda: self._screenshot_download(event.client))
        )
        for shortcut, command in panel.commands:
            command.on_trigger(self._trigger(shortcut.action))

    def _trigger(self, action: str) -> Any:
        return lambda event: self.act(action, event.client)

    def _refresh_panel(self, select: int | None = None) -> None:
        """Make the panel show the rods, the selected rod and what can be done now."""
        for rod_id in self.rods.take_falling():
            self.feedback.notify(
                None,
                "error",
                f"Rod {rod_id} cannot hang as captured",
                "Under gravity, what holds it cannot carry its weight, so it falls. Hold it at an end "
                "(Held at), or turn Gravity off.",
            )
        panel = self.panel
        with self._panel_lock:
            entries = self.rods.entries
            names = tuple(f"rod {e.id}" for e in entries) or (NO_ROD,)
            panel.rod.options = names
            if select is not None:
                panel.rod.value = f"rod {select}"  # type: ignore[misc]  # viser's dropdown value is settable
            elif panel.rod.value not in names:
                panel.rod.value = names[-1]  # type: ignore[misc]
            entry = self.selected_rod()
            if entry is None:
                panel.rod_info.content = "Sketch (2) over a slender part to make a rod."
            else:
                params = entry.rod.params
                panel.rod_info.content = (
                    f"{entry.rod.num_vertices} points, {len(entry.gaussian_ids):,} Gaussians, "
                    f"R = {entry.extraction.radius:.3g}, E = {params.youngs_modulus:.3g} Pa"
                )
                panel.clamp.value = CLAMP_LABELS[entry.clamp]  # type: ignore[misc]
            for widget in (panel.rod, panel.clamp, panel.frame, panel.remove_rod, panel.reset, panel.remove_all):
                widget.disabled = entry is None
            panel.save_rods.disabled = not entries
            panel.undo.disabled = not self.history.can_undo
            panel.redo.disabled = not self.history.can_redo

    def _frame_done(self, timings: dict[str, float]) -> None:
        now = time.perf_counter()
        if now - self._last_timings < TIMINGS_INTERVAL:
            return
        self._last_timings = now
        bound = int(sum(len(e.gaussian_ids) for e in self.rods.entries))
        self.panel.timings.content = (
            f"**Frame** ({bound:,} rod Gaussians, {self.splat_update}, mean of the last "
            f"{min(self.loop.timings.count, 60)}): {self.loop.timings.summary()}"
        )


def _size(count: int) -> str:
    """A byte count for people."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= scale:
            return f"{count / scale:.1f} {unit}"
    return f"{count} bytes"
