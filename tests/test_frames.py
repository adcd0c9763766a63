"""Frames of an animation rendered incrementally (docs/rendering.md, "Frames of an animation"):
every frame of a real pull equals a full render of the same scene, and bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest

import sketchrodgs
from conftest import outputs_per_thread_count
from sketchrodgs.animate import Animation, Pull
from sketchrodgs.errors import SketchRodGSError
from sketchrodgs.frames import FrameRenderer
from sketchrodgs.render import COLOR_OUTPUTS, render


@pytest.fixture(scope="module")
def plant_animation():
    scene = sketchrodgs.load_scene(sketchrodgs.data.sample("plant"))
    camera, stroke = sketchrodgs.data.sample_camera("plant"), sketchrodgs.data.sample_stroke("plant")
    rod = sketchrodgs.extract_rod(scene, camera, stroke)
    return Animation(scene, [rod]), camera.resized(480, 270)


def test_every_frame_of_a_real_pull_equals_a_full_render(plant_animation):
    animation, camera = plant_animation
    renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows, background=(1, 1, 1))
    pull = Pull(-1, (0.0, -0.06, 0.03), duration=0.2, hold=0.1, release=True, settle=0.1)
    moved = 0.0
    for frame in animation.frames(pull, fps=30):
        got = renderer.frame(animation.means, animation.scales, animation.quats)
        want = render(animation.current_scene(), camera, background=(1, 1, 1))
        np.testing.assert_array_equal(got.index, want.index, err_msg=f"frame {frame.index}")
        np.testing.assert_array_equal(got.index_depth, want.index_depth)
        assert np.abs(got.rgb - want.rgb).max() <= 1e-6 and np.abs(got.alpha - want.alpha).max() <= 1e-6
        moved = max(moved, float(np.abs(animation.means - animation.rest_scene.means).max()))
    assert moved > 0.02  # the pull moved the stem: the frames were not all the rest frame
    index_only = FrameRenderer(animation.rest_scene, camera, animation.moving_rows, outputs="index")
    frame = index_only.render(animation.current_scene())
    assert frame.rgb is None
    np.testing.assert_array_equal(frame.index, render(animation.current_scene(), camera, outputs="index").index)
    # colour only (what `sketchrodgs animate` writes): the same colour, no index image
    colour_only = FrameRenderer(animation.rest_scene, camera, animation.moving_rows, outputs=COLOR_OUTPUTS)
    got = colour_only.frame(animation.means, animation.scales, animation.quats)
    want = render(animation.current_scene(), camera)
    assert got.index is None and got.rgb is not None and want.rgb is not None
    assert np.abs(got.rgb - want.rgb).max() <= 1e-6 and np.abs(got.alpha - want.alpha).max() <= 1e-6


def test_bad_frames_are_refused(plant_animation):
    animation, camera = plant_animation
    with pytest.raises(SketchRodGSError, match="moving"):
        FrameRenderer(animation.rest_scene, camera, np.array([len(animation.rest_scene)]))
    renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows[:10])
    with pytest.raises(SketchRodGSError, match="means"):
        renderer.frame(animation.means[:-1], animation.scales, animation.quats)
    with pytest.raises(SketchRodGSError, match="Gaussians"):
        renderer.render(animation.rest_scene.subset(np.arange(5)))


def test_frames_are_the_same_for_any_thread_count():
    code = (
        "import hashlib, sketchrodgs as s; from sketchrodgs.animate import Animation, Pull; "
        "from sketchrodgs.frames import FrameRenderer; sc = s.load_scene(s.data.sample('plant')); "
        "c, st = s.data.sample_camera('plant').resized(320, 180), s.data.sample_stroke('plant'); "
        "a = Animation(sc, [s.extract_rod(sc, s.data.sample_camera('plant'), st)]); "
        "r = FrameRenderer(a.rest_scene, c, a.moving_rows); h = hashlib.sha256(); "
        "[h.update(r.frame(a.means, a.scales, a.quats).rgb.tobytes()) for f in a.frames(Pull(-1, (0, -0.05, 0), 0.1, 0, False, 0), 30)]; "
        "print(h.hexdigest())"
    )
    assert len(outputs_per_thread_count(code, (1, 3))) == 1
