"""`sketchrodgs extract SCENE --camera CAM.json --stroke STROKE.json -o rod.json`: sketch to rod."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ._args import IMAGE_SUFFIXES, output_file, positive, scene_help, scene_path
from ._framing import add_camera_file_argument, add_near_argument

if TYPE_CHECKING:
    import numpy as np

NAME = "extract"
HELP = "find the 3D polyline of the slender object under a stroke and write it as rod JSON"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help=scene_help())
    add_camera_file_argument(
        parser, "our camera JSON or a 3DGS cameras.json (default: a training output folder's cameras.json)"
    )
    parser.add_argument(
        "--stroke",
        required=True,
        metavar="STROKE.json",
        help='the stroke in pixel coordinates of that camera: {"points": [[x, y], ...]}',
    )
    add_near_argument(parser, "not seen")
    parser.add_argument("--radius", type=positive, help="the object's radius R in scene units (default: estimated)")
    parser.add_argument(
        "--alpha", type=float, default=1.0, help="weight of the stroke term of the path cost (default 1)"
    )
    parser.add_argument(
        "--edge-length", type=positive, help="spacing of the polyline vertices (default: from R and length)"
    )
    parser.add_argument(
        "--no-attach",
        action="store_true",
        help="only the part follows the rod, not the small parts attached to it (leaves, a tag) nor "
        "what continues it past its ends (a stem's tip past the stroke)",
    )
    parser.add_argument(
        "--attach-size",
        type=positive,
        metavar="SIZE",
        help="largest attached part that follows, in scene units (default: half the rod's length, "
        "between 12 and 20 radii, or 25 for a part with fewer Gaussians than the rod's own; past an "
        "end, the rod's length, between 8 and 20 radii)",
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        type=output_file(".json"),
        metavar="ROD.json",
        help="rod JSON to write (its bindings go beside it, ROD.bindings.npz)",
    )
    parser.add_argument(
        "--overlay",
        type=output_file(*IMAGE_SUFFIXES),
        metavar="OVERLAY.png",
        help="also draw the render with stroke, path and polyline (.png or .jpg)",
    )


def load_stroke(path: str) -> np.ndarray:
    """Read a stroke JSON (`{"points": [[x, y], ...]}` or a bare list) as an (S, 2) array."""
    import numpy as np

    from ..errors import SketchRodGSError
    from ..jsonfile import read_json

    data = read_json(path)
    points = data.get("points") if isinstance(data, dict) else data
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as err:  # a string, a ragged or nested list
        raise SketchRodGSError(f'{path}: expected {{"points": [[x, y], ...]}} of numbers ({err})') from None
    if array.ndim != 2 or array.shape[1] != 2:
        raise SketchRodGSError(f'{path}: expected {{"points": [[x, y], ...]}}, got points of shape {array.shape}')
    return array


def run(args: argparse.Namespace) -> int:
    from ..camera import select_camera
    from ..errors import PathNotFoundError
    from ..extract import extract_rod
    from ..images import draw_overlay, save_image
    from ..io import load_scene
    from ..render import render
    from ..rod_file import bindings_path
    from ._args import UsageError
    from ._framing import camera_file, scene_cameras, with_near
    from ._outputs import Outputs

    with Outputs() as outputs:
        rod_path = outputs.file(args.output, "-o", companions=[bindings_path(args.output)])
        overlay_path = outputs.file(args.overlay, "--overlay") if args.overlay else None
        cameras = scene_cameras(args)
        if not cameras:
            raise UsageError("give --camera CAM.json (the scene is not a training output folder with a cameras.json)")
        camera = with_near(select_camera(cameras, args.view, camera_file(args) or ""), args)
        stroke = load_stroke(args.stroke)
        scene = load_scene(args.scene)
        # the overlay needs the whole colour image; without one the sketch renders only its band
        images = render(scene, camera) if args.overlay else None
        try:
            extraction = extract_rod(
                scene,
                camera,
                stroke,
                args.radius,
                alpha=args.alpha,
                edge_length=args.edge_length,
                attach=not args.no_attach,
                attach_size=args.attach_size,
                render=images,
            )
        except PathNotFoundError as err:
            if overlay_path is not None and images is not None:  # show the user what was found, where it stopped
                overlay = draw_overlay(
                    images.rgb_image, camera, stroke, getattr(err, "pixel_path", []), stops=getattr(err, "lost_at", [])
                )
                save_image(overlay_path, overlay)
                outputs.commit(args.overlay)
                raise PathNotFoundError(f"{err} (overlay of the stroke and the path so far: {args.overlay})") from None
            raise
        extraction.save(rod_path)
        if overlay_path is not None and images is not None:
            overlay = draw_overlay(
                images.rgb_image,
                camera,
                extraction.stroke,
                extraction.pixel_path,
                extraction.polyline,
                scene.means[extraction.gaussian_ids],
            )
            save_image(overlay_path, overlay)
        outputs.commit()
    pieces = len(extraction.pixel_path)
    print(
        f"rod: {len(extraction.polyline)} vertices, radius {extraction.radius:.4g}, edge {extraction.edge_length:.4g}; "
        f"{len(extraction.gaussian_ids):,} Gaussians bound ({int(extraction.binding.attached.sum()):,} in attached "
        f"parts); stroke covered {extraction.coverage:.0%} "
        f"in {pieces} piece{'s' if pieces > 1 else ''} -> {args.output}"
    )
    timings = ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in extraction.timings.items())
    print(f"timings: {timings}")
    return 0
