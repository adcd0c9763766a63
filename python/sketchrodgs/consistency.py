"""Measures of how consistent extractions are: between views, under stroke jitter, and reversed.

These functions only compare geometry (numpy and scipy); they know nothing of how a rod was
extracted, so they can judge any extraction method.

- `polyline_agreement(a, b, radius)`: how far apart two 3D polylines are over the arc length they
  share, in units of the object's radius.
- `jittered_strokes(stroke)`: strokes like one a user might draw over the same part again (pixel
  noise, dropped points, ends a little short or long).
- `reversed_stroke(stroke)`: the same stroke drawn from the other end.
- `farthest_shared_point(a, b, radius)`: where the first measure's max lies (a rod's end or middle).
- `jaccard(ids_a, ids_b)`: overlap of two sets of Gaussian indices (e.g. the segmented Gaussians).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from .polyline import arc_lengths, nearest_on_polyline, point_at

# Directed distances are taken from points this far apart along the polyline, at most (as a
# fraction of the radius), and from no more than MAX_SAMPLES points.
SAMPLE_SPACING = 0.25
MAX_SAMPLES = 4000
MIN_SAMPLES = 200


def _as_polyline(points: np.ndarray, dims: int, name: str) -> np.ndarray:
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != dims or len(array) < 2:
        raise ValueError(f"{name}: expected shape (N, {dims}) with N >= 2, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name}: contains NaN or infinite values")
    return array


def _resample(points: np.ndarray, count: int) -> np.ndarray:
    """`count` points evenly spaced in arc length, both ends included."""
    arc = arc_lengths(points)
    return point_at(points, arc, np.linspace(0.0, arc[-1], count))


def _directed(samples: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances from `samples` to `other` and whether each projects inside `other`."""
    distance, where = nearest_on_polyline(samples, other)
    total = arc_lengths(other)[-1]
    eps = 1e-9 * max(total, 1e-300)
    inside = (where > eps) & (where < total - eps)
    return distance, inside


def polyline_agreement(a: np.ndarray, b: np.ndarray, radius: float) -> dict[str, float]:
    """Symmetric distance between two 3D polylines over the arc length they share.

    Both polylines are resampled densely and evenly in arc length (spacing at most a quarter of
    `radius`, between 200 and 4000 points each). A sample of `a` counts when its nearest point
    on `b` is not one of b's two end points, i.e. it projects inside `b`; likewise for the samples
    of `b`. So a polyline that runs on past the other's end is judged only where they overlap.

    Args:
        a, b: (N, 3) and (M, 3) polylines, N, M >= 2, in world units.
        radius: the object's radius R (> 0); distances are reported in units of R.

    Returns:
        dict with
            mean: the average of the two directed mean distances (a to b and b to a), over
                counting samples, in units of R;
            max: the larger of the two directed maximum distances, in units of R;
            overlap: the fraction of the shorter polyline's length whose samples count (0..1).
        Where one direction has no counting sample, mean and max are inf (and overlap is
        computed as usual, 0 when the polylines do not overlap at all).

    Raises:
        ValueError: bad shapes, non-finite values or a radius that is not > 0.
    """
    (dist_ab, in_ab, along_a), (dist_ba, in_ba, along_b) = _shared_distances(a, b, radius)
    means, maxima = [], []
    for dist, inside in ((dist_ab, in_ab), (dist_ba, in_ba)):
        if inside.any():
            means.append(float(dist[inside].mean()) / radius)
            maxima.append(float(dist[inside].max()) / radius)
        else:
            means.append(np.inf)
            maxima.append(np.inf)
    shorter_inside = in_ab if along_a[-1] <= along_b[-1] else in_ba
    return {
        "mean": 0.5 * (means[0] + means[1]),
        "max": max(maxima),
        "overlap": float(shorter_inside.mean()),
    }


def farthest_shared_point(a: np.ndarray, b: np.ndarray, radius: float) -> tuple[int, float, float] | None:
    """Where `polyline_agreement`'s max lies: which polyline holds the farthest counting sample (0:
    `a`, 1: `b`), how far along that polyline it lies from its nearer end, and its distance to the
    other, both in units of `radius`; None where no sample counts. A max at a rod's end is a hook
    or a run onto what the part meets; one in the middle is the rod on something else there."""
    best: tuple[int, float, float] | None = None
    for which, (dist, inside, along) in enumerate(_shared_distances(a, b, radius)):
        if inside.any():
            k = int(np.flatnonzero(inside)[np.argmax(dist[inside])])
            if best is None or dist[k] / radius > best[2]:
                best = (which, float(min(along[k], along[-1] - along[k])) / radius, float(dist[k]) / radius)
    return best


def _shared_distances(a: np.ndarray, b: np.ndarray, radius: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """For `a` against `b` and `b` against `a`: each polyline's dense samples' distances to the
    other, whether each projects inside it, and the samples' arc lengths (`polyline_agreement`)."""
    a = _as_polyline(a, 3, "a")
    b = _as_polyline(b, 3, "b")
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: must be finite and > 0, got {radius}")
    out = []
    for poly, other in ((a, b), (b, a)):
        length = arc_lengths(poly)[-1]
        count = int(np.clip(np.ceil(length / (SAMPLE_SPACING * radius)) + 1, MIN_SAMPLES, MAX_SAMPLES))
        distance, inside = _directed(_resample(poly, count), other)
        out.append((distance, inside, np.linspace(0.0, length, count)))
    return out


def _end_tangent(stroke: np.ndarray, arc: np.ndarray, at_start: bool, span: float) -> np.ndarray:
    """Unit vector pointing out of the stroke at one end, from the point `span` px inside."""
    total = arc[-1]
    span = min(span, 0.5 * total)
    if at_start:
        inner = point_at(stroke, arc, np.array([span]))[0]
        out = stroke[0] - inner
    else:
        inner = point_at(stroke, arc, np.array([total - span]))[0]
        out = stroke[-1] - inner
    norm = np.linalg.norm(out)
    if norm == 0:
        step = stroke[1] - stroke[0] if at_start else stroke[-1] - stroke[-2]
        out = -step if at_start else step
        norm = np.linalg.norm(out)
    return out / norm if norm > 0 else np.zeros(2)


def _change_ends(stroke: np.ndarray, choices: tuple[int, int], amount: float) -> np.ndarray:
    """Shorten (-1), keep (0) or extend (+1) each end by `amount` px of arc length."""
    if amount <= 0:
        return stroke.copy()
    arc = arc_lengths(stroke)
    total = arc[-1]
    start_s, end_s = 0.0, total
    # An end is shortened only if at least `amount` px of stroke is left afterwards.
    if choices[0] < 0 and end_s - start_s >= 2 * amount:
        start_s = amount
    if choices[1] < 0 and end_s - start_s >= 2 * amount:
        end_s = total - amount
    keep = (arc > start_s) & (arc < end_s)
    ends = point_at(stroke, arc, np.array([start_s, end_s]))
    points = np.vstack([ends[:1], stroke[keep], ends[1:]])
    if choices[0] > 0:
        points = np.vstack([stroke[0] + amount * _end_tangent(stroke, arc, True, amount), points])
    if choices[1] > 0:
        points = np.vstack([points, stroke[-1] + amount * _end_tangent(stroke, arc, False, amount)])
    return points


def jittered_strokes(
    stroke: np.ndarray,
    count: int = 10,
    seed: int = 0,
    tangent_px: float = 10.0,
    *,
    sigma_px: tuple[float, float] = (3.0, 8.0),
    drop_p: float = 0.25,
) -> list[np.ndarray]:
    """Strokes a user might draw over the same part again.

    Each jittered stroke is made from `stroke` by, in order:
      1. each end, independently and with equal chance, shortened by `tangent_px` px of arc
         length, kept, or extended by `tangent_px` px along its tangent (the direction from the
         point `tangent_px` px inside the stroke to the end); an end is not shortened when
         less than `tangent_px` px of stroke would be left;
      2. each interior point dropped with probability `drop_p` (the end points are kept);
      3. Gaussian pixel noise added to every point, with one sigma per stroke drawn uniformly
         in `sigma_px` (3 to 8 px by default).

    Args:
        stroke: (S, 2) pixel coordinates, S >= 2.
        count: number of strokes to make.
        seed: seed of the random generator (the same seed gives the same strokes).
        tangent_px: how far an end is shortened or extended.
        sigma_px: (low, high) range of the noise sigma in px; (0, 0) for no noise.
        drop_p: probability of dropping each interior point.

    Returns:
        A list of `count` (S_i, 2) float64 arrays.
    """
    base = _as_polyline(stroke, 2, "stroke")
    if count < 0:
        raise ValueError(f"count: must be >= 0, got {count}")
    if not (np.isfinite(tangent_px) and tangent_px >= 0):
        raise ValueError(f"tangent_px: must be finite and >= 0, got {tangent_px}")
    low, high = (float(v) for v in sigma_px)
    if not (0 <= low <= high and np.isfinite(high)):
        raise ValueError(f"sigma_px: expected 0 <= low <= high, got {sigma_px}")
    if not 0 <= drop_p <= 1:
        raise ValueError(f"drop_p: must be in [0, 1], got {drop_p}")
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        sigma = rng.uniform(low, high)
        choices = (int(rng.integers(-1, 2)), int(rng.integers(-1, 2)))
        points = _change_ends(base, choices, tangent_px)
        keep = rng.random(len(points)) >= drop_p
        keep[0] = keep[-1] = True
        points = points[keep]
        points = points + rng.normal(0.0, 1.0, size=points.shape) * sigma
        out.append(points)
    return out


def reversed_stroke(stroke: np.ndarray) -> np.ndarray:
    """The same stroke drawn from its other end, as a new (S, 2) float64 array."""
    return _as_polyline(stroke, 2, "stroke")[::-1].copy()


def jaccard(ids_a: Iterable[int] | np.ndarray, ids_b: Iterable[int] | np.ndarray) -> float:
    """|A ∩ B| / |A ∪ B| of two sets of (Gaussian) indices; 1.0 when both are empty."""
    a, b = (np.unique(np.asarray(ids if isinstance(ids, np.ndarray) else list(ids)).ravel()) for ids in (ids_a, ids_b))
    union = np.union1d(a, b).size
    if union == 0:
        return 1.0
    return float(np.intersect1d(a, b).size / union)
