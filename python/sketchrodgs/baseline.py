"""The paper's naive baseline: the same path weight (Eq. 1) optimised over a 3D k-nearest-neighbour
graph of Gaussian centres instead of over screen pixels. Kept for comparison (tests, benchmarks).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from .camera import Camera


@dataclass(frozen=True)
class KnnPath:
    """Result of the k-NN baseline.

    Attributes:
        gaussian_ids: (L,) the path from start to goal, or to where it stopped.
        reached_goal: whether the goal Gaussian was reached.
        progress: how far along the stroke (0..1 of its length) the path got.
        seconds: time of graph construction plus search.
    """

    gaussian_ids: np.ndarray
    reached_goal: bool
    progress: float
    seconds: float


def stroke_distance(points_px: np.ndarray, stroke: np.ndarray, chunk: int = 65536) -> tuple[np.ndarray, np.ndarray]:
    """Distance (pixels) of each point to the stroke polyline and the arc-length fraction of its
    nearest stroke point. points_px (P, 2), stroke (S, 2)."""
    a, b = stroke[:-1].astype(np.float64), stroke[1:].astype(np.float64)
    ab = b - a
    seg_len = np.linalg.norm(ab, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg_len)])
    total = max(arc[-1], 1e-12)
    dist = np.empty(len(points_px))
    frac = np.empty(len(points_px))
    for s in range(0, len(points_px), chunk):
        p = points_px[s : s + chunk, None, :] - a[None]
        t = np.clip((p * ab[None]).sum(axis=2) / np.maximum(seg_len**2, 1e-12)[None], 0, 1)
        d2 = ((p - t[..., None] * ab[None]) ** 2).sum(axis=2)
        best = np.nan_to_num(d2, nan=np.inf).argmin(axis=1)
        rows = np.arange(len(p))
        dist[s : s + chunk] = np.sqrt(d2[rows, best])
        frac[s : s + chunk] = (arc[best] + t[rows, best] * seg_len[best]) / total
    return dist, frac


def knn_path(
    means: np.ndarray, camera: Camera, stroke: np.ndarray, start: int, goal: int, alpha: float = 1.0, k: int = 8
) -> KnnPath:
    """Shortest path from Gaussian `start` to `goal` over the k-NN graph with the paper's weight
    `|c_a - c_b| + alpha * D_s(b)^2` (D_s in pixels / (width / 2))."""
    clock = time.perf_counter()
    means = np.asarray(means, np.float64)
    uv, depth = camera.project(means)
    dist_px, frac = stroke_distance(np.nan_to_num(uv, nan=-1e9), np.asarray(stroke))
    deviation = np.where(depth > 0, dist_px / (camera.width / 2), np.inf)
    _, neighbours = cKDTree(means).query(means, k=k + 1)
    rows = np.repeat(np.arange(len(means)), k)
    cols = neighbours[:, 1:].ravel()
    weights = np.linalg.norm(means[rows] - means[cols], axis=1) + alpha * deviation[cols] ** 2
    finite = np.isfinite(weights)
    graph = csr_matrix((weights[finite] + 1e-12, (rows[finite], cols[finite])), shape=(len(means), len(means)))
    cost, previous = dijkstra(graph, directed=True, indices=start, return_predecessors=True)
    reached = np.isfinite(cost[goal])
    if reached:
        end = goal
    else:
        reachable = np.flatnonzero(np.isfinite(cost))
        end = int(reachable[np.argmax(frac[reachable])])
    path = [end]
    while previous[path[-1]] >= 0:
        path.append(int(previous[path[-1]]))
    ids = np.array(path[::-1], dtype=np.int64)
    return KnnPath(ids, bool(reached), float(frac[end]), time.perf_counter() - clock)
