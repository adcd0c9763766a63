"""`sketchrodgs render SCENE [--camera CAM.json | --orbit AZ,EL ...] -o out.png`: render a view to
an image (and the index image)."""

from __future__ import annotations

import argparse

from ._args import IMAGE_SUFFIXES, numbers, output_file, scene_help, scene_path
from ._framing import add_camera_file_argument, add_framing_arguments, add_near_argument

NAME = "render"
HELP = "render a scene for a camera to a PNG or JPEG, optionally with the index image K and its depth Z (.npz)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help=scene_help())
    add_camera_file_argument(
        parser,
        'our camera JSON (one camera or {"cameras": [...]}) or a 3DGS cameras.json (default: the '
        "training output folder's cameras.json; without one, or with a framing option, a camera "
        "framing the scene as `sketchrodgs camera` makes, up taken from these cameras)",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=output_file(*IMAGE_SUFFIXES),
        metavar="OUT.png",
        help="colour image to write, .png or .jpg (8-bit RGB, clamped to [0, 1])",
    )
    parser.add_argument(
        "--index",
        type=output_file(".npz"),
        metavar="OUT.npz",
        help="write index (int32, -1 = none), index_depth, alpha, depth and the camera as .npz",
    )
    parser.add_argument(
        "--background",
        type=numbers(3, "R,G,B"),
        default=(0.0, 0.0, 0.0),
        metavar="R,G,B",
        help="background colour in [0, 1] (default 0,0,0)",
    )
    add_near_argument(parser, "not drawn")
    add_framing_arguments(parser, default_size=None)
    parser.epilog = (
        "--width/--height resize a camera from a file (focal lengths scale; the aspect is kept if one is given)."
    )


def run(args: argparse.Namespace) -> int:
    import io
    import json
    import sys
    import time
    from typing import Any

    import numpy as np

    from ..atomic import atomic_open
    from ..camera import select_camera
    from ..errors import SketchRodGSError
    from ..images import save_image
    from ..io import load_scene
    from ..near_plane import why_nothing_is_visible
    from ..render import COLOR_OUTPUTS, render
    from ._framing import camera_file, framed_camera, framing_given, scene_cameras, with_near
    from ._outputs import Outputs

    if not args.output and not args.index:
        raise SketchRodGSError("nothing to write: give -o OUT.png and/or --index OUT.npz")
    with Outputs() as outputs:
        image_path = outputs.file(args.output, "-o") if args.output else None
        index_path = outputs.file(args.index, "--index") if args.index else None
        cameras = scene_cameras(args)
        framed = framing_given(args) or not cameras
        if not framed:
            camera = select_camera(cameras, args.view, camera_file(args) or "")
            if args.width or args.height:
                width = args.width or max(1, round(camera.width * args.height / camera.height))
                camera = camera.resized(width, args.height)
        scene = load_scene(args.scene)
        if framed:
            camera, _ = framed_camera(args, scene, cameras)
        start = time.perf_counter()
        # a picture alone needs no index image: colour only is cheaper (docs/rendering.md)
        outputs_wanted = ("all" if args.index else COLOR_OUTPUTS) if args.output else "index"
        camera = with_near(camera, args)
        result = render(scene, camera, background=args.background, outputs=outputs_wanted)
        elapsed = time.perf_counter() - start
        if image_path is not None:
            save_image(image_path, result.rgb_image)
        if index_path is not None:
            arrays: dict[str, Any] = {"index": result.index, "index_depth": result.index_depth, "alpha": result.alpha}
            if result.depth is not None:
                arrays.update(depth=result.depth)
            buffer = io.BytesIO()
            np.savez_compressed(buffer, camera=np.array(json.dumps(camera.to_dict())), **arrays)
            with atomic_open(index_path) as stream:
                stream.write(buffer.getvalue())
        outputs.commit()
    covered = float(result.covered().mean())
    print(
        f"rendered {len(scene):,} Gaussians ({result.n_visible:,} visible) at {camera.width}x{camera.height} "
        f"in {elapsed * 1e3:.1f} ms; {covered:.1%} of pixels covered"
    )
    if covered == 0:
        print(f"sketchrodgs render: warning: {why_nothing_is_visible(scene, camera)}", file=sys.stderr)
    return 0
