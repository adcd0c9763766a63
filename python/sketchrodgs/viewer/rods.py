"""The rods of a viewer session: built from extractions, stepped together, skinning the scene.

No viser here: the app drives a `RodSet` from the browser's events and a simulation thread, and
tests drive it directly. Every method takes the set's lock, so the event loop (grab, move,
release) and the simulation thread (step) may call it concurrently.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import SketchRodGSError
from ..extract import Extraction
from ..rig import Rig, clamped_end_weights
from ..rod import Rod, RodParams, World
from ..scene import GaussianScene
from ..skin import BoundRod, skin_into

# A rod sleeps (is no longer stepped or sent) once no vertex moved more than this fraction of
# its length per frame for SLEEP_FRAMES frames in a row, with nothing grabbed.
SLEEP_TOLERANCE = 1e-6
SLEEP_FRAMES = 10


@dataclass
class RodEntry:
    """One rod of the session.

    Attributes:
        id: stable identifier (never reused in a session), names its scene nodes.
        extraction: what it was built from; its binding holds only the Gaussians this rod owns.
        rod: the simulated rod (in the set's world).
        bound: its Gaussians, bound at rest.
        rest_edge_frames: (M-1, 3, 3) edge material frames at rest.
        length: rest length of the polyline.
        pieces: rows its needle splitting appended to the set's scene (bound or not).
        split: the input rows it split (their rows hold a first piece until it is removed).
    """

    id: int
    extraction: Extraction
    rod: Rod
    bound: BoundRod
    rest_edge_frames: np.ndarray
    length: float
    pieces: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0, np.int64))
    split: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0, np.int64))

    @property
    def gaussian_ids(self) -> np.ndarray:
        return self.bound.gaussian_ids

    def edge_rotations(self) -> np.ndarray:
        """(M-1, 3, 3) rotation of each edge's frame from rest to now (world axes)."""
        return np.asarray(self.rod.edge_frames, np.float64) @ np.transpose(self.rest_edge_frames, (0, 2, 1))


class RodSet:
    """Rods over one scene.

    Each rod's needle Gaussians are split when it is added (docs/deformation.md, "Subdivision"):
    the pieces are appended to `scene`, which so grows; `source` maps its rows to the input's.
    When a rod is removed its Gaussians go back to the input's and its extra pieces are hidden
    (opacity 0, left out of `export_scene`); `reset` rebuilds everything from the input.

    Args:
        scene: the scene at rest.
        params: material of new rods (each takes its extraction's radius).
        clamp_ends: clamp both ends of every rod (the authors' app does).
        skin_each_frame: skin the scene in every `step`; when False, `skinned` and
            `deformed_scene` skin on demand (for displays that move Gaussians by segment poses).
        subdivide: split needles when a rod is added.

    Attributes:
        scene: the input scene with the pieces of split needles appended (see above).
        source: (N',) int64 the input row of each row of `scene`.
        hidden: (N',) bool the pieces of removed rods.
        means, quats, scales: (N, 3), (N, 4) and (N, 3) float32, the scene's Gaussians as last
            skinned (rows of no rod stay at rest); see `skinned`.
        lock: held by every method; hold it to read `means`, `quats`, `scales` or the rods
            consistently.
    """

    def __init__(
        self,
        scene: GaussianScene,
        params: RodParams = RodParams(),
        clamp_ends: bool = True,
        skin_each_frame: bool = True,
        subdivide: bool = True,
    ) -> None:
        self.input_scene = scene
        self.scene = scene
        self.source = np.arange(len(scene), dtype=np.int64)
        self.hidden = np.zeros(len(scene), bool)
        self.subdivide = subdivide
        self.params = params
        self.clamp_ends = clamp_ends
        self.skin_each_frame = skin_each_frame
        self._stale = False
        self.lock = threading.RLock()
        self.means = scene.means.copy()
        self.quats = scene.quats.copy()
        self.scales = scene.scales.copy()
        self._world = World()
        self._entries: list[RodEntry] = []
        self._next_id = 0
        self._awake = False
        self._quiet = 0
        self._previous: list[np.ndarray] = []
        self.version = 0  # bumped whenever rods are added, removed or rebuilt

    # ----- rods -----

    @property
    def entries(self) -> list[RodEntry]:
        with self.lock:
            return list(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def get(self, rod_id: int) -> RodEntry:
        with self.lock:
            for entry in self._entries:
                if entry.id == rod_id:
                    return entry
        raise SketchRodGSError(f"no rod {rod_id}")

    def owned_ids(self) -> np.ndarray:
        """(K,) int64 the Gaussians (rows of `scene`) that follow some rod."""
        with self.lock:
            if not self._entries:
                return np.empty(0, np.int64)
            return np.concatenate([e.gaussian_ids for e in self._entries])

    def off_scene_node(self) -> np.ndarray:
        """(K,) int64 rows the scene node leaves out: the rods' and the hidden ones."""
        with self.lock:
            return np.concatenate([self.owned_ids(), np.flatnonzero(self.hidden)])

    def add(self, extraction: Extraction) -> RodEntry:
        """Build a rod from `extraction` and bind its Gaussians; those already owned by another
        rod stay with that rod.

        Raises:
            SketchRodGSError: the extraction binds Gaussians the scene does not have, or its
                polyline cannot be a rod (SimulationError).
        """
        ids = extraction.binding.gaussian_ids
        if len(ids) and (ids.min() < 0 or ids.max() >= len(self.scene)):
            raise SketchRodGSError(f"rod binds Gaussian {int(ids.max())} but the scene has {len(self.scene)}")
        with self.lock:
            keep = ~np.isin(ids, self.owned_ids()) & ~self.hidden[ids]
            extraction = _keep_binding(extraction, keep)
            entry = self._build(self._next_id, extraction, self._world)
            self._next_id += 1
            self._entries.append(entry)
            self._previous.append(np.asarray(entry.rod.positions))
            self.version += 1
            return entry

    def remove(self, rod_id: int) -> None:
        """Remove a rod; its Gaussians go back to the input's at rest and stay there (the extra
        pieces of its split needles are hidden)."""
        with self.lock:
            entry = self.get(rod_id)
            k = self._entries.index(entry)
            self.skinned()  # the other rods' Gaussians stay where they are
            self._world.remove(entry.rod)
            self._entries.pop(k)
            self._previous.pop(k)
            arrays = {f: getattr(self.scene, f).copy() for f in ("means", "quats", "scales", "opacities")}
            for field, values in arrays.items():
                values[entry.split] = getattr(self.input_scene, field)[entry.split]
            arrays["opacities"][entry.pieces] = 0.0
            self.scene = self.scene.replace(**arrays)
            self.hidden[entry.pieces] = True
            for rows in (entry.gaussian_ids, entry.split):
                self.means[rows] = self.scene.means[rows]
                self.quats[rows] = self.scene.quats[rows]
                self.scales[rows] = self.scene.scales[rows]
            self.version += 1

    def clear(self) -> None:
        with self.lock:
            for entry in list(self._entries):
                self.remove(entry.id)

    def reset(self) -> None:
        """Every rod back to rest (rebuilt from the input scene with the current material and
        clamps), nothing grabbed, nothing hidden."""
        with self.lock:
            world = World()
            self.scene, self.source = self.input_scene, np.arange(len(self.input_scene), dtype=np.int64)
            self.hidden = np.zeros(len(self.scene), bool)
            self.means, self.quats, self.scales = (getattr(self.scene, f).copy() for f in ("means", "quats", "scales"))
            entries = list(self._entries)
            self._entries = []
            for e in entries:  # each binds with the ones before it taken
                self._entries.append(self._build(e.id, e.extraction, world))
            self._world = world
            self._previous = [np.asarray(e.rod.positions) for e in self._entries]
            self._stale = False
            self._awake = False
            self.version += 1

    def set_params(self, params: RodParams) -> None:
        """New material for every rod; the rods restart from rest."""
        with self.lock:
            self.params = params
            self.reset()

    def set_clamp_ends(self, clamp: bool) -> None:
        """Clamp (where they are now) or free both ends of every rod, live."""
        with self.lock:
            self.clamp_ends = clamp
            for entry in self._entries:
                for end in (0, -1):
                    if clamp:
                        entry.rod.clamp(end)
                    else:
                        entry.rod.free(end)
                entry.bound = _eased(entry.bound, entry)
            self.wake()

    def _build(self, rod_id: int, extraction: Extraction, world: World) -> RodEntry:
        material = RodParams(**{**self.params.to_dict(), "radius": extraction.radius})
        rod = Rod(extraction.polyline, params=material, world=world)
        if self.clamp_ends:
            rod.clamp(0)
            rod.clamp(-1)
        taken = np.zeros(len(self.scene), bool)
        taken[self.owned_ids()] = True
        taken |= self.hidden
        rig = Rig.build(self.scene, [extraction], [rod], subdivide=self.subdivide, taken=taken)
        old = len(self.scene)
        pieces = np.arange(old, len(rig.scene), dtype=np.int64)
        split = np.unique(rig.source[pieces])
        # take the rig's scene: its new rows appended, its split rows replaced (all at rest)
        self.source = self.source[rig.source]
        self.hidden = np.concatenate([self.hidden, np.zeros(len(pieces), bool)])
        self.scene = rig.scene
        for field in ("means", "quats", "scales"):
            grown = np.concatenate([getattr(self, field), getattr(rig.scene, field)[old:]])
            grown[split] = getattr(rig.scene, field)[split]
            setattr(self, field, np.ascontiguousarray(grown))
        polyline = np.asarray(extraction.polyline, np.float64)
        length = float(np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum())
        return RodEntry(
            rod_id, extraction, rod, rig.bound[0], np.array(rod.edge_frames, np.float64), length, pieces, split
        )

    # ----- interaction -----

    def grab(self, rod_id: int, vertex: int, target: Sequence[float] | np.ndarray) -> None:
        """From the next step on, `vertex` of rod `rod_id` follows `target`."""
        with self.lock:
            self.get(rod_id).rod.grab(vertex, target)
            self.wake()

    def move_grab(self, rod_id: int, target: Sequence[float] | np.ndarray) -> None:
        with self.lock:
            rod = self.get(rod_id).rod
            if rod.grabbed is not None:
                rod.move_grab(target)
                self.wake()

    def release(self, rod_id: int) -> None:
        with self.lock:
            for entry in self._entries:
                if entry.id == rod_id and entry.rod.grabbed is not None:
                    entry.rod.release()
            self.wake()

    def grabbed(self) -> dict[int, int]:
        """Rod id -> grabbed vertex, for the rods held now."""
        with self.lock:
            return {e.id: g[0] for e in self._entries if (g := e.rod.grabbed) is not None}

    # ----- time -----

    @property
    def awake(self) -> bool:
        return self._awake

    def wake(self) -> None:
        with self.lock:
            self._awake = bool(self._entries)
            self._quiet = 0

    def step(self, dt: float) -> dict[str, float] | None:
        """Advance every rod by `dt` seconds and skin `means`/`quats`; None when asleep.

        Returns:
            Seconds spent: "simulate" and "skin".
        """
        with self.lock:
            if not self._awake:
                return None
            clock = time.perf_counter()
            self._world.step(dt)
            simulate = time.perf_counter() - clock
            clock = time.perf_counter()
            if self.skin_each_frame:
                self._skin()
            else:
                self._stale = True
            skin = time.perf_counter() - clock
            moving = False
            for k, entry in enumerate(self._entries):
                now = np.asarray(entry.rod.positions)
                moving |= float(np.abs(now - self._previous[k]).max()) > SLEEP_TOLERANCE * entry.length
                moving |= entry.rod.grabbed is not None
                self._previous[k] = now
            self._quiet = 0 if moving else self._quiet + 1
            if self._quiet >= SLEEP_FRAMES:
                self._awake = False
            return {"simulate": simulate, "skin": skin}

    def _skin(self) -> None:
        skin_into(self.means, self.quats, self.scales, [e.bound for e in self._entries], [e.rod for e in self._entries])
        self._stale = False

    def skinned(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(means, quats, scales) of the scene now, skinning first if a step left them stale (hold
        `lock` while using them)."""
        with self.lock:
            if self._stale:
                self._skin()
            return self.means, self.quats, self.scales

    def deformed_scene(self) -> GaussianScene:
        """The scene now (copies; the rows of `scene`, hidden ones included at opacity 0)."""
        with self.lock:
            means, quats, scales = self.skinned()
            return self.scene.replace(means=means.copy(), quats=quats.copy(), scales=scales.copy())

    def export_scene(self) -> GaussianScene:
        """The scene now without the hidden rows (what "Export deformed .ply" writes)."""
        with self.lock:
            scene = self.deformed_scene()
            return scene if not self.hidden.any() else scene.subset(np.flatnonzero(~self.hidden))


def _eased(bound: BoundRod, entry: RodEntry) -> BoundRod:
    """`bound` with its motion easing in at the rod's clamped ends (docs/deformation.md)."""
    weight = clamped_end_weights(bound, entry.rod, entry.extraction).astype(np.float32)
    return dataclasses.replace(bound, weight=weight)


def _keep_binding(extraction: Extraction, keep: np.ndarray) -> Extraction:
    """`extraction` with only the bound Gaussians where `keep` is True."""
    if keep.all():
        return extraction
    binding = extraction.binding.take(keep)
    return dataclasses.replace(extraction, gaussian_ids=binding.gaussian_ids, binding=binding)
