"""How cleanly a deformed scene follows its rods (issue: pulled real objects deform cleanly):
needles that stick out of a bend, neighbours that tear apart, and pieces left behind where the
part was, each comparing a scene at rest with the same scene deformed, row for row, in units of
the rod's radius R; and a ground truth, a synthetic tube bent into an arc by the exact continuum
map, rendered against our skinning.

Used by `tests/test_deform.py` (asserted) and `benches/bench_skin.py` (printed).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from . import synthetic
from .camera import Camera
from .extract import extract_rod
from .render import render
from .rig import Rig
from .rod import Rod
from .scene import GaussianScene

MOVED = 0.05  # a Gaussian "moved" when its centre moved more than this many R
NEEDLE = 0.5  # a tip sticking out by more than this many R is a needle
TEAR_PAIR = 0.25  # neighbours at rest: centres within this many R
TEAR = 0.5  # a pair tears when their displacements differ by more than this many R
LEFT_NEAR = 2.0  # left behind: within this many R of the rest axis,
LEFT_AXIS_MOVED = 2.0  # where the axis moved more than this many R,
LEFT_SHARE = 0.25  # moving less than this share of the axis's motion there


def _moved(rest: GaussianScene, deformed: GaussianScene, radius: float) -> np.ndarray:
    return np.linalg.norm(deformed.means.astype(np.float64) - rest.means, axis=1) > MOVED * radius


def _reach(scene: GaussianScene, rows: np.ndarray, axes: list[np.ndarray]) -> np.ndarray:
    """(G,) how far the rows' Gaussians reach from the nearest of `axes`: the largest distance of
    their six 3-sigma tips (both ends of each own axis). All three axes count, not only the
    longest: a flat disk's two long axes are equal, and a stretch turns which one is the longest,
    which would swing a "major" tip by a right angle where nothing changed (docs/deformation.md,
    "How it is measured")."""
    scales = scene.scales[rows].astype(np.float64)
    frames = Rotation.from_quat(scene.quats[rows][:, [1, 2, 3, 0]].astype(np.float64)).as_matrix()
    centre = scene.means[rows].astype(np.float64)
    directions = [frames[:, :, axis] * (3 * scales[:, axis])[:, None] for axis in range(3)]
    tips = np.concatenate([centre + sign * direction for direction in directions for sign in (1, -1)])
    distance = np.min([_distance_to_polyline(tips, polyline) for polyline in axes], axis=0)
    return distance.reshape(6, len(rows)).max(axis=0)


def _distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest point of a polyline (dense resampling, exact enough
    at the R/8 spacing used here)."""
    polyline = np.asarray(polyline, np.float64)
    steps = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    length = steps.sum()
    spacing = max(length / 4000, 1e-12)
    dense = [polyline[:1]]
    for a, b, step in zip(polyline[:-1], polyline[1:], steps):
        count = max(1, int(np.ceil(step / spacing)))
        dense.append(a + np.linspace(0, 1, count + 1)[1:, None] * (b - a))
    return cKDTree(np.concatenate(dense)).query(points)[0]


def needle_fraction(
    rest: GaussianScene,
    deformed: GaussianScene,
    rest_axes: list[np.ndarray],
    deformed_axes: list[np.ndarray],
    radius: float,
    rows: np.ndarray | None = None,
) -> float:
    """Among the Gaussians that moved more than 0.05 R, the opacity-weighted fraction that reach
    further from the deformed axes than they did from the rest axes, by more than 0.5 R (the reach:
    the farthest of a Gaussian's 3-sigma tips along its own axes).

    Args:
        rest, deformed: the same scene (same rows) at rest and deformed.
        rest_axes, deformed_axes: each rod's polyline at rest and now, in the same order.
        radius: R, the unit.
        rows: only these rows count (default: all). Attached parts (a leaf riding rigidly on its
            stem) are left out by the callers here: they are meant to keep their shape, not to
            follow the axis, so their tips do move away from a bent axis.
    """
    moved = _moved(rest, deformed, radius)
    if rows is not None:
        keep = np.zeros(len(moved), bool)
        keep[rows] = True
        moved &= keep
    rows = np.flatnonzero(moved)
    if len(rows) == 0:
        return 0.0
    out = _reach(deformed, rows, deformed_axes) - _reach(rest, rows, rest_axes) > NEEDLE * radius
    weight = rest.opacities[rows].astype(np.float64)
    return float(weight[out].sum() / max(weight.sum(), 1e-300))


def tear_fraction(rest: GaussianScene, deformed: GaussianScene, radius: float) -> float:
    """Among pairs of Gaussians within 0.25 R of each other at rest, with at least one moved more
    than 0.05 R, the fraction whose displacements differ by more than 0.5 R."""
    moved = _moved(rest, deformed, radius)
    if not moved.any():
        return 0.0
    displacement = deformed.means.astype(np.float64) - rest.means
    # only pairs near something that moved can count: search around the moved rows
    near = np.flatnonzero(moved)
    tree = cKDTree(rest.means.astype(np.float64))
    partners = tree.query_ball_point(rest.means[near].astype(np.float64), TEAR_PAIR * radius)
    first = np.repeat(near, [len(p) for p in partners])
    second = np.concatenate([np.asarray(p, np.int64) for p in partners]) if len(partners) else np.zeros(0, np.int64)
    # each unordered pair once: keep (i, j) with i < j, or with j not moved (seen only from i)
    keep = (first != second) & ((first < second) | ~moved[second])
    first, second = first[keep], second[keep]
    if len(first) == 0:
        return 0.0
    torn = np.linalg.norm(displacement[first] - displacement[second], axis=1) > TEAR * radius
    return float(torn.mean())


def left_behind_fraction(
    rest: GaussianScene, deformed: GaussianScene, rest_axis: np.ndarray, deformed_axis: np.ndarray, radius: float
) -> float:
    """Among the Gaussians within 2 R of the rest axis where the axis moved more than 2 R, the
    opacity-weighted fraction that moved less than a quarter as far as the axis there: what stays
    where the part was, a ghost of it (a tear inside the part's reach, which the tear fraction does
    not see where the piece left is joined to the part by few close pairs).

    `rest_axis` and `deformed_axis` are one rod's polyline at rest and now, vertex for vertex."""
    rest_axis, deformed_axis = np.asarray(rest_axis, np.float64), np.asarray(deformed_axis, np.float64)
    # both axes resampled alike, 16 points per segment, so that a point's motion is the axis's there
    t = np.linspace(0.0, len(rest_axis) - 1.0, 16 * (len(rest_axis) - 1) + 1)
    segment = np.minimum(t.astype(np.int64), len(rest_axis) - 2)
    along = (t - segment)[:, None]
    dense_rest = rest_axis[segment] * (1 - along) + rest_axis[segment + 1] * along
    dense_now = deformed_axis[segment] * (1 - along) + deformed_axis[segment + 1] * along
    means = rest.means.astype(np.float64)
    distance, nearest = cKDTree(dense_rest).query(means, distance_upper_bound=LEFT_NEAR * radius)
    near = np.flatnonzero(np.isfinite(distance))
    axis_motion = np.linalg.norm(dense_now[nearest[near]] - dense_rest[nearest[near]], axis=1)
    moved = axis_motion > LEFT_AXIS_MOVED * radius
    near, axis_motion = near[moved], axis_motion[moved]
    if len(near) == 0:
        return 0.0
    motion = np.linalg.norm(deformed.means[near].astype(np.float64) - means[near], axis=1)
    weight = rest.opacities[near].astype(np.float64)
    left = motion < LEFT_SHARE * axis_motion
    return float(weight[left].sum() / max(weight.sum(), 1e-300))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two images in [0, 1]."""
    error = np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2)
    return float(10 * np.log10(1.0 / max(error, 1e-20)))


def arc_bend(angle: float = np.pi / 2, seed: int = 3, subdivide: bool = True) -> dict[str, float]:
    """Bend a synthetic tube (R = 0.01, 1 long, along x) into an arc of `angle` two ways and
    compare their renders at 960x540: by the exact continuum map (`synthetic.bend_into_arc`,
    every Gaussian moved and its covariance carried by the map's Jacobian), and by our pipeline
    (extract the rod from a stroke, clamp its start where the map fixes it, put its vertices on
    the arc, skin).

    Returns: psnr (dB), gaussians (bound, after splitting), vertices.
    """
    tubes = synthetic.tube_scene([synthetic.straight], radius=0.01, clutter=0, seed=seed)
    scene = tubes.scene.replace(means=tubes.scene.means - np.array([0.0, 0.05, 0.0], np.float32))  # axis on y = 0
    straight_view = Camera.look_at((0, 0, -1.5), (0, 0, 0), up=(0, -1, 0), width=960, height=540, fov_y_deg=40)
    uv, _ = straight_view.project(tubes.axes[0] - [0.0, 0.05, 0.0])
    extraction = extract_rod(scene, straight_view, uv[np.r_[0 : len(uv) : 40, len(uv) - 1]], radius=0.01)
    polyline = extraction.polyline.astype(np.float64)
    start, end = float(polyline[0, 0]), float(polyline[-1, 0])
    # the map's band is the rod's extent; what lies past the rod's ends is left out of both
    inside = (scene.means[:, 0] >= start - 0.01) & (scene.means[:, 0] <= end + 0.01)
    scene = scene.subset(np.flatnonzero(inside))
    extraction = extract_rod(scene, straight_view, uv[np.r_[0 : len(uv) : 40, len(uv) - 1]], radius=0.01)
    polyline = extraction.polyline.astype(np.float64)
    start, length = float(polyline[0, 0]), float(polyline[-1, 0] - polyline[0, 0])

    rod = Rod(polyline, radius=extraction.radius)
    rod.clamp(0)
    rig = Rig.build(scene, [extraction], [rod], subdivide=subdivide)
    rod.set_positions(synthetic.bend_into_arc(polyline, start, length, angle)[0])
    ours = rig.skinned([rod])
    exact = synthetic.deform_exactly(scene, *synthetic.bend_into_arc(scene.means, start, length, angle))

    arc = synthetic.bend_into_arc(polyline, start, length, angle)[0]
    centre = 0.5 * (arc.min(axis=0) + arc.max(axis=0))
    camera = Camera.look_at(
        centre + [0.0, 0.0, -1.6 * float(np.ptp(arc, axis=0).max())],
        centre,
        up=(0, -1, 0),
        width=960,
        height=540,
        fov_y_deg=40,
    )
    return {
        "psnr": psnr(render(exact, camera).rgb_image, render(ours, camera).rgb_image),
        "gaussians": float(len(rig.bound[0].gaussian_ids)),
        "vertices": float(rod.num_vertices),
    }
