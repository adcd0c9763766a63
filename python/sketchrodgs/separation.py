"""Where a pulled part parts from what it touches (docs/deformation.md, "Separation").

The part's shell, its Gaussians between R and `grow * R` from the axis, is taken so that a
cross-section that is not round goes whole; but where the part touches something (a crossing
branch, the leaves at a stem's base) the shell also takes the pieces of it that lie within reach,
and pulled, the part tore from them along that reach: every pair of close Gaussians split between
what moves and what stays is a tear.

So the shell is trimmed by a minimum cut. On one side everything the rod carries for certain: the
core within R of the axis and the attached parts, continuations and strays. On the other the
Gaussians that stay. Each shell Gaussian goes to the side that splits the fewest pairs closer than
`PAIR_RADII * R` (the pairs the tear fraction counts), each pair counted by the share of the rod's
motion it takes (eased to 0 at a clamped end: a pair split where nothing moves does not tear),
and a shell Gaussian left behind counts `1 / STRAND_SHARE` of a pair: it is a ghost of the part
where the part was. Where the count ties it stays with the part.
On the real pulls (`benches/bench_skin.py`) the tree branch's tears went from 0.48 % to 0.25 %, the
plant side stem's from 0.40 % to 0.28 %, and the plant main stem's from 0.88 % to 0.13 %.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, maximum_flow
from scipy.spatial import cKDTree

from .polyline import near_box
from .segment import Binding

PAIR_RADII = 0.25  # pairs closer than this many R are what a tear splits (deform_metrics.TEAR_PAIR)
CORE_RADII = 1.0  # within this many R of the axis a Gaussian is the part's core and always moves

MOTION_STEPS = 16  # a pair's capacity: its share of the motion in sixteenths
# A shell Gaussian left behind costs a fifth of a split pair. Counting pairs alone, the cut left the
# far face of the guitar stand's legs (269 Gaussians joined to the leg by 3 pairs, touching the body
# by 18) where the legs had been, dark streaks over the body (docs/deformation.md, "Separation").
STRAND_SHARE = 5

SOURCE, SINK = 0, 1  # the graph's two terminal nodes; shell Gaussian k is node 2 + k


def trim_shell(means: np.ndarray, binding: Binding, radius: float, motion: np.ndarray | None = None) -> Binding:
    """`binding` (rows of the scene whose centres are `means`) without the shell Gaussians that the
    minimum cut leaves with the Gaussians that stay (the module docstring). `motion` (one per bound
    Gaussian, default 1): the share of the rod's motion each takes (eased to 0 at clamped ends); a
    pair split where it is small costs that much less."""
    distance = np.linalg.norm(binding.offset, axis=1)  # a part Gaussian is bound at its nearest point
    shell = ~binding.attached & (distance > CORE_RADII * radius)
    if not shell.any():
        return binding
    reach = PAIR_RADII * radius
    shell_rows = binding.gaussian_ids[shell]
    shell_points = means[shell_rows].astype(np.float64)
    # whatever can pair with a shell Gaussian lies in the shell's box grown by a pair's reach
    others = near_box(shell_points, means, reach)
    in_shell = np.zeros(len(means), bool)
    in_shell[shell_rows] = True
    others = others[~in_shell[others]]
    moves = np.zeros(len(means), bool)
    moves[binding.gaussian_ids] = True
    shell_tree = cKDTree(shell_points)
    between = shell_tree.query_pairs(reach, output_type="ndarray")
    touching = shell_tree.sparse_distance_matrix(
        cKDTree(means[others].astype(np.float64)), reach, output_type="ndarray"
    )
    k, other = touching["i"], others[touching["j"]]
    count = len(shell_rows)
    share = np.ones(count) if motion is None else np.asarray(motion, np.float64)[shell]
    cost = np.rint(MOTION_STEPS * share).astype(np.int64)  # a strand's; a pair's is STRAND_SHARE times it
    # per shell Gaussian, its pairs with what surely moves and with what stays: one edge to each
    # terminal; the edge to what moves also holds what leaving the Gaussian behind costs
    to_source = (np.bincount(k[moves[other]], minlength=count) * STRAND_SHARE + 1) * cost
    to_sink = np.bincount(k[~moves[other]], minlength=count) * STRAND_SHARE * cost
    nodes = 2 + np.arange(count)
    heads = np.concatenate([between[:, 0] + 2, np.full(count, SOURCE), nodes])
    tails = np.concatenate([between[:, 1] + 2, nodes, np.full(count, SINK)])
    pair_share = (share[between[:, 0]] + share[between[:, 1]]) / 2
    pair_cost = STRAND_SHARE * np.rint(MOTION_STEPS * pair_share).astype(np.int64)
    weights = np.concatenate([pair_cost, to_source, to_sink])
    used = weights > 0
    heads, tails, weights = heads[used], tails[used], weights[used]
    # a pair splits the same whichever way: an edge each way, as capacities
    capacity = coo_matrix(
        (
            np.concatenate([weights, weights]).astype(np.int32),
            (np.concatenate([heads, tails]), np.concatenate([tails, heads])),
        ),
        shape=(count + 2, count + 2),
    ).tocsr()
    capacity.sum_duplicates()
    flow = maximum_flow(capacity, SOURCE, SINK)
    residual = (capacity - flow.flow).tocsr()
    residual.data = np.maximum(residual.data, 0)
    residual.eliminate_zeros()
    # the shell Gaussians that still reach the stay side through unsaturated pairs go with it:
    # the smallest such side, so that on a tie a Gaussian stays with the part
    reaching = breadth_first_order(residual.T.tocsr(), SINK, directed=True, return_predecessors=False)
    stays = np.zeros(count + 2, bool)
    stays[reaching] = True
    keep = np.ones(len(binding.gaussian_ids), bool)
    keep[np.flatnonzero(shell)[stays[2:]]] = False
    return binding.take(np.flatnonzero(keep))
