"""`sketchrodgs camera SCENE -o CAM.json [--orbit AZ,EL] ...`: a camera that frames the scene."""

from __future__ import annotations

import argparse

from ._args import IMAGE_SUFFIXES, output_file, scene_help, scene_path
from ._framing import add_framing_arguments, add_near_argument

NAME = "camera"
HELP = "write a camera that shows the whole scene upright (no Python needed), optionally with a preview render"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help=scene_help())
    parser.add_argument(
        "-o", "--output", required=True, type=output_file(".json"), metavar="CAM.json", help="camera JSON to write"
    )
    parser.add_argument(
        "--camera",
        metavar="CAMERAS.json",
        help="the scene's training cameras (a 3DGS cameras.json or our camera JSON): up is theirs "
        "(default: the cameras.json of a training output folder)",
    )
    parser.add_argument(
        "--preview",
        type=output_file(*IMAGE_SUFFIXES),
        metavar="PREVIEW.png",
        help="also render the view (.png or .jpg)",
    )
    add_framing_arguments(parser, default_size=(960, 540))
    add_near_argument(parser, "not drawn, written into the camera JSON")


def run(args: argparse.Namespace) -> int:
    import sys

    from ..images import save_image
    from ..io import load_scene
    from ..near_plane import why_nothing_is_visible
    from ..render import COLOR_OUTPUTS, render
    from ._framing import describe, framed_camera, scene_cameras, with_near
    from ._outputs import Outputs

    with Outputs() as outputs:
        camera_path = outputs.file(args.output, "-o")
        preview_path = outputs.file(args.preview, "--preview") if args.preview else None
        cameras = scene_cameras(args)
        scene = load_scene(args.scene)
        camera, up = framed_camera(args, scene, cameras)
        camera = with_near(camera, args)
        camera.save(camera_path)
        print(f"camera {describe(camera, up)} -> {args.output}")
        if preview_path is not None:
            image = render(scene, camera, outputs=COLOR_OUTPUTS)
            save_image(preview_path, image.rgb_image)
            covered = float(image.covered().mean())
            print(f"preview: {covered:.1%} of the pixels covered -> {args.preview}")
            if covered == 0:
                print(f"sketchrodgs camera: warning: {why_nothing_is_visible(scene, camera)}", file=sys.stderr)
        outputs.commit()
    return 0
