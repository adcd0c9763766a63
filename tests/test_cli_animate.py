"""`sketchrodgs animate`: frames, video and deformed .ply from a rod file; readable failures."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import plyfile
import pytest
from PIL import Image

from sketchrodgs import Camera, data, extract_rod, load_scene

CAMERA = Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=320, height=180, fov_y_deg=40)


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "sketchrodgs", *args], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def ring_rod(tmp_path_factory):
    scene = load_scene(data.sample("ring"))
    theta = np.radians(np.linspace(20, 160, 25))
    uv, _ = CAMERA.project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    path = tmp_path_factory.mktemp("rod") / "rod.json"
    extraction = extract_rod(scene, CAMERA, uv)
    extraction.save(path)
    return path, extraction


def test_animate_writes_frames_video_and_ply(ring_rod, tmp_path):
    path, extraction = ring_rod
    middle = len(extraction.polyline) // 2
    out = tmp_path / "anim"
    result = run_cli(
        "animate",
        "sample:ring",
        str(path),
        "--grab",
        str(middle),
        "--to",
        "0,0.12,-0.08",
        "--duration",
        "0.3",
        "--hold",
        "0.2",
        "--release",
        "--settle",
        "0.5",
        "--fps",
        "20",
        "-o",
        str(out),
        "--ply",
        "--video",
        "pull.gif",
    )
    assert result.returncode == 0, result.stderr
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert len(frames) == 20  # (0.3 + 0.2 + 0.5) s at 20 fps
    first, held, last = (np.asarray(Image.open(frames[k]), np.int16) for k in (0, 7, -1))  # 7: frame 8, held
    assert first.shape == (180, 320, 3)

    def changed(a, b) -> int:  # pixels that changed visibly
        return int((np.abs(a - b).max(axis=2) > 40).sum())

    assert changed(held, first) > 500  # visibly pulled while held
    assert changed(last, first) < changed(held, first) / 10  # and sprang back
    with Image.open(out / "pull.gif") as gif:
        assert gif.is_animated and gif.n_frames >= 10  # Pillow merges identical frames at rest
    plys = sorted((out / "ply").glob("frame_*.ply"))
    source = json.loads((out / "ply" / "source.json").read_text())
    rows = source["source"]  # the input's rows, then the pieces of split needles
    assert source["input_gaussians"] == 10_000 and rows[:10_000] == list(range(10_000)) and max(rows) < 10_000
    assert len(plys) == 20 and plyfile.PlyData.read(plys[9])["vertex"].count == len(rows)
    assert "20 frames" in result.stdout


def test_animate_mp4(ring_rod, tmp_path):
    path, extraction = ring_rod
    result = run_cli(
        "animate",
        "sample:ring",
        str(path),
        "--grab",
        "5",
        "--to",
        "0,0.05,0",
        "--duration",
        "0.2",
        "--hold",
        "0.1",
        "--fps",
        "20",
        "-o",
        str(tmp_path / "a"),
    )
    assert result.returncode == 0, result.stderr
    video = (tmp_path / "a" / "pull.mp4").read_bytes()
    assert len(video) > 1000 and video[4:8] == b"ftyp"


def test_bad_rod_files_and_arguments_fail_readably(ring_rod, tmp_path):
    path, extraction = ring_rod
    broken = extraction.to_json()  # the inline form older rod files have
    broken["binding"]["segment"] = broken["binding"]["segment"][:-1]
    (tmp_path / "broken.json").write_text(json.dumps(broken))
    result = run_cli(
        "animate",
        "sample:ring",
        str(tmp_path / "broken.json"),
        "--grab",
        "3",
        "--to",
        "0,0.1,0",
        "-o",
        str(tmp_path / "x"),
    )
    assert result.returncode == 1 and "binding.segment" in result.stderr and "Traceback" not in result.stderr
    result = run_cli("animate", "sample:ring", str(path), "--grab", "999", "--to", "0,0.1,0", "-o", str(tmp_path / "y"))
    assert result.returncode == 1 and "grab vertex" in result.stderr
    assert (
        run_cli(
            "animate", "sample:ring", str(path), "--grab", "3", "--to", "0,nan,0", "-o", str(tmp_path / "z")
        ).returncode
        == 2
    )
