"""The consistency measures (sketchrodgs.consistency)."""

from __future__ import annotations

import numpy as np
import pytest

from sketchrodgs.consistency import (
    farthest_shared_point,
    jaccard,
    jittered_strokes,
    polyline_agreement,
    reversed_stroke,
)

R = 0.01


def line(x0: float, x1: float, offset: float = 0.0, n: int = 7) -> np.ndarray:
    x = np.linspace(x0, x1, n)
    return np.stack([x, np.full(n, offset), np.zeros(n)], axis=1)


def test_identical_polylines_agree_exactly() -> None:
    t = np.linspace(0, np.pi, 30)
    arc = np.stack([np.cos(t), np.sin(t), 0.1 * t], axis=1) * 0.2
    out = polyline_agreement(arc, arc, R)
    assert out["mean"] == pytest.approx(0.0, abs=1e-9)
    assert out["max"] == pytest.approx(0.0, abs=1e-9)
    assert out["overlap"] == pytest.approx(1.0, abs=0.02)


def test_offset_is_measured_in_radii() -> None:
    out = polyline_agreement(line(0, 1), line(0, 1, offset=0.5 * R, n=3), R)
    assert out["mean"] == pytest.approx(0.5, rel=1e-6)
    assert out["max"] == pytest.approx(0.5, rel=1e-6)
    assert out["overlap"] == pytest.approx(1.0, abs=0.02)


def test_only_the_overlap_counts() -> None:
    # b runs on 1 past both ends of a, 3 R away: outside [0, 1] its points project onto a's ends.
    short, long_ = line(0, 1), line(-1, 2, offset=3 * R)
    out = polyline_agreement(short, long_, R)
    assert out["mean"] == pytest.approx(3.0, rel=1e-6)
    assert out["max"] == pytest.approx(3.0, rel=1e-6)
    assert out["overlap"] == pytest.approx(1.0, abs=0.02)
    assert polyline_agreement(long_, short, R) == pytest.approx(out)


def test_partial_overlap_fraction() -> None:
    out = polyline_agreement(line(0, 1), line(0.5, 1.5, offset=R), R)
    assert out["overlap"] == pytest.approx(0.5, abs=0.02)
    assert out["mean"] == pytest.approx(1.0, rel=1e-6)


def test_max_sees_a_local_bump() -> None:
    bumped = line(0, 1, n=101)
    bumped[50, 1] = 2 * R
    out = polyline_agreement(line(0, 1), bumped, R)
    assert out["max"] == pytest.approx(2.0, rel=1e-3)
    assert 0 < out["mean"] < 0.1


def test_the_farthest_point_says_which_rod_and_where_along_it() -> None:
    # a hook: b turns where a ends and runs 10 R back beside a, 3 to 6 R to its side
    straight = line(0, 0.8, n=81)
    hooked = np.concatenate([line(0, 0.8, n=81), [[0.8, 0.03, 0.0], [0.7, 0.06, 0.0]]])
    which, from_end, distance = farthest_shared_point(straight, hooked, R)
    assert (which, distance) == (1, pytest.approx(polyline_agreement(straight, hooked, R)["max"]))
    assert from_end < 0.5 and distance == pytest.approx(6.0, rel=1e-3)
    # a bump in the middle of a: far from either of its ends
    bumped = line(0, 1, n=101)
    bumped[50, 1] = 2 * R
    which, from_end, distance = farthest_shared_point(bumped, line(0, 1), R)
    half = np.linalg.norm(np.diff(bumped, axis=0), axis=1).sum() / 2 / R  # 51.2 R: the bump's two sides
    assert which == 0 and from_end == pytest.approx(half, abs=0.25) and distance == pytest.approx(2.0, rel=1e-3)
    # no shared arc: nowhere
    assert farthest_shared_point(line(0, 1), np.array([[0.0, 0.5, 0.0], [0.0, 0.8, 0.0]]), R) is None


def test_disjoint_polylines_have_no_overlap() -> None:
    a = line(0, 1)
    b = np.array([[0.0, 0.5, 0.0], [0.0, 0.8, 0.0]])  # sideways, past a's start: projects onto a's end
    out = polyline_agreement(a, b, R)
    assert out["overlap"] == 0.0
    assert out["mean"] == np.inf


def test_agreement_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        polyline_agreement(line(0, 1)[:, :2], line(0, 1), R)
    with pytest.raises(ValueError):
        polyline_agreement(line(0, 1), line(0, 1), 0.0)


STROKE = np.array([[100.0, 100.0], [150.0, 110.0], [200.0, 130.0], [250.0, 160.0], [300.0, 200.0], [340.0, 250.0]])


def test_jitter_count_shape_and_seed() -> None:
    a = jittered_strokes(STROKE, count=12, seed=3)
    b = jittered_strokes(STROKE, count=12, seed=3)
    c = jittered_strokes(STROKE, count=12, seed=4)
    assert len(a) == 12
    for s in a:
        assert s.dtype == np.float64 and s.ndim == 2 and s.shape[1] == 2
        assert 2 <= len(s) <= len(STROKE) + 2
        assert np.isfinite(s).all()
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(x.shape == y.shape and np.allclose(x, y) for x, y in zip(a, c, strict=True))
    assert jittered_strokes(STROKE, count=0) == []


def test_jitter_noise_is_a_few_pixels() -> None:
    # With no drops and no end changes, the residual is the noise alone.
    strokes = jittered_strokes(STROKE, count=200, seed=0, tangent_px=0.0, drop_p=0.0)
    sigmas = [np.std(s - STROKE) for s in strokes]
    assert 2.0 < np.median(sigmas) < 8.0
    assert max(sigmas) < 14.0


def test_jitter_drops_interior_points_only() -> None:
    many = np.stack([np.linspace(0, 500, 41), np.zeros(41)], axis=1)
    strokes = jittered_strokes(many, count=50, seed=1, tangent_px=0.0, sigma_px=(0, 0))
    kept = np.mean([len(s) - 2 for s in strokes]) / 39
    assert kept == pytest.approx(0.75, abs=0.05)
    for s in strokes:
        assert np.array_equal(s[0], many[0]) and np.array_equal(s[-1], many[-1])


def test_jitter_end_changes_are_tangent_px() -> None:
    straight = np.array([[0.0, 0.0], [100.0, 0.0], [200.0, 0.0]])
    seen = set()
    for s in jittered_strokes(straight, count=60, seed=2, tangent_px=10.0, sigma_px=(0, 0), drop_p=0.0):
        assert np.allclose(s[:, 1], 0.0)  # extension follows the tangent
        start, end = s[0, 0], s[-1, 0]
        assert start in (-10.0, 0.0, 10.0) and end in (190.0, 200.0, 210.0)
        seen.add((start, end))
    assert len(seen) == 9  # every combination of shorten / keep / extend occurs


def test_jitter_extension_follows_a_curved_end() -> None:
    bent = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])  # last leg points down (+y)
    for s in jittered_strokes(bent, count=40, seed=5, tangent_px=10.0, sigma_px=(0, 0), drop_p=0.0):
        assert s[-1, 0] == pytest.approx(100.0)
        assert s[-1, 1] in (pytest.approx(90.0), pytest.approx(100.0), pytest.approx(110.0))


def test_jitter_does_not_shorten_a_tiny_stroke_away() -> None:
    tiny = np.array([[0.0, 0.0], [12.0, 0.0]])
    for s in jittered_strokes(tiny, count=30, seed=0, sigma_px=(0, 0)):
        assert len(s) >= 2 and s[-1, 0] - s[0, 0] >= 2.0


def test_reversed_stroke() -> None:
    r = reversed_stroke(STROKE.tolist())
    assert np.array_equal(r, STROKE[::-1])
    r[0] = 0
    assert STROKE[-1, 0] == 340.0  # a copy
    assert np.array_equal(reversed_stroke(r)[-1], r[0])


def test_jaccard() -> None:
    assert jaccard([1, 2, 3], [2, 3, 4]) == pytest.approx(0.5)
    assert jaccard(np.array([5, 5, 6]), {5, 6}) == 1.0
    assert jaccard([], []) == 1.0
    assert jaccard([1], []) == 0.0
