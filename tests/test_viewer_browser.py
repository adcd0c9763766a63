"""The viewer in a real browser: headless Chromium drives the page with the mouse.

Sketch a stroke over the bundled ring, check a rod was extracted along it; pull a rod vertex in
Play mode, check the rod and its Gaussians moved (server state and what the browser draws); let
go, check they come back. Skipped only where Chromium is not installed (`.ci/run` installs it).
"""

from __future__ import annotations

import os
import shutil
import socket
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from playwright.sync_api import Page, sync_playwright

from sketchrodgs import Camera, data, load_scene, render
from sketchrodgs.viewer import ViewerApp, camera_from_viser

CHROMIUM = next((p for p in ("/usr/bin/chromium", shutil.which("chromium")) if p and os.path.exists(p)), None)
pytestmark = [
    pytest.mark.slow,  # run by default; `-m "not slow"` leaves it out
    pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)"),
]

FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
VIEWPORT = {"width": 640, "height": 480}
# The ring (a tube on the ellipse 0.455 x 0.136 in the XY plane) seen face-on from -z, shifted to
# the lower left of the page: viser's panel floats on the right, a notice may sit top left.
EYE = (-0.818, 0.307, -1.6)
LOOK_AT = (-0.818, 0.307, 0.0)
SEMI_AXES = (0.455, 0.136)


def wait_for(condition: Callable[[], object], timeout: float, what: str, interval: float = 0.05) -> object:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Iterator[tuple[ViewerApp, Page, object]]:
    scene = load_scene(data.sample("ring"))
    start = Camera.look_at(EYE, LOOK_AT, up=(0.0, 1.0, 0.0), width=640, height=480, fov_y_deg=60.0)
    app = ViewerApp(
        scene, host="127.0.0.1", port=free_port(), up="+y", camera=start, output_dir=tmp_path_factory.mktemp("viewer")
    )
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=FLAGS, headless=True, timeout=30_000)
            try:
                page = browser.new_page(viewport=VIEWPORT)
                page.set_default_timeout(15_000)
                # half-resolution drawing buffer: software WebGL draws each frame 4x faster
                page.goto(f"{app.url}/?fixedDpr=0.5")
                client = wait_for(
                    lambda: next(iter(app.server.get_clients().values()), None), 20, "the page to connect"
                )
                wait_for(lambda: _camera_known(client), 20, "the browser's camera")
                # the page opens at the app's initial camera
                wait_for(lambda: np.allclose(client.camera.position, EYE, atol=1e-4), 10, "the initial camera")
                # the splats are sorted off the main thread: wait until the ring is drawn
                wait_for(lambda: mask(browser_render(client)).sum() > 2000, 30, "the browser to draw the splats", 0.5)
                canvas_box(page)
                yield app, page, client
            finally:
                browser.close()
    finally:
        app.close()


def _camera_known(client) -> bool:
    try:
        return client.camera.image_width > 0
    except AssertionError:
        return False


def browser_render(client) -> np.ndarray:
    """What the browser draws now, at its canvas size (client.get_render)."""
    return client.get_render(height=client.camera.image_height, width=client.camera.image_width, timeout=30)


def client_camera(client, width: int) -> Camera:
    cam = client.camera
    return camera_from_viser(cam.wxyz, cam.position, cam.fov, cam.aspect, width)


_CANVAS_BOXES: dict[int, dict] = {}

CANVAS_RECT_JS = """() => {
  const canvases = [...document.querySelectorAll("canvas")].map(c => c.getBoundingClientRect());
  const r = canvases.reduce((a, b) => (b.width * b.height > a.width * a.height ? b : a));
  return {x: r.x, y: r.y, width: r.width, height: r.height};
}"""


def canvas_box(page: Page) -> dict:
    """Page rectangle of the 3D canvas (the largest canvas; measured once per page, in one call:
    every round trip waits for a frame, which software WebGL draws slowly)."""
    if id(page) not in _CANVAS_BOXES:
        _CANVAS_BOXES[id(page)] = page.evaluate(CANVAS_RECT_JS)
    return _CANVAS_BOXES[id(page)]


def to_page(page: Page, camera: Camera, points: np.ndarray) -> np.ndarray:
    """World points -> page coordinates (CSS pixels) through `camera`, which spans the canvas."""
    box = canvas_box(page)
    uv, depth = camera.project(np.asarray(points, np.float64))
    assert (depth > 0).all()
    return np.stack(
        [box["x"] + uv[:, 0] / camera.width * box["width"], box["y"] + uv[:, 1] / camera.height * box["height"]], axis=1
    )


def drag(page: Page, path: np.ndarray, pause: float = 0.06, hold: float = 0.0) -> None:
    """Press at path[0], move through the path (slower than viser's ~20 Hz drag updates), release."""
    page.mouse.move(*path[0])
    page.mouse.down()
    for x, y in path[1:]:
        # each move waits for a frame, a few tenths of a second in software WebGL: keep them few
        page.mouse.move(float(x), float(y))
        time.sleep(pause)
    time.sleep(hold)
    page.mouse.up()


def mask(image: np.ndarray) -> np.ndarray:
    """Where the (red-brown) ring is on viser's white background."""
    return image[..., :3].astype(np.int32).min(axis=2) < 200


def test_browser_camera_matches_our_projection(session):
    """What the browser draws lines up with our CPU render from the converted camera."""
    app, page, client = session
    width, height = client.camera.image_width, client.camera.image_height
    shot = client.get_render(height=height, width=width, timeout=30)
    assert shot.shape[:2] == (height, width) and shot.std() > 5
    ours = render(app.scene, client_camera(client, width), background=(1.0, 1.0, 1.0))
    theirs, mine = mask(shot), ours.alpha > 0.5
    iou = (theirs & mine).sum() / (theirs | mine).sum()
    assert mine.sum() > 2000 and iou > 0.85, f"IoU {iou:.2f}"
    # the panel's screenshot button does the same through the app
    path = app.screenshot(client)
    from PIL import Image

    with Image.open(path) as image:
        assert image.size == (width, height) and np.asarray(image).std() > 5


def test_sketch_extracts_a_rod_along_the_stroke(session):
    app, page, client = session
    page.get_by_role("button", name="Sketch", exact=True).click()
    wait_for(lambda: app.mode == "Sketch", 10, "Sketch mode")
    theta = np.radians(np.linspace(25, 155, 10))
    centre_line = np.stack([SEMI_AXES[0] * np.cos(theta), SEMI_AXES[1] * np.sin(theta), 0 * theta], axis=1)
    camera = client_camera(client, 960)
    position_before = client.camera.position.copy()
    drag(page, to_page(page, camera, centre_line))
    wait_for(lambda: app.extractions == 1 or app.last_error, 30, "the extraction")
    assert app.last_error is None, app.last_error
    # the camera stayed still while sketching
    assert np.allclose(client.camera.position, position_before, atol=1e-6)
    [entry] = app.rods.entries
    polyline = entry.extraction.polyline.astype(np.float64)
    # every vertex on the ring's centre line (the ellipse), the rod spanning the stroke's arc
    angle = np.arctan2(polyline[:, 1] / SEMI_AXES[1], polyline[:, 0] / SEMI_AXES[0])
    on_ellipse = np.stack([SEMI_AXES[0] * np.cos(angle), SEMI_AXES[1] * np.sin(angle)], axis=1)
    off = np.linalg.norm(polyline[:, :2] - on_ellipse, axis=1)
    assert np.abs(polyline[:, 2]).max() < entry.extraction.radius
    assert off.max() < entry.extraction.radius, off.max()
    span = np.degrees([angle.min(), angle.max()])
    assert span[0] < 45 and span[1] > 135, span
    assert len(entry.gaussian_ids) > 1000
    # the stroke arrived as a polyline of many samples, not just its ends
    assert len(entry.extraction.stroke) >= 8


def test_pull_moves_rod_and_gaussians_and_release_brings_them_back(session):
    app, page, client = session
    [entry] = app.rods.entries
    page.get_by_role("button", name="Play", exact=True).click()
    wait_for(lambda: app.mode == "Play", 10, "Play mode")
    time.sleep(0.5)  # let the handles appear
    width, height = client.camera.image_width, client.camera.image_height
    before = client.get_render(height=height, width=width, timeout=30)
    rest = np.asarray(entry.rod.rest_positions)
    ids = entry.gaussian_ids
    rest_means = app.scene.means[ids].astype(np.float64)
    node = app.display._rods[entry.id].splats[0]
    vertex = len(rest) // 2
    camera = client_camera(client, width)
    start = to_page(page, camera, rest[vertex : vertex + 1])[0]
    path = start + np.outer(np.linspace(0, 1, 6), [0.0, -45.0])  # up the screen by 45 px

    page.mouse.move(*start)
    page.mouse.down()
    for x, y in path[1:]:
        page.mouse.move(float(x), float(y))
        time.sleep(0.06)
    try:
        wait_for(
            lambda: np.linalg.norm(np.asarray(entry.rod.positions)[vertex] - rest[vertex]) > 0.05,
            10,
            "the grabbed vertex to follow the pointer",
        )
        time.sleep(0.5)
        moved = np.asarray(entry.rod.positions)
        assert moved[vertex, 1] - rest[vertex, 1] > 0.05  # up the screen is +y in this view
        assert np.abs(moved[[0, -1]] - rest[[0, -1]]).max() < 1e-6  # the clamped ends stayed
        with app.rods.lock:
            means_now = app.rods.means[ids].astype(np.float64)
            sent = np.asarray(node.centers, np.float64) * app.display.unit  # nodes hold centres / unit
        assert np.linalg.norm(means_now - rest_means, axis=1).max() > 0.03
        assert np.linalg.norm(sent - rest_means, axis=1).max() > 0.03  # what the browser was sent moved too
        pulled = client.get_render(height=height, width=width, timeout=30)
    finally:
        page.mouse.up()
    assert pulled.shape == before.shape and pulled.std() > 5
    assert (mask(pulled) ^ mask(before)).sum() > 300  # the picture changed where the ring moved

    wait_for(lambda: not app.rods.awake and not app.rods.grabbed(), 15, "the rod to come to rest")
    assert np.abs(np.asarray(entry.rod.positions) - rest).max() < 1e-3
    with app.rods.lock:
        assert np.abs(app.rods.means[ids] - rest_means).max() < 1e-3
        assert np.abs(np.asarray(node.centers, np.float64) * app.display.unit - rest_means).max() < 1e-3
    after = client.get_render(height=height, width=width, timeout=30)
    assert (mask(after) ^ mask(before)).sum() < 0.2 * (mask(pulled) ^ mask(before)).sum()
    assert "frame" in app.loop.timings.mean()
