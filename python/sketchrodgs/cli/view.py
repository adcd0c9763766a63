"""`sketchrodgs view SCENE [--port 8080] [--host 127.0.0.1] [--rod ROD.json ...]`: the browser viewer."""

from __future__ import annotations

import argparse
import time

from ..camera import load_cameras, select_camera
from ..extract import load_rod
from ..io import load_scene
from ..rod import RodParams
from ._args import scene_path

NAME = "view"
HELP = "serve the interactive viewer (orbit, sketch a rod, pull it) as a local web page"


def _port(value: str) -> int:
    try:
        port = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {value!r}") from None
    if not 0 < port < 65536:
        raise argparse.ArgumentTypeError(f"port must be in 1..65535, got {port}")
    return port


def _fps(value: str) -> float:
    try:
        fps = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not 1 <= fps <= 240:
        raise argparse.ArgumentTypeError(f"fps must be in 1..240, got {value}")
    return fps


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..viewer.app import UP_DIRECTIONS

    parser.add_argument("scene", type=scene_path, help="scene file, or sample:NAME")
    parser.add_argument(
        "--port", type=_port, default=8080, help="port to serve on (default 8080; the next free one if taken)"
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="interface to listen on (default 127.0.0.1, this machine only; 0.0.0.0 exposes the viewer to the network)",
    )
    parser.add_argument(
        "--rod",
        action="extend",
        nargs="+",
        default=[],
        metavar="ROD.json",
        help="start with these rods (files written by `extract` or the viewer)",
    )
    parser.add_argument(
        "--up",
        choices=sorted(UP_DIRECTIONS),
        default="-y",
        help="the scene's up direction (default -y, as in COLMAP-derived captures)",
    )
    parser.add_argument(
        "--camera",
        metavar="CAM.json",
        help="open the page at this camera (default: the first rod's, else framing the scene)",
    )
    parser.add_argument("--view", metavar="N|NAME", help="which camera of --camera (default: the first)")
    parser.add_argument(
        "-o", "--output-dir", default=".", metavar="DIR", help="where exports, rods and screenshots go (default .)"
    )
    parser.add_argument("--fps", type=_fps, default=60.0, help="simulation frames per second (default 60)")
    parser.add_argument(
        "--splat-update",
        choices=("auto", "exact", "segments"),
        default="auto",
        help="how pulled Gaussians are sent: exact per Gaussian, or per rod segment (a pose each; "
        "for large scenes); auto picks by scene size",
    )
    parser.add_argument("--no-clamp", action="store_true", help="leave rod ends free instead of clamping them")


def run(args: argparse.Namespace) -> int:
    from ..viewer import ViewerApp

    scene = load_scene(args.scene)
    loaded = [load_rod(path) for path in args.rod]
    camera = select_camera(load_cameras(args.camera), args.view, args.camera) if args.camera else None
    params = RodParams.from_dict({**loaded[0][1], "radius": RodParams().radius}) if loaded and loaded[0][1] else None
    app = ViewerApp(
        scene,
        host=args.host,
        port=args.port,
        rods=[e for e, _ in loaded],
        params=params,
        clamp_ends=not args.no_clamp,
        up=args.up,
        camera=camera,
        output_dir=args.output_dir,
        fps=args.fps,
        splat_update=args.splat_update,
    )
    try:
        print(
            f"sketchrodgs viewer: {app.url}  ({len(scene):,} Gaussians, {len(loaded)} rod(s); Ctrl-C to stop)",
            flush=True,
        )
        while True:
            time.sleep(3600)
    finally:
        app.close()
