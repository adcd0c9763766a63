"""`sketchrodgs render SCENE --camera CAM.json -o out.png`: render a view to a PNG (and the index image)."""

from __future__ import annotations

import argparse
import io
import json
import time
from typing import Any

import numpy as np

from ..atomic import atomic_open
from ..camera import load_cameras, select_camera
from ..errors import SketchRodGSError
from ..images import save_png
from ..io import load_scene
from ..render import render
from ._args import number_triple, scene_path

NAME = "render"
HELP = "render a scene for a camera to a PNG, optionally with the index image K and its depth Z (.npz)"


def _side(value: str) -> int:
    try:
        side = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of pixels, got {value!r}") from None
    if side < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1 pixel, got {side}")
    return side


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help="scene file (.ply or .splat), or sample:NAME")
    parser.add_argument(
        "--camera",
        required=True,
        metavar="CAM.json",
        help='our camera JSON (one camera or {"cameras": [...]}) or a 3DGS cameras.json',
    )
    parser.add_argument(
        "--view", metavar="N|NAME", help="which camera of the file: position or name (default: the first)"
    )
    parser.add_argument(
        "-o", "--output", metavar="OUT.png", help="colour image to write (8-bit RGB, clamped to [0, 1])"
    )
    parser.add_argument(
        "--index",
        metavar="OUT.npz",
        help="write index (int32, -1 = none), index_depth, alpha, depth and the camera as .npz",
    )
    parser.add_argument("--width", type=_side, help="render at this width (focal lengths scale with it)")
    parser.add_argument("--height", type=_side, help="render at this height (default: keeps the aspect ratio)")
    parser.add_argument(
        "--background",
        type=number_triple("R,G,B"),
        default=(0.0, 0.0, 0.0),
        metavar="R,G,B",
        help="background colour in [0, 1] (default 0,0,0)",
    )


def run(args: argparse.Namespace) -> int:
    if not args.output and not args.index:
        raise SketchRodGSError("nothing to write: give -o OUT.png and/or --index OUT.npz")
    camera = select_camera(load_cameras(args.camera), args.view, args.camera)
    if args.width or args.height:
        width = args.width or max(1, round(camera.width * args.height / camera.height))
        camera = camera.resized(width, args.height)
    scene = load_scene(args.scene)
    start = time.perf_counter()
    result = render(scene, camera, background=args.background, outputs="all" if args.output else "index")
    elapsed = time.perf_counter() - start
    if args.output:
        save_png(args.output, result.rgb_image)
    if args.index:
        arrays: dict[str, Any] = {"index": result.index, "index_depth": result.index_depth, "alpha": result.alpha}
        if result.depth is not None:
            arrays.update(depth=result.depth)
        buffer = io.BytesIO()
        np.savez_compressed(buffer, camera=np.array(json.dumps(camera.to_dict())), **arrays)
        with atomic_open(args.index) as stream:
            stream.write(buffer.getvalue())
    covered = float((result.index >= 0).mean())
    print(
        f"rendered {len(scene):,} Gaussians ({result.n_visible:,} visible) at {camera.width}x{camera.height} "
        f"in {elapsed * 1e3:.1f} ms; {covered:.1%} of pixels covered"
    )
    return 0
