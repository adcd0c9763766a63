"""Undo and redo of rod operations (extract, remove, clamps, pins, material).

Each operation is recorded as a `Step` that knows how to undo and redo itself; the session's
history is shared by every tab, as the rods are.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

HISTORY_LIMIT = 200
MERGE_SECONDS = 2.0  # steps with the same merge key this close together are one step (a slider drag)


@dataclass
class Step:
    """One operation: what it is called, and how to undo and redo it.

    Attributes:
        label: what the user did, e.g. "remove rod 2".
        undo: puts things back as they were before.
        redo: does it again.
        merge: steps with the same non-empty key recorded within MERGE_SECONDS are merged.
    """

    label: str
    undo: Callable[[], object]
    redo: Callable[[], object]
    merge: str = ""
    time: float = 0.0


class History:
    """The undo and redo stacks (thread-safe)."""

    def __init__(self, limit: int = HISTORY_LIMIT) -> None:
        self.limit = limit
        self._done: list[Step] = []
        self._undone: list[Step] = []
        self._lock = threading.RLock()

    def record(self, step: Step) -> None:
        """Remember a step just taken (what was undone can no longer be redone)."""
        with self._lock:
            step.time = time.monotonic()
            last = self._done[-1] if self._done else None
            if last is not None and step.merge and last.merge == step.merge and step.time - last.time < MERGE_SECONDS:
                self._done[-1] = Step(step.label, last.undo, step.redo, step.merge, step.time)
            else:
                self._done.append(step)
                del self._done[: -self.limit]
            self._undone.clear()

    def undo(self) -> Step | None:
        """Undo the last step; returns it (None when there is nothing to undo)."""
        with self._lock:
            if not self._done:
                return None
            step = self._done[-1]
            step.undo()  # if this raises, the step stays where it was
            self._undone.append(self._done.pop())
            return step

    def redo(self) -> Step | None:
        """Redo the last step undone; returns it (None when there is nothing to redo)."""
        with self._lock:
            if not self._undone:
                return None
            step = self._undone[-1]
            step.redo()
            self._done.append(self._undone.pop())
            return step

    @property
    def can_undo(self) -> bool:
        return bool(self._done)

    @property
    def can_redo(self) -> bool:
        return bool(self._undone)

    def next_undo(self) -> str | None:
        """Label of the step `undo` would undo."""
        with self._lock:
            return self._done[-1].label if self._done else None

    def next_redo(self) -> str | None:
        with self._lock:
            return self._undone[-1].label if self._undone else None
