"""`sketchrodgs animate`: frames, video and deformed .ply from a rod file; readable failures."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import plyfile
import pytest
from PIL import Image

from conftest import DATA
from sketchrodgs import Camera, GaussianScene, SketchRodGSError, data, extract_rod, load_scene, save_scene
from sketchrodgs.cli import main

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
    # a hold of 1e308 s was an OverflowError, a rate of 1e9 fps a billion frames written for days
    for option, value, frames in (("--hold", "1e308", "inf frames"), ("--fps", "1e9", "1e+09 frames")):
        result = run_cli(
            "animate",
            "sample:ring",
            str(path),
            "--grab",
            "3",
            "--to",
            "0,0.1,0",
            option,
            value,
            "-o",
            str(tmp_path / "w"),
        )
        assert result.returncode == 1 and frames in result.stderr and "at most 100,000" in result.stderr, result.stderr
        assert "Traceback" not in result.stderr and not (tmp_path / "w").exists()


# ----- pulls in screen space, along the rod, with negative values ---------------------------------


def test_negative_values_follow_their_option():
    from sketchrodgs.cli import build_parser
    from sketchrodgs.cli._args import attach_negative_lists

    words = attach_negative_lists(["animate", "s.ply", "r.json", "--grab", "-1", "--to", "-0.02,0,0", "-o", "out"])
    assert words[-4:] == ["-1", "--to=-0.02,0,0", "-o", "out"]
    args = build_parser("animate").parse_args(words)
    assert args.to == (-0.02, 0.0, 0.0) and args.grab == -1
    assert attach_negative_lists(["--drag", "-10,-5e-1"]) == ["--drag=-10,-5e-1"]


def test_drag_pulls_in_pixels_of_the_camera(ring_rod, tmp_path):
    """--drag 40,-30: the grabbed vertex's Gaussians move 40 px right and 30 px up in the rod's view."""
    path, extraction = ring_rod
    out = tmp_path / "drag"
    assert main([
        "animate", "sample:ring", str(path), "--grab", "0.5", "--drag", "40,-30",
        "--duration", "0.2", "--hold", "0.1", "--fps", "10", "--video", "none", "--ply", "-o", str(out),
    ]) == 0  # fmt: skip
    rest = load_scene(data.sample("ring")).means
    held = load_scene(out / "ply" / "frame_0003.ply").means[: len(rest)]
    middle = int(np.argmin(np.abs(np.linspace(0, 1, len(extraction.polyline)) - 0.5)))
    near = np.linalg.norm(rest - extraction.polyline[middle], axis=1) < 1.5 * extraction.radius
    (before, _), (after, _) = CAMERA.project(rest[near]), CAMERA.project(held[near])
    np.testing.assert_allclose(np.median(after - before, axis=0), [40, -30], atol=4)


def test_camera_screen_offset_moves_the_projection_by_the_pixels():
    point = np.array([0.1, -0.05, 0.3])
    offset = CAMERA.screen_offset(point, (12.0, -7.0))
    (a, b), depth = CAMERA.project(np.stack([point, point + offset]))
    np.testing.assert_allclose(b - a, [12, -7], atol=1e-9)
    assert depth[0] == pytest.approx(depth[1])  # at the point's depth


def test_a_pull_longer_than_the_rod_is_warned_about(ring_rod, tmp_path, caplog):
    path, _ = ring_rod
    assert main([
        "animate", "sample:ring", str(path), "--grab", "3", "--to", "-5,0,0",
        "--duration", "0.1", "--hold", "0", "--fps", "10", "--video", "none", "-o", str(tmp_path / "far"),
    ]) == 0  # fmt: skip
    assert "the pull (5) is longer than the rod" in caplog.text


# ----- clamps and pins -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("clamp", "pins", "ends_move"),
    [
        ("both", [], (False, False)),
        ("start", [], (False, True)),
        ("end", [], (True, False)),
        ("none", [-1], (True, False)),
    ],
)
def test_clamp_choices_hold_the_ends_they_name(ring_rod, clamp, pins, ends_move):
    from sketchrodgs.animate import Animation, Pull

    _, extraction = ring_rod
    scene = load_scene(data.sample("ring"))
    animation = Animation(scene, [extraction], clamp=clamp, pins=[pins])
    rod = animation.rods[0]
    kinds = rod.boundaries
    assert (kinds[0], kinds[-1]) == {
        "both": ("clamped", "clamped"),
        "start": ("clamped", "free"),
        "end": ("free", "clamped"),
        "none": ("free", "pinned"),
    }[clamp]
    for _ in animation.frames(Pull(len(rod) // 3, (0, 0.1, 0), duration=0.2, hold=0.1, release=False), fps=20):
        pass
    moved = np.linalg.norm(rod.positions - rod.rest_positions, axis=1)
    assert tuple(bool(m > 1e-4) for m in (moved[0], moved[-1])) == ends_move


def test_animate_clamp_and_pin_options(ring_rod, tmp_path):
    path, _ = ring_rod
    assert main([
        "animate", "sample:ring", str(path), "--grab", "-1", "--to", "0,0.05,0", "--clamp", "start",
        "--pin", "0.5", "--duration", "0.1", "--hold", "0", "--fps", "10", "--video", "none", "-o", str(tmp_path / "c"),
    ]) == 0  # fmt: skip
    with pytest.raises(SystemExit) as usage:
        main(["animate", "sample:ring", str(path), "--grab", "1", "--to", "0,1,0", "--clamp", "top", "-o", "x"])
    assert usage.value.code == 2


# ----- the rod's scene ------------------------------------------------------------------------------


def test_a_rod_refuses_another_scene_of_the_same_size(ring_rod, tmp_path, capsys):
    from sketchrodgs.animate import Animation

    path, extraction = ring_rod
    assert json.loads(path.read_text())["scene"]["count"] == 10_000
    torus = DATA / "torus_10k.splat"  # 10,000 Gaussians too
    assert main(["animate", str(torus), str(path), "--grab", "3", "--to", "0,0.1,0", "-o", str(tmp_path / "t")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{path}: this rod was extracted from another scene" in err
    assert "torus_10k.splat" in err and not (tmp_path / "t").exists()
    with pytest.raises(SketchRodGSError, match="rod 0: this rod was extracted from another scene"):
        Animation(load_scene(torus), [extraction])
    assert main(["view", str(torus), "--rod", str(path), "--port", "1"]) == 1
    assert "another scene" in capsys.readouterr().err


def test_the_scene_identity_survives_conversion_and_old_rods_still_load(ring_rod, tmp_path):
    from sketchrodgs.animate import Animation
    from sketchrodgs.rod_file import Extraction

    path, extraction = ring_rod
    save_scene(load_scene(data.sample("ring")), tmp_path / "ring.ply")  # .splat -> .ply: the same means
    Animation(load_scene(tmp_path / "ring.ply"), [extraction])
    old = extraction.to_json()
    del old["scene"]  # a rod file written before the scene was recorded: not checked
    Animation(load_scene(DATA / "torus_10k.splat"), [Extraction.from_json(old)])


# ----- the scene around the rod: contact and gravity (docs/contact.md) ------------------------------


@pytest.fixture(scope="module")
def ring_before_a_wall(tmp_path_factory):
    """The ring with a wall of Gaussians 4 R behind its top arc (seen from CAMERA), and the rod of
    that arc."""
    ring = load_scene(data.sample("ring"))
    step = 0.008
    x, y, z = np.meshgrid(np.arange(-0.3, 0.3, step), np.arange(-0.1, 0.3, step), [0.2 + step, 0.2 + 2 * step])
    wall = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    n = len(wall)

    def rows(a, b):
        return np.concatenate([a, b]).astype(np.float32)

    scene = GaussianScene.from_colors(
        rows(ring.means, wall),
        rows(ring.scales, np.full((n, 3), step)),
        rows(ring.quats, np.tile([1.0, 0, 0, 0], (n, 1))),
        rows(ring.opacities, np.full(n, 0.95)),
        rows(ring.colors, np.full((n, 3), 0.3)),
    )
    folder = tmp_path_factory.mktemp("wall")
    save_scene(scene, folder / "scene.ply")
    theta = np.radians(np.linspace(20, 160, 25))
    uv, _ = CAMERA.project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    extraction = extract_rod(scene, CAMERA, uv)
    assert extraction.gaussian_ids.max() < len(ring)  # the rod carries none of the wall
    extraction.save(folder / "rod.json")
    return folder, extraction


@pytest.mark.parametrize("contact", [True, False])
def test_a_rod_pulled_into_a_wall_stops_at_it_unless_contact_is_off(ring_before_a_wall, tmp_path, capsys, contact):
    folder, extraction = ring_before_a_wall
    out = tmp_path / "pull"
    switch = [] if contact else ["--no-contact"]
    assert main([
        "animate", str(folder / "scene.ply"), str(folder / "rod.json"), "--grab", "0.5", "--to", "0,0,0.4",
        "--duration", "0.5", "--hold", "0.2", "--fps", "10", "--video", "none", "--ply", "-o", str(out), *switch,
    ]) == 0  # fmt: skip
    assert ("contact on" if contact else "no contact") in capsys.readouterr().out
    held = load_scene(out / "ply" / "frame_0007.ply").means
    carried = np.percentile(held[extraction.gaussian_ids, 2], 99)  # how far back the rod's Gaussians went
    if contact:
        assert carried < 0.2 + 0.1 * extraction.radius  # the wall's front face (its Gaussians reach 1 sigma)
    else:
        assert carried > 0.35  # through the wall


def test_gravity_with_the_up_axis_keeps_the_shape_and_refuses_a_rod_that_cannot_hang(ring_rod, tmp_path, capsys):
    path, extraction = ring_rod
    quiet = ["--duration", "0", "--hold", "1", "--fps", "10", "--video", "none", "--ply"]
    assert main(["animate", "sample:ring", str(path), "--grab", "0.5", "--to", "0,0,0", *quiet, "--up", "+y",
                 "-o", str(tmp_path / "g")]) == 0  # fmt: skip
    assert "gravity 9.81 down, +y up (given)" in capsys.readouterr().out
    rest = load_scene(data.sample("ring")).means[extraction.gaussian_ids]
    held = load_scene(tmp_path / "g" / "ply" / "frame_0010.ply").means[extraction.gaussian_ids]
    assert np.abs(held - rest).max() < 0.02 * extraction.radius  # no sag after 1 s
    # held only by a pin at one end, the arc cannot carry its weight: one line naming the file
    args = ["animate", "sample:ring", str(path), "--grab", "0.5", "--to", "0,0,0", *quiet, "--clamp", "none"]
    assert main([*args, "--pin", "0", "--up", "+y", "-o", str(tmp_path / "h")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and "cannot carry its weight" in err
    assert "--gravity 0" in err and not (tmp_path / "h").exists()
    assert main([*args, "--pin", "0", "--up", "+y", "--gravity", "0", "-o", str(tmp_path / "h")]) == 0


def test_gravity_is_on_where_the_file_format_fixes_up_and_off_where_it_is_only_guessed():
    from argparse import Namespace

    from sketchrodgs.cli.animate import _gravity_up

    biker = str(DATA / "biker.spz")  # SPZ is right-up-back: +y is up by the format
    up = _gravity_up(Namespace(gravity=9.81, scene=biker, up=None), load_scene(biker))
    assert up is not None and up.axis == "+y" and up.source == "format"
    assert _gravity_up(Namespace(gravity=0.0, scene=biker, up=None), load_scene(biker)) is None
    ring = load_scene(data.sample("ring"))  # only guessed from its shape
    assert _gravity_up(Namespace(gravity=9.81, scene="sample:ring", up=None), ring) is None
