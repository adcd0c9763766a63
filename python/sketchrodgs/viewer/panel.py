"""The viewer's shared GUI panel and keyboard shortcuts.

The panel only holds the widgets; the app attaches what they do. Widgets here are shared by every
tab (the rods and their material are the session's); each tab adds its own mode buttons and view
toggles (`tabs.py`) at the orders given here. The panel is docked to the right edge, so that the
canvas never lies under it (a stroke started under a floating panel reached nothing), and the
dock can be collapsed to a rail.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import viser

from .material import CLAMPS, GRAVITY, Clamp, Material
from .sketch import SketchSettings

NO_ROD = "(no rods yet)"
CLAMP_LABELS: dict[Clamp, str] = {
    "both": "both ends",
    "start": "stroke's start",
    "end": "stroke's end",
    "none": "none",
}
CAMERA_VIEWS = ("Start", "Front", "Side", "Top")

# Panel order: loading note, then each tab's mode buttons and hint, then the shared parts.
ORDER_LOADING = 0.0
ORDER_MODES = 1.0  # 1.0, 1.1, 1.2: a tab's mode buttons
ORDER_HINT = 2.0
ORDER_EDIT = 3.0
ORDER_RODS = 10.0
ORDER_VIEW = 20.0
ORDER_MOTION = 30.0
ORDER_SKETCH = 40.0
ORDER_EXPORT = 50.0
ORDER_KEYS = 60.0
ORDER_TIMINGS = 70.0


@dataclass(frozen=True)
class Shortcut:
    """A keyboard shortcut: the action it triggers (`ViewerApp.act`), its key and what it does."""

    action: str
    key: Any  # viser's HotkeyKey
    modifier: Any  # viser's KeyModifier or None
    description: str

    def keys(self) -> str:
        """How the keys are written, e.g. "Ctrl+Shift+Z"."""
        names = {"cmd/ctrl": "Ctrl", "shift": "Shift", "home": "Home", "delete": "Delete"}
        parts = [*(self.modifier.split("+") if self.modifier else []), self.key]
        return "+".join(names.get(p, p) for p in parts)


# W, A, S, D, Q and E move viser's camera; Ctrl+K opens viser's command search.
SHORTCUTS = (
    Shortcut("View", "1", None, "View mode: orbit, pan, zoom"),
    Shortcut("Sketch", "2", None, "Sketch mode: drag along a part to make it a rod"),
    Shortcut("Play", "3", None, "Play mode: pull a rod by its balls"),
    Shortcut("Undo", "Z", "cmd/ctrl", "Undo the last rod operation"),
    Shortcut("Redo", "Z", "cmd/ctrl+shift", "Redo what was undone"),
    Shortcut("Redo", "Y", "cmd/ctrl", "Redo what was undone"),
    Shortcut("Frame", "F", None, "Frame the selected rod"),
    Shortcut("Start", "home", None, "Back to the view the page opened with"),
    Shortcut("Handles", "H", None, "Show or hide the balls on the rods (this tab)"),
    Shortcut("Bound", "B", None, "Show or hide the dots on the rods' Gaussians (this tab)"),
    Shortcut("Reset", "R", None, "Every rod back to rest"),
    Shortcut("Remove", "delete", None, "Remove the selected rod"),
)


def shortcuts_markdown() -> str:
    """The on-page list of keys."""
    rows = [f"| {s.keys()} | {s.description} |" for s in SHORTCUTS]
    return "\n".join(
        ["| key | does |", "|---|---|", *rows, "| W A S D Q E | move the camera |", "| Ctrl+K | search commands |"]
    )


class Panel:
    """The shared widgets (created on `server.gui`)."""

    def __init__(self, gui: viser.GuiApi, material: Material, working_width: int, scene_size: int) -> None:
        self.loading = gui.add_markdown(
            f"**Loading the scene** ({scene_size:,} Gaussians): it appears as it arrives.", order=ORDER_LOADING
        )
        self.loading_bar = gui.add_progress_bar(100.0, animated=True, order=ORDER_LOADING + 0.1)
        self.undo = gui.add_button("Undo (Ctrl+Z)", icon=viser.Icon.ARROW_BACK_UP, disabled=True, order=ORDER_EDIT)
        self.redo = gui.add_button(
            "Redo (Ctrl+Shift+Z)", icon=viser.Icon.ARROW_FORWARD_UP, disabled=True, order=ORDER_EDIT + 0.1
        )
        with gui.add_folder("Rods", order=ORDER_RODS):
            self.rod = gui.add_dropdown("Rod", (NO_ROD,), disabled=True)
            self.rod_info = gui.add_markdown("Sketch over a slender part to make a rod.")
            self.clamp = gui.add_dropdown(
                "Held at",
                tuple(CLAMP_LABELS.values()),
                disabled=True,
                hint="which ends of the selected rod stay in place (in Play, click a ball to pin that point)",
            )
            self.frame = gui.add_button("Frame rod (F)", icon=viser.Icon.FOCUS_CENTERED, disabled=True)
            self.remove_rod = gui.add_button("Remove rod (Delete)", icon=viser.Icon.TRASH, disabled=True)
            self.reset = gui.add_button("Reset all to rest (R)", icon=viser.Icon.REFRESH, disabled=True)
            self.remove_all = gui.add_button("Remove all rods", icon=viser.Icon.TRASH_X, disabled=True)
        with gui.add_folder("View", order=ORDER_VIEW) as self.view_folder:
            self.camera = gui.add_button_group("Camera", CAMERA_VIEWS, hint="Start: the view the page opened with")
        with gui.add_folder("Motion", order=ORDER_MOTION):
            self.swing_period = gui.add_slider(
                "Swing period (s)",
                0.2,
                2.0,
                0.05,
                material.swing_period,
                marks=((0.2, "stiff"), (2.0, "soft")),
                hint="how long one swing takes when a rod is let go; each rod's stiffness follows from it",
            )
            self.damping = gui.add_number(
                "Damping (1/s)", material.damping, min=0.0, max=100.0, step=0.1, hint="how fast the swing dies out"
            )
            self.gravity = gui.add_checkbox("Gravity", any(material.gravity), hint="9.81 m/s² along the scene's down")
            self.contact = gui.add_checkbox(
                "Contact", True, hint="rods stay out of the scene's solid parts and out of each other"
            )
            self.friction = gui.add_slider(
                "Friction", 0.0, 1.0, 0.05, 0.0, hint="how much a rod sticks where it touches the scene"
            )
        with gui.add_folder("Sketch settings", order=ORDER_SKETCH, expand_by_default=False):
            self.auto_radius = gui.add_checkbox("Auto radius", True, hint="estimate R from the image and the Gaussians")
            self.radius = gui.add_number(
                "Radius R", 0.01, min=1e-6, step=1e-4, disabled=True, hint="object radius in scene units"
            )
            self.alpha = gui.add_number(
                "Alpha", 1.0, min=0.0, step=0.1, hint="weight of the stroke distance (paper Eq. 1)"
            )
            self.edge_length = gui.add_number(
                "Edge length", 0.0, min=0.0, step=1e-3, hint="rod edge length in scene units; 0 for the default"
            )
            self.working_width = gui.add_number(
                "Working width",
                working_width,
                min=64,
                max=4096,
                step=1,
                hint="pixels across the render the stroke is traced on",
            )
            self.attach = gui.add_checkbox(
                "Attached parts follow",
                True,
                hint="small parts joined to the rod (leaves, a tag), and what continues it past a free end, ride "
                "with it",
            )
        with gui.add_folder("Export", order=ORDER_EXPORT, expand_by_default=False):
            self.export_ply = gui.add_button("Download deformed .ply", icon=viser.Icon.DOWNLOAD)
            self.save_rods = gui.add_button("Download rods (.zip)", icon=viser.Icon.DOWNLOAD, disabled=True)
            self.screenshot = gui.add_button("Download screenshot (.png)", icon=viser.Icon.CAMERA)
        with gui.add_folder("Keyboard shortcuts", order=ORDER_KEYS, expand_by_default=False):
            gui.add_markdown(shortcuts_markdown())
        with gui.add_folder("Timings", order=ORDER_TIMINGS, expand_by_default=False):
            self.timings = gui.add_markdown("No frames yet: pull a rod in Play mode.")
        # shared commands: a trigger says which tab it came from
        self.commands = [
            (s, gui.add_command(f"{s.description} ({s.keys()})", hotkey=s.key, modifier=s.modifier)) for s in SHORTCUTS
        ]

    def scene_loaded(self) -> None:
        """Hide the loading note. Sent after the scene's nodes, so a browser that connects later
        replays the note, the scene, then this."""
        self.loading.visible = False
        self.loading_bar.visible = False

    def sketch_settings(self) -> SketchSettings:
        return SketchSettings(
            radius=None if self.auto_radius.value else float(self.radius.value),
            alpha=float(self.alpha.value),
            edge_length=float(self.edge_length.value) or None,
            attach=bool(self.attach.value),
        )

    def material(self, down: Any, density: float) -> Material:
        """The material in the panel; `down` is the scene's (3,) unit down direction."""
        g = [float(GRAVITY * d) for d in down] if self.gravity.value else [0.0, 0.0, 0.0]
        return Material(
            swing_period=float(self.swing_period.value),
            damping=float(self.damping.value),
            density=density,
            gravity=(g[0], g[1], g[2]),
        )

    def show_material(self, material: Material) -> None:
        """Put `material` in the widgets (after an undo)."""
        self.swing_period.value = material.swing_period  # type: ignore[misc]  # viser's values are settable
        self.damping.value = material.damping  # type: ignore[misc]
        self.gravity.value = any(material.gravity)  # type: ignore[misc]

    def material_inputs(self) -> list[Any]:
        return [self.swing_period, self.damping, self.gravity]


def clamp_of(label: str) -> Clamp:
    """The clamp a "Held at" label names."""
    for clamp in CLAMPS:
        if CLAMP_LABELS[clamp] == label:
            return clamp
    raise ValueError(f"unknown clamp label {label!r}")
