"""`sketchrodgs extract`: rod JSON and overlay from files, readable failures."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from sketchrodgs import Camera, data, load_scene
from sketchrodgs.rod_file import load_rod

CAMERA = Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=480, height=270, fov_y_deg=40)


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "sketchrodgs", *args], capture_output=True, text=True, timeout=120)


def ring_stroke() -> list[list[float]]:
    theta = np.radians(np.linspace(20, 160, 25))
    uv, _ = CAMERA.project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    return uv.tolist()


def test_extract_writes_rod_json_and_overlay(tmp_path):
    CAMERA.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": ring_stroke()}))
    result = run_cli(
        "extract",
        "sample:ring",
        "--camera",
        str(tmp_path / "cam.json"),
        "--stroke",
        str(tmp_path / "stroke.json"),
        "-o",
        str(tmp_path / "rod.json"),
        "--overlay",
        str(tmp_path / "o.png"),
    )
    assert result.returncode == 0, result.stderr
    assert "stroke covered 100%" in result.stdout
    rod = json.loads((tmp_path / "rod.json").read_text())
    polyline = np.array(rod["polyline"])
    assert polyline.shape[1] == 3 and len(polyline) >= 10
    ids = load_rod(tmp_path / "rod.json")[0].gaussian_ids
    assert rod["radius"] > 0 and len(ids) > 1000 and len(rod["stroke"]) == 25
    assert ids.max() < len(load_scene(data.sample("ring")))
    overlay = np.asarray(Image.open(tmp_path / "o.png"))
    assert overlay.shape == (270, 480, 3)
    # the stroke (green) and the polyline (blue) are drawn
    green = (overlay[..., 1] > 200) & (overlay[..., 0] < 100)
    blue = (overlay[..., 2] > 200) & (overlay[..., 0] < 100) & (overlay[..., 1] < 200)
    assert green.sum() > 100 and blue.sum() > 50


def test_extract_on_background_fails_with_one_line(tmp_path):
    CAMERA.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": [[5, 5], [60, 8], [120, 5]]}))
    result = run_cli(
        "extract",
        "sample:ring",
        "--camera",
        str(tmp_path / "cam.json"),
        "--stroke",
        str(tmp_path / "stroke.json"),
        "-o",
        str(tmp_path / "rod.json"),
    )
    assert result.returncode == 1
    assert len(result.stderr.strip().splitlines()) == 1 and "background" in result.stderr
    assert not (tmp_path / "rod.json").exists()


def test_a_failed_extract_still_writes_the_overlay(tmp_path):
    """With --overlay a failure draws what the stroke met, so the user sees what to change."""
    CAMERA.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": [[5, 5], [60, 8], [120, 5]]}))
    result = run_cli(
        "extract",
        "sample:ring",
        "--camera",
        str(tmp_path / "cam.json"),
        "--stroke",
        str(tmp_path / "stroke.json"),
        "-o",
        str(tmp_path / "rod.json"),
        "--overlay",
        str(tmp_path / "fail.png"),
    )
    assert result.returncode == 1 and "fail.png" in result.stderr
    assert not (tmp_path / "rod.json").exists()
    overlay = np.asarray(Image.open(tmp_path / "fail.png").convert("RGB"))
    green = (overlay[..., 1] > 200) & (overlay[..., 0] < 100)
    assert green[:20, :130].sum() > 50  # the stroke is drawn where the user put it


@pytest.mark.parametrize(
    "points, message",
    [
        ([1, 2, 3], "stroke.json: expected .* got points of shape"),
        ([["a", "b"], [1, 2]], "stroke.json: .* of numbers .could not convert string to float"),
        ([[[1, 2]], [3, 4]], "stroke.json: .* of numbers .setting an array element"),
        ([[1e300, 1], [2, 3]], r"point 0 \(1e\+300, 1\) is beyond float32's range"),
    ],
)
def test_extract_rejects_a_malformed_stroke_file(tmp_path, points, message):
    CAMERA.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": points}))
    result = run_cli(
        "extract",
        "sample:ring",
        "--camera",
        str(tmp_path / "cam.json"),
        "--stroke",
        str(tmp_path / "stroke.json"),
        "-o",
        str(tmp_path / "rod.json"),
    )
    assert result.returncode == 1 and re.search(message, result.stderr), result.stderr
    assert "Traceback" not in result.stderr and "Warning" not in result.stderr
    assert not (tmp_path / "rod.json").exists()


def test_a_radius_not_above_zero_is_named_as_such(tmp_path):
    for radius in ("-1", "0", "nan"):
        result = run_cli(
            "extract", "sample:ring", "--stroke", "s.json", "-o", str(tmp_path / "r.json"), "--radius", radius
        )
        assert result.returncode == 2 and f"must be a finite number > 0, got {radius}" in result.stderr


def test_extract_can_leave_attached_parts_behind(tmp_path):
    """The plant sample's stem has leaves on it: by default they follow the rod, with --no-attach not."""
    camera, stroke = data.sample_camera("plant"), data.sample_stroke("plant")
    camera.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": stroke.tolist()}))
    rods = {}
    for name, extra in (("default", []), ("none", ["--no-attach"]), ("small", ["--attach-size", "1e-4"])):
        result = run_cli(
            "extract",
            "sample:plant",
            "--camera",
            str(tmp_path / "cam.json"),
            "--stroke",
            str(tmp_path / "stroke.json"),
            "-o",
            str(tmp_path / f"{name}.json"),
            *extra,
        )
        assert result.returncode == 0, result.stderr
        rods[name] = load_rod(tmp_path / f"{name}.json")[0]
    assert rods["default"].binding.attached.sum() > 100
    assert rods["none"].binding.attached.sum() == 0
    # no leaf is as small as 0.1 mm: they stay; lone floaters by the rod's ends still ride along
    assert rods["small"].binding.attached.sum() < 0.05 * rods["default"].binding.attached.sum()
    for name in ("none", "small"):
        assert len(rods[name].gaussian_ids) < len(rods["default"].gaussian_ids)
    result = run_cli(
        "extract",
        "sample:plant",
        "--camera",
        str(tmp_path / "cam.json"),
        "--stroke",
        str(tmp_path / "stroke.json"),
        "-o",
        str(tmp_path / "x.json"),
        "--attach-size",
        "-1",
    )
    assert result.returncode == 2 and "attach-size" in result.stderr
