"""Framing a scene without a camera: which way is up, where the scene is, and a camera that shows
it whole (`sketchrodgs camera`, `render --orbit`, `info`; docs/cli.md, "Cameras").

The up direction is the training cameras' (the mean of their image-up directions) when they are
given; otherwise it is guessed from the scene's shape (`guess_up_axis`). Centre and extent come
from the Gaussians, ignoring floaters (`core_points`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .camera import NEAR_PLANE, Camera
from .errors import CameraError
from .scene import GaussianScene

AXES = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}
# A scene whose thinnest extent is under this fraction of the middle one lies flat (a ring, a donut).
FLAT_RATIO = 0.5
# The sign of a guessed vertical axis, by the conventions of the tools that make most scenes:
# COLMAP-derived captures have camera y down, so -y is up; Blender-style worlds have +z up.
CONVENTIONAL_UP = {0: "+x", 1: "-y", 2: "+z"}
# Floaters lie outside the central 98 % of the centres along each axis, grown by a quarter of its size.
OUTER_FRACTION = 0.01
GROW = 0.25
SAMPLE = 500_000
# The cameras' image-up directions must agree this much (length of their mean) to be used.
CAMERAS_AGREE = 0.5
MARGIN = 0.1  # of the half-image left free around the framed scene (Gaussians reach past their centres)
NEAR_CLEARANCE = 2 * NEAR_PLANE  # no framed centre is nearer to the camera than this
DEFAULT_ORBIT = (30.0, 25.0)  # azimuth, elevation in degrees
DEFAULT_SIZE = (960, 540)
DEFAULT_FOV_Y = 40.0


@dataclass(frozen=True)
class Up:
    """A scene's up direction and how it was found.

    Attributes:
        vector: (3,) unit vector.
        axis: the nearest of AXES ("+x" ... "-z").
        source: "given", "cameras", "format" (the file's format fixes its axes: SPZ) or "guess".
        reason: one line for people ("from 12 training cameras", "guessed: stands tallest along y; ...").
    """

    vector: np.ndarray
    axis: str
    source: str
    reason: str

    @property
    def known(self) -> bool:
        """Given, from cameras or from the format, not guessed from the shape: enough to turn
        gravity on."""
        return self.source != "guess"


def nearest_axis(vector: npt.ArrayLike) -> str:
    """The name in AXES of the axis direction nearest to `vector`."""
    v = np.asarray(vector, np.float64)
    return max(AXES, key=lambda name: float(np.dot(AXES[name], v)))


def guess_up_axis(means: np.ndarray) -> tuple[str, str]:
    """Guess the up axis of a scene from the extent of its centres; returns (axis, reason).

    A scene that is flat along one axis (thinnest extent under FLAT_RATIO of the middle one) lies
    on it: that axis points up, with its positive sign. Otherwise the scene stands along its
    longest axis, signed by convention (CONVENTIONAL_UP): -y for y, the COLMAP convention of
    real captures, +z for z. The guess can be wrong (a capture stored upside down); `--up`
    overrides it.
    """
    if len(means) == 0:
        return CONVENTIONAL_UP[1], "empty scene: the COLMAP convention"
    low, high = np.quantile(np.asarray(means, np.float64), [OUTER_FRACTION, 1 - OUTER_FRACTION], axis=0)
    extent = high - low
    thin, middle, long = (int(k) for k in np.argsort(extent, kind="stable"))
    names = "xyz"
    if extent[thin] < FLAT_RATIO * extent[middle]:
        return "+" + names[thin], f"lies flat: thinnest along {names[thin]}"
    axis = CONVENTIONAL_UP[long]
    why = "the COLMAP convention" if long == 1 else "the z-up convention" if long == 2 else "no convention for x"
    return axis, f"stands tallest along {names[long]}; {axis} by {why}"


def up_from_cameras(cameras: Sequence[Camera]) -> np.ndarray | None:
    """(3,) the mean image-up direction of `cameras` in world coordinates, normalised; None when
    there are none or they disagree (the mean is shorter than CAMERAS_AGREE)."""
    if not cameras:
        return None
    # a camera's image up is its -y axis; row 1 of world_to_camera is its y axis in the world
    ups = np.array([-c.world_to_camera[1, :3] for c in cameras])
    mean = ups.mean(axis=0)
    length = float(np.linalg.norm(mean))
    return mean / length if length >= CAMERAS_AGREE else None


def scene_up(
    scene: GaussianScene,
    cameras: Sequence[Camera] = (),
    given: str | None = None,
    file_up: tuple[str, str] | None = None,
) -> Up:
    """The up direction to frame `scene` with: `given` (a name in AXES), else the training
    `cameras`', else the axis the file's format fixes (`file_up`: (axis, why), from
    `io.format_up`; SPZ's +y), else the guess from the scene's shape."""
    if given is not None:
        if given not in AXES:
            raise CameraError(f"up: expected one of {', '.join(AXES)}, got {given!r}")
        return Up(np.array(AXES[given]), given, "given", "given")
    vector = up_from_cameras(cameras)
    if vector is not None:
        many = f"{len(cameras)} training cameras" if len(cameras) > 1 else "the camera"
        return Up(vector, nearest_axis(vector), "cameras", f"from {many}")
    if file_up is not None:
        axis, reason = file_up
        return Up(np.array(AXES[axis]), axis, "format", f"by {reason}")
    axis, reason = guess_up_axis(scene.means)
    if cameras:
        reason += f" (the {len(cameras)} cameras disagree)"
    return Up(np.array(AXES[axis]), axis, "guess", f"guessed: {reason}")


def up_frame(up: npt.ArrayLike, means: np.ndarray | None = None) -> np.ndarray:
    """(3, 3) rows a, b, up: an orthonormal frame whose third axis is `up`. With the scene's
    centres `means`, a is the narrow horizontal direction of the scene (the camera at azimuth
    0 faces its broad side), signed towards the nearest positive world axis; else any."""
    u = np.asarray(up, np.float64)
    u = u / np.linalg.norm(u)
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    a = np.cross(u, helper)
    a /= np.linalg.norm(a)
    b = np.cross(u, a)
    if means is not None and len(means) > 2:
        flat = np.asarray(means, np.float64) @ np.stack([a, b]).T
        _, vectors = np.linalg.eigh(np.cov(flat.T))
        a = vectors[0, 0] * a + vectors[1, 0] * b  # the smaller spread
        a = a if a[np.argmax(np.abs(a))] > 0 else -a
    return np.stack([a, np.cross(u, a), u])


def core_points(scene: GaussianScene, up: npt.ArrayLike) -> np.ndarray:
    """(P, 3) float64 the scene's centres without its floaters.

    Floaters are the centres outside the box of the central 98 % along each axis (of a frame
    standing on `up`) grown by GROW of its size on every side. Large scenes are thinned to
    SAMPLE centres first.
    """
    if len(scene) == 0:
        raise CameraError("cannot frame an empty scene")
    frame = up_frame(up)
    local = np.asarray(scene.means[:: max(1, len(scene) // SAMPLE)], np.float64) @ frame.T
    low, high = np.quantile(local, [OUTER_FRACTION, 1 - OUTER_FRACTION], axis=0)
    pad = GROW * (high - low)
    return local[((local >= low - pad) & (local <= high + pad)).all(axis=1)] @ frame


def frame_scene(
    scene: GaussianScene,
    up: npt.ArrayLike,
    orbit: tuple[float, float] = DEFAULT_ORBIT,
    distance: float | None = None,
    look_at: npt.ArrayLike | None = None,
    width: int = DEFAULT_SIZE[0],
    height: int = DEFAULT_SIZE[1],
    fov_y_deg: float = DEFAULT_FOV_Y,
    name: str = "",
) -> Camera:
    """A camera on an orbit around the scene that shows all of it but its floaters (`core_points`).

    Args:
        scene: the scene.
        up: (3,) the scene's up direction (`scene_up(...).vector`); it points up in the image.
        orbit: (azimuth, elevation) in degrees: azimuth turns about `up` from the scene's
            broad side (`up_frame`), elevation lifts the camera towards `up`.
        distance: from the camera to the target (default: the nearest at which the centres fit,
            with MARGIN free around them).
        look_at: (3,) the target (default: the centre of the centres' box).
        width, height, fov_y_deg: the image.
        name: the camera's name.

    When the fitting distance would bring a centre within NEAR_CLEARANCE of the camera (a scene
    not much larger than the rasteriser's 0.2 near plane), the camera moves back and the field of
    view narrows to keep the same framing.
    """
    points = core_points(scene, up)
    frame = up_frame(up, points)
    a, b, u = frame
    local = points @ frame.T
    centre = (local.min(axis=0) + local.max(axis=0)) / 2 @ frame  # of the box in the scene's frame
    target = centre if look_at is None else np.asarray(look_at, np.float64)
    if target.shape != (3,) or not np.isfinite(target).all():
        raise CameraError(f"look_at: expected three finite numbers, got {look_at!r}")
    if distance is not None and not (math.isfinite(distance) and distance > 0):
        raise CameraError(f"distance: must be > 0, got {distance}")
    azimuth, elevation = (math.radians(v) for v in orbit)
    direction = math.cos(elevation) * (math.cos(azimuth) * a + math.sin(azimuth) * b) + math.sin(elevation) * u
    probe = Camera.look_at(target + direction, target, u, width, height, fov_y_deg)
    # the points in camera axes relative to the target; the camera sits `distance` behind it on z
    rel = (points - target) @ probe.world_to_camera[:3, :3].T
    x, y, z = np.abs(rel[:, 0]), np.abs(rel[:, 1]), rel[:, 2]
    half_w, half_h = (1 - MARGIN) * width / (2 * probe.fx), (1 - MARGIN) * height / (2 * probe.fy)
    fit = float(np.max(np.maximum(x / half_w, y / half_h) - z))
    if distance is None:
        distance = max(fit, NEAR_CLEARANCE - float(z.min()))
        if distance > fit:  # too close for the near plane: a longer lens from further away
            depth = z + distance
            zoom = float(np.min(np.minimum(half_w * depth / x.clip(1e-12), half_h * depth / y.clip(1e-12))))
            fov_y_deg = math.degrees(2 * math.atan(math.tan(math.radians(fov_y_deg) / 2) / zoom))
    return Camera.look_at(target + distance * direction, target, u, width, height, fov_y_deg, name)
