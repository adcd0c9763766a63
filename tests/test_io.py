"""Scene file readers and writers: round trips, real files, and bad input."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import numpy.lib.recfunctions
import plyfile
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import DATA, random_scene
from sketchrodgs import GaussianScene, SceneFormatError, data, load_scene, save_scene
from sketchrodgs.io.ply import reference_property_names

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def assert_scenes_equal(a: GaussianScene, b: GaussianScene, **tol: float) -> None:
    for name in ("means", "scales", "quats", "opacities", "sh"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), err_msg=name, **tol)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_ply_round_trip(tmp_path, degree):
    scene = random_scene(500, sh_degree=degree, seed=degree)
    save_scene(scene, tmp_path / "s.ply")
    again = load_scene(tmp_path / "s.ply")
    assert again.sh_degree == degree
    np.testing.assert_array_equal(again.means, scene.means)
    np.testing.assert_array_equal(again.sh, scene.sh)
    np.testing.assert_array_equal(again.quats, scene.quats)
    assert_scenes_equal(again, scene, rtol=1e-6, atol=1e-7)


def test_a_ply_of_many_blocks_reads_bit_for_bit_in_either_byte_order(tmp_path):
    # more rows than one read of the streaming reader (65,536), columns gathered in Rust
    scene = random_scene(70_001, sh_degree=3, seed=5)
    save_scene(scene, tmp_path / "little.ply")
    again = load_scene(tmp_path / "little.ply")
    for name in ("means", "sh", "quats"):
        np.testing.assert_array_equal(getattr(again, name), getattr(scene, name), err_msg=name)
    ply = plyfile.PlyData.read(tmp_path / "little.ply")
    plyfile.PlyData(ply.elements, text=False, byte_order=">").write(str(tmp_path / "big.ply"))
    big = load_scene(tmp_path / "big.ply")
    for name in ("means", "scales", "quats", "opacities", "sh"):
        np.testing.assert_array_equal(getattr(big, name), getattr(again, name), err_msg=name)


def test_ply_is_in_reference_layout_and_lossless_in_plyfile(tmp_path):
    scene = random_scene(50, sh_degree=3)
    save_scene(scene, tmp_path / "s.ply")
    ply = plyfile.PlyData.read(tmp_path / "s.ply")
    assert not ply.text and ply.byte_order == "<"
    vertex = ply["vertex"]
    assert [p.name for p in vertex.properties] == reference_property_names(3)
    assert len(reference_property_names(3)) == 62
    assert all(p.val_dtype in ("f4", "float32", "float") for p in vertex.properties)
    # raw values are what 3DGS training stores, bit for bit
    np.testing.assert_array_equal(vertex["x"], scene.means[:, 0])
    np.testing.assert_array_equal(vertex["f_rest_0"], scene.sh[:, 1, 0])  # channel-major:
    np.testing.assert_array_equal(vertex["f_rest_15"], scene.sh[:, 1, 1])  # R block, then G
    np.testing.assert_array_equal(vertex["f_rest_44"], scene.sh[:, 15, 2])
    np.testing.assert_array_equal(vertex["rot_0"], scene.quats[:, 0])
    np.testing.assert_array_equal(vertex["scale_1"], np.log(scene.scales[:, 1].astype(np.float64)).astype(np.float32))
    # and saving what was loaded reproduces the file's bytes
    save_scene(load_scene(tmp_path / "s.ply"), tmp_path / "t.ply")
    again = plyfile.PlyData.read(tmp_path / "t.ply")["vertex"].data
    for name in ("x", "f_dc_0", "f_rest_44", "rot_3"):
        np.testing.assert_array_equal(again[name], vertex[name])


def test_ascii_ply_reads(tmp_path):
    scene = random_scene(20, sh_degree=1)
    save_scene(scene, tmp_path / "b.ply")
    binary = plyfile.PlyData.read(tmp_path / "b.ply")
    plyfile.PlyData(binary.elements, text=True).write(str(tmp_path / "a.ply"))
    assert_scenes_equal(load_scene(tmp_path / "a.ply"), scene, rtol=1e-5, atol=1e-6)


def test_splat_round_trip_within_quantisation(tmp_path):
    scene = random_scene(1000, seed=3)
    save_scene(scene, tmp_path / "s.splat")
    assert os.path.getsize(tmp_path / "s.splat") == 32 * 1000
    again = load_scene(tmp_path / "s.splat")
    np.testing.assert_array_equal(again.means, scene.means)
    np.testing.assert_array_equal(again.scales, scene.scales)
    np.testing.assert_allclose(again.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(again.colors, scene.colors, atol=0.5 / 255 + 1e-6)
    # 8-bit quaternion: compare rotations up to sign
    dots = np.abs(np.sum(again.quats * scene.quats, axis=1))
    assert dots.min() > 0.999
    # a second pass through .splat changes nothing but the renormalised rotation's last bit
    save_scene(again, tmp_path / "t.splat")
    first = np.fromfile(tmp_path / "s.splat", np.uint8).reshape(-1, 32)
    second = np.fromfile(tmp_path / "t.splat", np.uint8).reshape(-1, 32)
    np.testing.assert_array_equal(second[:, :28], first[:, :28])
    assert np.abs(second[:, 28:].astype(int) - first[:, 28:]).max() <= 1


def test_bundled_sample_and_test_files_load():
    ring = load_scene(data.sample("ring"))
    assert len(ring) == 10_000 and ring.sh_degree == 0
    assert np.allclose(ring.means.min(axis=0), [-0.5, -0.181, -0.045], atol=1e-3)
    assert np.allclose(ring.means.max(axis=0), [0.5, 0.181, 0.045], atol=1e-3)
    torus = load_scene(DATA / "torus_10k.splat")
    assert len(torus) == 10_000
    donut = load_scene(DATA / "donut.ply")  # a real trained 3DGS .ply (Mip-Splatting output)
    assert len(donut) == 45_624 and donut.sh_degree == 0
    assert np.allclose(donut.means.min(axis=0), [-0.103, -0.098, -0.009], atol=1e-3)
    assert np.allclose(donut.means.max(axis=0), [0.105, 0.110, 0.086], atol=1e-3)


SHARED_COUNTS = {
    "plant.splat": 113_648,
    "tree_100k.splat": 100_000,
    "ring_100k.splat": 100_000,
    "ring_10k.splat": 10_000,
    "torus_100k.splat": 100_000,
    "torus_10k.splat": 10_000,
    "cylinder_100k.splat": 100_000,
    "donut.ply": 45_624,
}


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data is not beside this checkout")
@pytest.mark.parametrize("name", sorted(SHARED_COUNTS))
def test_shared_real_files_load_with_right_counts(name):
    assert len(load_scene(SHARED / name)) == SHARED_COUNTS[name]


def test_save_refuses_unknown_extension_and_keeps_existing_file(tmp_path):
    with pytest.raises(SceneFormatError, match=r"\.xyz"):
        save_scene(random_scene(3), tmp_path / "s.xyz")
    target = tmp_path / "keep.ply"
    target.write_bytes(b"precious")

    class Exploding(GaussianScene):
        @property
        def sh_degree(self) -> int:
            raise RuntimeError("disk full")

    bad = Exploding(**{n: getattr(random_scene(3), n) for n in ("means", "scales", "quats", "opacities", "sh")})
    with pytest.raises(RuntimeError):
        save_scene(bad, target)
    assert target.read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.ply"]  # no temporary left behind


# ---- bad input --------------------------------------------------------------------------------


def ply_bytes(tmp_path: Path, n: int = 10, degree: int = 0) -> bytes:
    save_scene(random_scene(n, sh_degree=degree), tmp_path / "ok.ply")
    return (tmp_path / "ok.ply").read_bytes()


def header_end(raw: bytes) -> int:
    return raw.index(b"end_header\n") + len(b"end_header\n")


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda raw: raw[:-7], "early end-of-file|truncated"),
        (lambda raw: raw[: header_end(raw) - 5], "not terminated"),
        (lambda raw: b"plx" + raw[3:], "unknown scene format"),
        (lambda raw: raw.replace(b"element vertex 10", b"element vertex 2000000000"), "2000000000 vertex rows"),
        (lambda raw: raw.replace(b"element vertex 10", b"element vertex -3"), "negative count"),
        (lambda raw: raw.replace(b"element vertex 10", b"element vertex 0"), "no rows"),
        (
            lambda raw: raw.replace(b"property float opacity", b"property float opaxity"),
            "missing vertex properties opacity",
        ),
        (lambda raw: raw.replace(b"format binary_little_endian", b"format binary_middle_endian"), "malformed PLY"),
    ],
)
def test_bad_ply_is_a_clear_error(tmp_path, mutate, message):
    path = tmp_path / "bad.ply"
    path.write_bytes(mutate(ply_bytes(tmp_path)))
    with pytest.raises(SceneFormatError, match=message) as info:
        load_scene(path)
    assert str(path) in str(info.value)


def test_nan_in_ply_names_row(tmp_path):
    raw = bytearray(ply_bytes(tmp_path))
    start = header_end(bytes(raw)) + 3 * 17 * 4  # row 3 of 17 float columns, field x
    raw[start : start + 4] = np.float32(np.nan).tobytes()
    (tmp_path / "nan.ply").write_bytes(bytes(raw))
    with pytest.raises(SceneFormatError, match=r"nan\.ply: means: NaN or infinite value in row 3"):
        load_scene(tmp_path / "nan.ply")


def test_ascii_ply_with_huge_count_fails_fast(tmp_path):
    path = tmp_path / "bomb.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 2000000000\nproperty float x\nend_header\n1\n")
    with pytest.raises(SceneFormatError, match="only 13 bytes follow"):
        load_scene(path)


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "empty"),
        (bytes(33), "not a multiple of the 32-byte"),
        (bytes(32), "scales must be > 0 in row 0"),
        (bytes(12) + np.full(3, 0.01, "<f4").tobytes() + bytes(4) + bytes([128] * 4), "zero quaternion in record 0"),
    ],
)
def test_bad_splat_is_a_clear_error(tmp_path, content, message):
    path = tmp_path / "bad.splat"
    path.write_bytes(content)
    with pytest.raises(SceneFormatError, match=message):
        load_scene(path)


def test_splat_with_nan_position_names_row(tmp_path):
    records = np.zeros(4, dtype=[("p", "<f4", 3), ("s", "<f4", 3), ("c", "u1", 4), ("q", "u1", 4)])
    records["s"] = 0.01
    records["q"] = [255, 128, 128, 128]
    records["p"][2, 1] = np.nan
    (tmp_path / "n.splat").write_bytes(records.tobytes())
    with pytest.raises(SceneFormatError, match=r"n\.splat: means: NaN or infinite value in row 2"):
        load_scene(tmp_path / "n.splat")


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(SceneFormatError, match="nope.ply: no such file"):
        load_scene(tmp_path / "nope.ply")
    with pytest.raises(FileNotFoundError):  # also what Python code expects of a missing file
        load_scene(tmp_path / "nope.ply")


def test_errors_pickle_for_multiprocessing(tmp_path):
    import pickle

    from sketchrodgs.errors import PathNotFoundError, SceneFileNotFoundError, SimulationError, SketchRodGSError

    for error in (
        SketchRodGSError("a"),
        PathNotFoundError("b"),
        SimulationError("c"),
        SceneFormatError("d"),
        SceneFileNotFoundError("e"),
    ):
        again = pickle.loads(pickle.dumps(error))
        assert type(again) is type(error) and str(again) == str(error)


def test_counts_below_the_data_are_errors_not_partial_loads(tmp_path):
    raw = ply_bytes(tmp_path)
    fewer = raw.replace(b"element vertex 10", b"element vertex 9")
    (tmp_path / "fewer.ply").write_bytes(fewer)
    with pytest.raises(SceneFormatError, match="fewer.ply: the header says 9 vertex rows .*data past the last row"):
        load_scene(tmp_path / "fewer.ply")
    # the same through plyfile (a double property, so not the float-table reader)
    scene = random_scene(10)
    vertex = plyfile.PlyData.read(str(tmp_path / "ok.ply"))["vertex"].data
    wide = np.lib.recfunctions.append_fields(vertex, "extra", np.zeros(10), dtypes="f8", usemask=False)
    plyfile.PlyData([plyfile.PlyElement.describe(wide, "vertex")]).write(str(tmp_path / "wide.ply"))
    assert len(load_scene(tmp_path / "wide.ply")) == len(scene)
    widened = (tmp_path / "wide.ply").read_bytes().replace(b"element vertex 10", b"element vertex 9")
    (tmp_path / "wide9.ply").write_bytes(widened)
    with pytest.raises(SceneFormatError, match="wide9.ply: .* bytes after the last row the header declares"):
        load_scene(tmp_path / "wide9.ply")
    # ASCII: more rows than declared, and a file cut inside a number
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex")], text=True).write(str(tmp_path / "a.ply"))
    text = (tmp_path / "a.ply").read_bytes()
    (tmp_path / "a9.ply").write_bytes(text.replace(b"element vertex 10", b"element vertex 9"))
    with pytest.raises(SceneFormatError, match="a9.ply: 10 rows of data but the header declares 9"):
        load_scene(tmp_path / "a9.ply")
    (tmp_path / "cut.ply").write_bytes(text.rstrip()[:-2])
    with pytest.raises(SceneFormatError, match="cut.ply: the file ends inside a value"):
        load_scene(tmp_path / "cut.ply")


# ---- fuzz ---------------------------------------------------------------------------------------

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def load_or_format_error(path: Path) -> None:
    try:
        scene = load_scene(path)
    except SceneFormatError:
        return
    assert np.isfinite(scene.means).all() and (scene.scales > 0).all()


@FUZZ
@given(st.binary(max_size=600), st.sampled_from(["x.ply", "x.splat"]))
def test_fuzz_random_bytes(tmp_path, content, name):
    path = tmp_path / name
    path.write_bytes(content)
    load_or_format_error(path)


@FUZZ
@given(st.data())
def test_fuzz_mutated_valid_files(tmp_path, data_strategy):
    name = data_strategy.draw(st.sampled_from(["m.ply", "m.splat"]))
    save_scene(random_scene(6, sh_degree=data_strategy.draw(st.sampled_from([0, 3]))), tmp_path / name)
    raw = bytearray((tmp_path / name).read_bytes())
    for _ in range(data_strategy.draw(st.integers(1, 8))):
        kind = data_strategy.draw(st.sampled_from(["flip", "cut", "insert"]))
        pos = data_strategy.draw(st.integers(0, max(0, len(raw) - 1)))
        if kind == "flip" and raw:
            raw[pos] = data_strategy.draw(st.integers(0, 255))
        elif kind == "cut":
            del raw[pos : pos + data_strategy.draw(st.integers(1, 40))]
        else:
            raw[pos:pos] = data_strategy.draw(st.binary(min_size=1, max_size=20))
    (tmp_path / name).write_bytes(bytes(raw))
    load_or_format_error(tmp_path / name)
