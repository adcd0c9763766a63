"""Cameras: projection, look-at, JSON and 3DGS cameras.json, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import DATA
from sketchrodgs import Camera, CameraError, load_cameras
from sketchrodgs.camera import select_camera


def test_project_follows_opencv_pinhole():
    cam = Camera(640, 480, 500.0, 400.0, 320.0, 240.0, np.eye(4))
    uv, depth = cam.project(np.array([[0.0, 0, 2], [1, 0, 2], [0, 1, 4], [0, 0, -1]]))
    np.testing.assert_allclose(uv[:3], [[320, 240], [570, 240], [320, 340]])
    np.testing.assert_allclose(depth, [2, 2, 4, -1])
    assert np.isnan(uv[3]).all()  # behind the camera: no pixel


def test_look_at_reproduces_the_oracle_cameras():
    for entry in json.loads((DATA / "cameras_plant.json").read_text())["cameras"]:
        cam = Camera.look_at(
            entry["eye"], entry["target"], entry["world_up"], 960, 540, fov_y_deg=np.degrees(2 * np.arctan(270 / 800))
        )
        np.testing.assert_allclose(cam.world_to_camera, entry["world_to_camera"], atol=1e-12)
        assert cam.fx == pytest.approx(800) and (cam.cx, cam.cy) == (480, 270)


def test_look_at_refuses_points_too_far_apart_or_not_finite():
    """A camera 1e300 away (a distance in the wrong units): the direction's square overflowed and
    the camera came out "not a rigid transform", naming nothing the user gave."""
    with pytest.raises(CameraError, match=r"too far apart for the camera's maths"):
        Camera.look_at((0.0, 0.0, -1e300), (0.0, 0.0, 0.0))
    with pytest.raises(CameraError, match="must be finite"):
        Camera.look_at((0.0, 0.0, np.nan), (0.0, 0.0, 0.0))
    assert np.isfinite(Camera.look_at((0.0, 0.0, -1e150), (0.0, 0.0, 0.0)).world_to_camera).all()


def test_look_at_orientation():
    cam = Camera.look_at(eye=(0, 0, -5), target=(0, 0, 0), up=(0, 1, 0), width=100, height=100, fov_y_deg=60)
    uv, depth = cam.project(np.array([[0.0, 0, 0], [0, 1, 0], [1, 0, 0]]))
    assert depth[0] == pytest.approx(5)
    assert uv[1, 1] < 50  # world up is image up
    assert uv[2, 0] < 50  # looking along +z with +y up, +x is on the image's left (right-handed)
    np.testing.assert_allclose(cam.center, [0, 0, -5], atol=1e-12)


def test_orbit_keeps_distance_and_looks_at_target():
    for az in (0, 90, 200):
        cam = Camera.orbit((1, 2, 3), 4.0, az, 30)
        np.testing.assert_allclose(np.linalg.norm(cam.center - [1, 2, 3]), 4.0)
        uv, _ = cam.project(np.array([[1.0, 2, 3]]))
        np.testing.assert_allclose(uv[0], [cam.cx, cam.cy], atol=1e-9)


def test_json_round_trip(tmp_path):
    cam = Camera.orbit((0, 0, 0), 3.0, 45, 20, width=320, height=200, name="front")
    cam.save(tmp_path / "cam.json")
    (again,) = load_cameras(tmp_path / "cam.json")
    assert again.name == "front" and (again.width, again.height) == (320, 200)
    np.testing.assert_array_equal(again.world_to_camera, cam.world_to_camera)
    assert again.near == 0.2 and "near" not in json.loads((tmp_path / "cam.json").read_text())


def test_the_near_plane_travels_with_the_camera(tmp_path):
    """A close-up's near plane is written with the camera (only where it is not the reference's
    0.2, so older files read as before) and kept when the camera is resized."""
    cam = Camera.look_at((0, 0, -0.1), (0, 0, 0), up=(0, -1, 0), near=0.01)
    cam.save(tmp_path / "cam.json")
    assert json.loads((tmp_path / "cam.json").read_text())["near"] == 0.01
    (again,) = load_cameras(tmp_path / "cam.json")
    assert again.near == 0.01 and again.resized(480).near == 0.01


def test_oracle_camera_file_loads_by_index_and_name():
    cams = load_cameras(DATA / "cameras_plant.json")
    assert len(cams) == 2
    assert select_camera(cams, "1") is cams[1]
    assert select_camera(cams, cams[0].name) is cams[0]
    with pytest.raises(CameraError, match="out of range"):
        select_camera(cams, 5)
    with pytest.raises(CameraError, match="no camera named"):
        select_camera(cams, "nope")


def test_3dgs_cameras_json(tmp_path):
    # A camera at C looking down world -z with 3DGS's camera-to-world rotation.
    c2w = np.diag([1.0, -1.0, -1.0])
    centre = np.array([0.5, 0.0, 3.0])
    entry = {
        "id": 0,
        "img_name": "IMG_0001",
        "width": 800,
        "height": 600,
        "position": centre.tolist(),
        "rotation": c2w.tolist(),
        "fx": 700.0,
        "fy": 700.0,
    }
    (tmp_path / "cameras.json").write_text(json.dumps([entry]))
    (cam,) = load_cameras(tmp_path / "cameras.json")
    assert cam.name == "IMG_0001" and (cam.cx, cam.cy) == (400, 300)
    np.testing.assert_allclose(cam.center, centre)
    uv, depth = cam.project(np.array([[0.5, 0.0, 0.0], [0.5, 1.0, 0.0]]))
    assert depth[0] == pytest.approx(3)
    np.testing.assert_allclose(uv[0], [400, 300])
    assert uv[1, 1] < 300  # world +y (camera y flipped) is up in the image


def test_resized_scales_intrinsics():
    cam = Camera(960, 540, 800, 800, 480, 270, np.eye(4)).resized(480)
    assert (cam.width, cam.height, cam.fx, cam.cx, cam.cy) == (480, 270, 400, 240, 135)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"fx": 0.0}, "focal length must be > 0"),
        ({"fy": -3.0}, "focal length must be > 0"),
        ({"width": 0}, "width: must be in 1..16384"),
        ({"height": 20000}, "height: must be in 1..16384"),
        ({"width": 10.5}, "width: expected an integer"),
        ({"cx": float("nan")}, "cx: must be finite"),
        ({"world_to_camera": np.diag([2.0, 1, 1, 1])}, "not a rigid transform"),
        ({"world_to_camera": np.diag([1.0, 1, -1, 1])}, "not a rigid transform"),
        ({"world_to_camera": np.eye(3)}, "expected shape"),
        ({"near": 0.0}, "near: must be finite and > 0"),
        ({"near": float("nan")}, "near: must be finite and > 0"),
        ({"near": "close"}, "near: expected a number"),
        ({"near": True}, "near: must be finite and > 0"),
    ],
)
def test_degenerate_cameras_are_errors(kwargs, message):
    args = {"width": 64, "height": 48, "fx": 50.0, "fy": 50.0, "cx": 32.0, "cy": 24.0, "world_to_camera": np.eye(4)}
    args.update(kwargs)
    with pytest.raises(CameraError, match=message):
        Camera(**args)


@pytest.mark.parametrize(
    "content, message",
    [
        ("not json", "not valid JSON"),
        ("[]", "non-empty list"),
        ('{"width": 10}', "camera 0: missing field"),
        (
            '[{"width": 10, "height": 10, "fx": 5, "fy": 5, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},'
            ' {"width": 10, "height": 10, "fx": -5, "fy": 5, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]',
            "camera 1: camera focal length",
        ),
        (
            '[{"id": 0, "width": 4, "height": 4, "position": [0, 0], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 1, "fy": 1}]',
            "rotation must be 3x3 and position 3 numbers",
        ),
    ],
)
def test_bad_camera_files_name_file_and_camera(tmp_path, content, message):
    path = tmp_path / "cams.json"
    path.write_text(content)
    with pytest.raises(CameraError, match=message) as info:
        load_cameras(path)
    assert str(path) in str(info.value)
