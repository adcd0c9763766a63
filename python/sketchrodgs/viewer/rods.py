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

from ..contact import SceneField
from ..errors import SketchRodGSError
from ..rig import Rig, clamped_end_weights
from ..rod import ContactSettings, Rod, SimulationError, World
from ..rod_file import Extraction
from ..scene import GaussianScene
from ..segment import check_rows
from ..skin import BoundRod, skin_into
from .material import CLAMPS, Clamp, Material

# A rod sleeps (is no longer stepped or sent) once no vertex moved more than this fraction of
# its length per frame for SLEEP_FRAMES frames in a row, with nothing grabbed.
SLEEP_TOLERANCE = 1e-6
SLEEP_FRAMES = 10
# A new rod most of whose Gaussians follow one rod already is that rod again (the same stroke twice).
REPEAT_SHARE = 0.5


class RodRefused(SketchRodGSError):
    """The set will not add this rod: it would bind no Gaussians, or it repeats a rod it has."""


@dataclass
class RodEntry:
    """One rod of the session.

    Attributes:
        id: stable identifier (a removed rod's is only reused when it is put back), names its nodes.
        extraction: what it was built from; its binding holds only the Gaussians this rod owns.
        rod: the simulated rod (in the set's world).
        bound: its Gaussians, bound at rest.
        rest_edge_frames: (M-1, 3, 3) edge material frames at rest.
        length: rest length of the polyline.
        clamp: which ends are held: "both", "start", "end" or "none".
        pins: vertices pinned in place (their position held, their frame free).
        pieces: rows its needle splitting appended to the set's scene (bound or not).
        split: the input rows it split (their rows hold a first piece until it is removed).
    """

    id: int
    extraction: Extraction
    rod: Rod
    bound: BoundRod
    rest_edge_frames: np.ndarray
    length: float
    clamp: Clamp = "both"
    pins: frozenset[int] = frozenset()
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
    (opacity 0, left out of `export_scene`). Material, clamps and `reset` rebuild the simulated
    rods at rest and keep the scene's rows, so the browser is sent nothing but their poses.

    Args:
        scene: the scene at rest.
        material: how the rods swing (default `Material()`; each takes its extraction's radius).
        clamp: how new rods are held ("both" ends, as in the authors' app).
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
        material: Material | None = None,
        clamp: Clamp = "both",
        skin_each_frame: bool = True,
        subdivide: bool = True,
    ) -> None:
        if clamp not in CLAMPS:
            raise SketchRodGSError(f"clamp: expected one of {', '.join(CLAMPS)}, got {clamp!r}")
        self.input_scene = scene
        self.scene = scene
        self.source = np.arange(len(scene), dtype=np.int64)
        self.hidden = np.zeros(len(scene), bool)
        self.subdivide = subdivide
        self.material = material or Material()
        self.clamp = clamp
        self.skin_each_frame = skin_each_frame
        self._stale = False
        self.lock = threading.RLock()
        self.means = scene.means.copy()
        self.quats = scene.quats.copy()
        self.scales = scene.scales.copy()
        self._world = World()
        self._world.contact = ContactSettings(scene=True, rods=True)
        self._entries: list[RodEntry] = []
        self._falling: list[Rod] = []  # made since `take_falling`, unable to hang under gravity
        self._next_id = 0
        self._awake = False
        self._quiet = 0
        self._previous: list[np.ndarray] = []
        self._changed: list[np.ndarray] = []  # rows of `scene` whose Gaussian was replaced
        self.layout = 0  # bumped whenever rods are added or removed (what the contact field depends on)

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
        raise SketchRodGSError(f"there is no rod {rod_id}")

    def owned_ids(self) -> np.ndarray:
        """(K,) int64 the Gaussians (rows of `scene`) that follow some rod."""
        with self.lock:
            if not self._entries:
                return np.empty(0, np.int64)
            return np.concatenate([e.gaussian_ids for e in self._entries])

    def static_rows(self) -> np.ndarray:
        """(N',) bool the rows drawn at rest: of no rod and not hidden."""
        with self.lock:
            static = ~self.hidden
            static[self.owned_ids()] = False
            return static

    def take_changed_rows(self) -> np.ndarray:
        """(K,) int64 rows of `scene` whose Gaussian was replaced since the last call (rows a rod
        split or gave back; rows appended since are not included)."""
        with self.lock:
            rows = np.unique(np.concatenate(self._changed)) if self._changed else np.empty(0, np.int64)
            self._changed = []
            return rows

    def add(
        self, extraction: Extraction, rod_id: int | None = None, clamp: Clamp | None = None, pins: Sequence[int] = ()
    ) -> RodEntry:
        """Build a rod from `extraction` and bind its Gaussians; those already owned by another
        rod stay with that rod.

        Args:
            extraction: the rod.
            rod_id: its id (to put a removed rod back); default a new one.
            clamp: how it is held (default `self.clamp`).
            pins: vertices to pin.

        Raises:
            RodRefused: most of its Gaussians follow one rod already (the same stroke twice), or
                none would follow it.
            SketchRodGSError: the extraction binds Gaussians the scene does not have, its polyline
                cannot be a rod (SimulationError), or `rod_id` is taken.
        """
        ids = extraction.binding.gaussian_ids
        with self.lock:
            check_rows(ids, len(self.scene), "rod")
            if rod_id is not None and any(e.id == rod_id for e in self._entries):
                raise SketchRodGSError(f"rod {rod_id} exists already")
            for entry in self._entries:
                mine = np.isin(ids, self.source[entry.gaussian_ids])
                if len(ids) and mine.mean() > REPEAT_SHARE:
                    raise RodRefused(f"that is rod {entry.id} again: select it under Rods to change or remove it")
            keep = ~np.isin(ids, self.owned_ids()) & ~self.hidden[ids]
            if not keep.any():
                raise RodRefused(
                    "no Gaussian under the stroke would follow it"
                    + (" (they all follow other rods)" if len(ids) else "")
                    + ": draw along a part that is not a rod yet"
                )
            extraction = _keep_binding(extraction, keep)
            rod_id = self._next_id if rod_id is None else rod_id
            entry = self._build(rod_id, extraction, clamp or self.clamp, frozenset(pins))
            self._next_id = max(self._next_id, rod_id + 1)
            self._entries.append(entry)
            self._entries.sort(key=lambda e: e.id)
            self._previous = [np.asarray(e.rod.positions) for e in self._entries]
            self._changed.append(entry.split)
            self.layout += 1
            return entry

    def remove(self, rod_id: int) -> RodEntry:
        """Remove a rod and return it; its Gaussians go back to the input's at rest and stay there
        (the extra pieces of its split needles are hidden)."""
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
            if self.scene.sort_offsets is not None:  # the input's Gaussians sort where they did
                offsets = self.scene.sort_offsets.copy()
                given = self.input_scene.sort_offsets
                offsets[entry.split] = 0.0 if given is None else given[entry.split]
                arrays["sort_offsets"] = offsets
            self.scene = self.scene.replace(**arrays)
            self.hidden[entry.pieces] = True
            for rows in (entry.gaussian_ids, entry.split):
                self.means[rows] = self.scene.means[rows]
                self.quats[rows] = self.scene.quats[rows]
                self.scales[rows] = self.scene.scales[rows]
            self._changed.append(entry.split)
            self.layout += 1
            return entry

    def clear(self) -> list[RodEntry]:
        """Remove every rod; returns them."""
        with self.lock:
            return [self.remove(entry.id) for entry in list(self._entries)]

    def reset(self) -> None:
        """Every rod back to rest, nothing grabbed (the rods are rebuilt; the scene is kept)."""
        with self.lock:
            for entry in self._entries:
                self._rebuild(entry)

    def set_material(self, material: Material) -> None:
        """New material for every rod; the rods restart from rest."""
        with self.lock:
            self.material = material or Material()
            self.reset()

    def set_clamp(self, rod_id: int, clamp: Clamp) -> None:
        """Hold rod `rod_id` at both ends, one end or none; it restarts from rest (its E follows,
        see `Material`)."""
        if clamp not in CLAMPS:
            raise SketchRodGSError(f"clamp: expected one of {', '.join(CLAMPS)}, got {clamp!r}")
        with self.lock:
            entry = self.get(rod_id)
            entry.clamp = clamp
            self._rebuild(entry)

    def set_pinned(self, rod_id: int, vertex: int, pinned: bool) -> None:
        """Pin vertex `vertex` of rod `rod_id` where it is now, or free it, live.

        Raises:
            SketchRodGSError: no such rod or vertex, or the vertex is a clamped end.
        """
        with self.lock:
            entry = self.get(rod_id)
            count = entry.rod.num_vertices
            if not 0 <= vertex < count:
                raise SketchRodGSError(f"rod {rod_id} has no vertex {vertex} (it has {count})")
            if entry.rod.boundaries[vertex] == "clamped":
                raise SketchRodGSError(f"vertex {vertex} of rod {rod_id} is a clamped end")
            grabbed = entry.rod.grabbed
            if pinned and grabbed is not None and grabbed[0] == vertex:
                entry.rod.release()
            if pinned:
                entry.rod.pin(vertex)
                entry.pins = entry.pins | {vertex}
            else:
                entry.rod.free(vertex)
                entry.pins = entry.pins - {vertex}
            self.wake()

    def _build(self, rod_id: int, extraction: Extraction, clamp: Clamp, pins: frozenset[int]) -> RodEntry:
        polyline = np.asarray(extraction.polyline, np.float64)
        length = float(np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum())
        rod = self._new_rod(extraction, length, clamp, pins)
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
        frames = np.array(rod.edge_frames, np.float64)
        return RodEntry(rod_id, extraction, rod, rig.bound[0], frames, length, clamp, pins, pieces, split)

    def _new_rod(self, extraction: Extraction, length: float, clamp: Clamp, pins: frozenset[int]) -> Rod:
        params = self.material.rod_params(length, extraction.radius, clamp)
        rod = Rod(extraction.polyline, params=params, world=self._world)
        if clamp in ("both", "start"):
            rod.clamp(0)
        if clamp in ("both", "end"):
            rod.clamp(-1)
        for vertex in sorted(pins):
            if rod.boundaries[vertex] == "free":
                rod.pin(vertex)
        if any(self.material.gravity):
            try:  # the captured shape is the shape under gravity: it does not sag at once
                rod.hold_under_gravity()
            except SimulationError:  # nothing holds it up (no clamp): it falls, and the app says so
                self._falling.append(rod)
        return rod

    def take_falling(self) -> list[int]:
        """Ids of the rods made since the last call whose holds cannot carry them under gravity."""
        ids = [e.id for e in self._entries if any(e.rod is rod for rod in self._falling)]
        self._falling.clear()
        return ids

    def _rebuild(self, entry: RodEntry) -> None:
        """`entry`'s rod made again at rest with the set's material and its clamp and pins."""
        self._world.remove(entry.rod)
        entry.rod = self._new_rod(entry.extraction, entry.length, entry.clamp, entry.pins)
        entry.bound = _eased(entry.bound, entry)
        rows = entry.gaussian_ids
        self.means[rows] = self.scene.means[rows]
        self.quats[rows] = self.scene.quats[rows]
        self.scales[rows] = self.scene.scales[rows]
        self._previous = [np.asarray(e.rod.positions) for e in self._entries]
        self.wake()  # one frame sends the rest pose

    # ----- contact with the scene (the field is built by `contact.SceneContact`) -----

    @property
    def contact(self) -> ContactSettings:
        with self.lock:
            return self._world.contact

    def set_contact(self, on: bool, friction: float = 0.0) -> None:
        """Rods keep out of the scene's solid parts and of each other (or not), with `friction`."""
        if not (np.isfinite(friction) and friction >= 0):
            raise SketchRodGSError(f"friction: must be >= 0, got {friction}")
        with self.lock:
            self._world.contact = ContactSettings(scene=on, rods=on, friction=float(friction))
            self.wake()

    def set_scene_field(self, field: SceneField | None) -> None:
        """The scene's solid parts the rods keep out of (None: nothing)."""
        with self.lock:
            if field is None:
                self._world.set_scene_field(None)
            else:
                self._world.set_scene_field(field.values, field.origin, field.spacing)

    @property
    def has_scene_field(self) -> bool:
        with self.lock:
            return self._world.has_scene_field

    # ----- interaction -----

    def grab(self, rod_id: int, vertex: int, target: Sequence[float] | np.ndarray) -> None:
        """From the next step on, `vertex` of rod `rod_id` follows `target`.

        Raises:
            SketchRodGSError: no such rod, or the vertex is clamped or pinned.
        """
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

    def release_all(self) -> None:
        with self.lock:
            for entry in self._entries:
                if entry.rod.grabbed is not None:
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
        """The scene now without the hidden rows (what "Download deformed .ply" writes)."""
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
