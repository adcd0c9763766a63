"""A 3DGS training output folder wherever a scene is expected: the latest point cloud, and its
cameras.json as the default camera and the source of the up direction."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from sketchrodgs import Camera, data, load_cameras, load_scene, save_scene
from sketchrodgs.cli import main
from sketchrodgs.io import detect_format, scene_file, training_cameras
from sketchrodgs.rod_file import load_rod

# what the reference trainer leaves: training views of the ring, taken with +y up in the image
VIEWS = [Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=320, height=180, fov_y_deg=40)] + [
    Camera.orbit((0, 0, 0), 1.5, az, 20, up=(0, 1, 0), width=320, height=180, fov_y_deg=40) for az in (60, 150, 240)
]


def inria_entry(index: int, camera: Camera) -> dict:
    """A `cameras.json` entry as graphdeco-inria's trainer writes it (rotation: camera to world)."""
    return {
        "id": index,
        "img_name": f"{index:05d}",
        "width": camera.width,
        "height": camera.height,
        "position": camera.center.tolist(),
        "rotation": camera.camera_to_world[:3, :3].tolist(),
        "fy": camera.fy,
        "fx": camera.fx,
    }


@pytest.fixture(scope="module")
def output(tmp_path_factory):
    folder = tmp_path_factory.mktemp("train") / "ring_run"
    ring = load_scene(data.sample("ring"))
    for iteration, scene in ((7000, ring.subset(np.arange(5000))), (30000, ring)):
        (folder / "point_cloud" / f"iteration_{iteration}").mkdir(parents=True)
        save_scene(scene, folder / "point_cloud" / f"iteration_{iteration}" / "point_cloud.ply")
    (folder / "cameras.json").write_text(json.dumps([inria_entry(i, c) for i, c in enumerate(VIEWS)]))
    return folder


def test_the_folder_stands_for_its_latest_point_cloud(output):
    assert scene_file(output) == output / "point_cloud" / "iteration_30000" / "point_cloud.ply"
    assert len(load_scene(output)) == 10_000 and detect_format(output) == "ply"
    assert training_cameras(output) == output / "cameras.json"
    assert training_cameras(scene_file(output)) is None


def test_info_takes_up_from_the_training_cameras(output, capsys):
    assert main(["info", str(output)]) == 0
    text = capsys.readouterr().out
    assert "10,000" in text and "iteration_30000" in text
    assert "up         +y  (from 4 training cameras" in text  # the shape alone says +z (flat ring)


def test_render_uses_the_folders_cameras_json(output, tmp_path):
    assert main(["render", str(output), "--view", "0", "-o", str(tmp_path / "a.png")]) == 0
    ply = scene_file(output)
    assert main(["render", str(ply), "--camera", str(output / "cameras.json"), "-o", str(tmp_path / "b.png")]) == 0
    a, b = (np.asarray(Image.open(tmp_path / name)) for name in ("a.png", "b.png"))
    assert a.shape == (180, 320, 3) and np.array_equal(a, b) and (a.max(axis=2) > 20).mean() > 0.05


def test_camera_frames_the_folder_upright_by_its_training_cameras(output, tmp_path, capsys):
    assert main(["camera", str(output), "-o", str(tmp_path / "cam.json"), "--preview", str(tmp_path / "p.png")]) == 0
    assert "up +y (from 4 training cameras" in capsys.readouterr().out
    (camera,) = load_cameras(tmp_path / "cam.json")
    uv, _ = camera.project(np.array([[0.0, 0.0, 0.0], [0.0, 0.1, 0.0]]))
    assert uv[1, 1] < uv[0, 1]  # +y is up in the image


def test_extract_and_animate_a_folder_without_camera_options(output, tmp_path, capsys):
    theta = np.radians(np.linspace(20, 160, 25))
    uv, _ = VIEWS[0].project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    (tmp_path / "stroke.json").write_text(json.dumps({"points": uv.tolist()}))
    rod = tmp_path / "rod.json"
    assert main(["extract", str(output), "--stroke", str(tmp_path / "stroke.json"), "-o", str(rod)]) == 0
    assert load_rod(rod)[0].camera.name == "00000"  # the folder's first camera
    args = ["animate", str(output), str(rod), "--grab", "0.5", "--to", "0,0.05,0", "--duration", "0.1", "--hold", "0"]
    capsys.readouterr()
    assert main([*args, "--fps", "10", "--video", "none", "-o", str(tmp_path / "anim")]) == 0
    assert len(list((tmp_path / "anim" / "frames").glob("*.png"))) == 1
    # the training cameras know which way is up: gravity is on, against it
    assert "gravity 9.81 down, +y up (from 4 training cameras)" in capsys.readouterr().out


def test_a_folder_that_is_no_training_output_is_one_line(tmp_path, capsys):
    (tmp_path / "point_cloud" / "iteration_x").mkdir(parents=True)
    assert main(["info", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(tmp_path) in err and "not a 3DGS training output" in err
