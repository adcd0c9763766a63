"""Argument types and help texts shared by the subcommands.

Kept free of numpy and the compiled core so that `--help` and `--version` start fast.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from pathlib import Path

from .. import data


class UsageError(Exception):
    """A combination of arguments that cannot work, found after parsing (exit code 2)."""


def scene_help() -> str:
    """The help text of a SCENE argument, with the bundled samples' names."""
    return (
        "scene file (INRIA .ply, compressed .ply, .splat, .spz), a 3DGS training output folder, "
        f"or sample:NAME for a bundled sample ({', '.join(data.SAMPLES)})"
    )


def scene_path(value: str) -> str:
    """A scene file path, a 3DGS training output folder, or `sample:NAME` for a bundled sample."""
    if value.startswith("sample:"):
        name = value.removeprefix("sample:")
        if name not in data.SAMPLES:
            raise argparse.ArgumentTypeError(f"no sample named {name!r} (samples: {', '.join(data.SAMPLES)})")
        return str(data.sample(name))
    return value


def numbers(count: int, labels: str) -> Callable[[str], tuple[float, ...]]:
    """A parser of `count` finite comma-separated numbers; `labels` (e.g. "R,G,B") names them."""

    def parse(value: str) -> tuple[float, ...]:
        try:
            parts = tuple(float(v) for v in value.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {labels} numbers, got {value!r}") from None
        if len(parts) != count or not all(math.isfinite(p) for p in parts):
            raise argparse.ArgumentTypeError(f"expected {count} finite numbers {labels}, got {value!r}")
        return parts

    return parse


# A value that starts like a negative number and holds a comma ("-0.02,0,0") is never an option,
# but argparse takes any word starting with "-" that is not a plain number for one.
_NEGATIVE_LIST = re.compile(r"-\.?\d[^=]*,.*")


def attach_negative_lists(argv: list[str]) -> list[str]:
    """`--to -0.02,0,0` as `--to=-0.02,0,0`, so that argparse reads it as the option's value."""
    out: list[str] = []
    for word in argv:
        previous = out[-1] if out else ""
        if _NEGATIVE_LIST.fullmatch(word) and previous.startswith("-") and "=" not in previous and previous != "--":
            out[-1] = f"{previous}={word}"
        else:
            out.append(word)
    return out


def vertex_or_fraction(value: str) -> int | float:
    """A rod vertex (an integer; negative counts from the end) or a fraction of the rod's length
    from its start (a number with a decimal point, 0.0 to 1.0)."""
    try:
        if re.fullmatch(r"[+-]?\d+", value):
            return int(value)
        fraction = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a vertex (e.g. 12, -1) or a fraction (e.g. 0.5), got {value!r}"
        ) from None
    if not 0 <= fraction <= 1:
        raise argparse.ArgumentTypeError(f"a fraction along the rod must be in 0.0..1.0, got {value}")
    return fraction


def _number(value: str) -> float:
    try:
        return float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None


def non_negative(value: str) -> float:
    """A finite number >= 0."""
    number = _number(value)
    if not (math.isfinite(number) and number >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {value}")
    return number


def positive(value: str) -> float:
    """A finite number > 0."""
    number = _number(value)
    if not (math.isfinite(number) and number > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {value}")
    return number


def in_range(low: float, high: float, what: str = "a number") -> Callable[[str], float]:
    """A number in low..high (`what` names it in the message: "a number of seconds")."""

    def parse(value: str) -> float:
        try:
            number = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {value!r}") from None
        if not low <= number <= high:
            raise argparse.ArgumentTypeError(f"must be in {low:g}..{high:g}, got {value}")
        return number

    return parse


def pixels(value: str) -> int:
    """An image side in pixels (>= 1)."""
    try:
        side = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of pixels, got {value!r}") from None
    if side < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1 pixel, got {side}")
    return side


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def output_file(*suffixes: str) -> Callable[[str], str]:
    """A path to write whose name must end in one of `suffixes` (checked before any work)."""

    def parse(value: str) -> str:
        if Path(value).suffix.lower() not in suffixes:
            kinds = ", ".join(suffixes[:-1]) + (" or " if len(suffixes) > 1 else "") + suffixes[-1]
            raise argparse.ArgumentTypeError(f"{value}: expected a file name ending in {kinds}")
        return value

    return parse
