"""`sketchrodgs view SCENE [--port 8080] [--host 127.0.0.1] [--rod ROD.json ...]`: the browser viewer."""

from __future__ import annotations

import argparse

from ._args import in_range, scene_help, scene_path
from ._framing import UP_CHOICES

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


def _origin(value: str) -> str:
    from ..errors import SketchRodGSError
    from ..viewer.origin import parse_origin

    try:
        parse_origin(value)
    except SketchRodGSError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help=scene_help())
    parser.add_argument(
        "--port", type=_port, default=8080, help="port to serve on (default 8080; the next free one if taken)"
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="interface to listen on (default 127.0.0.1, this machine only; 0.0.0.0 exposes the viewer to the network)",
    )
    parser.add_argument(
        "--allow-origin",
        action="append",
        type=_origin,
        default=[],
        metavar="ORIGIN",
        help="also let pages from ORIGIN (e.g. http://myhost:8080, as the browser's address bar shows it) "
        "use the viewer; only its own page at 127.0.0.1 or localhost (or --host) may by default",
    )
    parser.add_argument(
        "--rod",
        action="extend",
        nargs="+",
        default=[],
        metavar="ROD.json",
        help="start with these rods (files written by `extract` or the viewer, for this scene)",
    )
    parser.add_argument(
        "--up",
        choices=UP_CHOICES,
        help="the scene's up direction (default: the training cameras', else a guess from the shape: see `info`)",
    )
    parser.add_argument(
        "--camera",
        metavar="CAM.json",
        help="open the page at this camera (default: the first rod's, else the training output folder's "
        "first camera, else one framing the scene)",
    )
    parser.add_argument("--view", metavar="N|NAME", help="which camera of --camera (default: the first)")
    parser.add_argument(
        "-o", "--output-dir", default=".", metavar="DIR", help="where exports, rods and screenshots go (default .)"
    )
    parser.add_argument("--fps", type=in_range(1, 240), default=60.0, help="simulation frames per second (default 60)")
    parser.add_argument(
        "--splat-update",
        choices=("auto", "exact", "segments"),
        default="auto",
        help="how pulled Gaussians are sent: exact per Gaussian, or per rod segment (a pose each; "
        "for large scenes); auto picks by scene size",
    )
    parser.add_argument("--no-clamp", action="store_true", help="leave rod ends free instead of clamping them")
    parser.add_argument(
        "--no-contact",
        action="store_true",
        help="let rods pass through the scene and each other (the panel's Contact switch starts off)",
    )
    parser.add_argument(
        "--swing-period",
        type=in_range(0.05, 60, "a number of seconds"),
        default=0.5,
        metavar="S",
        help="seconds one swing of a let-go rod takes (default 0.5); each rod's stiffness follows from it",
    )


class _Stopped(Exception):
    """SIGTERM (or SIGINT) arrived: stop serving and close."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _stop(signum: int, frame: object) -> None:
    raise _Stopped(signum)


def _exposed(host: str, port: int) -> str:
    """The warning for a --host other machines can reach."""
    text = (
        f"--host {host} serves the viewer to other machines: anyone who can reach this one can open it, "
        "see the scene and change its rods. "
    )
    if host in ("", "0.0.0.0", "::"):
        return text + (
            f"Browsers are let in at http://127.0.0.1:{port} only, unless you allow the address they open, "
            f"e.g. --allow-origin http://<this machine's name or address>:{port}"
        )
    return text + f"Browsers may open it at http://{host}:{port}."


def run(args: argparse.Namespace) -> int:
    import signal
    import sys
    import time

    from ..camera import select_camera
    from ..framing import AXES, frame_scene, scene_up
    from ..io import format_up, load_scene
    from ..rod_file import load_rod
    from ..scene_identity import check_rod_scene
    from ..viewer import ViewerApp
    from ..viewer.material import GRAVITY, Material
    from ..viewer.origin import is_loopback
    from ._framing import camera_file, scene_cameras
    from ._outputs import check_folder

    check_folder(args.output_dir, "-o")
    loaded = [load_rod(path) for path in args.rod]
    cameras = scene_cameras(args)
    scene = load_scene(args.scene)
    for path, (extraction, _) in zip(args.rod, loaded):
        check_rod_scene(extraction.scene_identity, scene, path, args.scene)
    up = scene_up(scene, cameras, args.up, format_up(args.scene))
    if args.camera:
        camera = select_camera(cameras, args.view, camera_file(args) or "")
    elif loaded:
        camera = loaded[0][0].camera
    else:
        camera = cameras[0] if cameras else frame_scene(scene, up.vector)
    # a rod file's damping, density and gravity; its stiffness follows from the swing period
    saved = loaded[0][1] if loaded else {}
    default = Material()
    # gravity on where the up direction is known (given, the training cameras' or the format's), not guessed
    down = [-GRAVITY * v for v in AXES[up.axis]] if up.known else default.gravity
    g = [float(v) for v in saved.get("gravity", down)]
    material = Material(
        swing_period=args.swing_period,
        damping=float(saved.get("damping", default.damping)),
        density=float(saved.get("density", default.density)),
        gravity=(g[0], g[1], g[2]),
    )
    app = ViewerApp(
        scene,
        host=args.host,
        port=args.port,
        rods=[e for e, _ in loaded],
        material=material,
        clamp="none" if args.no_clamp else "both",
        up=up.axis,
        camera=camera,
        output_dir=args.output_dir,
        fps=args.fps,
        splat_update=args.splat_update,
        allow_origins=args.allow_origin,
        contact=not args.no_contact,
    )
    if not is_loopback(args.host):
        print(f"sketchrodgs view: warning: {_exposed(args.host, app.port)}", file=sys.stderr, flush=True)
    # Stop cleanly on SIGTERM, and on SIGINT unless it is ignored (a background job's is): a
    # server that only Ctrl-C stops cannot be stopped in the background.
    handled = [signal.SIGTERM] + ([signal.SIGINT] if signal.getsignal(signal.SIGINT) != signal.SIG_IGN else [])
    previous = {s: signal.signal(s, _stop) for s in handled}
    try:
        print(
            f"sketchrodgs viewer: {app.url}  ({len(scene):,} Gaussians, {len(loaded)} rod(s), up {up.axis}; "
            "Ctrl-C to stop)",
            flush=True,
        )
        while True:
            time.sleep(3600)
    except _Stopped as stop:
        print("stopped" if stop.signum == signal.SIGTERM else "interrupted", file=sys.stderr)
        return 128 + stop.signum
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        app.close()
