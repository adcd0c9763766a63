"""`sketchrodgs animate SCENE ROD.json ... --grab V --to DX,DY,DZ -o OUTDIR`: pull, release, render."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..animate import Animation, Pull
from ..atomic import atomic_write_text
from ..camera import load_cameras, select_camera
from ..errors import SketchRodGSError
from ..extract import load_rod
from ..frames import FrameRenderer
from ..images import FRAME_PNG_LEVEL, save_png, to_uint8
from ..io import load_scene, save_scene
from ..rod import RodParams
from ..video import write_video
from ._args import non_negative, number_triple, positive, scene_path

NAME = "animate"
HELP = "pull a rod vertex, hold, release; write rendered frames, a video and optionally deformed .ply files"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = RodParams()
    parser.add_argument("scene", type=scene_path, help="scene file, or sample:NAME")
    parser.add_argument(
        "rods", nargs="+", metavar="ROD.json", help="rod files written by `extract` (the first is grabbed)"
    )
    parser.add_argument(
        "--grab", type=int, required=True, metavar="VERTEX", help="rod vertex to pull (negative counts from the end)"
    )
    parser.add_argument(
        "--to",
        type=number_triple("DX,DY,DZ"),
        required=True,
        metavar="DX,DY,DZ",
        help="how far to pull it, in scene units",
    )
    parser.add_argument("--duration", type=non_negative, default=0.5, metavar="S", help="seconds to pull (default 0.5)")
    parser.add_argument("--hold", type=non_negative, default=0.5, metavar="S", help="seconds to hold (default 0.5)")
    parser.add_argument("--release", action="store_true", help="let go after holding and let the rod spring back")
    parser.add_argument(
        "--settle", type=non_negative, default=1.5, metavar="S", help="seconds after the release (default 1.5)"
    )
    parser.add_argument("--fps", type=positive, default=30.0, help="frames per second (default 30)")
    parser.add_argument(
        "-o", "--output", required=True, metavar="OUTDIR", help="directory for frames/, the video and ply/"
    )
    parser.add_argument("--camera", metavar="CAM.json", help="camera to render from (default: the first rod's camera)")
    parser.add_argument("--view", metavar="N|NAME", help="which camera of --camera (default: the first)")
    parser.add_argument("--width", type=int, help="render width (default: the camera's)")
    parser.add_argument(
        "--video",
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
    parser.add_argument("--no-clamp", action="store_true", help="leave the rod ends free instead of clamping them")
    parser.add_argument(
        "--no-subdivide",
        action="store_true",
        help="move each Gaussian with one binding point (needles then stick out of bends); with "
        "--ply the frames then keep the scene's rows",
    )


def run(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    extractions = [load_rod(path)[0] for path in args.rods]
    if args.camera:
        camera = select_camera(load_cameras(args.camera), args.view, args.camera)
    else:
        camera = extractions[0].camera
    if args.width:
        camera = camera.resized(args.width)
    params = RodParams(youngs_modulus=args.youngs_modulus, density=args.density, damping=args.damping)
    animation = Animation(scene, extractions, params, clamp_ends=not args.no_clamp, subdivide=not args.no_subdivide)
    pull = Pull(args.grab, args.to, args.duration, args.hold, args.release, args.settle)
    out = Path(args.output)
    (out / "frames").mkdir(parents=True, exist_ok=True)
    if args.ply:
        (out / "ply").mkdir(exist_ok=True)
        # the frames carry the split needles: the input's rows first, then the extra pieces
        source = {
            "input_gaussians": len(scene),
            "source": animation.rig.source.tolist(),
            "note": "row i of each frame comes from row source[i] of the input scene (docs/deformation.md)",
        }
        atomic_write_text(out / "ply" / "source.json", json.dumps(source) + "\n")
    totals: dict[str, float] = {}
    images = []
    count = int(round(pull.total * args.fps))
    # only the rods' Gaussians move: the rest is projected and binned once (docs/rendering.md)
    renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows)
    for frame in tqdm(animation.frames(pull, args.fps), total=count, unit="frame", desc="animate"):
        clock = time.perf_counter()
        rgb = to_uint8(renderer.frame(animation.means, animation.scales, animation.quats).rgb_image)
        frame.timings["render"] = time.perf_counter() - clock
        clock = time.perf_counter()
        save_png(out / "frames" / f"frame_{frame.index:04d}.png", rgb, compress_level=FRAME_PNG_LEVEL)
        if args.ply:
            save_scene(animation.current_scene(), out / "ply" / f"frame_{frame.index:04d}.ply")
        frame.timings["write"] = time.perf_counter() - clock
        images.append(rgb)
        for stage, seconds in frame.timings.items():
            totals[stage] = totals.get(stage, 0.0) + seconds
    if args.video.lower() != "none":
        clock = time.perf_counter()
        write_video(out / args.video, images, args.fps)
        totals["video"] = time.perf_counter() - clock
    rest = np.abs(animation.rods[0].positions - animation.rods[0].rest_positions).max()
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in totals.items())
    print(f"{count} frames at {camera.width}x{camera.height} -> {out}; rod 0 ends {rest:.3g} from rest; {stages}")
    if not np.isfinite(animation.means).all():
        raise SketchRodGSError("the simulation produced non-finite positions")
    return 0
