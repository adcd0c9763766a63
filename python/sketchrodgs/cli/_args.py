"""Argument types shared by the subcommands."""

from __future__ import annotations

import argparse

from .. import data


def scene_path(value: str) -> str:
    """A scene file path, or `sample:NAME` for a bundled sample."""
    if value.startswith("sample:"):
        name = value.removeprefix("sample:")
        if name not in data.SAMPLES:
            raise argparse.ArgumentTypeError(f"no sample named {name!r} (samples: {', '.join(data.SAMPLES)})")
        return str(data.sample(name))
    return value
