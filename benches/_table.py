"""Plain-text tables for benchmark output (one table per benchmark, never a timed assertion)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence


def print_table(title: str, headers: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Print `rows` under `headers` as an aligned text table headed by `title`."""
    cells = [[str(h) for h in headers]] + [[_fmt(v) for v in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    print(f"\n## {title}\n")
    for k, row in enumerate(cells):
        print("| " + " | ".join(c.rjust(w) for c, w in zip(row, widths)) + " |")
        if k == 0:
            print("|" + "|".join("-" * (w + 2) for w in widths) + "|")


def best_time(fn: Callable[[], object], repeat: int = 5, warmup: int = 1) -> float:
    """Best wall time of `fn()` in seconds over `repeat` runs after `warmup` runs."""
    return min(wall_times(fn, repeat, warmup))


def wall_times(fn: Callable[[], object], repeat: int = 5, warmup: int = 1) -> list[float]:
    """Wall times of `fn()` in seconds, `repeat` runs after `warmup` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def _fmt(v: object) -> str:
    if isinstance(v, float):
        if v == 0 or 0.01 <= abs(v) < 1e5:
            return f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}"
        return f"{v:.3g}"
    return str(v)
