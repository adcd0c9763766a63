"""`sketchrodgs animate SCENE ROD.json ... --grab V --to DX,DY,DZ -o OUTDIR`: pull, release, render."""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path
from typing import TYPE_CHECKING

from ._args import non_negative, numbers, pixels, positive, scene_help, scene_path, vertex_or_fraction
from ._framing import UP_CHOICES

if TYPE_CHECKING:
    from ..framing import Up
    from ..scene import GaussianScene

NAME = "animate"
HELP = "pull a rod vertex, hold, release; write rendered frames, a video and optionally deformed .ply files"
CLAMPS = ("both", "start", "end", "none")  # animate.CLAMPS, without importing numpy here


def _video(value: str) -> str:
    if value.lower() == "none":
        return "none"
    if Path(value).name != value:
        raise argparse.ArgumentTypeError(f"{value}: expected a file name inside OUTDIR, not a path")
    if Path(value).suffix.lower() not in (".mp4", ".gif"):
        raise argparse.ArgumentTypeError(f"{value}: expected a .mp4 or .gif file name, or none")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..rod import RodParams

    defaults = RodParams()
    parser.add_argument("scene", type=scene_path, help=scene_help())
    parser.add_argument(
        "rods", nargs="+", metavar="ROD.json", help="rod files written by `extract` (the first is grabbed)"
    )
    parser.add_argument(
        "--grab",
        type=vertex_or_fraction,
        required=True,
        metavar="VERTEX|FRACTION",
        help="rod vertex to pull: an index (negative counts from the end) or a fraction of the rod's "
        "length from its start, with a decimal point (0.5: the middle)",
    )
    pull = parser.add_mutually_exclusive_group(required=True)
    pull.add_argument(
        "--to", type=numbers(3, "DX,DY,DZ"), metavar="DX,DY,DZ", help="how far to pull it, in scene units (world axes)"
    )
    pull.add_argument(
        "--drag",
        type=numbers(2, "DX,DY"),
        metavar="DX,DY",
        help="how far to pull it, in pixels of the camera (x right, y down), at the grabbed vertex's depth",
    )
    parser.add_argument("--duration", type=non_negative, default=0.5, metavar="S", help="seconds to pull (default 0.5)")
    parser.add_argument("--hold", type=non_negative, default=0.5, metavar="S", help="seconds to hold (default 0.5)")
    parser.add_argument("--release", action="store_true", help="let go after holding and let the rod spring back")
    parser.add_argument(
        "--settle", type=non_negative, default=1.5, metavar="S", help="seconds after the release (default 1.5)"
    )
    parser.add_argument("--fps", type=positive, default=30.0, help="frames per second (default 30)")
    parser.add_argument(
        "--clamp",
        choices=CLAMPS,
        default="both",
        help="which ends of every rod are held, position and direction (default both; start: a branch "
        "held at its root with a free tip)",
    )
    parser.add_argument(
        "--pin",
        type=vertex_or_fraction,
        nargs="+",
        default=[],
        metavar="VERTEX|FRACTION",
        help="also hold these vertices of the grabbed rod in place (their direction stays free)",
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUTDIR",
        help="folder for frames/, the video and ply/ (made if missing)",
    )
    parser.add_argument(
        "--camera",
        metavar="CAM.json",
        help="camera to render (and --drag) from (default: the first rod's, the view its stroke was drawn in)",
    )
    parser.add_argument("--view", metavar="N|NAME", help="which camera of --camera (default: the first)")
    parser.add_argument("--width", type=pixels, help="render width (default: the camera's)")
    parser.add_argument(
        "--video",
        type=_video,
        default="pull.mp4",
        metavar="NAME",
        help="video file name in OUTDIR, .mp4 or .gif (default pull.mp4); 'none' for no video",
    )
    parser.add_argument("--ply", action="store_true", help="also write each deformed scene as ply/frame_NNNN.ply")
    parser.add_argument(
        "--youngs-modulus",
        type=positive,
        default=defaults.youngs_modulus,
        metavar="PA",
        help=f"Young's modulus (default {defaults.youngs_modulus:g})",
    )
    parser.add_argument(
        "--density", type=positive, default=defaults.density, help=f"density in kg/m^3 (default {defaults.density:g})"
    )
    parser.add_argument(
        "--damping",
        type=non_negative,
        default=defaults.damping,
        metavar="RATE",
        help=f"damping rate in 1/s (default {defaults.damping:g})",
    )
    scene = parser.add_argument_group("the scene around the rods (docs/contact.md)")
    scene.add_argument(
        "--no-contact",
        action="store_true",
        help="let the rods pass through the scene and each other (default: they stay out of its solid parts)",
    )
    scene.add_argument(
        "--friction",
        type=non_negative,
        default=0.0,
        metavar="MU",
        help="Coulomb friction of the rods on the scene (default 0: they slide freely)",
    )
    scene.add_argument(
        "--up",
        choices=UP_CHOICES,
        help="the scene's up axis, for gravity (default: the scene folder's training cameras', or the "
        "format's (SPZ: +y); without either, no gravity)",
    )
    scene.add_argument(
        "--gravity",
        type=non_negative,
        default=9.81,
        metavar="G",
        help="gravity in scene units per s^2 when the up axis is known (default 9.81; 0: none). Each rod's "
        "rest shape is made to hold its captured shape under it",
    )
    parser.add_argument(
        "--no-subdivide",
        action="store_true",
        help="move each Gaussian with one binding point (needles then stick out of bends); with "
        "--ply the frames then keep the scene's rows",
    )


def run(args: argparse.Namespace) -> int:
    import json
    import time

    import numpy as np
    from tqdm import tqdm

    from ..animate import Animation, Pull, vertex_at_fraction
    from ..atomic import atomic_write_text
    from ..camera import load_cameras, select_camera
    from ..errors import SimulationError, SketchRodGSError
    from ..frames import FrameRenderer
    from ..images import FRAME_PNG_LEVEL, save_png, to_uint8
    from ..io import load_scene, save_scene
    from ..render import COLOR_OUTPUTS
    from ..rod import RodParams
    from ..rod_file import load_rod
    from ..scene_identity import check_rod_scene
    from ..video import VideoWriter
    from ._outputs import Outputs

    with Outputs() as outputs:
        out = outputs.folder(args.output, "-o")
        # the gesture's length at this rate, before anything is read (the pull itself comes later)
        Pull(0, (0.0, 0.0, 0.0), args.duration, args.hold, args.release, args.settle).frame_count(args.fps)
        extractions = [load_rod(path)[0] for path in args.rods]
        camera = select_camera(load_cameras(args.camera), args.view, args.camera) if args.camera else None
        scene = load_scene(args.scene)
        for path, extraction in zip(args.rods, extractions):
            check_rod_scene(extraction.scene_identity, scene, path, args.scene)
        camera = camera or extractions[0].camera
        if args.width:
            camera = camera.resized(args.width)

        grabbed = extractions[0].polyline

        def vertex(value: int | float) -> int:
            return vertex_at_fraction(grabbed, value) if isinstance(value, float) else value

        params = RodParams(youngs_modulus=args.youngs_modulus, density=args.density, damping=args.damping)
        up = _gravity_up(args, scene)
        try:
            animation = Animation(
                scene,
                extractions,
                params,
                clamp=args.clamp,
                pins=[[vertex(v) for v in args.pin]],
                subdivide=not args.no_subdivide,
                contact=not args.no_contact,
                friction=args.friction,
                up=None if up is None else up.vector,
                gravity=args.gravity,
            )
        except SimulationError as err:
            if up is None:
                raise
            # "rod K: no rest shape holds ..." from Animation: name the file, say what to change
            rod, _, why = str(err).partition(": ")
            path = args.rods[int(rod.split()[-1])] if rod.startswith("rod ") else "the rods"
            raise SimulationError(f"{path}: {why} [{up.axis} up: --clamp, --pin, or --gravity 0]") from None
        # from here on the animation's own scene (the input's rows, then split needles' pieces)
        # is all there is: let the input go, a copy of it as large (most of a 2 M SH-3 scene)
        input_gaussians = len(scene)
        del scene
        grab = vertex(args.grab)
        if not -len(grabbed) <= grab < len(grabbed):
            raise SketchRodGSError(f"grab vertex: {grab} is outside the rod's {len(grabbed)} vertices")
        offset = args.to if args.drag is None else tuple(camera.screen_offset(grabbed[grab], args.drag))
        pull = Pull(grab, offset, args.duration, args.hold, args.release, args.settle)
        (out / "frames").mkdir()
        if args.ply:
            (out / "ply").mkdir()
            # the frames carry the split needles: the input's rows first, then the extra pieces
            source = {
                "input_gaussians": input_gaussians,
                "source": animation.rig.source.tolist(),
                "note": "row i of each frame comes from row source[i] of the input scene (docs/deformation.md)",
            }
            atomic_write_text(out / "ply" / "source.json", json.dumps(source) + "\n")
        totals: dict[str, float] = {}
        count = pull.frame_count(args.fps)
        # only the rods' Gaussians move: the rest is projected and binned once (docs/rendering.md)
        renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows, outputs=COLOR_OUTPUTS)
        with contextlib.ExitStack() as stack:
            # frames go to the video as they come: a long or large video is never held in memory
            video = stack.enter_context(VideoWriter(out / args.video, args.fps)) if args.video != "none" else None
            for frame in tqdm(animation.frames(pull, args.fps), total=count, unit="frame", desc="animate"):
                clock = time.perf_counter()
                rgb = to_uint8(renderer.frame(animation.means, animation.scales, animation.quats).rgb_image)
                frame.timings["render"] = time.perf_counter() - clock
                clock = time.perf_counter()
                save_png(out / "frames" / f"frame_{frame.index:04d}.png", rgb, compress_level=FRAME_PNG_LEVEL)
                if args.ply:
                    save_scene(animation.current_scene(), out / "ply" / f"frame_{frame.index:04d}.ply")
                frame.timings["write"] = time.perf_counter() - clock
                if video is not None:
                    clock = time.perf_counter()
                    video.append(rgb)
                    frame.timings["video"] = time.perf_counter() - clock
                for stage, seconds in frame.timings.items():
                    totals[stage] = totals.get(stage, 0.0) + seconds
            if not np.isfinite(animation.means).all():
                raise SketchRodGSError("the simulation produced non-finite positions")
            clock = time.perf_counter()
        if video is not None:  # closed as the block ended
            totals["video"] = totals.get("video", 0.0) + time.perf_counter() - clock
        outputs.commit()
    rest = np.abs(animation.rods[0].positions - animation.rods[0].rest_positions).max()
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in totals.items())
    world = "no gravity" if up is None else f"gravity {args.gravity:g} down, {up.axis} up ({up.reason})"
    touch = "no contact" if args.no_contact else "contact on"
    print(
        f"{count} frames at {camera.width}x{camera.height} -> {args.output}; {touch}, {world}; "
        f"rod 0 ends {rest:.3g} from rest; {stages}"
    )
    return 0


def _gravity_up(args: argparse.Namespace, scene: GaussianScene) -> Up | None:
    """The up direction gravity acts against: --up, else the training cameras' of a 3DGS output
    folder, else the one the file's format fixes (SPZ); None without any (a guess from the
    scene's shape is not enough to pull rods by)."""
    from ..camera import load_cameras
    from ..framing import scene_up
    from ..io import format_up, training_cameras

    if args.gravity == 0:
        return None
    found = training_cameras(args.scene)
    up = scene_up(scene, load_cameras(found) if found else [], args.up, format_up(args.scene))
    return up if up.known else None
