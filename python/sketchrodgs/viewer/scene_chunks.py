"""The Gaussians drawn at rest (those of no rod) as spatial chunks, one splat node each.

A rod takes its Gaussians out of what is drawn at rest. With the whole scene in one node, adding
or removing a rod sent all of it to every browser again: 32 MB at 1M Gaussians. Here the scene is
sent once, cut into chunks of Gaussians that lie together (the leaves of a k-d tree: median cuts
across the widest extent), and a change sends only the chunks holding a row that changed, which
costs 0.2-0.9x the rod's own Gaussians on top of them (benches/bench_viewer.py).

viser merges every splat node into one buffer and keeps one pose per node in a texture one texel
row high and three texels a node wide, so a browser can draw at most a third of its largest
texture size in nodes (2730 at 8192, software WebGL's and most GPUs' size). MAX_CHUNKS leaves
room for the rods' segment nodes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import viser

from .splats import SplatArrays

CHUNK_SIZE = 256  # Gaussians a chunk aims at; fewer, larger chunks above MAX_CHUNKS * CHUNK_SIZE
MAX_CHUNKS = 1536


def spatial_chunks(points: np.ndarray, count: int) -> list[np.ndarray]:
    """(N, 3) points -> `count` arrays of row indices, each a box of the space (k-d tree leaves,
    sizes within one of each other)."""
    points = np.asarray(points, np.float32)
    leaves: list[np.ndarray] = []
    stack = [(np.arange(len(points), dtype=np.int64), max(1, count))]
    while stack:
        rows, k = stack.pop()
        if k == 1 or len(rows) <= 1:
            leaves.append(rows)
            continue
        p = points[rows]
        axis = int(np.argmax(p.max(axis=0) - p.min(axis=0)))
        left = k // 2
        cut = len(rows) * left // k
        order = np.argpartition(p[:, axis], cut)
        stack += [(rows[order[:cut]], left), (rows[order[cut:]], k - left)]
    return leaves


def chunk_count(n: int) -> int:
    return min(MAX_CHUNKS, max(1, math.ceil(n / CHUNK_SIZE)))


class SceneChunks:
    """The chunk nodes of the Gaussians drawn at rest.

    Every row of the scene has a home chunk (rows appended later, the pieces of split needles, get
    new chunks); a chunk's node holds its rows that are drawn at rest.

    Args:
        server: the viser server (nodes are shared by every browser).
        unit: the splat nodes' length unit (`splats.splat_unit`).
    """

    def __init__(self, server: viser.ViserServer, unit: float) -> None:
        self.server = server
        self.unit = unit
        self.home = np.empty(0, np.int64)  # (N,) home chunk of each row, -1 for none
        self.members: list[np.ndarray] = []  # rows of each chunk
        self.nodes: dict[int, Any] = {}  # chunk -> its node, for the chunks with rows drawn
        self._shown = np.empty(0, bool)  # rows drawn at rest, as last sent

    def __len__(self) -> int:
        return len(self.members)

    def update(self, splats: SplatArrays, static: np.ndarray, changed: np.ndarray) -> int:
        """Send the chunks whose rows changed; returns how many Gaussians were sent.

        Args:
            splats: every row of the scene, as drawn.
            static: (N,) bool rows drawn at rest (N may have grown since the last call).
            changed: rows whose Gaussian was replaced since the last call.
        """
        old = len(self.home)
        fresh = np.arange(old, len(static), dtype=np.int64)
        self.home = np.concatenate([self.home, np.full(len(fresh), -1, np.int64)])
        self._shown = np.concatenate([self._shown, np.zeros(len(fresh), bool)])
        homeless = np.flatnonzero(static & (self.home < 0))  # new rows drawn at rest
        dirty = set(self._add_chunks(splats.centers, homeless))
        moved = np.union1d(np.flatnonzero(static != self._shown), np.asarray(changed, np.int64))
        dirty.update(int(c) for c in np.unique(self.home[moved]) if c >= 0)
        sent = 0
        for c in sorted(dirty):
            rows = self.members[c][static[self.members[c]]]
            if len(rows) == 0:
                node = self.nodes.pop(c, None)
                if node is not None:
                    node.remove()
                continue
            part = splats.subset(rows).in_unit(self.unit)
            self.nodes[c] = self.server.scene.add_gaussian_splats(
                f"/scene/{c}", part.centers, part.covariances, part.rgbs, part.opacities, scale=self.unit
            )
            sent += len(rows)
        self._shown = static.copy()
        return sent

    def _add_chunks(self, centers: np.ndarray, rows: np.ndarray) -> range:
        """Give `rows` new home chunks; returns the new chunks' numbers."""
        first = len(self.members)
        if len(rows) == 0:
            return range(first, first)
        for leaf in spatial_chunks(centers[rows], chunk_count(len(rows))):
            self.members.append(rows[leaf])
            self.home[rows[leaf]] = len(self.members) - 1
        return range(first, len(self.members))
