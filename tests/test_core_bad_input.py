"""The Rust core's path and polyline functions on bad input: NaN, infinite, huge, empty and
out-of-range values give an error or an answer, never a panic ("internal error"), a hang or memory
run out (docs/extraction.md, "Failures")."""

from __future__ import annotations

import numpy as np
import pytest

from sketchrodgs import SketchRodGSError, _core

BAD_VALUES = np.array([np.nan, np.inf, -np.inf, 1e38, -1e38, 0.0, 1e-40], np.float32)


def values(rng: np.random.Generator, shape: tuple[int, ...], dtype: type, mode: str) -> np.ndarray:
    """Normal values, or with a tenth of them bad ("weird"), scaled by 1e30 ("huge"), or none ("empty")."""
    if mode == "empty":
        shape = (0, *shape[1:])
    array = rng.normal(size=shape).astype(dtype)
    if mode == "weird" and array.size:
        at = rng.integers(0, array.size, max(1, array.size // 10))
        array.flat[at] = rng.choice(BAD_VALUES, len(at))
    if mode == "huge":
        array *= dtype(1e30)
    return array


def calls(rng: np.random.Generator) -> list[tuple]:
    """One round of calls with inputs drawn from `rng`."""
    mode = str(rng.choice(["ok", "weird", "huge", "empty"]))
    m, n, h, w = (int(rng.integers(1, k)) for k in (30, 300, 40, 40))
    polyline, points = values(rng, (m, 3), np.float32, mode), values(rng, (n, 3), np.float32, mode)
    axis, tangents = values(rng, (m, 3), np.float64, mode), values(rng, (m, 3), np.float64, mode)
    index = rng.integers(-1, n + (3 if mode == "weird" else 0), (h, w)).astype(np.int32)
    depth, alpha = values(rng, (h, w), np.float32, mode), values(rng, (h, w), np.float32, mode)
    if mode != "weird":
        depth = np.abs(depth) + np.float32(0.1)
    stroke = (rng.random((int(rng.integers(0, 12)), 2)) * [w, h]).astype(np.float32)
    radius = float(rng.choice([0.05, np.nan, 0.0, 1e30]))
    focal = float(rng.choice([100.0, 0.0, np.nan]))
    with np.errstate(invalid="ignore", over="ignore"):
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(axis, axis=0), axis=1))])
    return [
        (_core.nearest_on_polyline, polyline, points, float(rng.choice([0.1, 1.0, np.nan, 1e30, 0.0, -1.0]))),
        (
            _core.cross_section_centroids,
            axis,
            tangents,
            points,
            rng.integers(-2, m + 3, n).astype(np.int32),
            0.1,
            0.3,
            1.0,
            # each vertex's share of the reach: none, one per vertex, or one too many
            None if rng.random() < 0.3 else np.abs(values(rng, (int(rng.choice([m, m + 1])),), np.float64, mode)),
        ),
        (_core.crowding, axis, tangents, points, 0.5, 1.25, float(rng.choice([2.5, np.nan, -1.0]))),
        (_core.rows_in_box, points, tuple(rng.normal(size=3)), tuple(rng.normal(size=3))),
        (_core.median_neighbour_distance, points, int(rng.integers(0, 6)), int(rng.integers(0, 600))),
        (
            _core.small_clusters,
            points,
            float(rng.choice([0.1, np.nan, 0.0, -1.0, 1e30])),
            rng.integers(-1, n + 2, int(rng.integers(0, 5))).astype(np.int64),
            float(rng.choice([0.5, np.nan, -1.0, np.inf])),
        ),
        (_core.bumps, axis, 0.01, 3.0, 1.0, 30.0, 2.0, 4.0),
        (
            _core.continuation,
            points,
            rng.integers(-1, n + 5, int(rng.integers(0, 5))).astype(np.int64),
            tuple(rng.normal(size=3)),
            tuple(rng.normal(size=3)),
            float(rng.choice([1.0, np.nan, -1.0])),
            float(rng.choice([0.1, np.nan, 0.0])),
        ),
        (
            _core.forward_along_stroke,
            values(rng, (n, 2), np.float32, mode),
            values(rng, (n,), np.float32, mode),
            stroke,
        ),
        (_core.trace_stroke, index, depth, points, stroke, radius, 1.0, 0.0, 10.0, focal, alpha),
        (_core.estimate_radius, index, depth, alpha, stroke, focal),
        (_core.shown_ids, [index], (int(rng.integers(0, w)), int(rng.integers(0, h))), (w, h), n),
        (_core.segment_and_bind, axis, arc, float(arc[-1]), points, radius, 1.5, 1.5, 0.5, 4.0, 1.0, 3.0, None),
    ]


@pytest.mark.parametrize("seed", range(4))
def test_bad_input_is_an_error_or_an_answer_never_a_panic(seed):
    rng = np.random.default_rng(seed)
    for _ in range(150):
        for function, *args in calls(rng):
            try:
                function(*args)
            except (SketchRodGSError, ValueError, TypeError) as err:
                assert "internal error" not in str(err), f"{function.__name__}: {err}"


def test_a_radius_wider_than_the_image_is_refused_at_once():
    """A radius in the wrong units made the band cover the whole image at every stroke sample
    (minutes); such a radius is refused before any reading of the image. The stroke turns straight
    back, where it has no direction and a width walk stays on its pixel."""
    index = np.zeros((20, 30), np.int32)
    depth = np.ones((20, 30), np.float32)
    stroke = np.array([[5.0, 10.0], [25.0, 10.0], [5.0, 10.0]], np.float32)
    with pytest.raises(
        SketchRodGSError, match="radius [0-9]+ is [0-9]+ pixels at the stroke's depth, wider than the 30x20 image"
    ):
        _core.trace_stroke(index, depth, np.zeros((1, 3), np.float32), stroke, 1e30, focal_px=100.0)


def test_a_negative_depth_under_a_shown_gaussian_is_named():
    index = np.zeros((20, 30), np.int32)
    depth = np.ones((20, 30), np.float32)
    depth[4, 7] = -2.0
    stroke = np.array([[5.0, 10.0], [25.0, 10.0]], np.float32)
    with pytest.raises(SketchRodGSError, match=r"index image: the depth at pixel \(7, 4\) is -2 where a Gaussian"):
        _core.trace_stroke(index, depth, np.zeros((1, 3), np.float32), stroke, 0.05, focal_px=100.0)
