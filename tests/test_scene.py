"""GaussianScene validation: the constructor is the one gate every array passes."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_scene
from sketchrodgs import GaussianScene, SceneFormatError


def fields(n: int = 4) -> dict[str, np.ndarray]:
    scene = random_scene(n)
    return {name: getattr(scene, name).copy() for name in ("means", "scales", "quats", "opacities", "sh")}


def test_arrays_are_float32_c_contiguous():
    f = fields()
    f["means"] = np.asfortranarray(f["means"].astype(np.float64))
    scene = GaussianScene(**f)
    assert scene.means.dtype == np.float32 and scene.means.flags.c_contiguous
    assert len(scene) == 4 and scene.sh_degree == 0


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_sh_degree_from_coefficients(degree):
    assert random_scene(3, sh_degree=degree).sh_degree == degree


@pytest.mark.parametrize(
    "field, row, value, message",
    [
        ("means", 2, np.nan, "means: NaN or infinite value in row 2"),
        ("scales", 1, 0.0, "scales: scales must be > 0 in row 1"),
        ("scales", 3, -1.0, "scales must be > 0 in row 3"),
        ("opacities", 0, 1.5, "opacity must be in [0, 1] in row 0"),
        ("sh", 1, np.inf, "sh: NaN or infinite value in row 1"),
    ],
)
def test_bad_values_name_field_and_first_row(field, row, value, message):
    f = fields()
    f[field][row] = value
    with pytest.raises(SceneFormatError, match=message.replace("[", r"\[").replace("]", r"\]")):
        GaussianScene(**f)


def test_zero_and_non_unit_quaternions_are_errors():
    f = fields()
    f["quats"][1] = 0
    with pytest.raises(SceneFormatError, match="quats: zero quaternion in row 1"):
        GaussianScene(**f)
    f = fields()
    f["quats"][2] *= 2
    with pytest.raises(SceneFormatError, match="quats: quaternion is not unit length in row 2"):
        GaussianScene(**f)


@pytest.mark.parametrize(
    "field, shape",
    [("means", (4, 2)), ("scales", (3, 3)), ("quats", (4, 3)), ("opacities", (4, 1)), ("sh", (4, 2, 3))],
)
def test_wrong_shapes_are_named(field, shape):
    f = fields()
    f[field] = np.ones(shape, np.float32)
    with pytest.raises(SceneFormatError, match=f"^{field}: expected shape"):
        GaussianScene(**f)


def test_subset_and_replace_make_new_scenes():
    scene = random_scene(10)
    part = scene.subset(np.arange(10) % 2 == 0)
    assert len(part) == 5
    np.testing.assert_array_equal(part.means, scene.means[::2])
    moved = scene.replace(means=scene.means + 1)
    np.testing.assert_array_equal(moved.means, scene.means + 1)
    assert moved.scales is scene.scales


def test_sort_offsets_are_checked_and_carried_along():
    f = fields()
    with pytest.raises(SceneFormatError, match=r"^sort_offsets: expected shape \(4, 3\)"):
        GaussianScene(**f, sort_offsets=np.zeros((3, 3)))
    bad = np.zeros((4, 3))
    bad[2, 1] = np.nan
    with pytest.raises(SceneFormatError, match="^sort_offsets: NaN or infinite value in row 2"):
        GaussianScene(**f, sort_offsets=bad)
    offsets = np.arange(12, dtype=np.float64).reshape(4, 3)
    scene = GaussianScene(**f, sort_offsets=offsets)
    assert scene.sort_offsets.dtype == np.float32 and scene.sort_offsets.flags.c_contiguous
    np.testing.assert_array_equal(scene.subset(np.array([3, 1])).sort_offsets, offsets[[3, 1]])
    assert scene.replace(means=scene.means + 1).sort_offsets is scene.sort_offsets
    assert scene.replace(sort_offsets=None).sort_offsets is None
    assert GaussianScene(**f).sort_offsets is None


def test_shared_sh_rows_are_checked_and_read_per_gaussian():
    f = fields(6)
    table = f["sh"][:3].copy()
    rows = np.array([2, 0, 1, 1, 2, 0])
    scene = GaussianScene(**{**f, "sh": table}, sh_rows=rows)
    assert scene.sh_rows.dtype == np.uint32 and scene.sh is table
    np.testing.assert_array_equal(scene.row_sh(), table[rows])
    np.testing.assert_array_equal(scene.colors, np.clip(0.5 + 0.28209479177387814 * table[rows, 0], 0, 1))
    part = scene.subset(np.array([5, 0]))
    assert part.sh is table  # still shared
    np.testing.assert_array_equal(part.row_sh(), table[[0, 2]])
    own = scene.replace(sh=table[rows])  # a new sh without rows is one row per Gaussian
    assert own.sh_rows is None
    np.testing.assert_array_equal(own.row_sh(), scene.row_sh())
    with pytest.raises(SceneFormatError, match="^sh_rows: row outside the 3 rows of sh in row 4"):
        GaussianScene(**{**f, "sh": table}, sh_rows=np.array([0, 1, 2, 0, 3, 1]))
    with pytest.raises(SceneFormatError, match="^sh_rows: row outside the 3 rows of sh in row 0"):
        GaussianScene(**{**f, "sh": table}, sh_rows=np.array([-1, 1, 2, 0, 0, 1]))
    with pytest.raises(SceneFormatError, match=r"^sh_rows: expected \(6,\) integers"):
        GaussianScene(**{**f, "sh": table}, sh_rows=np.zeros(5, np.int64))
    with pytest.raises(SceneFormatError, match=r"^sh: expected shape \(6, K, 3\)"):
        GaussianScene(**{**f, "sh": table})


def test_from_colors_round_trips_the_dc_colour():
    scene = random_scene(5)
    again = GaussianScene.from_colors(scene.means, scene.scales, scene.quats, scene.opacities, scene.colors)
    np.testing.assert_allclose(again.colors, scene.colors, atol=1e-6)


@pytest.mark.parametrize("sh_degree", [0, 3])
def test_the_colours_of_a_few_gaussians_do_not_copy_the_whole_colour_column(sh_degree):
    """`colors_of` gathers rows of the SH table: `np.take` on the strided DC column copied the column
    whole first (27 MB and 22 ms at 2.27 M SH-3 Gaussians, twice per extraction; docs/extraction.md,
    "Speed")."""
    import tracemalloc

    scene = random_scene(100_000, sh_degree=sh_degree)
    rows = np.arange(3, len(scene.means), 500)
    tracemalloc.start()
    colours = scene.colors_of(rows)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 0.1 * len(scene.means) * 3 * 4, peak  # the column would be 1.2 MB
    np.testing.assert_array_equal(colours, scene.colors[rows])
