"""`sketchrodgs convert IN OUT`: rewrite a scene in another format."""

from __future__ import annotations

import argparse

from ._args import output_file, scene_help, scene_path

NAME = "convert"
HELP = "convert a scene (.ply, compressed .ply, .splat, .spz, a 3DGS training output folder) to INRIA .ply or .splat"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", type=scene_path, help=scene_help())
    parser.add_argument(
        "output",
        type=output_file(".ply", ".splat"),
        help="file to write; its extension (.ply or .splat) picks the format",
    )


def run(args: argparse.Namespace) -> int:
    import logging
    import os
    from pathlib import Path

    from ..io import FORMAT_NAMES, detect_format, load_scene, save_scene
    from ._outputs import Outputs

    with Outputs() as outputs:
        staged = outputs.file(args.output, "OUT")  # checked before the (possibly long) read
        source_format = detect_format(args.input)
        scene = load_scene(args.input)
        splat = Path(args.output).suffix.lower() == ".splat"
        if splat and scene.sh_degree > 0:
            logging.getLogger("sketchrodgs").warning(
                ".splat keeps only the DC colour: SH degree %d dropped", scene.sh_degree
            )
        save_scene(scene, staged)
        outputs.commit()
    print(
        f"{args.input} ({FORMAT_NAMES[source_format]}) -> {args.output}: {len(scene):,} Gaussians, "
        f"SH degree {0 if splat else scene.sh_degree}, {os.path.getsize(args.output) / 1e6:.2f} MB"
    )
    return 0
