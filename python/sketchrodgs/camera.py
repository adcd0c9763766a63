"""Pinhole cameras in the OpenCV convention, their JSON form, and 3DGS `cameras.json`.

Conventions (docs/conventions.md): x right, y down, z forward; `world_to_camera` is 4x4;
`u = fx * X / Z + cx`, `v = fy * Y / Z + cy` in continuous pixel coordinates whose origin is the
top-left corner of the image (pixel (col, row) has its centre at (col + 0.5, row + 0.5)).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import CameraError
from .jsonfile import read_json

MAX_IMAGE_SIDE = 16384  # larger images are refused rather than allocated
RIGID_TOLERANCE = 1e-4  # |R R^T - I| and |det R - 1| allowed in world_to_camera
# The reference 3DGS rasteriser culls Gaussians at camera z <= 0.2 whatever the scene's units; our
# cameras default to it (docs/rendering.md, "Near plane"; rust/sketchrodgs-raster NEAR_PLANE).
NEAR_PLANE = 0.2


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera.

    Attributes:
        width, height: image size in pixels (1..16384).
        fx, fy: focal lengths in pixels (> 0).
        cx, cy: principal point in continuous pixel coordinates (3DGS uses width/2, height/2).
        world_to_camera: (4, 4) float64 rigid transform, OpenCV axes.
        name: optional label (the image name of a 3DGS camera).
        near: Gaussians at camera z at or below this are not drawn (> 0; default the reference's
            0.2, whatever the scene's units: lower it for close-ups of a small scene).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    world_to_camera: np.ndarray = field(repr=False)
    name: str = ""
    near: float = NEAR_PLANE

    def __post_init__(self) -> None:
        for attr in ("width", "height"):
            value = getattr(self, attr)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, np.integer))
                and not (isinstance(value, float) and value.is_integer())
            ):
                raise CameraError(f"camera {attr}: expected an integer, got {value!r}")
            value = int(value)
            if not 1 <= value <= MAX_IMAGE_SIDE:
                raise CameraError(f"camera {attr}: must be in 1..{MAX_IMAGE_SIDE} pixels, got {value}")
            object.__setattr__(self, attr, value)
        for attr in ("fx", "fy", "cx", "cy"):
            try:
                value = float(getattr(self, attr))
            except (TypeError, ValueError):
                raise CameraError(f"camera {attr}: expected a number, got {getattr(self, attr)!r}") from None
            if not math.isfinite(value):
                raise CameraError(f"camera {attr}: must be finite, got {value}")
            object.__setattr__(self, attr, value)
        if self.fx <= 0 or self.fy <= 0:
            raise CameraError(f"camera focal length must be > 0, got fx={self.fx}, fy={self.fy}")
        try:
            near = float(self.near) if not isinstance(self.near, bool) else math.nan
        except (TypeError, ValueError):
            raise CameraError(f"camera near: expected a number, got {self.near!r}") from None
        if not (math.isfinite(near) and near > 0):
            raise CameraError(f"camera near: must be finite and > 0, got {near}")
        object.__setattr__(self, "near", near)
        try:
            matrix = np.array(self.world_to_camera, dtype=np.float64)
        except (TypeError, ValueError):
            raise CameraError("camera world_to_camera: expected a 4x4 matrix of numbers") from None
        if matrix.shape == (3, 4):
            matrix = np.vstack([matrix, [0.0, 0.0, 0.0, 1.0]])
        if matrix.shape != (4, 4):
            raise CameraError(f"camera world_to_camera: expected shape (4, 4), got {matrix.shape}")
        if not np.isfinite(matrix).all():
            raise CameraError("camera world_to_camera: contains NaN or infinite values")
        rotation = matrix[:3, :3]
        if (
            np.abs(rotation @ rotation.T - np.eye(3)).max() > RIGID_TOLERANCE
            or abs(np.linalg.det(rotation) - 1) > RIGID_TOLERANCE
            or np.abs(matrix[3] - [0, 0, 0, 1]).max() > 0
        ):
            raise CameraError("camera world_to_camera: not a rigid transform (rotation must be orthonormal, det +1)")
        matrix.setflags(write=False)
        object.__setattr__(self, "world_to_camera", matrix)

    # -- derived quantities -------------------------------------------------------------------

    @property
    def camera_to_world(self) -> np.ndarray:
        """(4, 4) float64 inverse of `world_to_camera`."""
        rotation, translation = self.world_to_camera[:3, :3], self.world_to_camera[:3, 3]
        inverse = np.eye(4)
        inverse[:3, :3] = rotation.T
        inverse[:3, 3] = -rotation.T @ translation
        return inverse

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return self.camera_to_world[:3, 3]

    @property
    def fov_y_deg(self) -> float:
        """Vertical field of view in degrees."""
        return math.degrees(2 * math.atan(self.height / (2 * self.fy)))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points to pixels.

        Args:
            points: (N, 3) world coordinates.

        Returns:
            uv: (N, 2) float64 continuous pixel coordinates (NaN where depth <= 0).
            depth: (N,) float64 camera z.
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points: expected shape (N, 3), got {pts.shape}")
        cam = pts @ self.world_to_camera[:3, :3].T + self.world_to_camera[:3, 3]
        depth = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            safe = np.where(depth > 0, depth, np.nan)
            uv = np.stack([self.fx * cam[:, 0] / safe + self.cx, self.fy * cam[:, 1] / safe + self.cy], axis=1)
        return uv, depth

    def unproject(self, pixels: npt.ArrayLike, depth: float | npt.ArrayLike) -> np.ndarray:
        """The inverse of `project`: (S, 2) continuous pixel coordinates at camera depth `depth` (z,
        not distance; one for all or one per point) -> (S, 3) float64 world points."""
        px = np.asarray(pixels, np.float64).reshape(-1, 2)
        z = np.asarray(depth, np.float64).reshape(-1, 1)
        local = np.stack([(px[:, 0] - self.cx) / self.fx, (px[:, 1] - self.cy) / self.fy, np.ones(len(px))], axis=1)
        to_world = self.camera_to_world
        return (z * local) @ to_world[:3, :3].T + to_world[:3, 3]

    def screen_offset(self, point: npt.ArrayLike, pixels: Sequence[float]) -> np.ndarray:
        """(3,) the world displacement, parallel to the image plane, that moves `point` by
        `pixels` (du, dv; v down) in the image: pixels at the point's depth."""
        p = np.asarray(point, np.float64).reshape(3)
        depth = float(self.world_to_camera[2, :3] @ p + self.world_to_camera[2, 3])
        if not depth > 0:
            raise CameraError(f"the point {tuple(np.round(p, 6))} is behind the camera")
        du, dv = (float(v) for v in pixels)
        return self.world_to_camera[:3, :3].T @ np.array([du * depth / self.fx, dv * depth / self.fy, 0.0])

    def resized(self, width: int, height: int | None = None) -> Camera:
        """The same view at another image size (focal lengths and principal point scaled)."""
        if height is None:
            height = max(1, round(self.height * width / self.width))
        sx, sy = width / self.width, height / self.height
        return Camera(
            width,
            height,
            self.fx * sx,
            self.fy * sy,
            self.cx * sx,
            self.cy * sy,
            self.world_to_camera,
            self.name,
            self.near,
        )

    # -- construction -------------------------------------------------------------------------

    @classmethod
    def look_at(
        cls,
        eye: npt.ArrayLike,
        target: npt.ArrayLike,
        up: npt.ArrayLike = (0.0, -1.0, 0.0),
        width: int = 960,
        height: int = 540,
        fov_y_deg: float = 37.8,
        name: str = "",
        near: float = NEAR_PLANE,
    ) -> Camera:
        """A camera at `eye` looking at `target` with `up` pointing up in the image.

        The default `up` is -Y, the convention of COLMAP-derived 3DGS captures. The principal point
        is the image centre and pixels are square.
        """
        eye_v, target_v, up_v = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
        if not (np.isfinite(eye_v).all() and np.isfinite(target_v).all() and np.isfinite(up_v).all()):
            raise CameraError(f"look_at: eye, target and up must be finite, got {eye_v}, {target_v}, {up_v}")
        forward = target_v - eye_v
        largest = float(np.abs(forward).max())
        if not math.isfinite(largest * largest * 3):
            # (a distance of 1e300: its square overflows, and the camera came out "not a rigid transform")
            raise CameraError(
                f"look_at: eye {eye_v.tolist()} and target {target_v.tolist()} are too far apart for the camera's maths"
            )
        distance = np.linalg.norm(forward)
        if distance == 0:
            raise CameraError("look_at: eye and target coincide")
        z = forward / distance
        down = -up_v - np.dot(-up_v, z) * z
        if np.linalg.norm(down) < 1e-9:
            raise CameraError("look_at: up is parallel to the viewing direction")
        y = down / np.linalg.norm(down)
        x = np.cross(y, z)
        matrix = np.eye(4)
        matrix[:3, :3] = np.stack([x, y, z])
        matrix[:3, 3] = -matrix[:3, :3] @ eye_v
        if not 0 < fov_y_deg < 180:
            raise CameraError(f"look_at: fov_y_deg must be in (0, 180), got {fov_y_deg}")
        focal = height / (2 * math.tan(math.radians(fov_y_deg) / 2))
        return cls(width, height, focal, focal, width / 2, height / 2, matrix, name, near)

    @classmethod
    def orbit(
        cls,
        target: Sequence[float],
        distance: float,
        azimuth_deg: float,
        elevation_deg: float,
        up: Sequence[float] = (0.0, -1.0, 0.0),
        **kwargs: Any,
    ) -> Camera:
        """A look-at camera on a sphere around `target`.

        Azimuth turns about `up`; elevation lifts the eye towards `up`. Extra keyword arguments go
        to `look_at` (width, height, fov_y_deg, name, near).
        """
        up_v = np.asarray(up, dtype=np.float64)
        up_v = up_v / np.linalg.norm(up_v)
        # Any direction orthogonal to up serves as azimuth zero.
        helper = np.array([1.0, 0.0, 0.0]) if abs(up_v[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
        a = np.cross(up_v, helper)
        a /= np.linalg.norm(a)
        b = np.cross(up_v, a)
        az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
        direction = math.cos(el) * (math.cos(az) * a + math.sin(az) * b) + math.sin(el) * up_v
        eye = np.asarray(target, dtype=np.float64) + distance * direction
        return cls.look_at(eye, target, up_v, **kwargs)

    # -- JSON ---------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """Our camera JSON object (docs/conventions.md)."""
        out: dict[str, Any] = {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "world_to_camera": self.world_to_camera.tolist(),
        }
        if self.name:
            out["name"] = self.name
        if self.near != NEAR_PLANE:
            out["near"] = self.near
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "camera") -> Camera:
        """Parse our camera JSON object; `source` names it in error messages."""
        if not isinstance(data, dict):
            raise CameraError(f"{source}: expected a JSON object, got {type(data).__name__}")
        missing = [k for k in ("width", "height", "fx", "fy", "world_to_camera") if k not in data]
        if missing:
            raise CameraError(f"{source}: missing field(s) {', '.join(missing)}")
        try:
            return cls(
                data["width"],
                data["height"],
                data["fx"],
                data["fy"],
                data.get("cx", data["width"] / 2),
                data.get("cy", data["height"] / 2),
                data["world_to_camera"],
                str(data.get("name", "")),
                data.get("near", NEAR_PLANE),
            )
        except CameraError as exc:
            raise CameraError(f"{source}: {exc}") from None

    @classmethod
    def from_3dgs(cls, data: dict[str, Any], source: str = "camera") -> Camera:
        """Parse one entry of the `cameras.json` written by 3DGS training.

        `rotation` there is camera-to-world and `position` the camera centre; the principal point
        is implicitly the image centre (docs/conventions.md, `cameras.json`).
        """
        missing = [k for k in ("width", "height", "position", "rotation", "fx", "fy") if k not in data]
        if missing:
            raise CameraError(f"{source}: missing field(s) {', '.join(missing)}")
        try:
            rotation = np.array(data["rotation"], dtype=np.float64)
            centre = np.array(data["position"], dtype=np.float64)
        except (TypeError, ValueError):
            raise CameraError(f"{source}: rotation and position must be numbers") from None
        if rotation.shape != (3, 3) or centre.shape != (3,):
            raise CameraError(f"{source}: rotation must be 3x3 and position 3 numbers")
        matrix = np.eye(4)
        matrix[:3, :3] = rotation.T
        matrix[:3, 3] = -rotation.T @ centre
        name = str(data.get("img_name", data.get("id", "")))
        try:
            return cls(
                data["width"],
                data["height"],
                data["fx"],
                data["fy"],
                data["width"] / 2,
                data["height"] / 2,
                matrix,
                name,
            )
        except (CameraError, TypeError) as exc:
            raise CameraError(f"{source}: {exc}") from None

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write this camera as our camera JSON (atomically)."""
        from .atomic import atomic_write_text

        atomic_write_text(path, json.dumps(self.to_dict(), indent=1) + "\n")


def load_cameras(path: str | os.PathLike[str]) -> list[Camera]:
    """Load cameras from our camera JSON (one object, or `{"cameras": [...]}`) or a 3DGS `cameras.json`.

    Raises:
        CameraError: the file is missing, not JSON, or a camera in it is malformed (the message
            names the file and the camera's position in it).
    """
    source = str(path)
    data = read_json(path, CameraError)
    entries = data["cameras"] if isinstance(data, dict) and "cameras" in data else data
    if isinstance(entries, dict):
        entries = [entries]
    if not isinstance(entries, list) or not entries:
        raise CameraError(f"{source}: expected a camera object or a non-empty list of cameras")
    cameras = []
    for i, entry in enumerate(entries):
        where = f"{source}: camera {i}"
        if isinstance(entry, dict) and "rotation" in entry and "position" in entry:
            cameras.append(Camera.from_3dgs(entry, where))
        else:
            cameras.append(Camera.from_dict(entry, where))
    return cameras


def select_camera(cameras: list[Camera], view: str | int | None, source: str = "cameras") -> Camera:
    """Pick one camera by position (int or digit string) or by name; the first if `view` is None."""
    if view is None:
        return cameras[0]
    if isinstance(view, int) or str(view).lstrip("-").isdigit():
        index = int(view)
        if not 0 <= index < len(cameras):
            raise CameraError(f"{source}: view {index} out of range (file has {len(cameras)} cameras)")
        return cameras[index]
    for camera in cameras:
        if camera.name == view:
            return camera
    names = ", ".join(c.name for c in cameras if c.name) or "none"
    raise CameraError(f"{source}: no camera named {view!r} (names: {names})")
