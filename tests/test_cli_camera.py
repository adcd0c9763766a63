"""`sketchrodgs camera`, framing options of `render`, the up axis of `info`: cameras without Python."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from conftest import DATA
from sketchrodgs import Camera, GaussianScene, data, load_cameras, load_scene, render
from sketchrodgs.cli import main
from sketchrodgs.framing import AXES, frame_scene, guess_up_axis, scene_up
from sketchrodgs.io import format_up

WIDTH, HEIGHT = 240, 135
# scene -> (its up axis, the Gaussians at its foot: pot, trunk, stand), seen in renders
UPRIGHT = {
    "plant": (data.sample("plant"), "-y", lambda m: m[:, 1] > 0.3),
    "tree": (DATA / "tree_100k.splat", "-y", lambda m: m[:, 1] > 0.35),
    "guitar": (DATA / "guitar.compressed.ply", "-y", lambda m: m[:, 1] > -0.3),
    "ring": (data.sample("ring"), "+z", None),  # lies flat
    "donut": (DATA / "donut.ply", "+z", None),  # lies flat, icing up
    "biker": (DATA / "biker.spz", "+y", lambda m: m[:, 1] < 0.3),  # SPZ: right-up-back, feet at y = 0
}


@pytest.fixture(scope="module")
def scenes():
    return {name: load_scene(path) for name, (path, _, _) in UPRIGHT.items()}


def covered(scene: GaussianScene, camera: Camera) -> np.ndarray:
    return render(scene, camera, outputs="index").alpha > 0.5


@pytest.mark.parametrize("name", list(UPRIGHT))
def test_the_default_camera_shows_the_scene_whole_and_upright(name, scenes):
    scene = scenes[name]
    path, axis, foot = UPRIGHT[name]
    up = scene_up(scene, file_up=format_up(path))
    assert up.axis == axis and up.source == ("format" if path.suffix == ".spz" else "guess")
    camera = frame_scene(scene, up.vector, width=WIDTH, height=HEIGHT)
    mask = covered(scene, camera)
    assert 0.05 <= mask.mean() <= 0.95
    border = np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])
    assert border.mean() < 0.02  # framed, not cropped
    if foot is not None:  # the foot of the scene is at the bottom of the image
        uv, _ = camera.project(scene.means[foot(scene.means)])
        assert np.nanmedian(uv[:, 1]) > 0.6 * HEIGHT


def test_floaters_do_not_move_the_framing(scenes):
    plant = scenes["plant"]
    rng = np.random.default_rng(3)
    n = len(plant) // 100  # 1 % floaters, up to 15 plant sizes away
    floaters = GaussianScene.from_colors(
        rng.uniform(-8, 8, (n, 3)),
        np.full((n, 3), 0.01),
        np.tile([1.0, 0, 0, 0], (n, 1)),
        np.full(n, 0.9),
        np.ones((n, 3)),
    )
    both = GaussianScene(
        *(
            np.concatenate([getattr(plant, f), getattr(floaters, f)])
            for f in ("means", "scales", "quats", "opacities", "sh")
        )
    )
    up = np.array(AXES["-y"])
    clean, noisy = (frame_scene(s, up, width=WIDTH, height=HEIGHT) for s in (plant, both))
    assert np.linalg.norm(noisy.center - clean.center) < 0.05 * np.linalg.norm(clean.center)
    assert 0.05 <= covered(plant, noisy).mean()


def test_a_scene_smaller_than_the_near_plane_is_framed_from_further_with_a_longer_lens(scenes):
    tiny = scenes["donut"].replace(means=scenes["donut"].means * 0.1, scales=scenes["donut"].scales * 0.1)  # 2 cm
    camera = frame_scene(tiny, AXES["+z"], width=WIDTH, height=HEIGHT)
    assert camera.fov_y_deg < 10
    assert 0.05 <= covered(tiny, camera).mean() <= 0.95


def test_up_comes_from_the_training_cameras_when_given(scenes):
    ring = scenes["ring"]
    # cameras around the ring whose image up is world +x: the guess (+z) is overridden
    cameras = [Camera.orbit((0, 0, 0), 2.0, az, 10, up=(1, 0, 0)) for az in range(0, 360, 40)]
    up = scene_up(ring, cameras)
    assert up.source == "cameras" and up.axis == "+x" and np.allclose(up.vector, [1, 0, 0], atol=0.02)
    assert scene_up(ring, cameras, "-z").axis == "-z"  # --up still wins
    # cameras that disagree (every roll) say nothing: back to the guess
    rolled = [Camera.orbit((0, 0, 0), 2.0, 0, 0, up=u) for u in ((0, 1, 0), (0, -1, 0), (1, 0, 0), (-1, 0, 0))]
    assert scene_up(ring, rolled).source == "guess"


def test_the_guess_of_up_is_documented_by_shape():
    rng = np.random.default_rng(0)
    assert guess_up_axis(rng.normal(size=(1000, 3)) * [1, 3, 1])[0] == "-y"  # stands along y: COLMAP's -y
    assert guess_up_axis(rng.normal(size=(1000, 3)) * [1, 1, 3])[0] == "+z"  # stands along z: +z
    assert guess_up_axis(rng.normal(size=(1000, 3)) * [3, 1, 3])[0] == "+y"  # flat in xz: lies on y


def test_camera_command_writes_a_camera_and_preview(tmp_path, capsys):
    out, preview = tmp_path / "cam.json", tmp_path / "preview.png"
    assert main(["camera", "sample:plant", "-o", str(out), "--preview", str(preview), "--width", "320"]) == 0
    text = capsys.readouterr().out
    assert "up -y (guessed" in text and "cam.json" in text and "of the pixels covered" in text
    (camera,) = load_cameras(out)
    assert (camera.width, camera.height) == (320, 180)
    image = np.asarray(Image.open(preview))
    assert image.shape == (180, 320, 3) and 0.05 < (image.max(axis=2) > 20).mean() < 0.95


def test_camera_options_orbit_up_look_at_and_distance(tmp_path):
    out = tmp_path / "cam.json"
    # negative numbers after an option are its value, not options
    args = ["camera", "sample:ring", "-o", str(out), "--orbit", "-30,10", "--up", "+x", "--look-at", "-0.1,0,0"]
    assert main([*args, "--distance", "2"]) == 0
    (camera,) = load_cameras(out)
    assert np.linalg.norm(camera.center - [-0.1, 0, 0]) == pytest.approx(2)
    uv, _ = camera.project(np.array([[-0.1, 0, 0], [0.4, 0, 0]]))
    np.testing.assert_allclose(uv[0], [camera.cx, camera.cy], atol=1e-6)  # looks at the point
    assert uv[1, 1] < uv[0, 1]  # +x is up in the image
    assert camera.name == "orbit -30,10"


def test_render_frames_the_scene_with_the_same_options(tmp_path, capsys):
    image = tmp_path / "ring.png"
    assert main(["render", "sample:ring", "-o", str(image), "--orbit", "0,60", "--width", "200"]) == 0
    pixels = np.asarray(Image.open(image))
    assert pixels.shape == (112, 200, 3) and 0.05 < (pixels.max(axis=2) > 20).mean() < 0.95
    with pytest.raises(SystemExit) as usage:
        main(["render", "sample:ring", "-o", str(image), "--orbit", "0,90"])
    assert usage.value.code == 2 and "elevation" in capsys.readouterr().err


def test_render_says_why_nothing_is_visible_and_near_shows_it(tmp_path, capsys):
    """A close-up of the 0.2-wide donut (z from 0 to 0.09) from z = 0.17: the 0.2 near plane culls it all."""
    Camera.look_at((0, 0, 0.17), (0, 0, 0), up=(0, -1, 0), width=160, height=90).save(tmp_path / "cam.json")
    base = ["render", str(DATA / "donut.ply"), "--camera", str(tmp_path / "cam.json"), "-o", str(tmp_path / "d.png")]
    assert main(base) == 0
    captured = capsys.readouterr()
    assert "0.0% of pixels covered" in captured.out and "near plane (0.2)" in captured.err and "--near" in captured.err
    assert main([*base, "--near", "0.01"]) == 0
    assert "nothing is visible" not in capsys.readouterr().err
    assert (np.asarray(Image.open(tmp_path / "d.png")).max(axis=2) > 20).mean() > 0.3
    # a camera JSON carries its near plane, which render (and extract, animate) then use
    near_camera = tmp_path / "near.json"
    Camera.look_at((0, 0, 0.17), (0, 0, 0), up=(0, -1, 0), width=160, height=90, near=0.01).save(near_camera)
    assert main([*base[:3], str(near_camera), *base[4:]]) == 0
    assert "nothing is visible" not in capsys.readouterr().err
    assert (np.asarray(Image.open(tmp_path / "d.png")).max(axis=2) > 20).mean() > 0.3
    assert main(["camera", str(DATA / "donut.ply"), "-o", str(tmp_path / "framed.json"), "--near", "0.05"]) == 0
    assert json.loads((tmp_path / "framed.json").read_text())["near"] == 0.05


def test_a_cameras_near_plane_is_the_reference_cull_on_the_scene_scaled_up():
    """A render is unchanged when the scene and the camera's position are scaled together
    (projection, EWA footprint and SH direction are scale-free), but for the reference's cull at
    z <= 0.2: so a camera whose near plane is z renders as the default camera does the scene
    scaled by 0.2 / z. Checked on a close-up of the donut that the default plane culls whole."""
    import dataclasses

    donut = load_scene(DATA / "donut.ply")
    camera = Camera.look_at((0, 0, 0.17), (0, 0, 0), up=(0, -1, 0), width=160, height=90)
    assert render(donut, camera).covered().mean() == 0
    near, scale = 0.01, 0.2 / 0.01
    close = render(donut, dataclasses.replace(camera, near=near))
    matrix = camera.world_to_camera.copy()
    matrix[:3, 3] *= scale
    scaled = donut.replace(means=donut.means * np.float32(scale), scales=donut.scales * np.float32(scale))
    oracle = render(scaled, dataclasses.replace(camera, world_to_camera=matrix))
    assert close.covered().mean() > 0.3
    np.testing.assert_allclose(close.rgb, oracle.rgb, atol=1e-4)
    np.testing.assert_allclose(close.depth * scale, oracle.depth, rtol=1e-4)
    assert (close.index == oracle.index).mean() > 0.999


def test_info_reports_the_up_axis(capsys):
    assert main(["info", "sample:plant"]) == 0
    assert "up         -y  (guessed: stands tallest along y" in capsys.readouterr().out
    assert main(["info", "sample:ring", "--json"]) == 0
    up = json.loads(capsys.readouterr().out)["up"]
    assert up["axis"] == "+z" and up["source"] == "guess" and up["vector"] == [0, 0, 1]
    # an SPZ file's axes are fixed by its format (right-up-back), whatever its shape
    assert main(["info", str(DATA / "biker.spz")]) == 0
    assert "up         +y  (by the SPZ convention (right-up-back); --up overrides)" in capsys.readouterr().out


def test_help_lists_the_samples(capsys):
    for command in ("render", "camera", "info"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert "sample:NAME for a bundled sample (plant, ring)" in " ".join(capsys.readouterr().out.split())


def test_the_command_lines_choices_are_the_librarys():
    """The command line spells some choices out so that its help needs no numpy; they must agree."""
    from sketchrodgs.animate import CLAMPS
    from sketchrodgs.cli import animate, view
    from sketchrodgs.cli._framing import UP_CHOICES

    assert set(UP_CHOICES) == set(AXES) and animate.CLAMPS == CLAMPS and view.UP_CHOICES == UP_CHOICES
