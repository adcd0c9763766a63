"""The simulation thread: steps the rods at a fixed rate, skins, and pushes each frame to the browser.

Each tick advances the rods by 1/fps seconds of simulated time; when a frame takes longer than a
tick the simulation runs slower than real time rather than taking bigger steps. Rods at rest
sleep (see `RodSet.step`): nothing is stepped or sent until they are grabbed again.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from .display import SceneDisplay
from .rods import RodSet

logger = logging.getLogger("sketchrodgs")

STAGES = ("simulate", "skin", "push", "frame")


class FrameTimings:
    """Per-stage seconds of the last `window` frames (thread-safe)."""

    def __init__(self, window: int = 60) -> None:
        self._lock = threading.Lock()
        self._frames: deque[dict[str, float]] = deque(maxlen=window)
        self._stamps: deque[float] = deque(maxlen=window)
        self.count = 0

    def record(self, timings: dict[str, float]) -> None:
        with self._lock:
            self._frames.append(timings)
            self._stamps.append(time.perf_counter())
            self.count += 1

    def mean(self) -> dict[str, float]:
        """Mean seconds per stage over the window (empty when no frame was recorded)."""
        with self._lock:
            if not self._frames:
                return {}
            return {s: float(np.mean([f.get(s, 0.0) for f in self._frames])) for s in STAGES}

    def rate(self) -> float:
        """Frames per second over the window (0 when fewer than two frames)."""
        with self._lock:
            if len(self._stamps) < 2 or self._stamps[-1] <= self._stamps[0]:
                return 0.0
            return (len(self._stamps) - 1) / (self._stamps[-1] - self._stamps[0])

    def summary(self) -> str:
        mean = self.mean()
        if not mean:
            return "no frames yet"
        stages = " · ".join(f"{s} {1e3 * mean[s]:.2f} ms" for s in STAGES)
        return f"{stages} · {self.rate():.0f} Hz"


class SimulationLoop:
    """Steps `rods` and pushes them with `display` at `fps`, on its own thread.

    Args:
        rods: the rods.
        display: the browser's scene nodes.
        fps: frames per second (simulated seconds per frame = 1 / fps).
        on_frame: called after each pushed frame (from the thread) with the timings.
    """

    def __init__(
        self,
        rods: RodSet,
        display: SceneDisplay,
        fps: float = 60.0,
        on_frame: Callable[[dict[str, float]], None] | None = None,
    ) -> None:
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps: must be > 0, got {fps}")
        self.rods = rods
        self.display = display
        self.dt = 1.0 / fps
        self.timings = FrameTimings()
        self._on_frame = on_frame
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sketchrodgs-simulation", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def frame(self) -> dict[str, float] | None:
        """Step and push one frame now (None when every rod sleeps)."""
        clock = time.perf_counter()
        with self.rods.lock:
            timings = self.rods.step(self.dt)
            if timings is None:
                return None
            timings.update(self.display.push(self.rods))
        timings["frame"] = time.perf_counter() - clock
        self.timings.record(timings)
        return timings

    def _run(self) -> None:
        deadline = time.perf_counter()
        while not self._stop.is_set():
            try:
                timings = self.frame()
            except Exception:  # a failing frame must not kill the viewer: log it, keep going
                logger.exception("simulation frame failed")
                timings = None
            if timings is not None and self._on_frame is not None:
                self._on_frame(timings)
            deadline = max(deadline + self.dt, time.perf_counter())
            self._stop.wait(max(0.0, deadline - time.perf_counter()))
