"""Subdivision of needle Gaussians before skinning (docs/deformation.md, "Subdivision").

A Gaussian that reaches along the rod over more than one edge is moved rigidly by one binding
point, so at a bend it stays straight and sticks out (the paper names this its limitation). We
split such a Gaussian, once, at binding time, along its major axis into `k` pieces that each stay
within about one edge. The pieces keep the parent's rotation, colour and minor scales; their
spacing, major scale and opacities are fitted so that the pieces composite (front to back, as
the rasteriser does) to the parent's opacity profile, on the centre line and off it.

Rows: the parent keeps its row and becomes piece 0; the other pieces are appended after the
scene's rows. `source[i]` is the input row that row `i` came from.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .scene import GaussianScene

MAX_PIECES = 32
# A piece's standard deviation along the split axis is at most PIECE_STD / k of the parent's. The
# pieces must overlap to composite without ripple: the fit spaces them 1.8 of that deviation apart,
# and their composite dips between two pieces by at most 5 % of the parent's opacity (13 % for
# opaque ones; at 1.5 / k: 2.4 apart and 14-28 %, seen as bands across split needles;
# docs/deformation.md, "Subdivision", Why two pieces an edge).
PIECE_STD = 3.0
# A Gaussian is split into ceil(PIECES_PER_EDGE x its 3-sigma length along the rod / edge length)
# pieces, each then at most PIECE_STD / PIECES_PER_EDGE = 1.5 edges long (3-sigma), so that it
# follows a bend; one no longer than that (SPLIT_FROM edges) stays whole.
PIECES_PER_EDGE = 2.0
SPLIT_FROM = PIECE_STD / PIECES_PER_EDGE
# Fewer pieces at PIECE_STD / k would be no shorter than the parent (3: one piece and two empty).
MIN_PIECES = 4
_OPACITY_GRID = np.array([0.02, 0.1, 0.25, 0.4, 0.55, 0.7, 0.85, 0.95, 1.0])
# The fit's samples: along the axis in parent sigmas, and the factor of the cross-profile.
_ALONG = np.linspace(-4.5, 4.5, 121)
_ACROSS = np.array([0.1, 0.3, 0.5, 0.7, 0.85, 1.0])


def _composite(spacing: float, std: float, opacities: np.ndarray) -> np.ndarray:
    """Alpha of `len(opacities)` pieces composited, over (_ACROSS, _ALONG)."""
    centres = (np.arange(len(opacities)) - (len(opacities) - 1) / 2) * spacing
    alpha = opacities[:, None] * np.exp(-0.5 * ((_ALONG[None, :] - centres[:, None]) / std) ** 2)
    return 1 - np.prod(1 - alpha[None] * _ACROSS[:, None, None], axis=1)


# The fitted tables for 2..MAX_PIECES pieces, shipped with the package (fitting them all takes
# seconds); `python -m sketchrodgs.subdivide` writes it again.
TABLE_FILE = Path(__file__).parent / "data" / "piece_table.json"


@lru_cache(maxsize=1)
def _shipped() -> dict[str, dict[str, list]]:
    return json.loads(TABLE_FILE.read_text(encoding="utf-8"))


def piece_table(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For `k` pieces, per parent opacity on `_OPACITY_GRID`: the pieces' spacing and standard
    deviation (in parent sigmas, along the split axis) and their opacities (O, k)."""
    entry = _shipped()[str(k)]
    return np.array(entry["spacing"]), np.array(entry["std"]), np.array(entry["opacity"])


def fit_piece_table(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit `piece_table(k)`: least squares of the composited pieces against the parent's
    opacity profile, over `_ALONG` x `_ACROSS`, the pieces symmetric about the parent's centre."""
    half = (k + 1) // 2
    spacing, std, opacity = [], [], []
    target = np.exp(-0.5 * _ALONG**2)[None] * _ACROSS[:, None]
    x = None
    upper_std = np.log(PIECE_STD / k)
    for o in _OPACITY_GRID:
        if x is None:  # start: pieces spread over +-2 sigma, opacities from the profile
            start = (np.arange(half) - (k - 1) / 2) * (4.0 / k)
            p = np.clip(o * np.exp(-0.5 * start**2), 1e-3, 0.98)
            x = np.r_[np.log(4.0 / k), upper_std - 0.2, np.log(p / (1 - p))]

        def unpack(x: np.ndarray) -> tuple[float, float, np.ndarray]:
            side = 1 / (1 + np.exp(-x[2:]))
            return float(np.exp(x[0])), float(np.exp(x[1])), np.r_[side, side[: k // 2][::-1]]

        def residual(x: np.ndarray, o: float = float(o)) -> np.ndarray:
            return (_composite(*unpack(x)) - o * target).ravel()

        lower, upper = np.r_[-5.0, -6.0, -12 * np.ones(half)], np.r_[2.0, upper_std, 12 * np.ones(half)]
        x = least_squares(residual, np.clip(x, lower + 1e-6, upper - 1e-6), bounds=(lower, upper)).x
        d, s, piece = unpack(x)
        spacing.append(d)
        std.append(s)
        opacity.append(piece)
    return np.array(spacing), np.array(std), np.array(opacity)


def piece_counts(
    scene: GaussianScene,
    rows: np.ndarray,
    tangents: np.ndarray,
    edge_length: float,
    split_from: float | np.ndarray = SPLIT_FROM,
) -> np.ndarray:
    """How many pieces each of `rows` is split into (1: not split).

    A Gaussian is split when its 3-sigma length along the rod (`tangents`, (G, 3) unit, at each
    row's binding point) exceeds `split_from` edge lengths (per row, or one for all) and most of
    that length comes from its major axis (splitting along the major axis shortens it then), into
    PIECES_PER_EDGE pieces per edge of that length, at least MIN_PIECES."""
    scales = scene.scales[rows].astype(np.float64)
    axes = Rotation.from_quat(scene.quats[rows][:, [1, 2, 3, 0]].astype(np.float64)).as_matrix()
    local = np.einsum("gji,gj->gi", axes, tangents)  # the tangent in each Gaussian's own axes
    along_var = np.sum((local * scales) ** 2, axis=1)
    major = np.argmax(scales, axis=1)
    from_major = (local[np.arange(len(rows)), major] * scales[np.arange(len(rows)), major]) ** 2
    length = 6 * np.sqrt(along_var)
    counts = np.clip(np.ceil(PIECES_PER_EDGE * length / edge_length), MIN_PIECES, MAX_PIECES).astype(np.int64)
    counts[(length <= np.asarray(split_from) * edge_length) | (from_major < 0.5 * along_var)] = 1
    return counts


def split(scene: GaussianScene, rows: np.ndarray, counts: np.ndarray) -> tuple[GaussianScene, np.ndarray, np.ndarray]:
    """Split each of `rows` into `counts` pieces along its major axis.

    Returns:
        the new scene (the input's rows, then the extra pieces; it shares the input's SH table,
        each row taking its input row's coefficients (`sh_rows`), and each piece sorts at its
        parent's centre (`sort_offsets`)), `source` (N',) int64 input row of each new row, and
        `piece_rows` (P,) int64 the new rows that are pieces of split Gaussians (the parents' own
        rows included).
    """
    n = len(scene)
    counts = np.asarray(counts, np.int64)
    split_rows = np.asarray(rows, np.int64)[counts > 1]
    counts = counts[counts > 1]
    means, scales = scene.means.copy(), scene.scales.copy()
    opacities = scene.opacities.copy()
    # each piece sorts where its parent's centre is: at rest the pieces composite in the parent's
    # place among the other Gaussians (docs/rendering.md, "Sort points")
    offsets = np.zeros((n, 3), np.float32) if scene.sort_offsets is None else scene.sort_offsets.copy()
    extra_means, extra_scales, extra_opacity, extra_source, extra_offsets = [], [], [], [], []
    for k in np.unique(counts):
        parents = split_rows[counts == k]
        spacing, std, piece_opacity = piece_table(int(k))
        o = scene.opacities[parents].astype(np.float64)
        d = np.interp(o, _OPACITY_GRID, spacing)
        s = np.interp(o, _OPACITY_GRID, std)
        # interpolate the pieces' opacity relative to the parent's (constant where opacities are low)
        op = o[:, None] * np.stack(
            [np.interp(o, _OPACITY_GRID, piece_opacity[:, i] / _OPACITY_GRID) for i in range(k)], axis=1
        )
        op = np.minimum(op, 1.0)
        parent_scales = scene.scales[parents].astype(np.float64)
        major = np.argmax(parent_scales, axis=1)
        sigma = parent_scales[np.arange(len(parents)), major]
        axes = Rotation.from_quat(scene.quats[parents][:, [1, 2, 3, 0]].astype(np.float64)).as_matrix()
        direction = axes[np.arange(len(parents)), :, major]
        new_scales = parent_scales.copy()
        new_scales[np.arange(len(parents)), major] = s * sigma
        for i in range(k):
            shift = (i - (k - 1) / 2) * d * sigma  # along the major axis, from the parent's centre
            centre = scene.means[parents] + shift[:, None] * direction
            to_parent = offsets[parents].astype(np.float64)
            to_parent[np.arange(len(parents)), major] -= shift
            if i == 0:
                means[parents], scales[parents], opacities[parents] = centre, new_scales, op[:, 0]
                first_offsets = to_parent
            else:
                extra_means.append(centre)
                extra_scales.append(new_scales)
                extra_opacity.append(op[:, i])
                extra_source.append(parents)
                extra_offsets.append(to_parent)
        offsets[parents] = first_offsets
    source = np.concatenate([np.arange(n, dtype=np.int64)] + [np.asarray(s, np.int64) for s in extra_source])
    if len(source) == n:
        return scene, source, np.zeros(0, np.int64)
    new = GaussianScene(
        np.concatenate([means] + extra_means).astype(np.float32),
        np.concatenate([scales] + extra_scales).astype(np.float32),
        scene.quats[source],
        np.concatenate([opacities] + extra_opacity).astype(np.float32),
        scene.sh,  # shared: each piece takes its parent's row, not a copy of every row
        np.concatenate([offsets] + extra_offsets).astype(np.float32),
        source if scene.sh_rows is None else scene.sh_rows[source],
    )
    piece_rows = np.concatenate([split_rows, np.arange(n, len(source), dtype=np.int64)])
    return new, source, piece_rows


if __name__ == "__main__":
    tables = {}
    for k in range(2, MAX_PIECES + 1):
        spacing, std, opacity = fit_piece_table(k)
        tables[str(k)] = {
            "spacing": spacing.round(6).tolist(),
            "std": std.round(6).tolist(),
            "opacity": opacity.round(6).tolist(),
        }
    TABLE_FILE.write_text(json.dumps({"opacity_grid": _OPACITY_GRID.tolist(), **tables}) + "\n", encoding="utf-8")
    print(f"wrote {TABLE_FILE}")
