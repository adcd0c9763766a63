"""The viewer's GUI panel: mode, parameters, rods, exports, status and timings.

The panel only holds the widgets; the app attaches what they do.
"""

from __future__ import annotations

from typing import Any

import viser

from ..rod import RodParams
from .sketch import SketchSettings

MODES = ("View", "Sketch", "Play")
MODE_HELP = {
    "View": "drag to orbit, right-drag to pan, scroll to zoom",
    "Sketch": "left-drag along a slender part to extract it as a rod (the camera stays still)",
    "Play": "drag a rod vertex (blue ball) to pull it; let go and it springs back",
}
NO_ROD = "(none)"
GRAVITY = 9.81  # m/s^2, along the scene's down direction when gravity is on


class Panel:
    """The widgets (created on `server.gui`, shared by every browser)."""

    def __init__(self, gui: viser.GuiApi, params: RodParams, clamp_ends: bool, working_width: int) -> None:
        self.mode = gui.add_button_group("Mode", MODES)
        self.mode_text = gui.add_markdown(self.mode_markdown("View"))
        with gui.add_folder("Sketch"):
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
                "Attached parts follow", True, hint="small parts joined to the rod (leaves, a tag) ride with it"
            )
        with gui.add_folder("Rod material"):
            self.youngs_modulus = gui.add_number(
                "Stiffness E (Pa)",
                params.youngs_modulus,
                min=1.0,
                step=1e5,
                hint="Young's modulus; changing it restarts the rods from rest",
            )
            self.damping = gui.add_number("Damping (1/s)", params.damping, min=0.0, step=0.1)
            self.density = gui.add_number("Density (kg/m³)", params.density, min=1e-3, step=10.0)
            self.gravity = gui.add_checkbox("Gravity", any(params.gravity), hint="9.81 m/s² along the scene's down")
            self.clamp_ends = gui.add_checkbox("Clamp ends", clamp_ends, hint="hold both ends of every rod in place")
        with gui.add_folder("Rods"):
            self.rod = gui.add_dropdown("Rod", (NO_ROD,))
            self.remove_rod = gui.add_button("Remove rod")
            self.reset = gui.add_button("Reset all to rest")
            self.remove_all = gui.add_button("Remove all rods")
        with gui.add_folder("Export"):
            self.export_ply = gui.add_button("Export deformed .ply")
            self.save_rods = gui.add_button("Save rods (rod JSON)")
            self.screenshot = gui.add_button("Save screenshot")
        self.status = gui.add_markdown("")
        self.timings = gui.add_markdown("")

    @staticmethod
    def mode_markdown(mode: str) -> str:
        return f"**{mode}**: {MODE_HELP[mode]}"

    def sketch_settings(self) -> SketchSettings:
        return SketchSettings(
            radius=None if self.auto_radius.value else float(self.radius.value),
            alpha=float(self.alpha.value),
            edge_length=float(self.edge_length.value) or None,
            attach=bool(self.attach.value),
        )

    def rod_params(self, down: Any) -> RodParams:
        """The material in the panel; `down` is the scene's (3,) unit down direction."""
        g = [float(GRAVITY * d) for d in down] if self.gravity.value else [0.0, 0.0, 0.0]
        gravity = (g[0], g[1], g[2])
        return RodParams(
            youngs_modulus=float(self.youngs_modulus.value),
            damping=float(self.damping.value),
            density=float(self.density.value),
            gravity=gravity,
        )

    def material_inputs(self) -> list[Any]:
        return [self.youngs_modulus, self.damping, self.density, self.gravity]
