"""The viewer without a browser: camera and pointer conversions, splat packing, the rod set (its
swing, refusals, clamps and pins), undo, origins, contact, the display's two ways of moving
Gaussians and its chunks, the app's actions, and `sketchrodgs view` serving a page."""

from __future__ import annotations

import dataclasses
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
from sketchrodgs.contact import scene_field
from sketchrodgs.errors import SketchRodGSError
from sketchrodgs.io import load_scene as load_any
from sketchrodgs.rod_file import load_rod
from sketchrodgs.skin import skin
from sketchrodgs.viewer import ViewerApp
from sketchrodgs.viewer.camera import (
    camera_from_viser,
    pixels_to_screen,
    quat_to_matrix,
    screen_to_pixels,
    viser_view,
)
from sketchrodgs.viewer.display import SceneDisplay, handle_radii, towards_camera
from sketchrodgs.viewer.feedback import describe_failure
from sketchrodgs.viewer.history import History, Step
from sketchrodgs.viewer.material import Material
from sketchrodgs.viewer.origin import OriginGuard, allowed_origins, is_loopback, parse_origin
from sketchrodgs.viewer.rods import RodRefused, RodSet
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
    # the browser draws splats from viser's near plane on, and a sketch sees what it draws
    assert camera.near == 0.2 and camera_from_viser(wxyz, position, 1.0, 1.5, near=0.01).near == 0.01


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
    uv, depth = camera.project(camera.unproject(pixels, 3.0))
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


def settle(rods: RodSet, frames: int = 1200) -> None:
    for _ in range(frames):
        if rods.step(1 / 60) is None:
            return
    raise AssertionError("the rods did not come to rest")


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
    settle(rods)
    assert np.abs(entry.rod.positions - entry.rod.rest_positions).max() < 1e-3
    assert np.abs(rods.means[ids] - ring.means[ids]).max() < 1e-3


@pytest.fixture(scope="module")
def plant():
    scene = load_scene(data.sample("plant"))
    return scene, extract_rod(scene, data.sample_camera("plant"), data.sample_stroke("plant"))


@pytest.mark.parametrize("which", ["ring", "plant"])
def test_a_released_rod_visibly_swings_back_with_the_default_material(which, ring, ring_rod, plant):
    """Issue 18: at the defaults a pulled rod swings past rest and back, with a first period
    near `Material.swing_period` (0.3-1 s), instead of snapping back within a frame."""
    scene, extraction = (ring, ring_rod) if which == "ring" else plant
    rods = RodSet(scene)
    entry = rods.add(extraction)
    offset = 2.0 * extraction.radius * np.array([0.0, 0.0, 1.0])
    vertex = pull(rods, entry.id, offset=offset, frames=30)
    for _ in range(30):  # hold it still
        rods.step(1 / 60)
    rest = entry.rod.rest_positions[vertex]
    pulled = float(np.dot(entry.rod.positions[vertex] - rest, offset))
    rods.release(entry.id)
    along = []
    for _ in range(120):
        rods.step(1 / 60)
        along.append(float(np.dot(entry.rod.positions[vertex] - rest, offset)) / pulled)
    along = np.array(along)
    assert along[0] > 0.5, along[:3]  # most of the pull is still there one frame after release
    crossings = np.flatnonzero((along[:-1] > 0) & (along[1:] <= 0))
    assert len(crossings) >= 2, "it did not swing through rest twice"
    period = (crossings[1] - crossings[0]) / 60
    assert 0.3 <= period <= 1.0 and abs(period - Material().swing_period) < 0.2 * Material().swing_period, period
    assert along.min() < -0.2  # past rest by a visible share of the pull


def test_same_stroke_twice_is_refused_and_remove_gives_the_gaussians_back(ring, ring_rod):
    rods = RodSet(ring)
    first = rods.add(ring_rod)
    with pytest.raises(RodRefused, match="rod 0 again"):
        rods.add(ring_rod)  # the same stroke again: a phantom rod on the first
    assert len(rods) == 1
    pull(rods, first.id)
    rods.remove(first.id)
    np.testing.assert_array_equal(rods.means, ring.means)
    with pytest.raises(SketchRodGSError, match="no rod"):
        rods.get(first.id)
    again = rods.add(ring_rod)  # free again
    assert len(again.gaussian_ids) == len(first.gaussian_ids) and again.id == 1


def test_a_rod_that_binds_nothing_is_refused(ring, ring_rod):
    empty = dataclasses.replace(
        ring_rod, gaussian_ids=ring_rod.gaussian_ids[:0], binding=ring_rod.binding.take(np.zeros(0, np.int64))
    )
    with pytest.raises(RodRefused, match="no Gaussian"):
        RodSet(ring).add(empty)


def test_rod_set_splits_needles_and_hides_them_when_removed(plant):
    """The plant stem's needles are split when its rod is added (the pieces appended to the set's
    scene) and hidden when it is removed; the export is then the input again."""
    scene, extraction = plant
    n = len(scene)
    rods = RodSet(scene)
    entry = rods.add(extraction)
    pieces = entry.gaussian_ids[entry.gaussian_ids >= n]
    assert len(pieces) > 500 and len(rods.scene) == n + len(entry.pieces) and np.isin(pieces, entry.pieces).all()
    np.testing.assert_array_equal(rods.source[:n], np.arange(n))
    assert (rods.source[pieces] < n).all()
    pull(rods, entry.id, offset=(0.0, -0.05, 0.03))
    moved = np.linalg.norm(rods.means[pieces] - rods.scene.means[pieces], axis=1)
    assert moved.max() > 0.01  # the pieces follow the rod
    assert rods.scene.sort_offsets[entry.split].any()  # the pieces sort at their parents' centres
    rods.remove(entry.id)
    assert rods.hidden[n:].all() and np.all(rods.scene.opacities[n:] == 0)
    assert not rods.scene.sort_offsets[:n].any()  # the input's Gaussians sort at their centres again
    exported = rods.export_scene()
    for field in ("means", "quats", "scales", "opacities"):
        np.testing.assert_array_equal(getattr(exported, field), getattr(scene, field))
    again = rods.add(extraction)  # the hidden pieces are not taken; the needles split anew
    assert not np.isin(again.gaussian_ids, np.flatnonzero(rods.hidden)).any()


def test_material_clamps_and_pins(ring, ring_rod):
    rods = RodSet(ring)
    entry = rods.add(ring_rod)
    pull(rods, entry.id)
    rods.reset()
    np.testing.assert_array_equal(rods.means, ring.means)
    assert not rods.grabbed() and entry.rod.boundaries[0] == "clamped"
    stiff = entry.rod.params.youngs_modulus
    rods.set_clamp(entry.id, "start")
    assert entry.rod.boundaries[0] == "clamped" and entry.rod.boundaries[-1] == "free"
    assert entry.rod.params.youngs_modulus > stiff  # one end held: stiffer for the same period
    rods.set_material(Material(swing_period=1.0, gravity=(0.0, -9.81, 0.0)))
    assert entry.rod.params.radius == ring_rod.radius and entry.rod.boundaries[0] == "clamped"
    rods.set_pinned(entry.id, 5, True)
    assert entry.rod.boundaries[5] == "pinned" and entry.pins == {5}
    with pytest.raises(SketchRodGSError, match="clamped"):
        rods.set_pinned(entry.id, 0, True)
    with pytest.raises(SketchRodGSError, match="pinned"):
        rods.grab(entry.id, 5, entry.rod.positions[5])
    rods.set_clamp(entry.id, "none")  # pins survive a rebuild
    assert entry.rod.boundaries[5] == "pinned" and entry.rod.boundaries[0] == "free"
    with pytest.raises(SketchRodGSError, match="swing period"):
        Material(swing_period=0.0)


def test_an_end_let_go_in_the_viewer_carries_what_continues_the_stem_past_it():
    """The bundled plant's stroke stops short of its stem's tip (docs/deformation.md,
    "Continuations"): held at both ends the tip stays; held at its base only, pulled, it follows."""
    scene, camera = load_scene(data.sample("plant")), data.sample_camera("plant")
    extraction = extract_rod(scene, camera, data.sample_stroke("plant"))
    b = extraction.binding
    tip = b.gaussian_ids[b.attached & (b.segment == len(extraction.polyline) - 2) & (b.t == 1)]
    rods = RodSet(scene)
    entry = rods.add(extraction)
    for clamp in ("both", "start"):
        rods.set_clamp(entry.id, clamp)
        vertex = entry.rod.num_vertices // 2
        offset = camera.screen_offset(extraction.polyline[vertex], (25, -45))
        pull(rods, entry.id, offset=tuple(offset), frames=40)
        moved = np.linalg.norm(rods.means[tip] - scene.means[tip], axis=1)
        if clamp == "both":
            assert moved.max() < 1e-6  # float32 rounding of the rest pose
        else:
            assert np.median(moved) > 5 * extraction.radius
        rods.reset()


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


def test_history_undoes_redoes_and_merges():
    state = []
    history = History()
    assert history.undo() is None and not history.can_undo
    for k in range(3):
        state.append(k)
        history.record(Step(f"add {k}", undo=state.pop, redo=lambda k=k: state.append(k)))
    assert history.undo().label == "add 2" and state == [0, 1]
    assert history.redo().label == "add 2" and state == [0, 1, 2]
    history.undo()
    history.record(Step("other", undo=lambda: None, redo=lambda: None))
    assert not history.can_redo  # a new step forgets what was undone
    value = [0]
    for v in (1, 2, 3):  # a slider drag: one step
        before = value[0]
        value[0] = v
        history.record(Step("slider", undo=lambda b=before: value.__setitem__(0, b), redo=lambda: None, merge="m"))
    history.undo()
    assert value == [0]


def test_failures_speak_of_the_stroke_not_of_pixels():
    from sketchrodgs.errors import PathNotFoundError

    text = describe_failure(PathNotFoundError("the stroke is entirely on background (alpha < 0.5) at px (3, 4)"))
    assert "on the background" in text and "px" not in text and "alpha" not in text
    leaving = "stroke lies on background inside the 960x540 image (no Gaussian near its points there), and 1 of"
    assert describe_failure(PathNotFoundError(leaving)) == text
    assert "bug" in describe_failure(RuntimeError("boom"))


# ----- origins ------------------------------------------------------------------------------------


def test_allowed_origins():
    allowed = allowed_origins("127.0.0.1", 8080, ["http://myhost:9000"])
    guard = OriginGuard.__new__(OriginGuard)
    guard.allowed = allowed
    for ok in ("http://127.0.0.1:8080", "http://localhost:8080", "http://LOCALHOST:8080/", "http://myhost:9000", None):
        assert guard.allows(ok), ok
    for bad in ("http://evil.example", "http://127.0.0.1:8081", "https://127.0.0.1:8080", "null", "file://", ""):
        assert not guard.allows(bad), bad
    assert ("http", "10.0.0.5", 8080) in allowed_origins("10.0.0.5", 8080)
    assert ("http", "0.0.0.0", 8080) not in allowed_origins("0.0.0.0", 8080)
    with pytest.raises(SketchRodGSError, match="origin"):
        parse_origin("http://myhost:8080/path")
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and not is_loopback("0.0.0.0")


def test_a_websocket_from_a_foreign_page_is_closed(ring):
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    app = ViewerApp(ring, port=free_port(), up="+y", allow_origins=["http://friend.example:8000"])
    try:
        url = f"ws://127.0.0.1:{app.port}"

        def first_message(origin):
            with connect(url, origin=origin, open_timeout=10, subprotocols=["viser-v1.1.1"]) as ws:
                try:
                    return ws.recv(timeout=10)
                except ConnectionClosed as closed:
                    return closed.rcvd.code if closed.rcvd else None

        assert first_message("http://evil.example") == 1008
        assert app.origins.refused == 1
        for origin in (f"http://localhost:{app.port}", "http://friend.example:8000"):
            assert isinstance(first_message(origin), bytes)  # the scene and the GUI
        assert app.origins.refused == 1
    finally:
        app.close()


def test_the_balls_and_the_line_are_drawn_in_front_of_the_axis_where_it_is_seen():
    camera = Camera.look_at((0.0, 0.0, -2.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), width=640, height=480)
    points = np.random.default_rng(1).uniform(-0.3, 0.3, (50, 3))
    lifted = towards_camera(points, 0.1, camera).astype(np.float64)
    (seen, depth), (now, nearer) = camera.project(points), camera.project(lifted)
    assert np.abs(now - seen).max() < 1e-3  # the same pixels
    assert np.allclose(np.linalg.norm(lifted - points, axis=1), 0.1, rtol=1e-4) and (nearer < depth).all()
    near = np.array([[0.0, 0.0, -1.95]])  # 0.05 from the camera: half way there at most
    assert np.allclose(towards_camera(near, 0.1, camera), [[0.0, 0.0, -1.975]])
    assert np.array_equal(towards_camera(points, 0.1, None), points.astype(np.float32))  # no view yet


# ----- contact ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def plant_push():
    """The prepared push of `sketchrodgs demo --contact`: the plant's left side stem, held at its
    far end, its near end dragged up past the main stem (`data.contact_push`)."""
    push = data.contact_push()
    scene = load_scene(data.sample("plant"))
    camera = Camera.from_dict(push["camera"])
    extraction = extract_rod(scene, camera, np.asarray(push["stroke"]["points"], np.float64), radius=push["radius"])
    return scene, camera, extraction, push


@pytest.mark.parametrize("on", [True, False])
def test_a_rod_pulled_into_the_scene_stays_out_with_contact_on(plant_push, on):
    scene, camera, extraction, push = plant_push
    app = ViewerApp(scene, port=free_port(), up="-y", contact=on)
    try:
        app.loop.stop()  # frames stepped here
        entry = app.add_extraction(extraction, clamp=push["clamp"])
        app.contact.rebuild().result(timeout=60)
        assert app.rods.has_scene_field and app.rods.contact.scene is on
        field = scene_field(app.rods.scene, [extraction.polyline], [extraction.radius], app.rods.owned_ids())
        polyline = extraction.polyline.astype(np.float64)
        grab = int(push["grab"])
        offset = camera.screen_offset(polyline[grab], push["drag"])
        app.rods.grab(entry.id, grab, polyline[grab])
        closest = np.inf
        for k in range(1, 31):  # dragged across the main stem
            app.rods.move_grab(entry.id, polyline[grab] + offset * min(1.0, k / 15))
            app.loop.frame()
            closest = min(closest, float(field.distance(np.asarray(entry.rod.positions)).min()))
        if on:
            assert closest > 0.9 * extraction.radius, closest / extraction.radius
        else:
            assert closest < 0.5 * extraction.radius, closest / extraction.radius
        app.set_contact(not on)
        assert app.rods.contact.scene is not on and app.panel.contact.value is not on
    finally:
        app.close()


# ----- display ----------------------------------------------------------------------------------


@pytest.mark.parametrize("update", ["exact", "segments"])
def test_display_sends_where_the_gaussians_are(server, ring, ring_rod, update):
    rods = RodSet(ring, skin_each_frame=update == "exact")
    display = SceneDisplay(server, ring, update, lambda rod_id, vertex, event: None)
    assert display.sync(rods) == len(ring)  # the scene, once
    entry = rods.add(ring_rod)
    sent = display.sync(rods)
    # only the chunks the rod took Gaussians from, and the rod's own nodes
    assert len(entry.gaussian_ids) <= sent <= 2 * len(entry.gaussian_ids)
    drawn = sum(len(node.buffer) for node in display.chunks.nodes.values())
    assert drawn == len(ring) - len(entry.gaussian_ids)
    pull(rods, entry.id)
    with rods.lock:
        display.push(rods)
        means, _, _ = rods.skinned()
        want = means[entry.gaussian_ids].astype(np.float64)
    nodes = display._rods[entry.id]
    if update == "exact":
        sent_means = np.asarray(nodes.splats[0].centers, np.float64) * display.unit
        np.testing.assert_allclose(sent_means, want, atol=1e-6)
    else:
        # each segment's node: world = position + R(wxyz) (unit * local centre)
        ids = entry.gaussian_ids
        sent_means = np.empty_like(want)
        for node, j in zip(nodes.splats, nodes.segments):
            rows = np.flatnonzero(entry.bound.segment == j)
            local = np.asarray(node.centers, np.float64) * display.unit
            sent_means[rows] = node.position + local @ quat_to_matrix(node.wxyz).T
        moved = np.linalg.norm(want - ring.means[ids], axis=1).max()
        error = np.linalg.norm(sent_means - want, axis=1)
        assert moved > 0.05 and np.median(error) < 0.05 * ring_rod.radius, (moved, np.median(error))
    shown = display.shown_handles(entry.id)
    np.testing.assert_allclose(nodes.handles.batched_positions, entry.rod.positions[shown], atol=1e-6)
    np.testing.assert_allclose(nodes.polyline.points[:, 0], entry.rod.positions[:-1], atol=1e-6)
    rods.remove(entry.id)
    display.sync(rods)
    assert sum(len(node.buffer) for node in display.chunks.nodes.values()) == len(ring)
    assert display.rod_ids() == []


def test_handles_are_thin_and_do_not_crowd_the_rod(ring_rod):
    rest = ring_rod.polyline.astype(np.float64)
    vertices, radii = handle_radii(rest, ring_rod.radius, None)
    assert (radii < ring_rod.radius).all()  # the rod shows around its balls
    assert vertices[0] == 0 and vertices[-1] == len(rest) - 1
    gaps = np.linalg.norm(np.diff(rest[vertices], axis=0), axis=1)
    assert (gaps[:-1] >= 2.9 * radii[:-2]).all()
    # far away a ball keeps a few pixels to be grabbed by
    far = Camera.look_at((0, 0, -50), (0, 0, 0), up=(0, 1, 0), width=960, height=720, fov_y_deg=60)
    _, radii_far = handle_radii(rest, ring_rod.radius, far)
    assert np.allclose(radii_far * far.fy / 50, 4.0, rtol=0.05)


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
    # the panel's working width is the size traced: at 480 px, not scaled up to extract_rod's 960
    small = Stroke(camera.resized(480), list(stroke.screen))
    traced = extract(ring, small, SketchSettings())
    np.testing.assert_array_equal(
        traced.polyline, extract_rod(ring, small.camera, small.pixels(), working_width=None).polyline
    )
    assert traced.camera.width == 480


def test_frame_timings():
    timings = FrameTimings(window=3)
    assert timings.mean() == {} and timings.rate() == 0.0 and "no frames" in timings.summary()
    for k in range(5):
        timings.record({"simulate": 0.001 * k, "skin": 0.0, "push": 0.002, "frame": 0.003})
        time.sleep(0.01)
    assert timings.mean()["simulate"] == pytest.approx(0.003)  # the last three frames
    assert 10 < timings.rate() < 200 and "Hz" in timings.summary()


# ----- the app ----------------------------------------------------------------------------------


def ring_stroke(degrees) -> Stroke:
    theta = np.radians(degrees)
    uv, _ = RING_CAMERA.project(np.stack([SEMI_AXES[0] * np.cos(theta), SEMI_AXES[1] * np.sin(theta), 0 * theta], 1))
    return Stroke(RING_CAMERA, [tuple(p) for p in pixels_to_screen(uv, RING_CAMERA)])


def test_app_sketch_undo_redo_and_exports(tmp_path, ring):
    app = ViewerApp(ring, port=free_port(), up="+y", output_dir=tmp_path, splat_update="segments")
    try:
        # a stroke on the background: a message in the user's terms, no rod
        assert app.sketch(Stroke(RING_CAMERA, [(0.02, 0.02), (0.1, 0.03), (0.2, 0.02)])).result(timeout=30) is None
        assert len(app.rods) == 0 and app.feedback.last.kind == "error" and "background" in app.feedback.last.body
        assert app.panel.undo.disabled and app.panel.remove_rod.disabled and app.panel.save_rods.disabled
        entry = app.sketch(ring_stroke(np.linspace(20, 160, 15))).result(timeout=30)
        assert entry is not None and app.feedback.last.title == "Rod 0" and not app.panel.remove_rod.disabled
        assert len(app.display._rods[entry.id].splats) == len(np.unique(entry.bound.segment))
        # the same stroke again: refused, with a message
        assert app.sketch(ring_stroke(np.linspace(20, 160, 15))).result(timeout=30) is None
        assert len(app.rods) == 1 and "again" in app.feedback.last.body
        other = app.sketch(ring_stroke(np.linspace(195, 255, 10))).result(timeout=30)
        assert other is not None and app.panel.rod.options == ("rod 0", "rod 1")
        app.set_clamp(other.id, "start")
        app.remove_rod(entry.id)
        assert [e.id for e in app.rods.entries] == [other.id]
        app.undo()  # the removal
        assert [e.id for e in app.rods.entries] == [entry.id, other.id]
        assert app.rods.get(entry.id).gaussian_ids.tolist() == entry.gaussian_ids.tolist()
        app.undo()  # the clamp
        assert app.rods.get(other.id).clamp == "both"
        app.redo()
        assert app.rods.get(other.id).clamp == "start"
        app.set_material(Material(swing_period=1.5))
        app.undo()
        assert app.rods.material.swing_period == Material().swing_period
        assert app.panel.swing_period.value == Material().swing_period
        # under gravity a rod held nowhere cannot hang as captured: it falls, and the user is told
        app.set_material(Material(gravity=(0.0, -9.81, 0.0)))
        assert app.feedback.last.kind != "error"  # both rods are held at an end
        app.set_clamp(other.id, "none")
        assert app.feedback.last.kind == "error" and f"Rod {other.id} cannot hang" in app.feedback.last.title
        app.undo()
        app.undo()
        # exports: a .ply of the deformed scene and the rods as a zip
        assert len(load_any(app.export_ply())) == len(ring)
        name, data_bytes, _ = app._rods_download()
        import io
        import zipfile

        assert name == "rods.zip" and {"rod_0.json", "rod_1.json"} <= set(
            zipfile.ZipFile(io.BytesIO(data_bytes)).namelist()
        )
        loaded, material = load_rod(tmp_path / "rod_0.json")
        np.testing.assert_allclose(loaded.polyline, entry.extraction.polyline)
        with pytest.raises(SketchRodGSError, match="no browser"):
            app.screenshot()
        app.remove_all()
        assert len(app.rods) == 0 and sum(len(n.buffer) for n in app.display.chunks.nodes.values()) == len(ring)
        app.undo()
        assert len(app.rods) == 2
    finally:
        app.close()


def test_app_simulates_and_exports_split_needles(tmp_path, plant):
    scene, extraction = plant
    app = ViewerApp(scene, port=free_port(), up="-y", output_dir=tmp_path, splat_update="exact")
    try:
        entry = app.add_extraction(extraction)
        assert len(app.display.splats) == len(app.rods.scene) > len(scene)
        nodes = app.display._rods[entry.id]
        assert len(nodes.splats[0].buffer) == len(entry.gaussian_ids)  # pieces included
        vertex = entry.rod.num_vertices // 2
        with app.rods.lock:  # the simulation thread steps the rods under it
            rest = np.asarray(entry.rod.rest_positions[vertex])
        app.rods.grab(entry.id, vertex, rest + [0, 0, 0.03])
        deadline = time.monotonic() + 10
        while True:
            with app.rods.lock:
                if np.abs(entry.rod.positions[vertex] - rest).max() >= 0.02:
                    break
            assert time.monotonic() < deadline, "the simulation thread did not move the rod"
            time.sleep(0.02)
        assert np.abs(load_any(app.export_ply()).means[: len(scene)] - scene.means).max() > 0.01
        app.remove_rod(entry.id)
        assert sum(len(n.buffer) for n in app.display.chunks.nodes.values()) == len(scene)  # pieces gone
        assert len(load_any(app.export_ply())) == len(scene)
        assert app.loop.timings.count > 0
    finally:
        app.close()


def test_app_refuses_bad_settings(ring):
    with pytest.raises(SketchRodGSError, match="up"):
        ViewerApp(ring, port=free_port(), up="sideways")
    with pytest.raises(SketchRodGSError, match="splat update"):
        ViewerApp(ring, port=free_port(), splat_update="sometimes")
    with pytest.raises(SketchRodGSError, match="origin"):
        ViewerApp(ring, port=free_port(), allow_origins=["myhost"])


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


def test_view_command_checks_origins_and_warns_off_loopback():
    result = subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "view", "sample:ring", "--allow-origin", "myhost:80"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and "http://myhost:8080" in result.stderr
    from sketchrodgs.cli.view import _exposed

    assert "--allow-origin" in _exposed("0.0.0.0", 8080) and "other machines" in _exposed("10.0.0.5", 8080)
