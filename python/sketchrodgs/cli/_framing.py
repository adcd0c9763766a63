"""The camera options shared by `camera` and `render`: a camera file, or a camera framing the
scene (`framing.py`), and the scene's training cameras (a 3DGS output folder's cameras.json)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ._args import UsageError, numbers, pixels, positive

if TYPE_CHECKING:
    from ..camera import Camera
    from ..framing import Up
    from ..scene import GaussianScene

UP_CHOICES = ("+x", "-x", "+y", "-y", "+z", "-z")  # framing.AXES, without importing numpy here
FRAMING_OPTIONS = ("orbit", "distance", "up", "look_at")


def _orbit(value: str) -> tuple[float, float]:
    azimuth, elevation = numbers(2, "AZ,EL")(value)
    if not -90 < elevation < 90:
        raise argparse.ArgumentTypeError(f"elevation must be between -90 and 90 degrees, got {elevation:g}")
    return azimuth, elevation


def add_camera_file_argument(parser: argparse.ArgumentParser, help: str) -> None:
    parser.add_argument("--camera", metavar="CAM.json", help=help)
    parser.add_argument(
        "--view", metavar="N|NAME", help="which camera of the file: position or name (default: the first)"
    )


def add_near_argument(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--near",
        type=positive,
        metavar="Z",
        help=f"Gaussians nearer to the camera than this (camera z, scene units) are {what} (default: the "
        "camera's, 0.2 unless its JSON gives one: the reference 3DGS renderer's; lower it for close-ups of "
        'small scenes; docs/cli.md, "The near plane")',
    )


def with_near(camera: Camera, args: argparse.Namespace) -> Camera:
    """`camera` with the near plane of --near, if given."""
    import dataclasses

    return dataclasses.replace(camera, near=args.near) if args.near is not None else camera


def add_framing_arguments(parser: argparse.ArgumentParser, default_size: tuple[int, int] | None) -> None:
    """--orbit, --distance, --up, --look-at, and --width/--height (with `default_size` for a
    framed camera; None: the image size of the camera file)."""
    group = parser.add_argument_group('framing the scene (docs/cli.md, "Cameras")')
    group.add_argument(
        "--orbit",
        type=_orbit,
        metavar="AZ,EL",
        help="azimuth about the up axis (0: facing the scene's broad side) and elevation towards it, "
        "in degrees (default 30,25)",
    )
    group.add_argument("--distance", type=positive, metavar="D", help="from the camera to the target (default: fits)")
    group.add_argument(
        "--up",
        choices=UP_CHOICES,
        help="the scene's up axis (default: the training cameras', else a guess from the shape: see `info`)",
    )
    group.add_argument(
        "--look-at",
        type=numbers(3, "X,Y,Z"),
        metavar="X,Y,Z",
        help="the target (default: the centre of the scene, floaters left out)",
    )
    size = f" (default {default_size[0]}x{default_size[1]} for a framed camera)" if default_size else ""
    group.add_argument("--width", type=pixels, help=f"image width in pixels{size}")
    group.add_argument("--height", type=pixels, help=f"image height in pixels{size}")


def framing_given(args: argparse.Namespace) -> bool:
    return any(getattr(args, name, None) is not None for name in FRAMING_OPTIONS)


def camera_file(args: argparse.Namespace) -> str | None:
    """The camera file of the command: --camera, else the scene folder's cameras.json."""
    from ..io import training_cameras

    if args.camera:
        return str(args.camera)
    found = training_cameras(args.scene)
    return None if found is None else str(found)


def scene_cameras(args: argparse.Namespace) -> list[Camera]:
    """The cameras of `camera_file(args)` (none without one)."""
    from ..camera import load_cameras

    path = camera_file(args)
    return load_cameras(path) if path else []


def framed_camera(args: argparse.Namespace, scene: GaussianScene, cameras: list[Camera]) -> tuple[Camera, Up]:
    """The camera the framing options describe, with the up direction it used."""
    from ..framing import DEFAULT_ORBIT, DEFAULT_SIZE, frame_scene, scene_up
    from ..io import format_up

    if getattr(args, "view", None) is not None:
        raise UsageError(
            "--view picks a camera of a camera file; it cannot be used with --orbit, --distance, --up or "
            "--look-at, nor without a camera file"
        )
    up = scene_up(scene, cameras, args.up, format_up(args.scene))
    width, height = args.width, args.height
    if width is None and height is None:
        width, height = DEFAULT_SIZE
    elif height is None:
        height = max(1, round(width * DEFAULT_SIZE[1] / DEFAULT_SIZE[0]))
    elif width is None:
        width = max(1, round(height * DEFAULT_SIZE[0] / DEFAULT_SIZE[1]))
    orbit = args.orbit or DEFAULT_ORBIT
    name = f"orbit {orbit[0]:g},{orbit[1]:g}"
    return frame_scene(scene, up.vector, orbit, args.distance, args.look_at, width, height, name=name), up


def describe_up(up: Up) -> str:
    """The up direction for people: the axis, and the vector when it is not an axis."""
    vector = ", ".join(f"{v:.3f}" for v in up.vector)
    return f"{up.axis} ({up.reason})" if up.source != "cameras" else f"{up.axis} ({up.reason}: {vector})"


def describe(camera: Camera, up: Up) -> str:
    """One line about a framed camera."""
    eye = ", ".join(f"{v:.4g}" for v in camera.center)
    return f"{camera.width}x{camera.height}, {camera.fov_y_deg:.1f} deg field of view, at ({eye}); up {describe_up(up)}"
