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

    from ..io import FORMAT_NAMES, detect_format, format_up, load_scene, save_scene
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
    up = format_up(args.input)
    if up is not None:
        # the coordinates are kept (so is the scene's identity, which rod files check), but the
        # written format does not say which way is up
        logging.getLogger("sketchrodgs").warning(
            "%s is %s up by %s; %s keeps its coordinates, and is guessed from its shape when read: "
            "give --up %s to camera, render and view",
            args.input,
            up[0],
            up[1],
            args.output,
            up[0],
        )
    print(
        f"{args.input} ({FORMAT_NAMES[source_format]}) -> {args.output}: {len(scene):,} Gaussians, "
        f"SH degree {0 if splat else scene.sh_degree}, {os.path.getsize(args.output) / 1e6:.2f} MB"
    )
    return 0
