"""Discrete elastic rods: the extracted polyline becomes a rod the user pulls and releases.

The solver is the Rust crate `sketchrodgs-rod` (Bergou et al. 2008/2010 discrete elastic rods,
backward Euler solved by Newton's method on the banded Hessian). Parameters are SI: the scene's
length unit is taken as the metre.

Example:
    >>> import numpy as np
    >>> from sketchrodgs.rod import Rod
    >>> rod = Rod(np.c_[np.linspace(0, 1, 21), np.zeros(21), np.zeros(21)], radius=0.01)
    >>> rod.clamp(0); rod.clamp(-1)
    >>> rod.grab(10, (0.5, 0.3, 0.0))
    >>> report = rod.step(1 / 60, n=30)     # half a second, pulled
    >>> rod.release()
    >>> report = rod.step(1 / 60, n=300)    # let go
    >>> bool(np.abs(rod.positions - rod.rest_positions).max() < 1e-3)
    True

Several rods share a `World` and are stepped together: `w = World(); a = Rod(p, world=w)`.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _core
from .errors import SimulationError

_DEFAULT_MATERIAL: dict[str, Any] = _core.default_rod_params()
_DEFAULT_SOLVER: dict[str, Any] = _core.default_solver_settings()

__all__ = [
    "ContactSettings",
    "HoldReport",
    "Rod",
    "RodEnergy",
    "RodParams",
    "SolverSettings",
    "StaticReport",
    "StepReport",
    "World",
    "merge_coincident",
]

logger = logging.getLogger("sketchrodgs")


@dataclass(frozen=True)
class RodParams:
    """Material of a rod with a solid circular cross-section, in SI units.

    Attributes:
        radius: cross-section radius r [m] (the paper's R).
        youngs_modulus: Young's modulus E [Pa]; stretching EA and bending EI.
        shear_modulus: shear modulus G [Pa] for twisting GJ; None derives E / (2 (1 + nu)).
        poisson_ratio: Poisson ratio nu, used only when `shear_modulus` is None.
        density: density rho [kg/m^3]: lumped vertex masses and twist inertia.
        damping: viscous (mass-proportional) damping rate alpha [1/s].
        gravity: gravitational acceleration [m/s^2]; zero (off) by default.
    """

    # the defaults are the rod crate's (`_core.default_rod_params`), the one place they are written
    radius: float = _DEFAULT_MATERIAL["radius"]
    youngs_modulus: float = _DEFAULT_MATERIAL["youngs_modulus"]
    shear_modulus: float | None = _DEFAULT_MATERIAL["shear_modulus"]
    poisson_ratio: float = _DEFAULT_MATERIAL["poisson_ratio"]
    density: float = _DEFAULT_MATERIAL["density"]
    damping: float = _DEFAULT_MATERIAL["damping"]
    gravity: tuple[float, float, float] = tuple(_DEFAULT_MATERIAL["gravity"])  # type: ignore[assignment]

    def __post_init__(self) -> None:
        g = tuple(float(v) for v in self.gravity)
        if len(g) != 3:
            raise SimulationError(f"gravity: expected 3 components, got {len(g)}")
        object.__setattr__(self, "gravity", g)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the rod file's "material")."""
        d = asdict(self)
        d["gravity"] = list(self.gravity)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RodParams:
        """Inverse of `to_dict`; unknown keys are an error."""
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise SimulationError(f"rod material: unknown keys {sorted(unknown)}")
        kw = dict(d)
        if "gravity" in kw:
            kw["gravity"] = tuple(kw["gravity"])
        return cls(**kw)


@dataclass(frozen=True)
class SolverSettings:
    """Settings of the implicit solver of a `World`.

    Attributes:
        tolerance: Newton stops when the largest update is below tolerance * rod length
            (positions) and tolerance radians (twist).
        max_iterations: Newton iterations per (sub)step before it is retried as two halves.
        max_halvings: how often a failing step may be halved (2**max_halvings substeps at most).
        max_static_iterations: Newton iterations of a quasi-static solve.
    """

    tolerance: float = _DEFAULT_SOLVER["tolerance"]
    max_iterations: int = _DEFAULT_SOLVER["max_iterations"]
    max_halvings: int = _DEFAULT_SOLVER["max_halvings"]
    max_static_iterations: int = _DEFAULT_SOLVER["max_static_iterations"]

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SolverSettings:
        return cls(**d)


@dataclass(frozen=True)
class StepReport:
    """What a step did for one rod.

    Attributes:
        substeps: substeps the step was finally taken in (1 when it converged at once).
        newton_iterations: Newton iterations over all attempts, rejected ones included.
        rejected: attempts rejected and retried as two half steps.
        converged: whether every substep converged (if not, the finest substeps kept their
            best finite iterate; positions are never NaN).
    """

    substeps: int
    newton_iterations: int
    rejected: int
    converged: bool


@dataclass(frozen=True)
class StaticReport:
    """Result of a quasi-static solve: Newton iterations, convergence, final energy [J]."""

    iterations: int
    converged: bool
    energy: float


@dataclass(frozen=True)
class RodEnergy:
    """Energy of a rod [J]."""

    stretch: float
    bend: float
    twist: float
    kinetic: float
    gravity: float

    @property
    def elastic(self) -> float:
        return self.stretch + self.bend + self.twist

    @property
    def total(self) -> float:
        return self.elastic + self.kinetic + self.gravity


def _points(a: npt.ArrayLike, name: str) -> np.ndarray:
    try:
        arr = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise SimulationError(f"{name}: expected an (N, 3) array of numbers") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise SimulationError(f"{name}: expected shape (N, 3), got {arr.shape}")
    return arr


# The most vertices a rod may have (docs/extraction.md): a 1000-vertex rod steps in ~2 ms; 100k
# vertices is already a minute's simulation per second of motion.
MAX_ROD_VERTICES = 100_000


def _rod_points(polyline: npt.ArrayLike) -> np.ndarray:
    points = _points(polyline, "polyline")
    if len(points) > MAX_ROD_VERTICES:
        raise SimulationError(f"polyline: {len(points):,} vertices, more than a rod may have ({MAX_ROD_VERTICES:,})")
    return points


def _vec3(v: npt.ArrayLike, name: str) -> tuple[float, float, float]:
    arr = np.asarray(v, dtype=np.float64).reshape(-1)
    if arr.shape != (3,):
        raise SimulationError(f"{name}: expected 3 values, got shape {np.shape(v)}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def merge_coincident(polyline: npt.ArrayLike, tol: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Drops vertices closer than `tol` to the previous kept one (a rod rejects zero-length edges).

    Args:
        polyline: (N, 3) points.
        tol: merge distance; default 1e-9 of the polyline's length.

    Returns:
        (M, 3) float64 polyline and (N,) int64 map from each input vertex to its kept vertex.
    """
    p = _points(polyline, "polyline")
    if tol is None:
        tol = 1e-9 * float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0
    keep = [0] if len(p) else []
    index = np.zeros(len(p), dtype=np.int64)
    for i in range(1, len(p)):
        if np.linalg.norm(p[i] - p[keep[-1]]) > tol:
            keep.append(i)
        index[i] = len(keep) - 1
    return p[keep].copy(), index


class _OneThreadAtATime:
    """The Rust world, whose calls raise a clear error where two threads use it at once (a step
    releases the GIL, and Rust refuses a second borrow of the world meanwhile)."""

    def __init__(self, world: Any) -> None:
        self._world = world

    def __getattr__(self, name: str) -> Any:
        method = getattr(self._world, name)

        def call(*args: Any, **kwargs: Any) -> Any:
            try:
                return method(*args, **kwargs)
            except RuntimeError as exc:
                if "borrowed" not in str(exc):
                    raise
                raise SimulationError(
                    f"{name}: this World (and its rods) is in use by another thread; a World is "
                    "not shared across threads: give each thread its own, or hold a lock"
                ) from None

        return call


@dataclass(frozen=True)
class ContactSettings:
    """What contact a `World` simulates (docs/contact.md).

    Attributes:
        scene: rods do not enter the scene's distance field (`World.set_scene_field`), where one
            is set; a grabbed vertex dragged into it slides on its surface.
        rods: rods do not pass through each other, nor through themselves.
        friction: Coulomb friction coefficient against the scene (0: none).
    """

    scene: bool = True
    rods: bool = True
    friction: float = 0.0


@dataclass(frozen=True)
class HoldReport:
    """What `Rod.hold_under_gravity` did: its fixed-point iterations and how far the equilibrium
    under gravity is from the shape held [m]."""

    iterations: int
    deviation: float


class World:
    """Rods stepped together: they do not pass through each other, nor into the scene's distance
    field where one is set (`contact`). A World and its rods belong to one thread at a time: a
    call while another thread steps it raises `SimulationError`.

    Args:
        solver: solver settings shared by the rods.
    """

    def __init__(self, solver: SolverSettings | None = None) -> None:
        self._raw = _core.RodWorld()
        self._core = _OneThreadAtATime(self._raw)
        self._rods: list[Rod] = []
        if solver is not None:
            self.solver = solver

    @property
    def solver(self) -> SolverSettings:
        return SolverSettings(**self._core.solver())

    @solver.setter
    def solver(self, s: SolverSettings) -> None:
        self._core.set_solver(
            float(s.tolerance), int(s.max_iterations), int(s.max_halvings), int(s.max_static_iterations)
        )

    @property
    def contact(self) -> ContactSettings:
        scene, rods, friction = self._core.contact()
        return ContactSettings(bool(scene), bool(rods), float(friction))

    @contact.setter
    def contact(self, c: ContactSettings) -> None:
        self._core.set_contact(bool(c.scene), bool(c.rods), float(c.friction))

    def set_scene_field(
        self, values: np.ndarray | None, origin: npt.ArrayLike = (0, 0, 0), spacing: float = 1.0
    ) -> None:
        """The static scene the rods do not enter, as a signed distance field [m] (negative inside):
        `values` (nz, ny, nx) at the nodes `origin + spacing * (i, j, k)` (`contact.scene_field`
        builds one from a scene); None removes it."""
        if values is None:
            self._core.set_field(None, (0.0, 0.0, 0.0), 1.0)
            return
        array = np.ascontiguousarray(values, np.float32)
        if array.ndim != 3:
            raise SimulationError(f"distance field: expected (nz, ny, nx) values, got shape {array.shape}")
        o = np.asarray(origin, np.float64).ravel()
        if o.shape != (3,):
            raise SimulationError(f"distance field origin: expected 3 numbers, got {origin!r}")
        self._core.set_field(array, (float(o[0]), float(o[1]), float(o[2])), float(spacing))

    @property
    def has_scene_field(self) -> bool:
        return bool(self._core.has_field())

    @property
    def rods(self) -> list[Rod]:
        """The rods, in the order they were added."""
        return list(self._rods)

    def __len__(self) -> int:
        return len(self._rods)

    def add(self, polyline: npt.ArrayLike, params: RodParams | None = None, **material: Any) -> Rod:
        """Adds a rod at rest in the shape of `polyline` (N, 3); see `Rod`."""
        return Rod(polyline, params=params, world=self, **material)

    def remove(self, rod: Rod) -> None:
        """Removes `rod` from the world (its handle is then detached)."""
        self._core.remove(rod)
        self._rods.remove(rod)

    def step(self, dt: float, n: int = 1) -> list[StepReport]:
        """Advances every rod by `dt` seconds, `n` times (GIL released).

        A step that does not converge is retried in halves; one that still does not is kept
        (finite) and reported with `converged=False` and a logged warning.

        Returns:
            One report per rod, summed over the `n` steps.
        """
        raw = self._core.step(float(dt), int(n))
        reports = [StepReport(int(s), int(it), int(rj), bool(c)) for s, it, rj, c in raw]
        for k, r in enumerate(reports):
            if not r.converged:
                logger.warning("rod %d: step did not converge (%s)", k, r)
        return reports


class Rod(_core.Rod):
    """A discrete elastic rod built from a polyline (its rest, natural shape).

    The rod lives in its world's solver; this handle holds the world and the rod's identity, so it
    stays valid while other rods are added to or removed from the world. Its methods (clamps,
    pins, grabs, state) are the Rust core's (`_core.Rod`), documented there; the reports of the
    solves are wrapped here. Vertices may be given negative, counting from the end.

    Args:
        polyline: (N, 3) vertex positions [m], N >= 2, no zero-length edges (see
            `merge_coincident`).
        params: the material as a `RodParams`, or
        **material: its fields as keywords (radius=..., youngs_modulus=..., ...), the others at
            `RodParams`'s defaults (the rod crate's).
        world: the world to add the rod to; a private one by default.

    Raises:
        SimulationError: bad polyline (shape, NaN, zero-length edge, fold-back) or parameters.
    """

    _world: World
    _params: RodParams

    def __new__(
        cls,
        polyline: npt.ArrayLike,
        *,
        params: RodParams | None = None,
        world: World | None = None,
        **material: Any,
    ) -> Rod:
        if params is None:
            unknown = set(material) - set(RodParams.__dataclass_fields__)
            if unknown:
                raise SimulationError(f"unknown material field(s) {', '.join(sorted(unknown))}; see RodParams")
            params = RodParams(**material)
        elif material:
            raise SimulationError("give the material either as params=RodParams(...) or as keywords, not both")
        world = world if world is not None else World()
        p = params
        rod = super().__new__(
            cls,
            world._raw,
            _rod_points(polyline),
            float(p.radius),
            float(p.youngs_modulus),
            None if p.shear_modulus is None else float(p.shear_modulus),
            float(p.poisson_ratio),
            float(p.density),
            float(p.damping),
            _vec3(p.gravity, "gravity"),
        )
        rod._world, rod._params = world, p
        world._rods.append(rod)
        return rod

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        pass  # made in __new__

    @property
    def world(self) -> World:
        return self._world

    @property
    def params(self) -> RodParams:
        return self._params

    def step(self, dt: float, n: int = 1) -> StepReport:
        """Advances the rod's whole world by `dt` seconds, `n` times; returns this rod's report."""
        return self.world.step(dt, n)[self.index]

    def solve_static(self) -> StaticReport:
        """Moves the rod to its equilibrium under gravity and constraints (Newton on the
        potential, no inertia); velocities zeroed."""
        it, conv, e = self._solve_static()
        if not conv:
            logger.warning("rod %d: static solve did not converge in %d iterations", self.index, it)
        return StaticReport(int(it), bool(conv), float(e))

    def hold_under_gravity(self) -> HoldReport:
        """Changes the rest shape so that the rod stays in its current shape under its gravity
        with its current pins and clamps (an inverse static solve, docs/contact.md): a captured
        hanging cable then does not sag before it is pulled. No change without gravity.

        Raises:
            SimulationError: no rest shape holds the shape (its pins and clamps cannot carry its
                weight; clamp an end, or turn gravity off).
        """
        iterations, deviation = self._hold_under_gravity()
        return HoldReport(int(iterations), float(deviation))

    def energy(self) -> RodEnergy:
        """Stretch, bend, twist, kinetic and gravitational energy [J]."""
        return RodEnergy(**{k: float(v) for k, v in self._energy().items()})

    def frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(edge frames (N-1, 3, 3), vertex frames (N, 3, 3)) as rotation matrices."""
        return self.edge_frames, self.vertex_frames

    def __repr__(self) -> str:
        where = f"rod {self.index} of {len(self._world)}" if self in self._world._rods else "detached"
        return (
            f"Rod({self.num_vertices} vertices, radius={self._params.radius}, E={self._params.youngs_modulus}, {where})"
        )
