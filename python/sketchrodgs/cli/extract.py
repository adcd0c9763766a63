"""`sketchrodgs extract SCENE --camera CAM.json --stroke STROKE.json -o rod.json`: sketch to rod."""

from __future__ import annotations

import argparse

import numpy as np

from ..camera import load_cameras, select_camera
from ..errors import PathNotFoundError, SketchRodGSError
from ..extract import extract_rod
from ..images import draw_overlay, save_png
from ..io import load_scene
from ..jsonfile import read_json
from ..render import render
from ._args import positive, scene_path

NAME = "extract"
HELP = "find the 3D polyline of the slender object under a stroke and write it as rod JSON"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help="scene file (.ply or .splat), or sample:NAME")
    parser.add_argument("--camera", required=True, metavar="CAM.json", help="our camera JSON or a 3DGS cameras.json")
    parser.add_argument("--view", metavar="N|NAME", help="which camera of the file (default: the first)")
    parser.add_argument(
        "--stroke",
        required=True,
        metavar="STROKE.json",
        help='the stroke in pixel coordinates of that camera: {"points": [[x, y], ...]}',
    )
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
        help="only the part follows the rod, not the small parts attached to it (leaves, a tag)",
    )
    parser.add_argument(
        "--attach-size",
        type=positive,
        metavar="SIZE",
        help="largest attached part that follows, in scene units (default: half the rod's length)",
    )
    parser.add_argument("-o", "--output", required=True, metavar="ROD.json", help="rod JSON to write")
    parser.add_argument("--overlay", metavar="OVERLAY.png", help="also draw the render with stroke, path and polyline")


def load_stroke(path: str) -> np.ndarray:
    """Read a stroke JSON (`{"points": [[x, y], ...]}` or a bare list) as an (S, 2) array."""
    data = read_json(path)
    points = data.get("points") if isinstance(data, dict) else data
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        array = np.empty(0)
    if array.ndim != 2 or array.shape[1] != 2:
        raise SketchRodGSError(f'{path}: expected {{"points": [[x, y], ...]}}, got points of shape {array.shape}')
    return array


def run(args: argparse.Namespace) -> int:
    camera = select_camera(load_cameras(args.camera), args.view, args.camera)
    stroke = load_stroke(args.stroke)
    scene = load_scene(args.scene)
    images = render(scene, camera, outputs="all" if args.overlay else "index")
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
        if args.overlay:  # show what was found and where it stopped, so the user sees what to change
            overlay = draw_overlay(
                images.rgb_image, camera, stroke, getattr(err, "pixel_path", []), stops=getattr(err, "lost_at", [])
            )
            save_png(args.overlay, overlay)
            raise PathNotFoundError(f"{err} (overlay of the stroke and the path so far: {args.overlay})") from None
        raise
    extraction.save(args.output)
    if args.overlay:
        overlay = draw_overlay(
            images.rgb_image,
            camera,
            extraction.stroke,
            extraction.pixel_path,
            extraction.polyline,
            scene.means[extraction.gaussian_ids],
        )
        save_png(args.overlay, overlay)
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
