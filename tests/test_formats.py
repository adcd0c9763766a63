"""SPZ and PlayCanvas compressed PLY: real files, golden files from a test-side encoder, format
detection, conversion, and bad input (truncation, wrong versions, disagreeing counts, bombs)."""

from __future__ import annotations

import gzip
import json
import math
import os
import struct
import subprocess
import sys
import textwrap
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import DATA, random_scene
from reference.format_encoders import (
    encode_compressed_ply,
    encode_spz,
    spz_blocks,
    spz_gzip,
    spz_v4,
)
from sketchrodgs import Camera, GaussianScene, SceneFormatError, load_scene, save_scene
from sketchrodgs.cli import main
from sketchrodgs.io import detect_format
from sketchrodgs.io.ply import read_ply
from sketchrodgs.io.spz import read_spz
from sketchrodgs.render import render

BIKER = DATA / "biker.spz"
GUITAR = DATA / "guitar.compressed.ply"
SH_STEP_SPZ = 1 / 128


def scene_arrays(scene: GaussianScene) -> tuple[np.ndarray, ...]:
    return scene.means, scene.scales, scene.quats, scene.opacities, scene.sh


def bounded_scene(n: int, sh_degree: int = 0, seed: int = 0) -> GaussianScene:
    """A random scene inside what SPZ can hold: |position| < 100, scales in [e^-9, e^5],
    f_dc within the 0.15-scaled byte, SH coefficients inside (-1, 1)."""
    rng = np.random.default_rng(seed)
    scene = random_scene(n, sh_degree, seed)
    sh = rng.uniform(-0.95, 0.95, size=scene.sh.shape)
    sh[:, 0] = rng.uniform(-3.2, 3.2, size=(n, 3))
    return scene.replace(
        means=rng.uniform(-100, 100, size=(n, 3)),
        scales=np.exp(rng.uniform(-9, 5, size=(n, 3))),
        sh=sh,
    )


def assert_same_rotations(a: np.ndarray, b: np.ndarray, min_dot: float) -> None:
    dots = np.abs(np.sum(a.astype(np.float64) * b, axis=1))
    assert dots.min() > min_dot, f"worst |dot| {dots.min()}"


def write(tmp_path: Path, name: str, content: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(content)
    return path


# ---- the real files -----------------------------------------------------------------------------


def test_biker_spz_v4_loads_with_readme_count_and_bbox():
    assert BIKER.read_bytes()[:8] == b"NGSP\x04\x00\x00\x00"
    assert detect_format(BIKER) == "spz"
    scene = load_scene(BIKER)
    assert len(scene) == 152_746 and scene.sh_degree == 0
    # README: (-0.621, 0.0, -0.613) -> (0.414, 3.180, 0.532), as stored (no axis flips)
    np.testing.assert_allclose(scene.means.min(axis=0), [-0.621, 0.0, -0.613], atol=6e-4)
    np.testing.assert_allclose(scene.means.max(axis=0), [0.414, 3.180, 0.532], atol=6e-4)
    # 12 fractional bits: every coordinate is a multiple of 1/4096
    assert np.all(scene.means * 4096 == np.round(scene.means * 4096))
    assert 0 < scene.opacities.min() and scene.opacities.max() <= 1
    assert np.abs(np.linalg.norm(scene.quats, axis=1) - 1).max() < 1e-6


def test_guitar_compressed_ply_loads_with_readme_count_and_bbox():
    assert detect_format(GUITAR) == "compressed-ply"
    scene = load_scene(GUITAR)
    assert len(scene) == 90_854 and scene.sh_degree == 0
    np.testing.assert_allclose(scene.means.min(axis=0), [-0.655, -4.292, -0.528], atol=6e-4)
    np.testing.assert_allclose(scene.means.max(axis=0), [0.822, 0.086, 0.925], atol=6e-4)
    assert np.abs(np.linalg.norm(scene.quats, axis=1) - 1).max() < 1e-6


@pytest.mark.parametrize("path, up", [(BIKER, (0, 1, 0)), (GUITAR, (0, -1, 0))])
def test_real_files_render_sensibly_and_survive_a_ply_round_trip(tmp_path, path, up):
    scene = load_scene(path)
    centre = np.median(scene.means, axis=0)
    extent = float(np.ptp(scene.means, axis=0).max())
    camera = Camera.look_at(centre + np.array([0, 0, 1.3 * extent]), centre, up, 160, 160, 45)
    image = render(scene, camera)
    covered = image.alpha > 0.5
    # the object fills part of the view, sits around its centre, and is neither black nor white
    assert 0.03 < covered.mean() < 0.6
    assert covered[60:100, 60:100].mean() > 0.2
    colour = image.rgb[covered].mean(axis=0)
    assert np.all(colour > 0.03) and np.all(colour < 0.9)
    # Written to .ply and re-read, the scene is the same: means, rotations and SH bit for bit;
    # scales and opacities up to the float32 rounding of their stored log and logit.
    save_scene(scene, tmp_path / "again.ply")
    again = load_scene(tmp_path / "again.ply")
    for name in ("means", "quats", "sh"):
        np.testing.assert_array_equal(getattr(again, name), getattr(scene, name), err_msg=name)
    np.testing.assert_allclose(again.scales, scene.scales, rtol=3e-7)
    np.testing.assert_allclose(again.opacities, scene.opacities, rtol=3e-7, atol=1e-7)
    second = render(again, camera)
    np.testing.assert_allclose(second.rgb, image.rgb, atol=1e-4)
    assert (second.index == image.index).mean() > 0.9999


def test_incomplete_compressed_ply_is_named(tmp_path):
    raw = (
        b"ply\nformat binary_little_endian 1.0\nelement chunk 1\nproperty float min_x\n"
        b"element vertex 1\nproperty uint packed_position\nend_header\n" + bytes(8)
    )
    assert "compressed PLY 'chunk' element lacks min_y" in load_error(tmp_path, raw, "c.ply")


def test_the_inria_reader_hands_compressed_files_on():
    direct, loaded = read_ply(GUITAR), load_scene(GUITAR)
    np.testing.assert_array_equal(direct.means, loaded.means)
    np.testing.assert_array_equal(direct.sh, loaded.sh)


# ---- SPZ golden files ---------------------------------------------------------------------------


@pytest.mark.parametrize("version", [2, 3, 4])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_spz_from_the_test_encoder_decodes_within_quantisation(tmp_path, version, degree):
    scene = bounded_scene(300, degree, seed=10 * version + degree)
    path = write(tmp_path, "s.spz", encode_spz(*scene_arrays(scene), version=version))
    got = load_scene(path)
    assert len(got) == 300 and got.sh_degree == degree
    np.testing.assert_allclose(got.means, scene.means, atol=0.5 / 4096 + 1e-9)
    np.testing.assert_allclose(np.log(got.scales), np.log(scene.scales), atol=0.5 / 16 + 1e-6)
    np.testing.assert_allclose(got.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(got.sh[:, 0], scene.sh[:, 0], atol=0.5 / (0.15 * 255) + 1e-6)
    np.testing.assert_allclose(got.sh[:, 1:], scene.sh[:, 1:], atol=SH_STEP_SPZ / 2 + 1e-6)
    # v2: 8-bit x, y, z with w >= 0 rebuilt, coarse where w is near 0 (w = sqrt(1 - |xyz|^2) moves
    # by up to ~0.1 for a half-step error in xyz); v3+: 9-bit magnitudes of the smallest three
    assert_same_rotations(got.quats, scene.quats, 0.99 if version == 2 else 0.99998)


@pytest.mark.parametrize("version", [2, 3, 4])
def test_spz_decodes_across_parallel_blocks_with_reference_sh_rounding(tmp_path, version):
    # more splats than three of the decoder's parallel blocks, the last one partial; SH bytes
    # rounded as the reference writer does by default (5 bits for degree 1, 4 above)
    n = 50_000
    scene = bounded_scene(n, 2, seed=version)
    raw = encode_spz(*scene_arrays(scene), version=version, sh_bits=(5, 4))
    got = load_scene(write(tmp_path, "big.spz", raw))
    np.testing.assert_allclose(got.means, scene.means, atol=0.5 / 4096 + 1e-9)
    np.testing.assert_allclose(np.log(got.scales), np.log(scene.scales), atol=0.5 / 16 + 1e-6)
    np.testing.assert_allclose(got.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(got.sh[:, 0], scene.sh[:, 0], atol=0.5 / (0.15 * 255) + 1e-6)
    np.testing.assert_allclose(got.sh[:, 1:4], scene.sh[:, 1:4], atol=4.5 / 128 + 1e-6)  # buckets of 8
    np.testing.assert_allclose(got.sh[:, 4:], scene.sh[:, 4:], atol=8.5 / 128 + 1e-6)  # buckets of 16
    assert_same_rotations(got.quats, scene.quats, 0.99 if version == 2 else 0.99998)


def _load_with_threads(tmp_path, path, threads):
    """Load `path` in a fresh process with `threads` worker threads: the arrays and what it logged."""
    script = textwrap.dedent("""
        import sys, numpy as np, sketchrodgs
        s = sketchrodgs.load_scene(sys.argv[1])
        np.savez(sys.argv[2], means=s.means, scales=s.scales, quats=s.quats, opacities=s.opacities, sh=s.sh)
    """)
    target = tmp_path / f"threads{threads}.npz"
    env = dict(os.environ, SKETCHRODGS_NUM_THREADS=str(threads))
    run = subprocess.run(
        [sys.executable, "-c", script, str(path), str(target)], env=env, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    return np.load(target), run.stderr


@pytest.mark.parametrize("sh_bits", [(8, 8), (5, 4)])
def test_big_gzipped_spz_reads_the_same_for_any_thread_count(tmp_path, sh_bits):
    # over 2 MiB of gzip (a parallel inflater, since removed, panicked on such files with 3 or more
    # threads); with SH rounded as the reference writer does, few distinct bytes
    scene = bounded_scene(60_000 if sh_bits == (8, 8) else 90_000, 3, seed=11)
    path = write(tmp_path, "big.spz", encode_spz(*scene_arrays(scene), version=3, sh_bits=sh_bits))
    assert path.stat().st_size > 2 << 20
    loaded = {threads: _load_with_threads(tmp_path, path, threads)[0] for threads in (1, 2, 4)}
    for threads in (2, 4):
        for name in ("means", "scales", "quats", "opacities", "sh"):
            np.testing.assert_array_equal(loaded[1][name], loaded[threads][name], err_msg=name)
    # 4-bit SH above degree 1: buckets of 16 steps, and the half step of the byte itself
    atol = SH_STEP_SPZ / 2 if sh_bits == (8, 8) else 8.5 * SH_STEP_SPZ
    np.testing.assert_allclose(loaded[2]["sh"][:, 4:], scene.sh[:, 4:], atol=atol + 1e-6)


def test_bytes_after_the_gzip_member_are_ignored_with_a_warning(tmp_path):
    scene = bounded_scene(40_000, 3, seed=12)
    raw = encode_spz(*scene_arrays(scene), version=3)
    clean = _load_with_threads(tmp_path, write(tmp_path, "clean.spz", raw), 1)[0]
    path = write(tmp_path, "trailing.spz", raw + bytes(range(256)) * 4000)
    for threads in (1, 2, 4):
        loaded, log = _load_with_threads(tmp_path, path, threads)
        assert "continues after its gzip member; the extra bytes were ignored" in log and "trailing.spz" in log
        for name in ("means", "sh"):
            np.testing.assert_array_equal(loaded[name], clean[name])


def test_spz_golden_bytes_decode_to_exact_values(tmp_path):
    # One splat, written byte by byte from the format description.
    position = bytes(
        [
            0x00,
            0x08,
            0x00,  # x = +2048 / 2^12 = 0.5
            0x00,
            0xF8,
            0xFF,  # y = -2048 / 2^12 = -0.5
            0xFF,
            0xFF,
            0x7F,
        ]
    )  # z = (2^23 - 1) / 2^12
    alpha, colour, scale = bytes([51]), bytes([0, 128, 255]), bytes([160, 0, 255])
    # smallest three: largest is y (index 1 in x, y, z, w order); x = -0.5 * sqrt(2) * 511/511
    # (sign bit set, magnitude 511... scaled), z = 0, w = +sqrt(1/2) * 256/511
    x_field = (1 << 9) | 511
    z_field = 0
    w_field = 256
    rotation = struct.pack("<I", (1 << 30) | (x_field << 20) | (z_field << 10) | w_field)
    sh = bytes([0, 128, 255] * 3)
    blocks = [position, alpha, colour, scale, rotation, sh]
    for raw in (spz_gzip(blocks, 1, 1, 3), spz_v4(blocks, 1, 1)):
        scene = load_scene(write(tmp_path, "g.spz", raw))
        np.testing.assert_array_equal(scene.means[0], np.float32([0.5, -0.5, (2**23 - 1) / 4096]))
        assert scene.opacities[0] == np.float32(51 / 255)
        np.testing.assert_allclose(
            scene.sh[0, 0], [(0 / 255 - 0.5) / 0.15, (128 / 255 - 0.5) / 0.15, (1 - 0.5) / 0.15], rtol=1e-6
        )
        np.testing.assert_allclose(np.log(scene.scales[0]), [0.0, -10.0, 255 / 16 - 10], atol=1e-5)
        x, w = -math.sqrt(0.5), math.sqrt(0.5) * 256 / 511
        y = math.sqrt(1 - x * x - w * w)
        np.testing.assert_allclose(scene.quats[0], [w, x, y, 0.0], atol=1e-6)
        np.testing.assert_allclose(scene.sh[0, 1:], [[-1.0, 0.0, 127 / 128]] * 3, atol=1e-7)


def test_spz_v2_rotation_rebuilds_w(tmp_path):
    blocks = [bytes(9), bytes([255]), bytes([128] * 3), bytes([160] * 3), bytes([255, 128, 0]), b""]
    scene = load_scene(write(tmp_path, "v2.spz", spz_gzip(blocks, 1, 0, 2)))
    x, y, z = 1.0, 128 / 127.5 - 1, -1.0
    # |xyz| > 1, so w is 0 and the quaternion is scaled back to unit length
    np.testing.assert_allclose(scene.quats[0], np.array([0.0, x, y, z]) / math.sqrt(x * x + y * y + z * z), atol=1e-6)


def test_spz_sh_degree_4_keeps_degree_3(tmp_path):
    n = 20
    scene = bounded_scene(n, 3, seed=4)
    rng = np.random.default_rng(5)
    band4 = rng.uniform(-0.9, 0.9, size=(n, 9, 3))
    sh25 = np.concatenate([scene.sh, band4], axis=1)
    raw = encode_spz(scene.means, scene.scales, scene.quats, scene.opacities, sh25)
    got = load_scene(write(tmp_path, "d4.spz", raw))
    assert got.sh_degree == 3
    np.testing.assert_allclose(got.sh[:, 1:], scene.sh[:, 1:], atol=SH_STEP_SPZ / 2 + 1e-6)


def test_spz_extension_records_are_skipped(tmp_path):
    scene = bounded_scene(50, 1, seed=6)
    blocks = spz_blocks(*scene_arrays(scene), version=3)
    record = struct.pack("<II", 0xADBE0002, 12) + np.float32([0.1, 0.2, 3.0]).tobytes()
    plain = load_scene(write(tmp_path, "plain.spz", spz_v4(blocks, 50, 1)))
    for raw in (
        spz_v4(blocks, 50, 1, flags=2, extensions=record),
        spz_gzip(blocks, 50, 1, 3, flags=2, extensions=record),
    ):
        got = load_scene(write(tmp_path, "ext.spz", raw))
        np.testing.assert_array_equal(got.means, plain.means)
        np.testing.assert_array_equal(got.sh, plain.sh)


# ---- compressed PLY golden files ----------------------------------------------------------------


def chunk_ranges(values: np.ndarray) -> np.ndarray:
    """Per-splat (max - min) of each splat's 256-chunk, (N, ...)."""
    n = len(values)
    chunks = -(-n // 256)
    padded = np.concatenate([values, np.repeat(values[-1:], chunks * 256 - n, axis=0)])
    blocks = padded.reshape(chunks, 256, *values.shape[1:])
    span = blocks.max(axis=1) - blocks.min(axis=1)
    return np.repeat(span, 256, axis=0)[:n]


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
@pytest.mark.parametrize("chunk_colors", [True, False])
def test_compressed_ply_from_the_test_encoder_decodes_within_quantisation(tmp_path, degree, chunk_colors):
    n = 700  # two full chunks and a partial one
    scene = random_scene(n, degree, seed=degree)
    rng = np.random.default_rng(degree)
    sh = scene.sh.copy()
    sh[:, 1:] = rng.uniform(-3.9, 3.9, size=sh[:, 1:].shape)
    if not chunk_colors:  # the old layout stores colours directly, so they must lie in [0, 1]
        sh[:, 0] = (rng.uniform(0, 1, size=(n, 3)) - 0.5) / 0.28209479177387814
    scene = scene.replace(sh=sh)
    path = write(tmp_path, "c.ply", encode_compressed_ply(*scene_arrays(scene), chunk_colors=chunk_colors))
    assert detect_format(path) == "compressed-ply"
    got = load_scene(path)
    assert len(got) == n and got.sh_degree == degree
    step = chunk_ranges(scene.means.astype(np.float64)) / np.array([2047, 1023, 2047])
    assert np.all(np.abs(got.means - scene.means) <= step / 2 + 1e-6)
    log_step = chunk_ranges(np.log(scene.scales.astype(np.float64))) / np.array([2047, 1023, 2047])
    assert np.all(np.abs(np.log(got.scales) - np.log(scene.scales)) <= log_step / 2 + 1e-5)
    np.testing.assert_allclose(got.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    rgb, got_rgb = (0.5 + 0.28209479177387814 * s.sh[:, 0].astype(np.float64) for s in (scene, got))  # unclipped
    rgb_step = chunk_ranges(rgb) / 255 if chunk_colors else 1 / 255
    assert np.all(np.abs(got_rgb - rgb) <= rgb_step / 2 + 1e-6)
    np.testing.assert_allclose(got.sh[:, 1:], scene.sh[:, 1:], atol=8 / 256 + 1e-6)
    assert_same_rotations(got.quats, scene.quats, 0.99999)


def test_compressed_ply_decodes_across_parallel_blocks(tmp_path):
    n = 3 * 16384 + 77  # more than three of the decoder's blocks of whole chunks, the last partial
    scene = random_scene(n, 1, seed=9)
    got = load_scene(write(tmp_path, "big.ply", encode_compressed_ply(*scene_arrays(scene))))
    step = chunk_ranges(scene.means.astype(np.float64)) / np.array([2047, 1023, 2047])
    assert np.all(np.abs(got.means - scene.means) <= step / 2 + 1e-6)
    np.testing.assert_allclose(got.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(got.sh[:, 1:], np.clip(scene.sh[:, 1:], -4, 4), atol=8 / 256 + 1e-6)
    assert_same_rotations(got.quats, scene.quats, 0.99999)


def test_compressed_ply_golden_bytes_decode_to_exact_values(tmp_path):
    header = (
        "ply\nformat binary_little_endian 1.0\nelement chunk 1\n"
        + "".join(
            f"property float {p}\n"
            for p in (
                "min_x min_y min_z max_x max_y max_z min_scale_x min_scale_y min_scale_z "
                "max_scale_x max_scale_y max_scale_z"
            ).split()
        )
        + "element vertex 1\n"
        + "".join(f"property uint packed_{p}\n" for p in ("position", "rotation", "scale", "color"))
        + "element sh 1\n"
        + "".join(f"property uchar f_rest_{i}\n" for i in range(9))
        + "end_header\n"
    ).encode()
    chunk = np.float32([0, -1, 10, 2047, 1, 20, -5, -5, -5, -1, -3, -5]).tobytes()
    position = (2047 << 21) | (0 << 11) | 1023  # x = max, y = min, z = 1023/2047 of the range
    rotation = (2 << 30) | (1023 << 20) | (0 << 10) | 512  # largest is rot_2 (y)
    scale = (0 << 21) | (1023 << 11) | 2047
    color = (255 << 24) | (0 << 16) | (128 << 8) | 64
    vertex = np.uint32([position, rotation, scale, color]).tobytes()
    sh = bytes([0, 255, 128, 1, 2, 3, 4, 5, 6])
    scene = load_scene(write(tmp_path, "g.ply", header + chunk + vertex + sh))
    np.testing.assert_allclose(scene.means[0], [2047, -1, 10 + 10 * 1023 / 2047], rtol=1e-6)
    np.testing.assert_allclose(np.log(scene.scales[0]), [-5, -3, -5], atol=1e-5)
    np.testing.assert_allclose(scene.colors[0], [1.0, 0.0, 128 / 255], atol=1e-6)
    assert scene.opacities[0] == np.float32(64 / 255)
    a, b, c = (1 - 0.5) * math.sqrt(2), -0.5 * math.sqrt(2), (512 / 1023 - 0.5) * math.sqrt(2)
    m = math.sqrt(max(0.0, 1 - a * a - b * b - c * c))  # here |abc| > 1: m = 0 and q is rescaled
    q = np.array([a, b, m, c]) / math.sqrt(a * a + b * b + c * c + m * m)
    np.testing.assert_allclose(scene.quats[0], q, atol=2e-6)
    rest = [8 * ((v + 0.5) / 256 - 0.5) for v in sh]
    rest[0], rest[1] = -4.0, 4.0
    # channel-major: f_rest_{c*3+j} is basis j+1 of channel c
    np.testing.assert_allclose(scene.sh[0, 1:], np.array(rest).reshape(3, 3).T, atol=1e-6)


# ---- detection and round trips through our writers -----------------------------------------------


def test_detection_looks_at_content_not_names(tmp_path):
    scene = bounded_scene(40, 1)
    spz_raw = encode_spz(*scene_arrays(scene), version=3)
    assert detect_format(write(tmp_path, "a.bin", spz_raw)) == "spz"
    assert detect_format(write(tmp_path, "b.splat", spz_raw)) == "spz"
    assert detect_format(write(tmp_path, "c.dat", encode_spz(*scene_arrays(scene), version=4))) == "spz"
    compressed = encode_compressed_ply(*scene_arrays(scene))
    assert detect_format(write(tmp_path, "d.ply", compressed)) == "compressed-ply"
    assert len(load_scene(write(tmp_path, "e.anything", compressed))) == 40
    # a .splat whose first float starts with the gzip bytes is still a .splat
    records = np.zeros(3, dtype=[("p", "<f4", 3), ("s", "<f4", 3), ("c", "u1", 4), ("q", "u1", 4)])
    records["s"], records["q"] = 0.01, [255, 128, 128, 128]
    raw = bytearray(records.tobytes())
    raw[0:4] = b"\x1f\x8b\x08\x3f"
    path = write(tmp_path, "g.splat", bytes(raw))
    assert detect_format(path) == "splat" and len(load_scene(path)) == 3


@pytest.mark.parametrize("version", [2, 3, 4])
def test_spz_round_trips_through_ply_and_splat_writers(tmp_path, version):
    raw = encode_spz(*scene_arrays(bounded_scene(200, 2, seed=7)), version=version)
    scene = load_scene(write(tmp_path, "s.spz", raw))
    save_scene(scene, tmp_path / "s.ply")
    again = load_scene(tmp_path / "s.ply")
    for name in ("means", "quats", "sh"):
        np.testing.assert_array_equal(getattr(again, name), getattr(scene, name), err_msg=name)
    np.testing.assert_allclose(again.scales, scene.scales, rtol=3e-7)  # stored as float32 logs
    np.testing.assert_allclose(again.opacities, scene.opacities, rtol=3e-7, atol=1e-7)
    save_scene(scene, tmp_path / "s.splat")
    lossy = load_scene(tmp_path / "s.splat")
    np.testing.assert_array_equal(lossy.means, scene.means)
    np.testing.assert_allclose(lossy.colors, scene.colors, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(lossy.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    assert_same_rotations(lossy.quats, scene.quats, 0.999)


def test_convert_command(tmp_path, capsys, caplog):
    assert main(["convert", str(BIKER), str(tmp_path / "biker.ply")]) == 0
    assert "Niantic SPZ" in capsys.readouterr().out
    assert "+y up by the SPZ convention" in caplog.text and "give --up +y" in caplog.text  # a .ply does not say
    original, converted = load_scene(BIKER), load_scene(tmp_path / "biker.ply")
    np.testing.assert_array_equal(converted.means, original.means)
    np.testing.assert_array_equal(converted.sh, original.sh)
    assert main(["convert", str(GUITAR), str(tmp_path / "guitar.splat")]) == 0
    assert len(load_scene(tmp_path / "guitar.splat")) == 90_854
    with pytest.raises(SystemExit) as refused:  # a usage error, before the scene is read
        main(["convert", str(GUITAR), str(tmp_path / "guitar.spz")])
    assert (
        refused.value.code == 2
        and "guitar.spz: expected a file name ending in .ply or .splat" in capsys.readouterr().err
    )
    assert not (tmp_path / "guitar.spz").exists()


def test_info_names_the_format():
    out = subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "info", str(GUITAR), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    summary = json.loads(out.stdout)
    assert summary["format"] == "compressed-ply" and summary["format_name"] == "PlayCanvas compressed PLY"
    assert summary["count"] == 90_854
    text = subprocess.run(
        [sys.executable, "-m", "sketchrodgs", "info", str(BIKER)], capture_output=True, text=True, timeout=120
    ).stdout
    assert "(Niantic SPZ," in text and "152,746" in text


# ---- bad input ------------------------------------------------------------------------------------


def small_blocks(n: int = 30, degree: int = 1, version: int = 3) -> list[bytes]:
    return spz_blocks(*scene_arrays(bounded_scene(n, degree, seed=1)), version=version)


def load_error(tmp_path: Path, raw: bytes, name: str = "bad.spz") -> str:
    path = write(tmp_path, name, raw)
    with pytest.raises(SceneFormatError) as info:
        load_scene(path)
    message = str(info.value)
    assert name in message
    return message


@pytest.mark.parametrize("version", [2, 3, 4])
@pytest.mark.parametrize("keep", [0.1, 0.5, 0.95, 0.999])
def test_truncated_spz_is_a_clear_error(tmp_path, version, keep):
    blocks = small_blocks(version=version)
    raw = spz_v4(blocks, 30, 1) if version == 4 else spz_gzip(blocks, 30, 1, version)
    cut = raw[: max(20, int(len(raw) * keep))]
    message = load_error(tmp_path, cut)
    assert any(word in message for word in ("truncated", "ends", "corrupt", "past the end", "outside"))


@pytest.mark.parametrize(
    "version, message", [(1, "version 1"), (0, "version 0"), (5, "version 5"), (4, "must not be gzipped")]
)
def test_wrong_spz_versions_in_gzip(tmp_path, version, message):
    raw = spz_gzip(small_blocks(), 30, 1, version)
    assert message in load_error(tmp_path, raw)


def test_fractional_bits_past_the_24_bit_positions_are_refused(tmp_path):
    for raw in (
        spz_gzip(small_blocks(), 30, 1, 3, fractional_bits=255),
        spz_v4(small_blocks(), 30, 1, fractional_bits=25),
    ):
        assert "positions are 24-bit fixed point, so at most 24" in load_error(tmp_path, raw)


def test_wrong_spz_version_in_plain_header(tmp_path):
    raw = spz_v4(small_blocks(), 30, 1, version=3)
    assert "must be gzipped" in load_error(tmp_path, raw)
    raw = spz_v4(small_blocks(), 30, 1, version=7)
    assert "unsupported SPZ version 7" in load_error(tmp_path, raw)


def test_bad_spz_headers(tmp_path):
    blocks = small_blocks()
    # a gzip or plain file without the SPZ magic is not taken for SPZ at all ...
    assert "unknown scene format" in load_error(tmp_path, spz_gzip(blocks, 30, 1, 3, magic=b"NGSX"))
    # ... and the SPZ reader itself names the bad magic
    with pytest.raises(SceneFormatError, match="bad SPZ magic b'NGSX'"):
        read_spz(write(tmp_path, "m.spz", spz_gzip(blocks, 30, 1, 3, magic=b"NGSX")))
    assert "SH degree 5" in load_error(tmp_path, spz_v4(blocks, 30, 5))
    assert "0 splats" in load_error(tmp_path, spz_v4([b""] * 6, 0, 0))
    assert "lists 6 streams" in load_error(tmp_path, spz_v4(small_blocks(degree=0), 30, 0, stream_count=6))
    assert "ends inside the 16-byte SPZ header" in load_error(tmp_path, gzip.compress(b"NGSP\x03\x00"))


@pytest.mark.parametrize("declared", [29, 31, 1000])
def test_spz_counts_that_disagree_with_the_data(tmp_path, declared):
    blocks = small_blocks()  # 30 splats
    for raw in (spz_gzip(blocks, declared, 1, 3), spz_v4(blocks, declared, 1)):
        assert "disagrees" in load_error(tmp_path, raw)


def test_spz_toc_outside_the_file_and_streams_past_the_end(tmp_path):
    blocks = small_blocks()
    raw = bytearray(spz_v4(blocks, 30, 1))
    raw[16:20] = struct.pack("<I", len(raw) + 5)
    assert "outside" in load_error(tmp_path, bytes(raw))
    raw = bytearray(spz_v4(blocks, 30, 1))
    toc_last = 32 + 16 * 5
    raw[toc_last : toc_last + 8] = struct.pack("<Q", 10**6)  # last stream claims a megabyte
    assert "runs past the end" in load_error(tmp_path, bytes(raw))


def test_corrupt_streams(tmp_path):
    blocks = small_blocks()
    frames = [zstandard.ZstdCompressor().compress(b) for b in blocks if b]
    frames[2] = b"\x00" * len(frames[2])  # not zstd at all
    assert "colors stream is corrupt" in load_error(tmp_path, spz_v4(blocks, 30, 1, frames=frames))
    raw = bytearray(spz_gzip(blocks, 30, 1, 3))
    raw[-8] ^= 0xFF  # CRC of the gzip member
    assert "corrupt gzip" in load_error(tmp_path, bytes(raw))


def zstd_bomb(size: int) -> bytes:
    """A zstd frame of zeros that expands to `size` bytes, with no content size in its header."""
    compressor = zstandard.ZstdCompressor(level=1, write_content_size=False).compressobj()
    zeros = bytes(1 << 20)
    parts = [compressor.compress(zeros) for _ in range(size >> 20)]
    return b"".join(parts) + compressor.flush()


def test_zstd_bomb_stops_at_the_declared_size(tmp_path):
    blocks = small_blocks(degree=0)  # 30 splats: 270 bytes of positions
    frames = [zstandard.ZstdCompressor().compress(b) for b in blocks if b]
    frames[0] = zstd_bomb(256 << 20)  # 256 MiB of zeros for a 270-byte stream
    path = write(tmp_path, "bomb.spz", spz_v4(blocks, 30, 0, frames=frames))
    assert path.stat().st_size < 100_000
    # in a fresh process, so that the peak resident memory is the load's own
    script = textwrap.dedent("""
        import sys, time
        import sketchrodgs
        def peak():
            return next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmHWM:"))
        before, start = peak(), time.perf_counter()
        try:
            sketchrodgs.load_scene(sys.argv[1])
        except sketchrodgs.SceneFormatError as exc:
            print(f"{peak() - before} {time.perf_counter() - start:.3f} {exc}")
    """)
    out = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=120)
    growth, seconds, message = out.stdout.split(" ", 2)
    assert "positions stream decompresses past its declared 270 bytes" in message
    assert int(growth) < 32 << 20 and float(seconds) < 5


def test_gzip_bomb_stops_at_the_declared_count(tmp_path):
    blocks = small_blocks(degree=0)
    header = struct.pack("<4sIIBBBB", b"NGSP", 3, 30, 0, 12, 0, 0)
    compressor = gzip.compress(header + b"".join(blocks) + bytes(64 << 20), compresslevel=1)
    message = load_error(tmp_path, compressor)
    assert "continues past" in message


def test_forged_huge_counts_fail_before_allocating(tmp_path):
    blocks = small_blocks(degree=0)
    assert "more than the 10,000,000" in load_error(tmp_path, spz_v4(blocks, 4_000_000_000, 0))
    big = 9_000_000
    sizes = [9 * big, big, 3 * big, 3 * big, 4 * big]
    assert "cannot expand" in load_error(tmp_path, spz_v4(blocks, big, 0, sizes=sizes))
    assert "more than" in load_error(tmp_path, spz_gzip(blocks, big, 0, 3))


def test_bad_compressed_ply(tmp_path):
    scene = random_scene(300, 1, seed=2)
    arrays = scene_arrays(scene)
    assert "3 chunk rows for 300 splats" in load_error(tmp_path, encode_compressed_ply(*arrays, chunk_rows=3), "c.ply")
    assert "'sh' element has 299 rows" in load_error(tmp_path, encode_compressed_ply(*arrays, sh_rows=299), "c.ply")
    raw = encode_compressed_ply(*arrays)
    renamed = raw.replace(b"uint packed_scale", b"uint packed_scalf")
    assert "lacks packed_scale" in load_error(tmp_path, renamed, "c.ply")
    assert "lacks max_scale_z" in load_error(tmp_path, raw.replace(b"float max_scale_z", b"float max_scale_w"), "c.ply")
    retyped = raw.replace(b"uint packed_color", b"float packed_color")
    assert "must be an integer" in load_error(tmp_path, retyped, "c.ply")
    assert "malformed PLY" in load_error(tmp_path, raw[:-500], "c.ply")
    message = load_error(tmp_path, raw.replace(b"element vertex 300", b"element vertex 3000000"), "c.ply")
    assert "3000000 vertex rows" in message
    # a NaN chunk bound is reported like any NaN position
    header_end = raw.index(b"end_header\n") + len(b"end_header\n")
    broken = bytearray(raw)
    broken[header_end : header_end + 4] = np.float32(np.nan).tobytes()  # min_x of chunk 0
    assert "NaN" in load_error(tmp_path, bytes(broken), "c.ply")


# ---- fuzz -----------------------------------------------------------------------------------------

FUZZ = settings(
    max_examples=150,
    deadline=timedelta(seconds=10),
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def load_or_format_error(path: Path) -> None:
    try:
        scene = load_scene(path)
    except SceneFormatError:
        return
    assert np.isfinite(scene.means).all() and (scene.scales > 0).all()
    assert np.all((scene.opacities >= 0) & (scene.opacities <= 1))


def valid_file(kind: str) -> bytes:
    scene = bounded_scene(12, 1, seed=3)
    if kind == "compressed":
        return encode_compressed_ply(*scene_arrays(scene))
    return encode_spz(*scene_arrays(scene), version={"spz2": 2, "spz3": 3, "spz4": 4}[kind])


VALID = {kind: valid_file(kind) for kind in ("spz2", "spz3", "spz4", "compressed")}


@FUZZ
@given(st.data())
def test_fuzz_mutated_spz_and_compressed_files(tmp_path, data_strategy):
    kind = data_strategy.draw(st.sampled_from(sorted(VALID)))
    raw = bytearray(VALID[kind])
    for _ in range(data_strategy.draw(st.integers(1, 6))):
        action = data_strategy.draw(st.sampled_from(["flip", "cut", "insert", "word"]))
        pos = data_strategy.draw(st.integers(0, max(0, len(raw) - 1)))
        if action == "flip" and raw:
            raw[pos] = data_strategy.draw(st.integers(0, 255))
        elif action == "cut":
            del raw[pos : pos + data_strategy.draw(st.integers(1, 64))]
        elif action == "insert":
            raw[pos:pos] = data_strategy.draw(st.binary(min_size=1, max_size=16))
        else:  # overwrite a header-sized word with an extreme value
            raw[pos : pos + 4] = struct.pack("<I", data_strategy.draw(st.sampled_from([0, 1, 255, 2**31, 2**32 - 1])))
    load_or_format_error(write(tmp_path, "m.spz" if kind != "compressed" else "m.ply", bytes(raw)))


@FUZZ
@given(st.data())
def test_fuzz_mutated_gzip_payloads(tmp_path, data_strategy):
    """Mutations inside the gzip stream, where versions 2 and 3 keep their header and counts."""
    version = data_strategy.draw(st.sampled_from([2, 3]))
    payload = bytearray(gzip.decompress(VALID[f"spz{version}"]))
    for _ in range(data_strategy.draw(st.integers(1, 4))):
        pos = data_strategy.draw(st.integers(0, len(payload) - 1))
        if data_strategy.draw(st.booleans()):
            payload[pos] = data_strategy.draw(st.integers(0, 255))
        else:
            del payload[pos : pos + data_strategy.draw(st.integers(1, 32))]
    load_or_format_error(write(tmp_path, "p.spz", gzip.compress(bytes(payload))))


@FUZZ
@given(st.binary(max_size=400), st.sampled_from([b"NGSP", b"\x1f\x8b\x08\x00", b"ply\n"]))
def test_fuzz_random_bytes_behind_a_magic(tmp_path, content, magic):
    load_or_format_error(write(tmp_path, "r.spz", magic + content))
