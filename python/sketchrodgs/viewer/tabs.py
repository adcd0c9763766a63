"""Each browser tab: its mode, its mode buttons, what it shows, and the stroke it draws.

Tabs share the scene, the rods and the panel, but each has its own mode (one tab pressing View does
not take another out of Play), its own view toggles, its own sketch surface and stroke. What a tab
shows is chosen with client-scoped frames named like the shared branches `/overlay`,
`/overlay/bound` and `/play` (`display.py`): viser draws a client's own node in place of the
server's of the same name, and the server's children under it, so hiding the tab's frame hides
the branch in that tab only.

- View: the scene alone.
- Sketch: rods' axes and dots; an invisible box around camera and scene (opacity 0, back faces,
  this tab's own) catches left drags, so that a drag draws a stroke instead of orbiting.
- Play: axes, dots and the rods' handles.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from ..camera import Camera
from ..errors import SketchRodGSError
from ..images import STROKE_COLOUR
from .camera import camera_from_viser
from .panel import ORDER_HINT, ORDER_MODES
from .sketch import Stroke

MODES = ("View", "Sketch", "Play")
MODE_KEYS = {"View": "1", "Sketch": "2", "Play": "3"}
MODE_ICONS = {"View": viser.Icon.EYE, "Sketch": viser.Icon.PENCIL, "Play": viser.Icon.HAND_GRAB}
MODE_HELP = {
    "View": "**View**: drag to orbit, right-drag to pan, scroll to zoom.",
    "Sketch": "**Sketch**: drag along a slender part (a stem, a cable) to make it a rod. The camera stays still.",
    "Play": "**Play**: drag a ball on a rod to pull it, let go and it swings back. Click a ball to pin it there.",
}
ACTIVE_COLOUR = "blue"
IDLE_COLOUR = "gray"
FAILED_STROKE_COLOUR = (230, 40, 40)
BRUSH_COLOUR = (150, 235, 170)
VIEW_UPDATE_SECONDS = 0.25  # at most this often a Play tab's moving camera resizes the handles


class Tab:
    """One connected browser tab.

    Args:
        client: its viser client.
        view_folder: the panel's View folder (the tab's toggles go in it).
        reach: (3,) centre and extent of the scene, for the sketch surface.
        on_change: called with the tab after its mode or its toggles changed.
        on_stroke: called with the tab and its stroke when a stroke ends.
        on_view: called with the tab when its camera moved in Play (at most every
            VIEW_UPDATE_SECONDS).
        working_width: returns the width of the render strokes are traced on.
    """

    def __init__(
        self,
        client: Any,
        view_folder: Any,
        reach: tuple[np.ndarray, float],
        on_change: Callable[[Tab], None],
        on_stroke: Callable[[Tab, Stroke], None],
        on_view: Callable[[Tab], None],
        working_width: Callable[[], int],
    ) -> None:
        self.client = client
        self.mode = "View"
        self.show_handles = True
        self.show_bound = True
        self._centre, self._extent = reach
        self._on_change, self._on_stroke, self._on_view = on_change, on_stroke, on_view
        self._working_width = working_width
        self._lock = threading.RLock()
        self._stroke: Stroke | None = None
        self._stroke_depth = 0.0
        self._stroke_nodes: list[Any] = []
        self._surface: Any = None
        self._last_view = 0.0
        gui, scene = client.gui, client.scene
        self.buttons = {
            mode: gui.add_button(
                f"{mode} ({MODE_KEYS[mode]})",
                icon=MODE_ICONS[mode],
                color=ACTIVE_COLOUR if mode == self.mode else IDLE_COLOUR,
                order=ORDER_MODES + 0.1 * k,
            )
            for k, mode in enumerate(MODES)
        }
        for mode, button in self.buttons.items():
            button.on_click(lambda event, mode=mode: self.set_mode(mode))
        self.hint = gui.add_markdown(MODE_HELP[self.mode], order=ORDER_HINT)
        with view_folder:
            self.handles_box = gui.add_checkbox("Handles (H)", True, hint="the balls you pull a rod by")
            self.bound_box = gui.add_checkbox(
                "Bound Gaussians (B)", True, hint="dots on the Gaussians that follow a rod"
            )
        self.handles_box.on_update(self._toggled)
        self.bound_box.on_update(self._toggled)
        self._frames = {
            name: scene.add_frame(name, show_axes=False) for name in ("/overlay", "/overlay/bound", "/play")
        }
        self._show()
        client.camera.on_update(self._camera_moved)

    @property
    def id(self) -> int:
        return int(self.client.client_id)

    # ----- mode and toggles -----

    def set_mode(self, mode: str) -> None:
        """Switch this tab to "View", "Sketch" or "Play"."""
        if mode not in MODES:
            raise SketchRodGSError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
        with self._lock:
            if mode == self.mode:
                return
            self.mode = mode
            self._stroke = None
            self._clear_stroke()
            with self.client.atomic():
                for name, button in self.buttons.items():
                    button.color = ACTIVE_COLOUR if name == mode else IDLE_COLOUR
                self.hint.content = MODE_HELP[mode]
                self._show()
                if mode == "Sketch":
                    self._add_surface()
                elif self._surface is not None:
                    self._surface.remove()
                    self._surface = None
        self._on_change(self)

    def set_toggles(self, handles: bool | None = None, bound: bool | None = None) -> None:
        """Show or hide this tab's handles and bound-Gaussian dots."""
        with self._lock:
            if handles is not None:
                self.show_handles = handles
                self.handles_box.value = handles  # type: ignore[misc]  # viser's values are settable
            if bound is not None:
                self.show_bound = bound
                self.bound_box.value = bound  # type: ignore[misc]
            self._show()
        self._on_change(self)

    def _toggled(self, event: Any) -> None:
        if event.client is not None:  # from the browser (assigning a value here calls this too)
            self.set_toggles(handles=bool(self.handles_box.value), bound=bool(self.bound_box.value))

    @property
    def shows_dots(self) -> bool:
        return self.mode != "View" and self.show_bound

    def _show(self) -> None:
        self._frames["/overlay"].visible = self.mode != "View"
        self._frames["/overlay/bound"].visible = self.show_bound
        self._frames["/play"].visible = self.mode == "Play" and self.show_handles

    # ----- camera -----

    def camera(self, width: int | None = None) -> Camera | None:
        """Our camera for this tab's view (at `width` pixels, default the canvas'), None before the
        browser reported it."""
        try:
            cam = self.client.camera
            return camera_from_viser(
                cam.wxyz, cam.position, cam.fov, cam.aspect, width or int(cam.image_width), near=cam.near
            )
        except (AssertionError, SketchRodGSError, ValueError):  # not reported yet, or a zero-size canvas
            return None

    def _camera_moved(self, camera: Any) -> None:
        now = time.monotonic()
        if self.mode == "Play" and now - self._last_view >= VIEW_UPDATE_SECONDS:
            self._last_view = now
            self._on_view(self)

    # ----- sketch -----

    def _add_surface(self) -> None:
        """The invisible box that catches this tab's strokes: around the scene and the camera. It
        takes drags only: viser outlines a mesh that takes clicks in yellow while the pointer is
        over it, and this one, around the camera, painted a yellow wedge over the scene."""
        reach = self._extent
        try:
            reach = max(reach, float(np.linalg.norm(self.client.camera.position - self._centre)))
        except AssertionError:  # the camera is not reported yet
            pass
        self._surface = self.client.scene.add_box(
            "/sketch/surface",
            color=(255, 255, 255),
            dimensions=(20 * reach,) * 3,
            position=tuple(self._centre),
            opacity=0.0,
            side="back",
            cast_shadow=False,
            receive_shadow=False,
        )
        self._surface.on_drag("left")(self._on_drag)

    async def _on_drag(self, event: Any) -> None:
        # async: drag phases then arrive in order (viser awaits async callbacks on its loop)
        if self.mode != "Sketch":
            return
        if event.phase == "start":
            camera = self.camera(self._working_width())
            self._stroke = Stroke(camera) if camera is not None else None  # None: no camera reported yet
            if self._stroke is None:
                return
            cam = self.client.camera
            # draw the stroke halfway to the orbit centre: in front of what is looked at (viser washes
            # out lines very close to the camera)
            self._stroke_depth = max(2 * cam.near, 0.5 * float(np.linalg.norm(cam.look_at - cam.position)))
            self._stroke.add(event.start_screen_pos)
        stroke = self._stroke
        if stroke is None:
            return
        stroke.add(event.end_screen_pos)
        self.show_stroke(stroke, brush=event.phase != "end")
        if event.phase == "end":
            self._stroke = None
            self._on_stroke(self, stroke)

    def show_stroke(self, stroke: Stroke, brush: bool = False, failed: bool = False) -> None:
        """Draw `stroke` in this tab (with the band the search looks in while it is drawn; red
        when it made no rod)."""
        points = stroke.world_points(self._stroke_depth)
        with self._lock:
            self._clear_stroke()
            scene = self.client.scene
            if brush:
                outline = stroke.brush(self._stroke_depth)
                if len(outline):
                    self._stroke_nodes.append(
                        scene.add_line_segments(
                            "/sketch/brush", outline, BRUSH_COLOUR, thickness=1.5, thickness_units="screen"
                        )
                    )
            if len(points) > 1:
                segments = np.ascontiguousarray(np.stack([points[:-1], points[1:]], axis=1), np.float32)
                colour = FAILED_STROKE_COLOUR if failed else STROKE_COLOUR
                self._stroke_nodes.append(
                    scene.add_line_segments("/sketch/stroke", segments, colour, thickness=3.0, thickness_units="screen")
                )

    def clear_stroke(self) -> None:
        with self._lock:
            self._clear_stroke()

    def _clear_stroke(self) -> None:
        for node in self._stroke_nodes:
            try:
                node.remove()
            except Exception:  # the tab closed meanwhile
                continue
        self._stroke_nodes = []


class Tabs:
    """The connected tabs, made as browsers connect (see `Tab` for the arguments)."""

    def __init__(self, server: viser.ViserServer, make: Callable[[Any], Tab]) -> None:
        self._tabs: dict[int, Tab] = {}
        self._lock = threading.Lock()
        self._make = make
        server.on_client_connect(self._connected)
        server.on_client_disconnect(self._disconnected)

    def _connected(self, client: Any) -> None:
        tab = self._make(client)
        with self._lock:
            self._tabs[int(client.client_id)] = tab

    def _disconnected(self, client: Any) -> None:
        with self._lock:
            self._tabs.pop(int(client.client_id), None)

    def of(self, client: Any) -> Tab | None:
        """The tab of a viser client (None once it closed, or before it is set up)."""
        if client is None:
            return None
        with self._lock:
            return self._tabs.get(int(client.client_id))

    def all(self) -> list[Tab]:
        with self._lock:
            return list(self._tabs.values())
