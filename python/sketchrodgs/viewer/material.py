"""How springy the viewer's rods are: a swing period, and each rod's Young's modulus from it.

A user wants motion they can see, not a modulus. At the rod crate's default E = 1e7 Pa an
extracted plant stem (13 cm, R = 7 mm) swings with a period of a few hundredths of a second,
shorter than a frame at 60 Hz, and backward Euler damps that away: 98 % of a pull is gone one
frame after release, so the rod snaps back instead of swinging. The viewer instead takes the period
of the rod's first bending mode, T, and gives each rod the E that has it (Euler-Bernoulli beam,
solid circular section of radius r, length L, density rho):

    omega = (beta L)^2 / L^2 * sqrt(E I / (rho A)),  I = pi r^4 / 4,  A = pi r^2
    =>  E = 4 rho (2 pi / T)^2 L^4 / ((beta L)^4 r^2)

with beta L = 4.730 for a rod held at both ends (the same for a free one), 1.875 for one held at
one end. Measured on the extracted plant stem and ring arc (tests/test_viewer.py): released after
a pull, the rod swings past rest with a first period within 15 % of T. Pins are not counted.
Density then has no visible effect (pulls move vertices, and the sag under gravity is
g (beta L)^4 / (384 omega^2) whatever the density), so the panel does not offer it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..errors import SketchRodGSError
from ..rod import RodParams

Clamp = Literal["both", "start", "end", "none"]
CLAMPS: tuple[Clamp, ...] = ("both", "start", "end", "none")
# beta L of the first bending mode for each way of holding the rod
FIRST_MODE = {"both": 4.730, "start": 1.875, "end": 1.875, "none": 4.730}
SWING_PERIOD = 0.5  # s: a pulled rod visibly swings back, about twice a second
DAMPING = 1.0  # 1/s: a few swings before it rests (the crate's 2.0 stops it in about two)
GRAVITY = 9.81  # m/s^2, along the scene's down direction when gravity is on


@dataclass(frozen=True)
class Material:
    """The viewer's rod material.

    Attributes:
        swing_period: T [s], the period of each rod's first bending mode as it is clamped.
        damping: viscous damping rate alpha [1/s] (`RodParams.damping`).
        density: rho [kg/m^3].
        gravity: [m/s^2] (zero: off).
    """

    swing_period: float = SWING_PERIOD
    damping: float = DAMPING
    density: float = RodParams().density
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.swing_period) and self.swing_period > 0):
            raise SketchRodGSError(f"swing period: must be > 0 seconds, got {self.swing_period}")
        if not (math.isfinite(self.damping) and self.damping >= 0):
            raise SketchRodGSError(f"damping: must be >= 0 per second, got {self.damping}")
        if not (math.isfinite(self.density) and self.density > 0):
            raise SketchRodGSError(f"density: must be > 0 kg/m^3, got {self.density}")

    def youngs_modulus(self, length: float, radius: float, clamp: Clamp) -> float:
        """E [Pa] that gives a rod of `length` and `radius` held as `clamp` the swing period."""
        omega = 2 * math.pi / self.swing_period
        return 4 * self.density * omega**2 * length**4 / (FIRST_MODE[clamp] ** 4 * radius**2)

    def rod_params(self, length: float, radius: float, clamp: Clamp) -> RodParams:
        """The solver's parameters for one rod."""
        return RodParams(
            radius=radius,
            youngs_modulus=self.youngs_modulus(length, radius, clamp),
            density=self.density,
            damping=self.damping,
            gravity=self.gravity,
        )
