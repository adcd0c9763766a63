"""Synthetic scenes with a known centre line, for tests, benchmarks and trying the pipeline out.

A tube is covered with the kind of Gaussians real captures have on thin objects: elongated,
randomly oriented and partly transparent, with their centres scattered slightly around the
surface. Clutter (unrelated Gaussians) can be added away from the tubes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .camera import Camera
from .polyline import arc_lengths
from .scene import GaussianScene

Curve = Callable[[np.ndarray], np.ndarray]  # (S,) parameters in [0, 1] -> (S, 3) points


@dataclass(frozen=True, eq=False)
class TubeScene:
    """A scene and the truth about it.

    Attributes:
        scene: the Gaussians (tubes first, in `tubes` order, then clutter).
        axes: one (S, 3) densely sampled centre line per tube.
        radius: tube radius R.
        labels: (N,) int32 tube index per Gaussian, -1 for clutter.
    """

    scene: GaussianScene
    axes: list[np.ndarray]
    radius: float
    labels: np.ndarray


def sample_curve(curve: Curve, samples: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Points of `curve` at `samples` parameters and their cumulative arc length."""
    points = curve(np.linspace(0.0, 1.0, samples))
    arc = arc_lengths(points)
    return points, arc


def tube_gaussians(
    curve: Curve,
    radius: float,
    rng: np.random.Generator,
    density: float = 8000.0,
    color: tuple[float, float, float] = (0.8, 0.5, 0.2),
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Gaussians on the surface of the tube of `radius` around `curve` (density per unit length
    at R = 0.01, scaled with the surface area). Returns the arrays and the dense axis."""
    axis, arc = sample_curve(curve)
    count = max(50, int(density * arc[-1] * radius / 0.01))
    s = rng.uniform(0.0, arc[-1], count)
    # locate on the dense axis by arc length, with a tangent frame there
    idx = np.clip(np.searchsorted(arc, s), 1, len(arc) - 1)
    f = ((s - arc[idx - 1]) / np.maximum(arc[idx] - arc[idx - 1], 1e-12))[:, None]
    centre = axis[idx - 1] + f * (axis[idx] - axis[idx - 1])
    tangent = axis[idx] - axis[idx - 1]
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    helper = np.where(np.abs(tangent[:, [2]]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    n1 = np.cross(tangent, helper)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(tangent, n1)
    theta = rng.uniform(0, 2 * np.pi, count)[:, None]
    radial = radius * rng.normal(1.0, 0.08, count)[:, None]
    means = centre + radial * (np.cos(theta) * n1 + np.sin(theta) * n2)
    scales = radius * np.stack(
        [rng.uniform(0.15, 0.6, count), rng.uniform(0.08, 0.3, count), rng.uniform(0.03, 0.1, count)], axis=1
    )
    quats = rng.normal(size=(count, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    colors = np.clip(np.asarray(color) + rng.normal(0, 0.05, (count, 3)), 0, 1)
    arrays = {
        "means": means,
        "scales": scales,
        "quats": quats,
        "opacities": rng.uniform(0.35, 1.0, count),
        "colors": colors,
    }
    return arrays, axis


def clutter_gaussians(
    count: int,
    low: np.ndarray,
    high: np.ndarray,
    keep_away: list[np.ndarray],
    distance: float,
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    """`count` blobs in the box [low, high], none within `distance` of the given axes."""
    from scipy.spatial import cKDTree

    means = rng.uniform(low, high, (count * 2, 3))
    if keep_away:
        d, _ = cKDTree(np.concatenate(keep_away)).query(means)
        means = means[d > distance]
    means = means[:count]
    n = len(means)
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    return {
        "means": means,
        "scales": np.exp(rng.uniform(np.log(0.004), np.log(0.03), (n, 3))),
        "quats": quats,
        "opacities": rng.uniform(0.2, 0.9, n),
        "colors": rng.uniform(0.1, 0.9, (n, 3)),
    }


def tube_scene(
    curves: list[Curve], radius: float = 0.01, *, clutter: int = 3000, seed: int = 0, radii: list[float] | None = None
) -> TubeScene:
    """Tubes around `curves` (radius per tube from `radii`, else `radius`) plus clutter."""
    rng = np.random.default_rng(seed)
    parts, axes, labels = [], [], []
    palette = [(0.85, 0.55, 0.2), (0.3, 0.6, 0.9), (0.4, 0.8, 0.4)]
    for i, curve in enumerate(curves):
        r = radii[i] if radii else radius
        arrays, axis = tube_gaussians(curve, r, rng, color=palette[i % len(palette)])
        parts.append(arrays)
        axes.append(axis)
        labels.append(np.full(len(arrays["means"]), i, np.int32))
    if clutter:
        everything = np.concatenate(axes)
        low, high = everything.min(axis=0) - 0.3, everything.max(axis=0) + 0.3
        low[2] = everything[:, 2].max() + 0.15  # clutter behind the tubes (camera looks along +z)
        high[2] = low[2] + 0.5
        arrays = clutter_gaussians(clutter, low, high, axes, 4 * radius, rng)
        parts.append(arrays)
        labels.append(np.full(len(arrays["means"]), -1, np.int32))
    merged = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    scene = GaussianScene.from_colors(
        merged["means"], merged["scales"], merged["quats"], merged["opacities"], merged["colors"]
    )
    return TubeScene(scene, axes, radius, np.concatenate(labels))


def rope_on_floor_scene(
    radius: float = 0.01,
    *,
    seed: int = 0,
    floor_count: int = 60_000,
    floor_scatter: float = 0.0,
    floor_colour_spread: float = 0.05,
) -> TubeScene:
    """A rope lying on a floor: a gently winding tube along x in the plane y = 0 (its axis `radius`
    above the floor, so it touches it), on a grey floor of flat Gaussians at y = `radius`
    (+y is down), their heights scattered by `floor_scatter` radii and their colours by
    `floor_colour_spread` (standard deviations). The floor's Gaussians are labelled -1. What lies
    under a part at its own depth (a cable on a table, a sprinkle on icing) shows no depth edge
    beside the part."""
    rng = np.random.default_rng(seed)
    arrays, axis = tube_gaussians(
        lambda u: np.stack([-0.25 + 0.5 * u, np.zeros_like(u), 0.03 * np.sin(6 * u)], axis=1), radius, rng
    )
    n = floor_count
    floor = {
        "means": np.stack([rng.uniform(-0.4, 0.4, n), np.full(n, radius), rng.uniform(-0.3, 0.3, n)], axis=1),
        "scales": np.stack([rng.uniform(0.3, 0.8, n), np.full(n, 0.05), rng.uniform(0.3, 0.8, n)], axis=1) * radius,
        "quats": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        "opacities": np.full(n, 0.9),
        "colors": np.clip(np.array([0.5, 0.45, 0.4]) + rng.normal(0, floor_colour_spread, (n, 3)), 0, 1),
    }
    if floor_scatter:  # drawn last, so that the flat floor's draws are the same with or without it
        floor["means"][:, 1] += rng.normal(0, floor_scatter * radius, n)
    merged = {k: np.concatenate([arrays[k], floor[k]]) for k in arrays}
    scene = GaussianScene.from_colors(
        merged["means"], merged["scales"], merged["quats"], merged["opacities"], merged["colors"]
    )
    labels = np.concatenate([np.zeros(len(arrays["means"]), np.int32), np.full(n, -1, np.int32)])
    return TubeScene(scene, [axis], radius, labels)


def floor_camera(tilt_deg: float) -> Camera:
    """A 960x540 camera looking down at `rope_on_floor_scene`'s rope, `tilt_deg` above the floor's
    plane."""
    t = np.radians(tilt_deg)
    eye = (0.0, -0.6 * np.sin(t), -0.6 * np.cos(t))
    return Camera.look_at(eye, (0, 0, 0), up=(0, -1, 0), width=960, height=540, fov_y_deg=50)


def floor_stroke(axis: np.ndarray, camera: Camera) -> np.ndarray:
    """A stroke along the rope's `axis` seen by `camera`: every 100th axis sample projected, with
    2 px of hand noise."""
    uv, _ = camera.project(axis[::100])
    return uv + np.random.default_rng(0).normal(0, 2.0, uv.shape)


# -- curves used by the tests and benchmarks (parameters in [0, 1]) -----------------------------


def straight(u: np.ndarray) -> np.ndarray:
    return np.stack([u - 0.5, 0.05 * np.ones_like(u), np.zeros_like(u)], axis=1)


def curved(u: np.ndarray) -> np.ndarray:
    return np.stack([0.9 * (u - 0.5), 0.15 * np.sin(2 * np.pi * u), 0.08 * np.cos(np.pi * u)], axis=1)


def pole(u: np.ndarray) -> np.ndarray:
    """A vertical pole in front of the middle of `straight` (closer to a camera on -z)."""
    return np.stack([np.zeros_like(u), 0.3 * (u - 0.5) * 2, -0.12 * np.ones_like(u)], axis=1)


def loop(u: np.ndarray) -> np.ndarray:
    """A prolate cycloid: its projection along z crosses itself once; the strands are 0.14 apart in z."""
    v = (u - 0.5) * 2 * np.pi
    return np.stack([0.1 * v - 0.25 * np.sin(v), 0.25 * np.cos(v) - 0.05, 0.08 * np.sin(v / 2)], axis=1)


# -- an exact deformation, the ground truth for skinning -----------------------------------------


def bend_into_arc(points: np.ndarray, start: float, length: float, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The continuum map that bends the straight band `start <= x <= start + length` (axis along x
    at y = 0) into a circular arc of `angle` radians turning towards +y, fixed at x = start; beyond
    the band the material moves rigidly with its end (x < start does not move).

    Args:
        points: (N, 3) points at rest.

    Returns:
        (N, 3) mapped points and (N, 3, 3) the map's Jacobian at each point (rotation about z by the
        local angle times a stretch of 1 - kappa y along the axis).
    """
    p = np.asarray(points, np.float64)
    kappa = angle / length
    s = np.clip(p[:, 0] - start, 0.0, length)
    beyond = p[:, 0] - start - s  # past either end, along x
    phi = kappa * s
    rho = 1.0 / kappa - p[:, 1]
    out = np.empty_like(p)
    out[:, 0] = start + rho * np.sin(phi) + beyond * np.cos(phi)
    out[:, 1] = 1.0 / kappa - rho * np.cos(phi) + beyond * np.sin(phi)
    out[:, 2] = p[:, 2]
    inside = (p[:, 0] >= start) & (p[:, 0] <= start + length)
    along = np.where(inside, 1.0 - kappa * p[:, 1], 1.0)
    c, sn = np.cos(phi), np.sin(phi)
    jacobian = np.zeros((len(p), 3, 3))
    jacobian[:, 0, 0], jacobian[:, 1, 0] = c * along, sn * along
    jacobian[:, 0, 1], jacobian[:, 1, 1] = -sn, c
    jacobian[:, 2, 2] = 1.0
    return out, jacobian


def deform_exactly(scene: GaussianScene, mapped: np.ndarray, jacobian: np.ndarray) -> GaussianScene:
    """`scene` with each Gaussian moved to `mapped` and its covariance carried by `jacobian`
    (J Sigma J^T, diagonalised again into a rotation and scales)."""
    axes = Rotation.from_quat(scene.quats[:, [1, 2, 3, 0]].astype(np.float64)).as_matrix()
    scales = scene.scales.astype(np.float64)
    covariance = (
        jacobian @ axes @ (scales[:, :, None] ** 2 * np.transpose(axes, (0, 2, 1))) @ np.transpose(jacobian, (0, 2, 1))
    )
    values, vectors = np.linalg.eigh(covariance)
    vectors[np.linalg.det(vectors) < 0, :, 0] *= -1  # a proper rotation
    quats = Rotation.from_matrix(vectors).as_quat()[:, [3, 0, 1, 2]]
    return scene.replace(
        means=mapped.astype(np.float32),
        scales=np.sqrt(np.maximum(values, 1e-20)).astype(np.float32),
        quats=quats.astype(np.float32),
    )
