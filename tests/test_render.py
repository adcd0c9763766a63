"""The CPU rasteriser on cases worked out by hand, against the NumPy reference, and on bad input."""

from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import sketchrodgs
from conftest import DATA, PLANT, random_scene
from reference.raster_reference import render_reference
from sketchrodgs import Camera, CameraError, GaussianScene, SketchRodGSError, _core
from sketchrodgs.extract import extract_rod
from sketchrodgs.render import COLOR_OUTPUTS, release_buffers, render, render_mode

SH_C0 = 0.28209479177387814
ALPHA_MIN = 1.0 / 255.0
IDENTITY = np.eye(4)


def camera(width=64, height=48, f=100.0, cx=32.5, cy=24.5, world_to_camera=IDENTITY) -> Camera:
    """Looks down +z from the origin unless told otherwise."""
    return Camera(width, height, f, f, cx, cy, world_to_camera)


def scene_of(means, scales, opacities, colors=None, sh=None, quats=None) -> GaussianScene:
    """Gaussians with isotropic `scales` (or (N, 3)) and either RGB `colors` or SH `sh`."""
    means = np.atleast_2d(np.asarray(means, np.float64))
    n = len(means)
    scales = np.asarray(scales, np.float64)
    scales = np.repeat(scales.reshape(-1, 1), 3, axis=1) if scales.ndim <= 1 else scales
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if quats is None else quats
    if sh is None:
        sh = ((np.asarray(colors, np.float64).reshape(n, 3) - 0.5) / SH_C0)[:, None, :]
    opacities = np.broadcast_to(np.asarray(opacities, np.float64), (n,))
    return GaussianScene(means, np.broadcast_to(scales, (n, 3)), quats, opacities, sh)


def sigma2_px(scale: float, z: float, f: float = 100.0) -> float:
    """Screen variance of an isotropic Gaussian on the optical axis, with the 0.3 px² low-pass."""
    return (f * scale / z) ** 2 + 0.3


# -- one Gaussian ---------------------------------------------------------------------------


def test_single_isotropic_gaussian_peak_colour_and_footprint():
    color = (0.9, 0.5, 0.2)
    scene = scene_of([0.0, 0.0, 2.0], 0.05, 0.8, colors=color)
    # cx, cy put the mean exactly on the centre of pixel (32, 24).
    r = render(scene, camera())
    assert r.rgb.shape == (48, 64, 3) and r.alpha.shape == r.depth.shape == r.index.shape == (48, 64)
    assert r.alpha[24, 32] == pytest.approx(0.8, abs=1e-6)
    np.testing.assert_allclose(r.rgb[24, 32], np.array(color) * 0.8, atol=1e-6)
    assert r.index[24, 32] == 0
    assert r.index_depth[24, 32] == pytest.approx(2.0, abs=1e-6)
    assert r.depth[24, 32] == pytest.approx(2.0, abs=1e-6)

    # The 3-sigma radius is ceil(3 sqrt(σ²)) = 8 px; with pu = 32, pv = 24 the tile rectangle is
    # x: trunc(24/16) = 1 .. trunc(55/16) = 3 (px 16..47), y: trunc(16/16) = 1 .. trunc(47/16) = 2
    # (px 16..31). Every pixel there gets alpha = 0.8 exp(-d²/(2σ²)) where that reaches 1/255;
    # no pixel outside gets anything, even row 32 (d = 8) where the formula still gives 0.0060.
    var = sigma2_px(0.05, 2.0)
    assert math.ceil(3 * math.sqrt(var)) == 8
    rows, cols = np.mgrid[0:48, 0:64]
    expected = 0.8 * np.exp(-0.5 * ((cols - 32.0) ** 2 + (rows - 24.0) ** 2) / var)
    assert expected[32, 32] > 0.006
    expected[expected < ALPHA_MIN] = 0.0
    expected[(rows < 16) | (rows > 31) | (cols < 16) | (cols > 47)] = 0.0
    np.testing.assert_allclose(r.alpha, expected, atol=2e-6)
    assert ((r.index == 0) == (expected > 0)).all() and ((r.index == -1) == (expected == 0)).all()
    # Along the centre row the footprint reaches d with 0.8 exp(-d²/2σ²) >= 1/255.
    reach = math.floor(math.sqrt(2 * var * math.log(0.8 * 255)))
    lit = np.flatnonzero(r.alpha[24] > 0)
    assert (lit.min(), lit.max()) == (32 - reach, 32 + reach)


def test_shared_sh_rows_and_sort_offsets_render_as_their_plain_scene():
    """A scene whose Gaussians share SH rows renders as the same scene with each row copied; zero
    sort offsets render as none (docs/rendering.md, "Sort points")."""
    scene = random_scene(300, sh_degree=2, seed=5)
    rows = np.arange(300) % 37
    shared = GaussianScene(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh[:37], sh_rows=rows)
    plain = shared.replace(sh=shared.row_sh())
    cam = Camera.look_at((0.3, -0.4, -4.0), (0, 0, 0), width=80, height=56, fov_y_deg=50)
    a, b = render(shared, cam), render(plain, cam)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.index, b.index)
    zeros = render(plain.replace(sort_offsets=np.zeros((300, 3))), cam)
    np.testing.assert_array_equal(zeros.rgb, b.rgb)


def test_alpha_is_capped_at_0_99():
    scene = scene_of([0.0, 0.0, 2.0], 0.05, 1.0, colors=(1.0, 0.5, 0.0))
    r = render(scene, camera(), background=(0.0, 0.0, 1.0))
    assert r.alpha[24, 32] == pytest.approx(0.99, abs=1e-7)
    np.testing.assert_allclose(r.rgb[24, 32], [0.99, 0.495, 0.01], atol=1e-6)


def test_footprint_stops_at_the_tiles_of_the_3_sigma_rectangle():
    # σ² = 400.3 px², radius = ceil(3 sqrt(400.3)) = 61; the mean sits at pu = u - 0.5 = 77.5, so
    # the tile rectangle starts at tile trunc((77.5 - 61) / 16) = 1, i.e. pixel 16. Pixel 15 would
    # still get alpha = exp(-62.5² / (2 · 400.3)) = 0.0076 > 1/255 without the tiles.
    var = sigma2_px(0.4, 2.0)
    assert math.ceil(3 * math.sqrt(var)) == 61
    scene = scene_of([0.0, 0.0, 2.0], 0.4, 1.0, colors=(1, 1, 1))
    r = render(scene, camera(width=256, height=64, cx=78.0, cy=32.5))
    alpha_at = lambda d: min(0.99, math.exp(-0.5 * d * d / var))  # noqa: E731
    assert alpha_at(62.5) > 0.0076 > ALPHA_MIN
    assert r.alpha[32, 15] == 0.0 and r.index[32, 15] == -1
    assert r.alpha[32, 16] == pytest.approx(alpha_at(61.5), rel=1e-4)
    # On the right the rectangle ends with tile trunc((77.5 + 61 + 15) / 16) - 1 = 8 (px 128..143),
    # short of the 1/255 reach floor(77.5 + 66.6) = 144: cut there too.
    assert math.floor(77.5 + math.sqrt(2 * var * math.log(255))) == 144
    lit = np.flatnonzero(r.alpha[32] > 0)
    assert (lit.min(), lit.max()) == (16, 143)


# -- compositing order and the index image --------------------------------------------------


def two_gaussians(front_first: bool) -> GaussianScene:
    back = ([0.0, 0.0, 3.0], 0.1, 0.9, (0.0, 1.0, 0.0))
    front = ([0.0, 0.0, 2.0], 0.02, 0.6, (1.0, 0.0, 0.0))
    rows = [front, back] if front_first else [back, front]
    return scene_of([g[0] for g in rows], [g[1] for g in rows], [g[2] for g in rows], colors=[g[3] for g in rows])


def test_two_overlapping_gaussians_blend_front_to_back():
    r = render(two_gaussians(front_first=False), camera(), background=(0.0, 0.0, 1.0))
    front, back = 1, 0
    # Centre pixel: front alpha 0.6, back alpha 0.9 behind it.
    np.testing.assert_allclose(r.rgb[24, 32], [0.6, 0.4 * 0.9, 0.4 * 0.1 * 1.0], atol=1e-6)
    assert r.alpha[24, 32] == pytest.approx(1 - 0.4 * 0.1, abs=1e-6)
    assert r.depth[24, 32] == pytest.approx((0.6 * 2 + 0.36 * 3) / 0.96, rel=1e-6)
    assert r.index[24, 32] == front and r.index_depth[24, 32] == pytest.approx(2.0)
    # Three pixels right of centre the small front Gaussian has faded: the back one weighs more.
    a_front = 0.6 * math.exp(-0.5 * 9 / sigma2_px(0.02, 2.0))
    a_back = 0.9 * math.exp(-0.5 * 9 / sigma2_px(0.1, 3.0))
    assert a_back * (1 - a_front) > a_front
    np.testing.assert_allclose(r.rgb[24, 35, :2], [a_front, a_back * (1 - a_front)], atol=1e-6)
    assert r.index[24, 35] == back and r.index_depth[24, 35] == pytest.approx(3.0)
    # The index image is exactly the argmax of w_i = alpha_i T_i, computed by hand per pixel.
    rows, cols = np.mgrid[0:48, 0:64]
    d2 = (cols - 32.0) ** 2 + (rows - 24.0) ** 2
    af = np.minimum(0.99, 0.6 * np.exp(-0.5 * d2 / sigma2_px(0.02, 2.0)))
    ab = np.minimum(0.99, 0.9 * np.exp(-0.5 * d2 / sigma2_px(0.1, 3.0)))
    af[af < ALPHA_MIN] = 0
    ab[ab < ALPHA_MIN] = 0
    wf, wb = af, ab * (1 - af)
    expected = np.where((wf == 0) & (wb == 0), -1, np.where(wf >= wb, front, back))
    decided = np.abs(wf - wb) > 1e-5  # leave exact ties to rounding
    assert (r.index[decided] == expected[decided]).all()

    # Depth decides the order, not the row: swapping the rows swaps only the indices.
    swapped = render(two_gaussians(front_first=True), camera(), background=(0.0, 0.0, 1.0))
    np.testing.assert_array_equal(swapped.rgb, r.rgb)
    np.testing.assert_array_equal(swapped.index, np.where(r.index >= 0, 1 - r.index, -1))


def test_transmittance_stop_skips_the_gaussian_that_triggers_it():
    # At the shared centre: T = 1 -> 0.01 (alpha 0.99) -> 2e-4 (alpha 0.98); the third (alpha 0.9)
    # would leave 2e-5 < 1e-4, so the pixel stops and the third adds nothing.
    means = [[0, 0, 2.0], [0, 0, 2.5], [0, 0, 3.0]]
    scene = scene_of(means, [0.05, 0.0625, 0.075], [0.99, 0.98, 0.9], colors=[(1, 0, 0), (0, 1, 0), (0, 0, 1)])
    r = render(scene, camera())
    np.testing.assert_allclose(r.rgb[24, 32], [0.99, 0.01 * 0.98, 0.0], atol=1e-6)
    assert r.rgb[24, 32, 2] == 0.0
    assert r.alpha[24, 32] == pytest.approx(1 - 0.01 * 0.02, abs=1e-6)
    assert r.index[24, 32] == 0
    # A faint Gaussian whose alpha at that pixel is below 1/255 is skipped without touching T.
    var = sigma2_px(0.01, 1.0)
    assert 0.02 * math.exp(-0.5 * 9 / var) < ALPHA_MIN < 0.02
    faint = scene_of([[0.03, 0.0, 1.0]], 0.01, 0.02, colors=[(1, 1, 1)])  # centred on pixel (35, 24)
    fields = ("means", "scales", "quats", "opacities", "sh")
    both = GaussianScene(*(np.concatenate([getattr(scene, k), getattr(faint, k)]) for k in fields))
    r2 = render(both, camera())
    np.testing.assert_array_equal(r2.rgb[24, 32], r.rgb[24, 32])
    assert r2.alpha[24, 32] == r.alpha[24, 32]
    assert r2.alpha[24, 35] > r.alpha[24, 35]  # where it is bright enough, it blends


# -- near plane, empty renders --------------------------------------------------------------


@pytest.mark.parametrize("z", [-1.0, 0.0, 0.15, 0.2])
def test_gaussians_at_or_behind_the_near_plane_are_culled(z):
    scene = scene_of([0.0, 0.0, z], 0.5, 0.9, colors=(1, 1, 1))
    r = render(scene, camera(), background=(0.25, 0.5, 0.75))
    assert (r.index == -1).all() and (r.alpha == 0).all() and (r.index_depth == 0).all()
    np.testing.assert_array_equal(r.rgb, np.broadcast_to([0.25, 0.5, 0.75], r.rgb.shape).astype(np.float32))
    assert r.n_visible == 0


def test_gaussian_across_the_near_plane_still_renders():
    # Centre at z = 0.25 > 0.2, extending well behind the camera: kept, as in the reference.
    scene = scene_of([0.0, 0.0, 0.25], 0.5, 0.9, colors=(1, 1, 1))
    r = render(scene, camera())
    assert r.index[24, 32] == 0 and r.alpha[24, 32] == pytest.approx(0.9, abs=1e-6)
    assert r.index_depth[24, 32] == pytest.approx(0.25)


def test_empty_scene_renders_background():
    empty = GaussianScene(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0), np.zeros((0, 1, 3)))
    r = render(empty, camera(), background=(0.1, 0.2, 0.3))
    assert (r.index == -1).all() and (r.alpha == 0).all() and (r.depth == 0).all()
    np.testing.assert_allclose(r.rgb.reshape(-1, 3), np.tile([0.1, 0.2, 0.3], (48 * 64, 1)), atol=1e-7)
    assert r.n_visible == 0 and r.n_tile_pairs == 0


def test_zero_size_gaussian_is_the_low_pass_blob():
    scene = GaussianScene([[0.0, 0.0, 2.0]], [[1e-9, 1e-9, 1e-9]], [[1.0, 0, 0, 0]], [0.5], np.zeros((1, 1, 3)))
    r = render(scene, camera())
    assert r.alpha[24, 32] == pytest.approx(0.5, abs=1e-6)
    assert r.alpha[24, 33] == pytest.approx(0.5 * math.exp(-0.5 / 0.3), rel=1e-4)


# -- spherical harmonics --------------------------------------------------------------------

C1 = 0.4886025119029199
C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396]
C3 = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435]  # fmt: skip


def sh_basis(x: float, y: float, z: float) -> list[float]:
    """The 16 basis values of docs/conventions.md (Spherical harmonics) for the unit direction (x, y, z)."""
    xx, yy, zz = x * x, y * y, z * z
    return [
        SH_C0, -C1 * y, C1 * z, -C1 * x,
        C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy),
        C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
        C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
        C3[6] * x * (xx - 3 * yy),
    ]  # fmt: skip


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_sh_colour_for_a_known_direction(degree):
    # Camera at eye, Gaussian at eye + 1.5 (2, 3, 6)/7... seen along the unit direction (2, 3, 6)/7.
    direction = np.array([2.0, 3.0, 6.0]) / 7.0
    eye = np.array([1.0, -2.0, -3.0])
    mean = eye + 3.5 * direction
    cam = Camera.look_at(eye, mean, width=64, height=48, fov_y_deg=40)
    k = (degree + 1) ** 2
    rng = np.random.default_rng(degree)
    sh = rng.normal(scale=0.3, size=(1, k, 3))
    sh[0, 0] = [0.5, -0.2, 3.0]  # the blue channel comes out above 1: not clamped
    scene = scene_of([mean], 0.05, 0.95, sh=sh)
    r = render(scene, cam)
    basis = sh_basis(*direction)[:k]
    expected = np.maximum(0.5 + np.einsum("k,kc->c", basis, sh[0]), 0.0)
    assert expected[2] > 1.0
    peak = np.unravel_index(np.argmax(r.alpha), r.alpha.shape)
    np.testing.assert_allclose(r.rgb[peak] / r.alpha[peak], expected, rtol=2e-5, atol=2e-6)
    # The view from the opposite side flips the odd bands.
    other = Camera.look_at(mean + 3.5 * direction, mean, width=64, height=48, fov_y_deg=40)
    r2 = render(scene, other)
    expected2 = np.maximum(0.5 + np.einsum("k,kc->c", sh_basis(*-direction)[:k], sh[0]), 0.0)
    peak2 = np.unravel_index(np.argmax(r2.alpha), r2.alpha.shape)
    np.testing.assert_allclose(r2.rgb[peak2] / r2.alpha[peak2], expected2, rtol=2e-5, atol=2e-6)


def test_negative_sh_colour_clamps_at_zero():
    scene = scene_of([0.0, 0.0, 2.0], 0.05, 0.8, colors=(-0.5, 0.5, 2.0))
    r = render(scene, camera())
    np.testing.assert_allclose(r.rgb[24, 32], [0.0, 0.4, 1.6], atol=1e-6)


# -- tile borders and the reference implementation -----------------------------------------


def test_gaussian_on_a_tile_corner_is_symmetric_and_matches_the_reference():
    # The mean at continuous (32, 16): the corner shared by tiles (1, 0), (2, 0), (1, 1), (2, 1).
    scene = scene_of([0.0, 0.0, 2.0], 0.08, 0.9, colors=(0.3, 0.6, 0.9))
    cam = camera(cx=32.0, cy=16.0)
    r = render(scene, cam)
    window = r.alpha[4:28, 20:44]  # centred on the corner
    np.testing.assert_array_equal(window, window[::-1, :])
    np.testing.assert_array_equal(window, window[:, ::-1])
    assert r.alpha[15, 31] == r.alpha[16, 32] > 0.5
    ref = render_reference(scene, cam)
    np.testing.assert_allclose(r.rgb, ref["rgb"], atol=1e-6)
    np.testing.assert_array_equal(r.index, ref["index"])


def test_gaussians_on_tile_and_image_borders_match_the_reference():
    # Means on tile edges, tile corners, the image edge and just outside the image.
    uv = [(16.0, 24.5), (48.0, 16.0), (0.0, 0.0), (64.0, 48.0), (-3.0, 20.0), (70.0, 30.0), (32.5, -4.0), (40.0, 32.0)]
    z = np.linspace(2.0, 3.4, len(uv))
    means = [((u - 32.5) * zi / 100.0, (v - 24.5) * zi / 100.0, zi) for (u, v), zi in zip(uv, z)]
    rng = np.random.default_rng(7)
    quats = rng.normal(size=(len(uv), 4))
    scales = rng.uniform(0.02, 0.15, size=(len(uv), 3))
    scene = scene_of(
        means,
        scales,
        rng.uniform(0.3, 0.95, len(uv)),
        colors=rng.uniform(0, 1, (len(uv), 3)),
        quats=quats / np.linalg.norm(quats, axis=1, keepdims=True),
    )
    cam = camera()
    r = render(scene, cam, background=(0.2, 0.2, 0.2))
    ref = render_reference(scene, cam, background=(0.2, 0.2, 0.2))
    np.testing.assert_allclose(r.rgb, ref["rgb"], atol=1e-5)
    np.testing.assert_allclose(r.alpha, ref["alpha"], atol=1e-5)
    np.testing.assert_array_equal(r.index, ref["index"])
    np.testing.assert_allclose(r.index_depth, ref["index_depth"], rtol=1e-6)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_random_scenes_match_the_reference(degree):
    scene = random_scene(500, degree, seed=10 + degree)
    scene = scene.replace(scales=scene.scales * 3)
    cam = Camera.look_at((0.4, -0.6, -4.0), (0, 0, 0), width=80, height=56, fov_y_deg=50)
    r = render(scene, cam, background=(0.1, 0.2, 0.3))
    ref = render_reference(scene, cam, background=(0.1, 0.2, 0.3))
    assert np.abs(r.rgb - ref["rgb"]).max() < 1e-4
    assert np.abs(r.alpha - ref["alpha"]).max() < 1e-5
    assert (r.index == ref["index"]).mean() >= 0.999
    fg = ref["alpha"] > 0.05
    np.testing.assert_allclose(r.depth[fg], ref["depth"][fg], rtol=1e-4)
    same = r.index == ref["index"]
    np.testing.assert_allclose(r.index_depth[same], ref["index_depth"][same], rtol=1e-5)


# -- modes, arrays, determinism, GIL --------------------------------------------------------


def test_index_only_mode_gives_the_same_index_images():
    scene = random_scene(2000, 2, seed=3)
    cam = Camera.look_at((0.0, -1.0, -4.0), (0, 0, 0), width=120, height=90, fov_y_deg=45)
    full = render(scene, cam)
    for outputs in ("index", ("index", "alpha"), {"alpha", "solid"}):
        fast = render(scene, cam, outputs=outputs)
        assert fast.rgb is None and fast.depth is None
        np.testing.assert_array_equal(fast.index, full.index)
        np.testing.assert_array_equal(fast.index_depth, full.index_depth)
        np.testing.assert_array_equal(fast.alpha, full.alpha)  # alpha is free: T is tracked anyway
        np.testing.assert_array_equal(fast.solid, full.alpha >= 0.5)
    # without alpha, pixels stop once their index is decided: the same index, depth and solid
    for outputs in (["index"], ("index", "index_depth"), {"index_depth"}, ("index", "solid")):
        fast = render(scene, cam, outputs=outputs)
        assert fast.rgb is None and fast.depth is None and fast.alpha is None
        np.testing.assert_array_equal(fast.index, full.index)
        np.testing.assert_array_equal(fast.index_depth, full.index_depth)
        np.testing.assert_array_equal(fast.solid, full.alpha >= 0.5)
    assert render(scene, cam, outputs=["rgb", "index"]).rgb is not None
    with pytest.raises(SketchRodGSError, match="outputs"):
        render(scene, cam, outputs=["colour"])
    with pytest.raises(SketchRodGSError, match="outputs"):
        render(scene, cam, outputs=[])


def test_colour_only_mode_gives_the_same_colour_without_the_index():
    scene = random_scene(2000, 3, seed=4)
    cam = Camera.look_at((0.0, -1.0, -8.0), (0, 0, 0), width=120, height=90, fov_y_deg=45)  # 65 % covered
    full = render(scene, cam, background=(0.2, 0.4, 0.6))
    for outputs in ("rgb", ("rgb", "alpha"), COLOR_OUTPUTS):
        colour = render(scene, cam, background=(0.2, 0.4, 0.6), outputs=outputs)
        assert colour.index is None and colour.index_depth is None and colour.depth is None
        np.testing.assert_array_equal(colour.rgb, full.rgb)  # the same bits
        np.testing.assert_array_equal(colour.alpha, full.alpha)
        np.testing.assert_array_equal(colour.covered(), full.index >= 0)
        assert 0.1 < colour.covered().mean() < 0.9
    with pytest.raises(SketchRodGSError, match="no index image"):
        _ = colour.index_image
    # a render that cannot give the sketch its index image is refused, saying so
    with pytest.raises(SketchRodGSError, match="no index image"):
        extract_rod(scene, cam, np.array([[30.0, 40.0], [90.0, 50.0]]), render=colour)
    assert render_mode(["rgb", "depth"]) == "all" and render_mode(["alpha"]) == "index"


def test_outputs_are_numpy_arrays_owned_by_rust():
    r = render(random_scene(100, 0), camera())
    for name, dtype, shape in [
        ("rgb", np.float32, (48, 64, 3)),
        ("alpha", np.float32, (48, 64)),
        ("depth", np.float32, (48, 64)),
        ("index", np.int32, (48, 64)),
        ("index_depth", np.float32, (48, 64)),
    ]:
        array = getattr(r, name)
        assert array.dtype == dtype and array.shape == shape and array.flags.c_contiguous
        assert not array.flags.owndata  # the buffer is the Rust Vec, moved, not copied
    assert set(r.timings) == {"project", "sort", "composite"} and all(t >= 0 for t in r.timings.values())


def plant_scene():
    return sketchrodgs.load_scene(PLANT)


def plant_camera(width=480, height=270):
    return sketchrodgs.load_cameras(DATA / "cameras_plant.json")[0].resized(width, height)


def test_render_is_deterministic_across_runs_and_thread_counts():
    scene, cam = plant_scene(), plant_camera()
    first, second = render(scene, cam), render(scene, cam)
    for name in ("rgb", "alpha", "depth", "index", "index_depth"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    digest = hashlib.sha256(first.rgb.tobytes() + first.index.tobytes() + first.depth.tobytes()).hexdigest()
    code = (
        "import hashlib, sys; sys.path.insert(0, sys.argv[1]); import test_render as t; "
        "r = t.render(t.plant_scene(), t.plant_camera()); "
        "print(hashlib.sha256(r.rgb.tobytes() + r.index.tobytes() + r.depth.tobytes()).hexdigest())"
    )
    for threads in ("1", "3"):
        env = {**os.environ, "RAYON_NUM_THREADS": threads}
        out = subprocess.run(
            [sys.executable, "-c", code, os.path.dirname(__file__)],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == digest, f"{threads} threads gave a different image"


def test_renders_after_a_larger_scene_or_a_release_are_the_same():
    # a render keeps its buffers for the next (docs/rendering.md, "Buffers kept between renders")
    small, cam = random_scene(2_000, seed=5), camera()
    first = render(small, cam)
    render(plant_scene(), cam)  # larger: its buffers are kept, and the small scene reuses them
    after_larger = render(small, cam)
    release_buffers()
    after_release = render(small, cam)
    for name in ("rgb", "alpha", "depth", "index", "index_depth"):
        np.testing.assert_array_equal(getattr(after_larger, name), getattr(first, name))
        np.testing.assert_array_equal(getattr(after_release, name), getattr(first, name))


def test_an_image_larger_than_memory_is_an_error_not_an_abort():
    # under a 4 GB address-space limit, a 16384x16384 render (7.5 GB of outputs) must raise
    code = (
        "import resource, sketchrodgs as s; from sketchrodgs.render import render; "
        "resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30)); "
        "cam = s.Camera.look_at((0, 0, -2), (0, 0, 0), up=(0, 1, 0), width=16384, height=16384, fov_y_deg=40)\n"
        "try:\n    render(s.load_scene(s.data.sample('ring')), cam)\n"
        "except s.SketchRodGSError as e:\n    print(e)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "the image needs 7.52 GB, more memory than can be had: render a smaller image" in out.stdout


def test_render_releases_the_gil():
    scene, cam = plant_scene(), plant_camera(1920, 1080)
    render(scene, cam)  # warm up
    span: list[float] = []

    def worker():
        span.append(time.perf_counter())
        render(scene, cam)
        span.append(time.perf_counter())

    thread = threading.Thread(target=worker)
    ticks = []
    thread.start()
    while thread.is_alive():
        ticks.append(time.perf_counter())
    thread.join()
    start, end = span
    assert end - start > 0.01
    inside = [t for t in ticks if start + 0.25 * (end - start) < t < end - 0.25 * (end - start)]
    assert len(inside) > 10, "the main thread did not run while the render was in progress"


# -- bad input ------------------------------------------------------------------------------


def raw_call(scene, **overrides):
    args = dict(world_to_camera=np.eye(4), width=64, height=48, fx=100.0, fy=100.0, cx=32.0, cy=24.0)
    args.update(overrides)
    return _core.rasterize(
        scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, args["world_to_camera"],
        args["width"], args["height"], args["fx"], args["fy"], args["cx"], args["cy"],
    )  # fmt: skip


@pytest.mark.parametrize(
    ("field", "overrides"),
    [
        ("fx", {"fx": 0.0}),
        ("fy", {"fy": -100.0}),
        ("fx", {"fx": float("nan")}),
        ("cx", {"cx": float("inf")}),
        ("width", {"width": 0}),
        ("height", {"height": 0}),
        ("width", {"width": 16385}),
        ("world_to_camera", {"world_to_camera": np.diag([2.0, 1.0, 1.0, 1.0])}),
        ("world_to_camera", {"world_to_camera": np.diag([1.0, 1.0, -1.0, 1.0])}),
        (
            "world_to_camera",
            {"world_to_camera": np.array([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])},
        ),
        ("world_to_camera", {"world_to_camera": np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]])}),
    ],
)
def test_degenerate_cameras_are_refused_naming_the_field(field, overrides):
    with pytest.raises(SketchRodGSError, match=field):
        raw_call(random_scene(10), **overrides)


def test_the_python_camera_refuses_the_same_cameras():
    for bad in (dict(fx=0.0), dict(width=0), dict(height=20000)):
        kwargs = dict(width=64, height=48, fx=100.0, fy=100.0, cx=32.0, cy=24.0, world_to_camera=np.eye(4)) | bad
        with pytest.raises(CameraError):
            Camera(**kwargs)
    with pytest.raises(CameraError, match="camera"):
        render(random_scene(10), "not a camera")  # type: ignore[arg-type]


def test_largest_image_side_renders():
    scene = scene_of([0.0, 0.0, 2.0], 0.05, 0.8, colors=(1, 1, 1))
    r = render(scene, Camera(16384, 2, 100.0, 100.0, 8192.5, 1.0, np.eye(4)), outputs="index")
    assert r.index.shape == (2, 16384) and r.index[0, 8192] == 0


def test_bad_arrays_are_refused_naming_the_array():
    scene = random_scene(10)
    with pytest.raises(SketchRodGSError, match="scales"):
        _core.rasterize(
            scene.means, scene.scales[:5], scene.quats, scene.opacities, scene.sh, np.eye(4), 8, 8, 10.0, 10.0, 4.0, 4.0
        )
    with pytest.raises(SketchRodGSError, match="sh"):
        _core.rasterize(
            scene.means,
            scene.scales,
            scene.quats,
            scene.opacities,
            np.zeros((10, 5, 3), np.float32),
            np.eye(4),
            8,
            8,
            10.0,
            10.0,
            4.0,
            4.0,
        )
    with pytest.raises(SketchRodGSError, match="means"):
        strided = np.zeros((10, 6), np.float32)[:, ::2]
        _core.rasterize(
            strided, scene.scales, scene.quats, scene.opacities, scene.sh, np.eye(4), 8, 8, 10.0, 10.0, 4.0, 4.0
        )
    with pytest.raises(TypeError):
        _core.rasterize(
            scene.means.astype(np.float64),
            scene.scales,
            scene.quats,
            scene.opacities,
            scene.sh,
            np.eye(4),
            8,
            8,
            10.0,
            10.0,
            4.0,
            4.0,
        )
    for background in ((0, 0), ("a", 0, 0), (0, 0, float("nan")), 3):
        with pytest.raises(SketchRodGSError, match="background"):
            render(scene, camera(), background=background)


def test_non_finite_gaussians_in_raw_arrays_are_dropped_not_fatal():
    scene = scene_of([[0.0, 0.0, 2.0], [0.0, 0.0, 3.0]], 0.05, 0.8, colors=[(1, 0, 0), (0, 1, 0)])
    means = scene.means.copy()
    means[1] = np.nan
    scales = scene.scales.copy()
    out = _core.rasterize(
        means, scales, scene.quats, scene.opacities, scene.sh, np.eye(4), 64, 48, 100.0, 100.0, 32.5, 24.5
    )
    assert out.n_visible == 1 and out.index[24, 32] == 0
    scales[0] = np.inf
    out = _core.rasterize(
        means, scales, scene.quats, scene.opacities, scene.sh, np.eye(4), 64, 48, 100.0, 100.0, 32.5, 24.5
    )
    assert out.n_visible == 0 and (out.index == -1).all()


# -- command line ---------------------------------------------------------------------------


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "render", *args], capture_output=True, text=True, timeout=300
    )


def read_png(path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        assert image.mode == "RGB"
        return np.asarray(image)


def test_cli_renders_png_and_index(tmp_path):
    png, npz = tmp_path / "plant.png", tmp_path / "plant.npz"
    out = run_cli(str(PLANT), "--camera", str(DATA / "cameras_plant.json"), "--view", "view0_az30_el25",
                  "--width", "240", "-o", str(png), "--index", str(npz), "--background", "1,1,1")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "240x135" in out.stdout
    cam = plant_camera(240, 135)
    expected = render(plant_scene(), cam, background=(1, 1, 1))
    image = read_png(png)
    assert image.shape == (135, 240, 3)
    np.testing.assert_array_equal(image, np.clip(np.round(expected.rgb * 255), 0, 255).astype(np.uint8))
    saved = np.load(npz)
    np.testing.assert_array_equal(saved["index"], expected.index)
    np.testing.assert_array_equal(saved["index_depth"], expected.index_depth)
    np.testing.assert_array_equal(saved["alpha"], expected.alpha)
    assert Camera.from_dict(__import__("json").loads(str(saved["camera"]))).width == 240


def test_cli_reads_a_3dgs_cameras_json(tmp_path):
    import json

    cam = plant_camera(200, 120)
    c2w = cam.camera_to_world
    entry = {"id": 0, "img_name": "frame_0", "width": 200, "height": 120, "position": c2w[:3, 3].tolist(),
             "rotation": c2w[:3, :3].tolist(), "fx": cam.fx, "fy": cam.fy}  # fmt: skip
    cameras = tmp_path / "cameras.json"
    cameras.write_text(json.dumps([entry]))
    npz = tmp_path / "k.npz"
    out = run_cli(str(PLANT), "--camera", str(cameras), "--view", "frame_0", "--index", str(npz))
    assert out.returncode == 0, out.stderr
    saved = np.load(npz)
    assert "depth" not in saved and "alpha" in saved  # index only: no colour; alpha comes free
    np.testing.assert_array_equal(saved["index"], render(plant_scene(), cam, outputs="index").index)


def test_cli_errors_are_one_line(tmp_path):
    base = [str(PLANT), "--camera", str(DATA / "cameras_plant.json")]
    for extra in (
        ["--view", "7", "-o", str(tmp_path / "a.png")],
        ["--view", "nope", "-o", str(tmp_path / "a.png")],
        [],
    ):
        out = run_cli(*base, *extra)
        assert out.returncode == 1 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    out = run_cli(str(PLANT), "--camera", str(tmp_path / "missing.json"), "-o", str(tmp_path / "a.png"))
    assert out.returncode == 1 and "missing.json" in out.stderr
    assert run_cli(*base, "--width", "0", "-o", str(tmp_path / "a.png")).returncode == 2
    assert not (tmp_path / "a.png").exists()
