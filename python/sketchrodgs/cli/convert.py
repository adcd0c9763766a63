"""`sketchrodgs convert IN OUT`: rewrite a scene in another format."""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

from ..errors import SceneFormatError
from ..io import FORMAT_NAMES, detect_format, load_scene, save_scene
from ._args import scene_path

NAME = "convert"
HELP = "convert a scene (.ply, compressed .ply, .splat, .spz) to INRIA .ply or .splat"

logger = logging.getLogger("sketchrodgs")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", type=scene_path, help="scene file in any readable format, or sample:NAME")
    parser.add_argument("output", help="file to write; its extension (.ply or .splat) picks the format")


def run(args: argparse.Namespace) -> int:
    suffix = Path(args.output).suffix.lower()
    if suffix not in (".ply", ".splat"):
        # checked before reading, so a typo does not cost a long load
        raise SceneFormatError(f"{args.output}: cannot write '{suffix}' files (use .ply or .splat)")
    source_format = detect_format(args.input)
    scene = load_scene(args.input)
    if suffix == ".splat" and scene.sh_degree > 0:
        logger.warning(".splat keeps only the DC colour: SH degree %d dropped", scene.sh_degree)
    save_scene(scene, args.output)
    print(
        f"{args.input} ({FORMAT_NAMES[source_format]}) -> {args.output}: {len(scene):,} Gaussians, "
        f"SH degree {scene.sh_degree if suffix == '.ply' else 0}, {os.path.getsize(args.output) / 1e6:.2f} MB"
    )
    return 0
