"""Between viser's browser camera and our pinhole `Camera`.

viser reports a client's camera as `wxyz` (the rotation camera -> world), `position` (the camera
centre), `fov` (vertical field of view in radians) and the canvas size, in the OpenCV convention
our `Camera` uses too (x right, y down, z forward). Pointer positions arrive normalised to the
canvas, `(0, 0)` the top-left corner and `(1, 1)` the bottom-right one; viser already puts an
integer CSS pixel at its centre (+0.5), so in our continuous pixel coordinates (docs/conventions.md) a
pointer at `(u, v)` is the pixel point `(u * W, v * H)` of an image of any size `W x H` with that
aspect ratio. (The issue's `px = u*W - 0.5` is the same point in pixel-index convention.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera import NEAR_PLANE, Camera
from ..errors import CameraError
from ..working_view import WORKING_WIDTH

DEFAULT_WORKING_WIDTH = WORKING_WIDTH  # px; extraction renders at this width whatever the browser's size


def quat_to_matrix(wxyz: Sequence[float] | np.ndarray) -> np.ndarray:
    """(3, 3) float64 rotation of a quaternion w, x, y, z (normalised first)."""
    q = np.asarray(wxyz, np.float64).reshape(4)
    norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm == 0:
        raise CameraError(f"camera rotation: not a quaternion: {tuple(q)}")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def camera_from_viser(
    wxyz: Sequence[float] | np.ndarray,
    position: Sequence[float] | np.ndarray,
    fov_y: float,
    aspect: float,
    width: int = DEFAULT_WORKING_WIDTH,
    near: float = NEAR_PLANE,
) -> Camera:
    """Our camera for a viser client camera, at `width` pixels wide.

    Args:
        wxyz: rotation camera -> world (viser's `client.camera.wxyz`).
        position: camera centre in world coordinates.
        fov_y: vertical field of view in radians.
        aspect: canvas width / height.
        width: image width of the returned camera; the height keeps the aspect ratio.
        near: the near plane (viser's `client.camera.near`): what the browser draws, a sketch sees,
            however near the user has come to a small scene (the reference's 0.2 would cull a
            sprinkle the user sees from 0.1 away).

    The focal lengths are chosen so that the canvas' edges are the image's edges exactly (fx and
    fy differ by the rounding of the height, at most half a pixel over the image).
    """
    if not (math.isfinite(fov_y) and 0 < fov_y < math.pi):
        raise CameraError(f"camera fov: must be in (0, pi) radians, got {fov_y}")
    if not (math.isfinite(aspect) and aspect > 0):
        raise CameraError(f"camera aspect: must be > 0, got {aspect}")
    height = max(1, round(width / aspect))
    tan_half = math.tan(fov_y / 2)
    camera_to_world = quat_to_matrix(wxyz)
    centre = np.asarray(position, np.float64).reshape(3)
    world_to_camera = np.eye(4)
    world_to_camera[:3, :3] = camera_to_world.T
    world_to_camera[:3, 3] = -camera_to_world.T @ centre
    return Camera(
        width,
        height,
        fx=width / (2 * aspect * tan_half),
        fy=height / (2 * tan_half),
        cx=width / 2,
        cy=height / 2,
        world_to_camera=world_to_camera,
        name="viewer",
        near=near,
    )


@dataclass(frozen=True)
class ViserView:
    """What to give viser to show the view of one of our cameras (its principal point is assumed
    to be the image centre, as in every camera we make)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_y: float


def viser_view(camera: Camera, look_distance: float = 1.0) -> ViserView:
    """The viser pose (position, look-at point `look_distance` ahead, up, vertical fov) of `camera`."""
    c2w = camera.camera_to_world
    centre, forward, down = c2w[:3, 3], c2w[:3, 2], c2w[:3, 1]
    return ViserView(
        tuple(centre.tolist()),
        tuple((centre + look_distance * forward).tolist()),
        tuple((-down).tolist()),
        math.radians(camera.fov_y_deg),
    )


def screen_to_pixels(screen: np.ndarray, camera: Camera) -> np.ndarray:
    """(S, 2) normalised canvas positions -> (S, 2) float32 continuous pixel coordinates of `camera`."""
    uv = np.asarray(screen, np.float64).reshape(-1, 2)
    return (uv * [camera.width, camera.height]).astype(np.float32)


def pixels_to_screen(pixels: np.ndarray, camera: Camera) -> np.ndarray:
    """Inverse of `screen_to_pixels` ((S, 2) float64)."""
    return np.asarray(pixels, np.float64).reshape(-1, 2) / [camera.width, camera.height]


FRAME_MARGIN = 1.4  # the framed sphere's radius, times this, fills the narrower field of view


def framing_view(points: np.ndarray, radius: float, camera: Camera, up: Sequence[float] | np.ndarray) -> ViserView:
    """The view that shows `points` (and `radius` around them) whole from `camera`'s direction."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    sphere = float(np.linalg.norm(p - centre, axis=1).max()) + radius
    forward = camera.camera_to_world[:3, 2]
    half = min(math.atan(camera.height / (2 * camera.fy)), math.atan(camera.width / (2 * camera.fx)))
    distance = FRAME_MARGIN * max(sphere, 1e-9) / math.sin(half)
    position = centre - distance * forward
    return ViserView(
        tuple(position.tolist()),
        tuple(centre.tolist()),
        (float(up[0]), float(up[1]), float(up[2])),
        2 * math.atan(camera.height / (2 * camera.fy)),
    )
