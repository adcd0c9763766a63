"""Pull and release: simulate extracted rods and skin the scene, frame by frame.

The app's interaction as a script: the ends of each rod clamped (both by default, as in the
authors' app; or one, or none) and any vertices pinned, one vertex grabbed and its target moved by
an offset over `duration` seconds, held for `hold` seconds, then released and left to spring back
for `settle` seconds.

The rods meet the scene (docs/contact.md): they do not enter its solid parts (a distance field of
the Gaussians they do not carry) nor each other; and with an up direction, gravity pulls them
while their rest shapes hold the captured shapes (a captured hanging cable stays until pulled).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from .contact import SceneField, scene_field
from .errors import SimulationError, SketchRodGSError
from .framing import AXES
from .polyline import arc_lengths, polyline_length
from .rig import DEFAULT_END_RAMP, Rig
from .rod import ContactSettings, Rod, RodParams, World
from .rod_file import Extraction
from .scene import GaussianScene
from .scene_identity import check_rod_scene
from .skin import skin_into

logger = logging.getLogger("sketchrodgs")

Clamp = Literal["both", "start", "end", "none"]
CLAMPS: tuple[str, ...] = get_args(Clamp)
# A gesture longer than this many frames is refused (`Pull.frame_count`): over 55 min at 30 fps.
MAX_FRAMES = 100_000
_CLAMPED_ENDS = {"both": (0, -1), "start": (0,), "end": (-1,), "none": ()}


def _gravity(up: str | Sequence[float] | np.ndarray | None, magnitude: float) -> tuple[float, float, float] | None:
    """The gravity vector for a scene whose up direction is `up` (None: no gravity)."""
    if up is None:
        return None
    if not (np.isfinite(magnitude) and magnitude >= 0):
        raise SketchRodGSError(f"gravity: must be finite and >= 0, got {magnitude}")
    if isinstance(up, str):
        if up not in AXES:
            raise SketchRodGSError(f"up: expected one of {', '.join(AXES)} or a vector, got {up!r}")
        vector = np.array(AXES[up], np.float64)
    else:
        vector = np.asarray(up, np.float64).ravel()
        if vector.shape != (3,) or not np.isfinite(vector).all() or not np.linalg.norm(vector) > 0:
            raise SketchRodGSError(f"up: expected a non-zero 3-vector, got {up!r}")
    g = -magnitude * vector / np.linalg.norm(vector)
    return (float(g[0]), float(g[1]), float(g[2]))


def vertex_at_fraction(polyline: np.ndarray, fraction: float) -> int:
    """The vertex of `polyline` (M, 3) nearest to `fraction` (0..1) of its length from the start."""
    if not 0 <= fraction <= 1:
        raise SketchRodGSError(f"fraction along the rod: must be in 0..1, got {fraction}")
    s = arc_lengths(np.asarray(polyline, np.float64))
    return int(np.argmin(np.abs(s - fraction * s[-1])))


@dataclass(frozen=True)
class Pull:
    """A grab-move-hold-release gesture on one rod vertex.

    Attributes:
        vertex: the grabbed vertex (negative counts from the end).
        offset: how far the grab target moves, in scene units.
        duration: seconds to move the target there.
        hold: seconds to hold it.
        release: let go after holding.
        settle: seconds simulated after the release.
        rod: which rod (index into the rods) is grabbed.
    """

    vertex: int
    offset: tuple[float, float, float]
    duration: float = 0.5
    hold: float = 0.5
    release: bool = True
    settle: float = 1.5
    rod: int = 0

    def __post_init__(self) -> None:
        offset = tuple(float(v) for v in self.offset)
        if len(offset) != 3 or not np.isfinite(offset).all():
            raise SketchRodGSError(f"pull offset: expected 3 finite numbers, got {self.offset!r}")
        object.__setattr__(self, "offset", offset)
        for name in ("duration", "hold", "settle"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise SketchRodGSError(f"pull {name}: must be >= 0 seconds, got {value}")

    @property
    def total(self) -> float:
        """Seconds of simulated time the gesture covers."""
        return self.duration + self.hold + (self.settle if self.release else 0.0)

    def frame_count(self, fps: float) -> int:
        """How many frames the gesture makes at `fps`; at most `MAX_FRAMES` (a duration or rate in
        the wrong units would simulate, and the command line write, frames for days)."""
        if not (np.isfinite(fps) and fps > 0):
            raise SketchRodGSError(f"fps: must be > 0, got {fps}")
        frames = self.total * fps
        if not frames <= MAX_FRAMES:
            raise SketchRodGSError(
                f"the pull lasts {self.total:.3g} s (duration, hold and settle), {frames:.3g} frames at {fps:g} fps;"
                f" at most {MAX_FRAMES:,}"
            )
        return int(round(frames))

    def phase(self, t: float) -> str:
        if t < self.duration:
            return "pull"
        if t < self.duration + self.hold or not self.release:
            return "hold"
        return "release"

    def target_fraction(self, t: float) -> float:
        """How far along its offset the grab target is at time `t` (smooth start and stop)."""
        if self.duration == 0:
            return 1.0
        s = min(max(t / self.duration, 0.0), 1.0)
        return s * s * (3 - 2 * s)


@dataclass
class Frame:
    """One animation frame: the time, the phase, and the stage timings of getting there."""

    index: int
    time: float
    phase: str
    timings: dict[str, float] = field(default_factory=dict)


class Animation:
    """Rods built from extractions, bound to a scene; `frames` steps them and skins the scene.

    Args:
        scene: the scene at rest.
        extractions: one per rod (from `extract_rod` or `load_rod`).
        params: material per rod (a single one is used for all); its radius is replaced by each
            extraction's radius.
        clamp: which ends of every rod are clamped (position and frame held): "both", as the
            authors' app does, "start" (vertex 0: a branch held at its root, its tip free), "end",
            or "none".
        pins: per rod, vertices whose positions are held (negative counts from the end); a
            shorter list leaves the remaining rods unpinned.
        subdivide: split needle Gaussians along the rods first (`Rig`); the animated scene then
            has more rows than `scene`, and `rig.source` maps them back.
        end_ramp: the motion eases in over this many R from a clamped end (`Rig.build`).
        separate: trim each part's shell where it parts from what it touches (`Rig.build`).
        contact: the rods do not enter the scene's solid parts, nor each other (docs/contact.md).
        friction: Coulomb friction coefficient of the rods against the scene.
        up: the scene's up direction (a unit vector, or "+x" ... "-z"): gravity (`gravity` m/s^2)
            pulls the rods the other way, and each rod's rest shape is made to hold its captured
            shape under it. None (default): no gravity.

    Attributes:
        rest_scene: the scene the frames deform (the rig's: `scene` with needles split).
        means, quats, scales: its arrays now, updated by every frame.
    """

    def __init__(
        self,
        scene: GaussianScene,
        extractions: Sequence[Extraction],
        params: RodParams | Sequence[RodParams] = RodParams(),
        clamp: Clamp = "both",
        pins: Sequence[Sequence[int]] = (),
        subdivide: bool = True,
        end_ramp: float = DEFAULT_END_RAMP,
        separate: bool = True,
        contact: bool = True,
        friction: float = 0.0,
        up: str | Sequence[float] | np.ndarray | None = None,
        gravity: float = 9.81,
    ) -> None:
        if not extractions:
            raise SketchRodGSError("no rods to animate")
        if clamp not in CLAMPS:
            raise SketchRodGSError(f"clamp: expected one of {', '.join(CLAMPS)}, got {clamp!r}")
        if len(pins) > len(extractions):
            raise SketchRodGSError(f"pins: {len(pins)} lists for {len(extractions)} rods")
        per_rod = [params] * len(extractions) if isinstance(params, RodParams) else list(params)
        if not (np.isfinite(friction) and friction >= 0):
            raise SketchRodGSError(f"friction: must be finite and >= 0, got {friction}")
        weight = _gravity(up, gravity)
        self.world = World()
        self.world.contact = ContactSettings(scene=contact, rods=contact, friction=float(friction))
        self.rods: list[Rod] = []
        for k, (extraction, p) in enumerate(zip(extractions, per_rod)):
            check_rod_scene(extraction.scene_identity, scene, f"rod {k}", "the scene animated")
            material = RodParams(**{**p.to_dict(), "radius": extraction.radius})
            if weight is not None:
                material = RodParams(**{**material.to_dict(), "gravity": weight})
            rod = Rod(extraction.polyline, params=material, world=self.world)
            for end in _CLAMPED_ENDS[clamp]:
                rod.clamp(end)
            for vertex in pins[k] if k < len(pins) else ():
                rod.pin(vertex)
            if weight is not None:
                try:
                    rod.hold_under_gravity()
                except SimulationError as err:
                    raise SimulationError(f"rod {k}: {err}") from None
            self.rods.append(rod)
        self.rig = Rig.build(scene, extractions, self.rods, subdivide=subdivide, end_ramp=end_ramp, separate=separate)
        # the scene's solid parts the rods do not enter: what they do not carry
        self.field: SceneField | None = None
        if contact:
            carried = np.concatenate([b.gaussian_ids for b in self.rig.bound] + [np.empty(0, np.int64)])
            polylines, radii = [e.polyline for e in extractions], [e.radius for e in extractions]
            self.field = scene_field(self.rig.scene, polylines, radii, carried)
            if self.field is not None:
                self.world.set_scene_field(self.field.values, self.field.origin, self.field.spacing)
        self.rest_scene = self.rig.scene
        self.means = self.rest_scene.means.copy()
        self.quats = self.rest_scene.quats.copy()
        self.scales = self.rest_scene.scales.copy()

    @property
    def moving_rows(self) -> np.ndarray:
        """(G,) int64 the rows of `rest_scene` the rods move, ascending (for `FrameRenderer`)."""
        return np.unique(np.concatenate([b.gaussian_ids for b in self.rig.bound] + [np.empty(0, np.int64)]))

    def current_scene(self) -> GaussianScene:
        """The deformed scene now (a new scene sharing nothing mutable with the animation)."""
        return self.rest_scene.replace(means=self.means.copy(), quats=self.quats.copy(), scales=self.scales.copy())

    def frames(self, pull: Pull, fps: float) -> Iterator[Frame]:
        """Simulate `pull` at `fps` frames per second, skinning after every frame."""
        count = pull.frame_count(fps)
        if not 0 <= pull.rod < len(self.rods):
            raise SketchRodGSError(f"pull rod: {pull.rod} is not one of the {len(self.rods)} rods")
        rod = self.rods[pull.rod]
        if not -rod.num_vertices <= pull.vertex < rod.num_vertices:
            raise SketchRodGSError(f"grab vertex: {pull.vertex} is outside the rod's {rod.num_vertices} vertices")
        held = rod.boundaries[pull.vertex]
        if held != "free":
            # a grab moves the vertex, so it cannot stay held: let go of it, and say so
            logger.warning("rod %d: vertex %d is %s; it is set free to be pulled", pull.rod, pull.vertex, held)
            rod.free(pull.vertex)
        start = np.array(rod.positions[pull.vertex], np.float64)
        offset = np.array(pull.offset)
        length = polyline_length(rod.rest_positions)
        reach = math.hypot(*pull.offset)  # (no overflow where the offset's square would)
        if reach > length:
            # the rod cannot follow that far; its Gaussians would be drawn out into a streak
            logger.warning(
                "rod %d: the pull (%.3g) is longer than the rod (%.3g); its Gaussians will be stretched far",
                pull.rod,
                reach,
                length,
            )
        dt = 1.0 / fps
        rod.grab(pull.vertex, start)
        released = False
        for index in range(1, count + 1):
            t = index * dt
            phase = pull.phase(t)
            timings: dict[str, float] = {}
            clock = time.perf_counter()
            if phase == "release" and not released:
                rod.release()
                released = True
            elif not released:
                rod.move_grab(start + pull.target_fraction(t) * offset)
            self.world.step(dt)
            timings["simulate"] = time.perf_counter() - clock
            clock = time.perf_counter()
            skin_into(self.means, self.quats, self.scales, self.rig.bound, self.rods)
            timings["skin"] = time.perf_counter() - clock
            yield Frame(index, t, phase, timings)
