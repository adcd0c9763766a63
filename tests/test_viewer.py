"""The viewer without a browser: camera and pointer conversions, splat packing, the rod set, the
display's two ways of moving Gaussians, the app's actions, and `sketchrodgs view` serving a page."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sketchrodgs import Camera, data, extract_rod, load_scene
from sketchrodgs.errors import SketchRodGSError
from sketchrodgs.extract import load_rod
from sketchrodgs.io import load_scene as load_any
from sketchrodgs.skin import skin
from sketchrodgs.viewer import ViewerApp
from sketchrodgs.viewer.camera import (
    camera_from_viser,
    pixels_to_screen,
    quat_to_matrix,
    screen_to_pixels,
    unproject,
    viser_view,
)
from sketchrodgs.viewer.display import SceneDisplay
from sketchrodgs.viewer.rods import RodSet
from sketchrodgs.viewer.simulation import FrameTimings
from sketchrodgs.viewer.sketch import SketchSettings, Stroke, extract
from sketchrodgs.viewer.splats import (
    SplatArrays,
    SplatPacker,
    covariance_triu,
    covariances,
    quats_to_matrices,
    splat_unit,
)

SEMI_AXES = (0.455, 0.136)  # the ring's centre line
RING_CAMERA = Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=960, height=720, fov_y_deg=60)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def ring():
    return load_scene(data.sample("ring"))


@pytest.fixture(scope="module")
def ring_rod(ring):
    theta = np.radians(np.linspace(20, 160, 25))
    uv, _ = RING_CAMERA.project(np.stack([SEMI_AXES[0] * np.cos(theta), SEMI_AXES[1] * np.sin(theta), 0 * theta], 1))
    return extract_rod(ring, RING_CAMERA, uv)


@pytest.fixture
def server():
    import viser

    srv = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield srv
    srv.stop()


# ----- camera and pointer -------------------------------------------------------------------


def random_pose(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    xyzw = Rotation.random(random_state=seed).as_quat()
    return np.r_[xyzw[3], xyzw[:3]], rng.normal(size=3)


@pytest.mark.parametrize("seed", range(5))
def test_point_ahead_of_the_viser_camera_projects_to_the_image_centre(seed):
    wxyz, position = random_pose(seed)
    camera = camera_from_viser(wxyz, position, fov_y=math.radians(50), aspect=4 / 3, width=960)
    assert (camera.width, camera.height) == (960, 720)
    r = quat_to_matrix(wxyz)  # columns: camera x (right), y (down), z (forward) in world axes
    ahead = position + 2.5 * r[:, 2]
    uv, depth = camera.project(np.array([ahead, ahead + 0.1 * r[:, 0], ahead + 0.1 * r[:, 1]]))
    np.testing.assert_allclose(uv[0], [480, 360], atol=1e-6)
    np.testing.assert_allclose(depth[0], 2.5)
    assert uv[1, 0] > 480 and abs(uv[1, 1] - 360) < 1e-6  # +x is right
    assert uv[2, 1] > 360 and abs(uv[2, 0] - 480) < 1e-6  # +y is down


def test_canvas_edges_are_the_image_edges():
    wxyz, position = random_pose(7)
    fov, aspect = math.radians(70), 16 / 9
    camera = camera_from_viser(wxyz, position, fov, aspect, width=640)
    r = quat_to_matrix(wxyz)
    # the top-right corner of the view frustum at depth 1
    corner = position + r[:, 2] + aspect * math.tan(fov / 2) * r[:, 0] - math.tan(fov / 2) * r[:, 1]
    uv, _ = camera.project(corner[None])
    np.testing.assert_allclose(uv[0], [camera.width, 0], atol=1e-6 * camera.width + 0.5)
    # the pointer there, in viser's normalised canvas coordinates, is that pixel point
    np.testing.assert_allclose(screen_to_pixels(np.array([[1.0, 0.0]]), camera)[0], [camera.width, 0])
    np.testing.assert_allclose(
        screen_to_pixels(np.array([[0.5, 0.5]]), camera)[0], [camera.width / 2, camera.height / 2]
    )


def test_screen_pixels_and_unproject_round_trip():
    camera = camera_from_viser(*random_pose(3), fov_y=1.0, aspect=1.5, width=900)
    screen = np.random.default_rng(0).uniform(0, 1, (20, 2))
    np.testing.assert_allclose(pixels_to_screen(screen_to_pixels(screen, camera), camera), screen, atol=1e-6)
    pixels = screen_to_pixels(screen, camera)
    uv, depth = camera.project(unproject(pixels, camera, 3.0))
    np.testing.assert_allclose(uv, pixels, atol=1e-3)
    np.testing.assert_allclose(depth, 3.0)


def test_viser_view_of_a_camera_gives_back_that_camera():
    camera = Camera.look_at((1, 2, -3), (0.2, 0.1, 0.5), up=(0, -1, 0), width=800, height=600, fov_y_deg=45)
    view = viser_view(camera, look_distance=2.0)
    again = Camera.look_at(
        view.position, view.look_at, up=view.up, width=800, height=600, fov_y_deg=math.degrees(view.fov_y)
    )
    np.testing.assert_allclose(again.world_to_camera, camera.world_to_camera, atol=1e-9)
    assert np.linalg.norm(np.subtract(view.look_at, view.position)) == pytest.approx(2.0)


def test_bad_viser_camera_is_refused():
    with pytest.raises(SketchRodGSError, match="fov"):
        camera_from_viser((1, 0, 0, 0), (0, 0, 0), fov_y=0.0, aspect=1.0)
    with pytest.raises(SketchRodGSError, match="aspect"):
        camera_from_viser((1, 0, 0, 0), (0, 0, 0), fov_y=1.0, aspect=float("nan"))
    with pytest.raises(SketchRodGSError, match="quaternion"):
        camera_from_viser((0, 0, 0, 0), (0, 0, 0), fov_y=1.0, aspect=1.0)


# ----- splats ---------------------------------------------------------------------------------


def test_covariances_are_r_s2_rt(ring):
    rng = np.random.default_rng(1)
    quats = Rotation.random(50, random_state=2).as_quat()[:, [3, 0, 1, 2]].astype(np.float32)
    scales = rng.uniform(0.01, 0.2, (50, 3)).astype(np.float32)
    r = Rotation.from_quat(quats[:, [1, 2, 3, 0]]).as_matrix()
    np.testing.assert_allclose(quats_to_matrices(quats), r, atol=1e-6)
    want = r @ (scales[:, :, None] ** 2 * np.transpose(r, (0, 2, 1)))
    np.testing.assert_allclose(covariances(scales, quats), want, atol=1e-7)
    triu = covariance_triu(scales, quats)
    np.testing.assert_allclose(triu, want.reshape(-1, 9)[:, [0, 1, 2, 4, 5, 8]], atol=1e-7)


def test_packer_builds_exactly_the_buffer_viser_builds(server, ring):
    part = SplatArrays.from_scene(ring).subset(np.arange(0, 2000, 3)).in_unit(0.01)
    handle = server.scene.add_gaussian_splats("/x", part.centers, part.covariances, part.rgbs, part.opacities)
    packer = SplatPacker(part.rgbs, part.opacities)
    triu = part.covariances.reshape(-1, 9)[:, [0, 1, 2, 4, 5, 8]]
    np.testing.assert_array_equal(packer.pack(part.centers, triu), handle.buffer)


def test_splat_unit_puts_covariances_in_float16_range(ring):
    unit = splat_unit(ring.scales)
    assert unit == pytest.approx(np.median(ring.scales.max(axis=1)))
    local = SplatArrays.from_scene(ring).in_unit(unit)
    diag = local.covariances[:, [0, 1, 2], [0, 1, 2]]
    # the largest variance of the median Gaussian is 1; its diagonal entries are at most that
    assert diag.max() < 65504 and 0.3 < np.median(diag.max(axis=1)) <= 1.0 + 1e-3
    assert (np.abs(diag.astype(np.float16).astype(np.float32) - diag) <= 1e-3 * diag + 1e-7).all()
    # a few huge Gaussians raise the unit so that none overflows float16
    scales = np.full((100, 3), 0.01, np.float32)
    scales[0] = 100.0
    assert splat_unit(scales) == pytest.approx(100.0 / 255)


def test_colours_are_the_baked_dc_term(ring):
    splats = SplatArrays.from_scene(ring)
    np.testing.assert_allclose(splats.rgbs, np.clip(0.5 + 0.28209479177387814 * ring.sh[:, 0], 0, 1), atol=1e-6)
    assert splats.opacities.shape == (len(ring), 1)


# ----- rods -----------------------------------------------------------------------------------


def pull(rods: RodSet, rod_id: int, offset=(0.0, 0.12, 0.0), frames: int = 20) -> int:
    entry = rods.get(rod_id)
    vertex = entry.rod.num_vertices // 2
    start = np.asarray(entry.rod.positions[vertex])
    rods.grab(rod_id, vertex, start)
    for k in range(1, frames + 1):
        rods.move_grab(rod_id, start + np.multiply(offset, k / frames))
        rods.step(1 / 60)
    return vertex


def test_rod_set_pulls_skins_and_springs_back(ring, ring_rod):
    rods = RodSet(ring)
    entry = rods.add(ring_rod)
    ids = entry.gaussian_ids
    others = np.setdiff1d(np.arange(len(ring)), ids)
    assert not rods.awake and rods.step(1 / 60) is None  # nothing to do at rest
    vertex = pull(rods, entry.id)
    assert rods.grabbed() == {entry.id: vertex}
    assert np.linalg.norm(entry.rod.positions[vertex] - entry.rod.rest_positions[vertex]) > 0.1
    assert np.linalg.norm(rods.means[ids] - ring.means[ids], axis=1).max() > 0.05
    np.testing.assert_array_equal(rods.means[others], ring.means[others])
    # the skinning is the library's
    np.testing.assert_allclose(rods.means, skin(ring, entry.bound, entry.rod).means, atol=1e-6)
    rods.release(entry.id)
    for _ in range(600):
        if rods.step(1 / 60) is None:
            break
    assert not rods.awake, "the rod did not come to rest"
    assert np.abs(entry.rod.positions - entry.rod.rest_positions).max() < 1e-4
    assert np.abs(rods.means[ids] - ring.means[ids]).max() < 1e-4


def test_second_rod_leaves_the_first_its_gaussians_and_remove_restores(ring, ring_rod):
    rods = RodSet(ring)
    first = rods.add(ring_rod)
    second = rods.add(ring_rod)  # the same stroke again: every Gaussian is taken already
    assert len(second.gaussian_ids) == 0 and len(rods) == 2
    assert len(np.unique(rods.owned_ids())) == len(rods.owned_ids())
    pull(rods, first.id)
    rods.remove(first.id)
    np.testing.assert_array_equal(rods.means, ring.means)
    with pytest.raises(SketchRodGSError, match="no rod"):
        rods.get(first.id)
    third = rods.add(ring_rod)  # free again
    assert len(third.gaussian_ids) == len(first.gaussian_ids) and third.id == 2


@pytest.fixture(scope="module")
def plant():
    scene = load_scene(data.sample("plant"))
    return scene, extract_rod(scene, data.sample_camera("plant"), data.sample_stroke("plant"))


def test_rod_set_splits_needles_and_undoes_it(plant):
    """The plant stem's needles are split when its rod is added (the pieces appended to the set's
    scene), hidden when it is removed, and made again from the input by a reset."""
    scene, extraction = plant
    n = len(scene)
    rods = RodSet(scene)
    entry = rods.add(extraction)
    pieces = entry.gaussian_ids[entry.gaussian_ids >= n]
    assert len(pieces) > 500 and len(rods.scene) == n + len(entry.pieces) and np.isin(pieces, entry.pieces).all()
    np.testing.assert_array_equal(rods.source[:n], np.arange(n))
    assert (rods.source[pieces] < n).all()  # pieces of its own needles and of static ones reaching in
    assert rods.means.shape == (len(rods.scene), 3) and not rods.hidden.any()
    pull(rods, entry.id, offset=(0.0, -0.05, 0.03))
    moved = np.linalg.norm(rods.means[pieces] - rods.scene.means[pieces], axis=1)
    assert moved.max() > 0.01  # the pieces follow the rod
    rods.remove(entry.id)
    assert rods.hidden[n:].all() and np.all(rods.scene.opacities[n:] == 0)
    exported = rods.export_scene()
    for field in ("means", "quats", "scales", "opacities"):
        np.testing.assert_array_equal(getattr(exported, field), getattr(scene, field))
    again = rods.add(extraction)  # the hidden pieces are not taken; the needles split anew
    assert not np.isin(again.gaussian_ids, np.flatnonzero(rods.hidden)).any()
    assert len(rods.scene) == n + 2 * len(entry.pieces)
    rods.reset()
    [again] = rods.entries
    assert len(rods.scene) == n + len(entry.pieces) and not rods.hidden.any()
    np.testing.assert_array_equal(rods.means, rods.scene.means)


def test_reset_params_and_clamps(ring, ring_rod):
    rods = RodSet(ring)
    entry = rods.add(ring_rod)
    pull(rods, entry.id)
    rods.reset()
    [entry] = rods.entries
    np.testing.assert_array_equal(rods.means, ring.means)
    assert not rods.grabbed() and entry.rod.boundaries[0] == "clamped"
    rods.set_clamp_ends(False)
    assert entry.rod.boundaries[0] == "free" and entry.rod.boundaries[-1] == "free"
    rods.set_params(rods.params.__class__(youngs_modulus=1e5, gravity=(0.0, -9.81, 0.0)))
    [entry] = rods.entries
    assert entry.rod.params.youngs_modulus == 1e5 and entry.rod.params.radius == ring_rod.radius
    assert entry.rod.boundaries[0] == "free"  # the clamp setting survives the rebuild
    rods.wake()
    for _ in range(30):
        rods.step(1 / 60)
    assert entry.rod.positions[:, 1].mean() < entry.rod.rest_positions[:, 1].mean() - 1e-3  # it sags


def test_skinning_on_demand_matches_skinning_every_frame(ring, ring_rod):
    eager, lazy = RodSet(ring), RodSet(ring, skin_each_frame=False)
    a, b = eager.add(ring_rod), lazy.add(ring_rod)
    pull(eager, a.id)
    pull(lazy, b.id)
    assert np.array_equal(lazy.means, ring.means)  # not skinned yet
    means, quats, _ = lazy.skinned()
    np.testing.assert_allclose(means, eager.means, atol=1e-6)
    np.testing.assert_allclose(lazy.deformed_scene().quats, eager.quats, atol=1e-6)


def test_rod_outside_the_scene_is_refused(ring, ring_rod):
    with pytest.raises(SketchRodGSError, match="scene has"):
        RodSet(ring.subset(np.arange(100))).add(ring_rod)


# ----- display ----------------------------------------------------------------------------------


@pytest.mark.parametrize("update", ["exact", "segments"])
def test_display_sends_where_the_gaussians_are(server, ring, ring_rod, update):
    rods = RodSet(ring, skin_each_frame=update == "exact")
    display = SceneDisplay(server, ring, update, lambda rod_id, event: None)
    display.show_scene(np.empty(0, np.int64))
    entry = rods.add(ring_rod)
    display.show_scene(rods.owned_ids())
    display.add_rod(entry)
    assert len(display._scene_node.buffer) == len(ring) - len(entry.gaussian_ids)
    pull(rods, entry.id)
    with rods.lock:
        display.push(rods)
        means, _, _ = rods.skinned()
        want = means[entry.gaussian_ids].astype(np.float64)
    nodes = display._rods[entry.id]
    if update == "exact":
        sent = np.asarray(nodes.splats[0].centers, np.float64) * display.unit
        np.testing.assert_allclose(sent, want, atol=1e-6)
    else:
        # each segment's node: world = position + R(wxyz) (unit * local centre)
        ids = entry.gaussian_ids
        sent = np.empty_like(want)
        for node, j in zip(nodes.splats, nodes.segments):
            rows = np.flatnonzero(entry.bound.segment == j)
            local = np.asarray(node.centers, np.float64) * display.unit
            sent[rows] = node.position + local @ quat_to_matrix(node.wxyz).T
        moved = np.linalg.norm(want - ring.means[ids], axis=1).max()
        error = np.linalg.norm(sent - want, axis=1)
        # a segment moves rigidly with its edge's frame where skinning blends the two vertex frames:
        # off by at most |offset| times half the (extra) turning angle between neighbouring edges
        edges = np.diff(entry.rod.positions, axis=0)
        rest_edges = np.diff(entry.rod.rest_positions, axis=0)

        def turning(e):
            u = e / np.linalg.norm(e, axis=1, keepdims=True)
            return np.arccos(np.clip((u[1:] * u[:-1]).sum(axis=1), -1, 1))

        bend = np.abs(turning(edges) - turning(rest_edges)).max() + turning(rest_edges).max()
        bound = np.linalg.norm(entry.bound.offset, axis=1).max() * bend / 2
        assert moved > 0.05 and error.max() < bound, (moved, error.max(), bound)
        assert np.median(error) < 0.05 * ring_rod.radius
    np.testing.assert_allclose(nodes.handles.batched_positions, entry.rod.positions, atol=1e-6)
    np.testing.assert_allclose(nodes.polyline.points[:, 0], entry.rod.positions[:-1], atol=1e-6)


# ----- sketch -----------------------------------------------------------------------------------


def test_stroke_samples_and_extraction(ring):
    # the ring's camera as viser would report it: camera-to-world rotation and centre
    c2w = RING_CAMERA.camera_to_world
    xyzw = Rotation.from_matrix(c2w[:3, :3]).as_quat()
    camera = camera_from_viser(np.r_[xyzw[3], xyzw[:3]], c2w[:3, 3], math.radians(60), 4 / 3, width=960)
    np.testing.assert_allclose(camera.world_to_camera, RING_CAMERA.world_to_camera, atol=1e-9)
    stroke = Stroke(camera)
    theta = np.radians(np.linspace(20, 160, 15))
    uv, _ = camera.project(np.stack([SEMI_AXES[0] * np.cos(theta), SEMI_AXES[1] * np.sin(theta), 0 * theta], 1))
    for point in pixels_to_screen(uv, camera):
        stroke.add(tuple(point))
        stroke.add(tuple(point))  # repeats are dropped
    stroke.add((float("nan"), 0.5))
    assert len(stroke.screen) == 15
    np.testing.assert_allclose(stroke.pixels(), uv, atol=1e-3)
    extraction = extract(ring, stroke, SketchSettings())
    assert len(extraction.gaussian_ids) > 1000 and extraction.coverage > 0.9
    with pytest.raises(SketchRodGSError, match="single point"):
        extract(ring, Stroke(camera, [(0.5, 0.5)]), SketchSettings())


def test_frame_timings():
    timings = FrameTimings(window=3)
    assert timings.mean() == {} and timings.rate() == 0.0 and "no frames" in timings.summary()
    for k in range(5):
        timings.record({"simulate": 0.001 * k, "skin": 0.0, "push": 0.002, "frame": 0.003})
        time.sleep(0.01)
    assert timings.mean()["simulate"] == pytest.approx(0.003)  # the last three frames
    assert 10 < timings.rate() < 200 and "Hz" in timings.summary()


# ----- the app ----------------------------------------------------------------------------------


def test_app_exports_and_modes(tmp_path, ring, ring_rod):
    app = ViewerApp(ring, port=free_port(), rods=[ring_rod], up="+y", output_dir=tmp_path, fps=60)
    try:
        assert app.url.startswith("http://127.0.0.1:") and app.splat_update == "exact"
        [entry] = app.rods.entries
        app.set_mode("Sketch")
        assert app._box.visible and app.display.show_segmented and not app.display.show_handles
        app.set_mode("Play")
        assert not app._box.visible and app.display.show_handles
        with pytest.raises(SketchRodGSError, match="mode"):
            app.set_mode("Fly")
        vertex = entry.rod.num_vertices // 2
        app.rods.grab(entry.id, vertex, np.asarray(entry.rod.positions[vertex]) + [0, 0.1, 0])
        deadline = time.monotonic() + 10
        while np.abs(entry.rod.positions[vertex] - entry.rod.rest_positions[vertex]).max() < 0.05:
            assert time.monotonic() < deadline, "the simulation thread did not move the rod"
            time.sleep(0.02)
        ply = app.export_ply()
        exported = load_any(ply)
        assert len(exported) == len(ring)
        assert np.abs(exported.means - ring.means).max() > 0.05
        [rod_file] = app.save_rods()
        loaded, material = load_rod(rod_file)
        np.testing.assert_allclose(loaded.polyline, ring_rod.polyline)
        assert material["radius"] == pytest.approx(ring_rod.radius)
        app.reset()
        assert (
            np.abs(entry.rod.positions - entry.rod.rest_positions).max() == 0.0
            or np.abs(app.rods.entries[0].rod.positions - entry.rod.rest_positions).max() < 1e-12
        )
        with pytest.raises(SketchRodGSError, match="no browser"):
            app.screenshot()
        app.remove_rod(app.rods.entries[0].id)
        assert len(app.rods) == 0 and len(app.display._scene_node.buffer) == len(ring)
        assert app.loop.timings.count > 0 and "frame" in app.panel.timings.content
    finally:
        app.close()


@pytest.mark.parametrize("update", ["exact", "segments"])
def test_app_shows_and_exports_split_needles(tmp_path, plant, update):
    scene, extraction = plant
    app = ViewerApp(scene, port=free_port(), up="-y", output_dir=tmp_path, fps=60, splat_update=update)
    try:
        entry = app.add_extraction(extraction)
        assert len(app.display.splats) == len(app.rods.scene) > len(scene)
        nodes = app.display._rods[entry.id]
        assert sum(len(node.buffer) for node in nodes.splats) == len(entry.gaussian_ids)  # pieces included
        assert len(app.display._scene_node.buffer) == len(app.rods.scene) - len(entry.gaussian_ids)
        app.reset()  # rebuilt from the input: same rows again, nodes made anew
        assert len(app.rods.scene) == len(app.display.splats)
        app.remove_rod(app.rods.entries[0].id)
        assert len(app.display._scene_node.buffer) == len(scene)  # the pieces are gone from view
        assert len(load_any(app.export_ply())) == len(scene)
    finally:
        app.close()


def test_app_sketch_on_background_reports_and_adds_nothing(ring):
    app = ViewerApp(ring, port=free_port(), up="+y", splat_update="segments")
    try:
        camera = RING_CAMERA
        stroke = Stroke(camera, [(0.02, 0.02), (0.1, 0.03), (0.2, 0.02)])
        assert app.sketch(stroke).result(timeout=30) is None
        assert len(app.rods) == 0 and app.last_error and "background" in app.panel.status.content
        theta = np.radians(np.linspace(20, 160, 15))
        uv, _ = camera.project(np.stack([SEMI_AXES[0] * np.cos(theta), SEMI_AXES[1] * np.sin(theta), 0 * theta], 1))
        entry = app.sketch(Stroke(camera, [tuple(p) for p in pixels_to_screen(uv, camera)])).result(timeout=30)
        assert entry is not None and app.extractions == 1 and app.last_error is None
        assert len(app.display._rods[entry.id].splats) == len(np.unique(entry.bound.segment))
        # a second rod on the lower arc (the ring is split at the bottom, theta = 270 degrees)
        theta = np.radians(np.linspace(195, 255, 10))
        uv, _ = camera.project(np.stack([SEMI_AXES[0] * np.cos(theta), SEMI_AXES[1] * np.sin(theta), 0 * theta], 1))
        other = app.sketch(Stroke(camera, [tuple(p) for p in pixels_to_screen(uv, camera)])).result(timeout=30)
        assert other is not None and len(app.rods) == 2, app.last_error
        assert not np.intersect1d(entry.gaussian_ids, other.gaussian_ids).size
        assert app.panel.rod.options == (f"rod {entry.id}", f"rod {other.id}")
        # both pulled at once
        for rod in (entry, other):
            v = rod.rod.num_vertices // 2
            app.rods.grab(rod.id, v, np.asarray(rod.rod.positions[v]) + [0, 0, 0.1])
        deadline = time.monotonic() + 10
        while min(np.abs(r.rod.positions - r.rod.rest_positions).max() for r in (entry, other)) < 0.05:
            assert time.monotonic() < deadline, "the simulation thread did not move both rods"
            time.sleep(0.02)
        app.remove_rod(entry.id)
        assert [e.id for e in app.rods.entries] == [other.id] and app.panel.rod.options == (f"rod {other.id}",)
    finally:
        app.close()


def test_app_refuses_bad_settings(ring):
    with pytest.raises(SketchRodGSError, match="up"):
        ViewerApp(ring, port=free_port(), up="sideways")
    with pytest.raises(SketchRodGSError, match="splat update"):
        ViewerApp(ring, port=free_port(), splat_update="sometimes")


# ----- the command ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("stop", "sigint", "code"),
    [
        (signal.SIGTERM, signal.SIG_IGN, 143),  # as a background job, whose SIGINT is ignored
        (signal.SIGINT, signal.SIG_DFL, 130),  # Ctrl-C: "interrupted"
    ],
)
def test_view_command_serves_the_page_on_loopback(tmp_path, ring_rod, stop, sigint, code):
    port = free_port()
    ring_rod.save(tmp_path / "rod.json")
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sketchrodgs",
            "view",
            "sample:ring",
            "--port",
            str(port),
            "--up",
            "+y",
            "-o",
            str(tmp_path),
            "--rod",
            str(tmp_path / "rod.json"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, sigint),
    )
    try:
        line, deadline = "", time.monotonic() + 60
        while "sketchrodgs viewer:" not in line:
            assert time.monotonic() < deadline and process.poll() is None, "the viewer did not start"
            line = process.stdout.readline()
        assert f"http://127.0.0.1:{port}" in line and "1 rod(s)" in line
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as response:
            assert response.status == 200 and b"<html" in response.read().lower()
    finally:
        process.send_signal(stop)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)
    assert process.returncode == code  # stopped cleanly, by either signal


def test_view_command_usage_errors():
    result = subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "view", "sample:ring", "--port", "70000"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and "port" in result.stderr
    result = subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "view", "missing.ply", "--port", str(free_port())],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1
