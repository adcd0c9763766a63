"""Argument types shared by the subcommands."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from .. import data


def scene_path(value: str) -> str:
    """A scene file path, or `sample:NAME` for a bundled sample."""
    if value.startswith("sample:"):
        name = value.removeprefix("sample:")
        if name not in data.SAMPLES:
            raise argparse.ArgumentTypeError(f"no sample named {name!r} (samples: {', '.join(data.SAMPLES)})")
        return str(data.sample(name))
    return value


def number_triple(labels: str) -> Callable[[str], tuple[float, float, float]]:
    """A parser of three finite comma-separated numbers; `labels` (e.g. "R,G,B") names them in errors."""

    def parse(value: str) -> tuple[float, float, float]:
        try:
            parts = tuple(float(v) for v in value.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {labels} numbers, got {value!r}") from None
        if len(parts) != 3 or not all(math.isfinite(p) for p in parts):
            raise argparse.ArgumentTypeError(f"expected three finite numbers {labels}, got {value!r}")
        return parts  # type: ignore[return-value]

    return parse


def non_negative(value: str) -> float:
    """A finite number >= 0."""
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not (math.isfinite(number) and number >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {value}")
    return number


def positive(value: str) -> float:
    """A finite number > 0."""
    number = non_negative(value)
    if number == 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {value}")
    return number
