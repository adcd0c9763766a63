"""`sketchrodgs demo`: the first thing a new user runs must work and leave files they can open."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from sketchrodgs import Camera, data, load_scene
from sketchrodgs.rod_file import load_rod

pytestmark = pytest.mark.slow  # run by default; `-m "not slow"` leaves it out


def test_demo_writes_everything_it_promises(tmp_path):
    out = tmp_path / "demo"
    result = subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "demo", "-o", str(out)], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    for name in ("view.png", "overlay.png", "pulled.png", "rod.json", "pull.mp4", "summary.txt"):
        assert (out / name).stat().st_size > 0, name
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert len(frames) == 60
    # the rod lies on the stem the stored stroke follows: its projection stays near the stroke
    rod = json.loads((out / "rod.json").read_text())
    camera = Camera.from_dict(rod["camera"])
    uv, _ = camera.project(np.array(rod["polyline"]))
    stroke = data.sample_stroke("plant")
    gaps = np.min(np.linalg.norm(uv[:, None] - stroke[None], axis=2), axis=1)
    assert np.median(gaps) < 15, gaps
    # the stem with its leaves, and its tip past the stroke with the tip's leaves: not the plant
    assert 300 < len(load_rod(out / "rod.json")[0].gaussian_ids) < len(load_scene(data.sample("plant"))) // 10
    # the pulled frame differs from the view where the stem is, and the last frame is back at rest
    view, pulled, last = (
        np.asarray(Image.open(out / n), np.int16) for n in ("view.png", "pulled.png", "frames/frame_0060.png")
    )
    moved = np.abs(pulled - view).max(axis=2) > 40
    assert moved.sum() > 200
    assert (np.abs(last - view).max(axis=2) > 40).sum() < moved.sum() / 10
    summary = (out / "summary.txt").read_text()
    assert "render frames" in summary and "total_s" in summary and "bound_gaussians" in summary


def test_demo_view_serves_the_viewer_with_the_rod(tmp_path):
    """`demo --view` ends in the viewer on loopback with the demo's rod loaded."""
    import socket
    import time
    import urllib.request

    with socket.socket() as probe:  # a free port on loopback
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    process = subprocess.Popen(
        [sys.executable, "-m", "sketchrodgs", "demo", "-o", str(tmp_path / "d"), "--view", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        url, deadline, seen = None, time.monotonic() + 240, []
        while url is None and time.monotonic() < deadline:
            line = process.stdout.readline()
            if not line:
                break
            seen.append(line)
            if line.startswith("sketchrodgs viewer: http"):
                url = line.split()[2]
        assert url is not None, "".join(seen)
        assert "1 rod(s)" in seen[-1] and url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(url, timeout=30) as response:
            assert response.status == 200 and b"<html" in response.read().lower()
    finally:
        process.terminate()
        process.wait(timeout=30)


def test_demo_contact_shows_a_stem_stopping_at_the_main_stem(tmp_path):
    from sketchrodgs.demo import push_past_the_main_stem

    summary = push_past_the_main_stem(tmp_path, progress=lambda line: None)
    # with contact the stem's surface stays out of the main stem (its axis a radius away); without
    # it the axis goes right up to it or into it
    assert summary["closest_on_radii"] > 0.95, summary
    assert summary["closest_off_radii"] < 0.5, summary
    picture = np.asarray(Image.open(tmp_path / "contact.png"))
    assert picture.shape[1] > 3 * picture.shape[0] / 2  # three panels side by side
    assert (tmp_path / "contact.mp4").stat().st_size > 1000 and summary["frames"] == 54
