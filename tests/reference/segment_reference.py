"""A slow, obvious NumPy implementation of segmentation and binding (docs/deformation.md,
"Segmentation"): the test oracle of `sketchrodgs_polyline::segment`.

`segment_and_bind` is the NumPy implementation the Rust one replaced, step for step; the proximity
queries it made in Rust (growing the part, linked components, the part a point touches) are
written out below over all pairs of centres within reach (scipy's k-d tree finds them), with the
candidates the grids decide on: two centres are linked when their cells (`floor(x / width)` in
float32) are at most one apart on every axis and their float32 squared distance, summed as
(dx^2 + dy^2) + dz^2, is at most the link squared. The nearest point on the polyline tries every
segment. Small scenes only.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from sketchrodgs.polyline import arc_lengths, polyline_length
from sketchrodgs.segment import (
    DEFAULT_GROW,
    END_MARGIN,
    LINK_MAX,
    LINK_MIN,
    LINK_SPACINGS,
    Binding,
    default_attach_size,
    point_at,
    which_end,
)

SEED, ELIGIBLE, OTHER = 0, 1, 2


def segment_and_bind(
    polyline: np.ndarray,
    means: np.ndarray,
    radius: float,
    *,
    grow: float = DEFAULT_GROW,
    attach: bool = True,
    attach_size: float | None = None,
    attach_size_fewer: float | None = None,
) -> Binding:
    """As `sketchrodgs.segment.part_and_attached`, over centres `means` (N, 3) float32 (the
    sizes as it takes them; `attach_size` None: `default_attach_size`)."""
    polyline = np.asarray(polyline, np.float64)
    length = polyline_length(polyline)
    if attach_size is None:
        attach_size = default_attach_size(length, radius)
    sizes = (attach_size, attach_size if attach_size_fewer is None else max(attach_size, attach_size_fewer))
    part_reach = grow * radius
    near_reach = part_reach + LINK_MAX * radius
    rows = near_box(polyline, means, near_reach)
    segment, t, distance = nearest_on_polyline(_f32(polyline), _f32(means[rows]), near_reach)
    near = segment >= 0
    rows, segment, t, distance = rows[near], segment[near], t[near], distance[near]
    points = _f32(means[rows])
    at_end = which_end(segment, t, len(polyline)) >= 0
    eligible = (distance <= part_reach) & (~at_end | (distance <= radius))
    kind = np.where(eligible & (distance <= radius), 0, np.where(eligible, 1, 2)).astype(np.uint8)
    link, part, touched = grow_part(
        points, kind, np.float32(LINK_SPACINGS), np.float32(LINK_MIN * radius), np.float32(LINK_MAX * radius)
    )
    link = float(link)
    home = np.where(part, np.arange(len(rows)), -1)
    attached = np.zeros(len(rows), bool)
    if attach and touched:
        reach = part_reach + sizes[1] + 2 * link
        around = near_box(polyline, means, reach)
        around = around[~np.isin(around, rows)]
        seg_far, t_far, far = nearest_on_polyline(_f32(polyline), _f32(means[around]), reach)
        past = which_end(seg_far, t_far, len(polyline))
        around, far, past = around[far <= reach], far[far <= reach], past[far <= reach]
        count = len(rows)
        end = np.concatenate([which_end(segment, t, len(polyline)), past])
        rows = np.concatenate([rows, around])
        distance = np.concatenate([distance, far])
        points = _f32(means[rows])
        part = np.concatenate([part, np.zeros(len(around), bool)])
        home = np.concatenate([home, np.full(len(around), -1)])
        attached = np.zeros(len(rows), bool)
        arc = arc_lengths(polyline)
        along = np.full(len(rows), np.nan)
        along[:count] = arc[segment] + t * (arc[segment + 1] - arc[segment])
        attached_rows, contact = _attached_parts(points, link, part, distance, reach - link, sizes)
        attached_rows, contact = _not_from_a_neighbour(attached_rows, contact, along, end, length, END_MARGIN * radius)
        home[attached_rows] = contact
        attached[attached_rows] = True
    centres = means[rows].astype(np.float64)
    keep = np.flatnonzero(home >= 0)
    keep = keep[np.argsort(rows[keep], kind="stable")]
    seg = segment[home[keep]]
    par = t[home[keep]]
    rest_points = point_at(polyline, seg, par)
    return Binding(
        rows[keep].astype(np.int64),
        seg.astype(np.int32),
        par.astype(np.float32),
        (centres[keep] - rest_points).astype(np.float32),
        distance[keep].astype(np.float32),
        attached[keep],
    )


def _attached_parts(
    points: np.ndarray, link: float, part: np.ndarray, distance: np.ndarray, shell: float, sizes: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    others = np.flatnonzero(~part)
    if len(others) == 0 or not part.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    label = linked_components(points[others], np.float32(link))
    touch = linked_to(points[others], points, part, np.float32(link))
    count = int(label.max()) + 1
    joined = np.flatnonzero(touch >= 0)
    first = np.unique(label[joined], return_index=True)
    contact_of = np.full(count, -1)
    contact_of[first[0]] = touch[joined[first[1]]]
    small = contact_of >= 0
    small[np.unique(label[distance[others] > shell])] = False
    contact = contact_of[label]
    members = small[label]
    spread = np.linalg.norm(points[others[members]] - points[contact[members]], axis=1)
    small[np.unique(label[members][spread > sizes[1]])] = False
    # past the first size, only a component with no more centres than the part
    wide = np.unique(label[members][spread > sizes[0]])
    small[wide] &= np.bincount(label, minlength=count)[wide] <= part.sum()
    chosen = small[label]
    return others[chosen], contact[chosen]


def _not_from_a_neighbour(
    rows: np.ndarray, contact: np.ndarray, along: np.ndarray, end: np.ndarray, length: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    keep = np.ones(len(rows), bool)
    for k, near_end in enumerate((along[contact] < margin, along[contact] > length - margin)):
        parts, index = np.unique(contact[near_end], return_inverse=True)
        if len(parts) == 0:
            continue
        past = np.bincount(index, weights=(end[rows[near_end]] == k).astype(float), minlength=len(parts))
        total = np.bincount(index, minlength=len(parts))
        keep[np.flatnonzero(near_end)[past[index] < 0.5 * total[index]]] = False
    return rows[keep], contact[keep]


def near_box(polyline: np.ndarray, centres: np.ndarray, margin: float) -> np.ndarray:
    """Rows of `centres` inside the polyline's box grown by `margin` (float32 bounds rounded out)."""
    low = np.nextafter((polyline.min(axis=0) - margin).astype(np.float32), np.float32(-np.inf))
    high = np.nextafter((polyline.max(axis=0) + margin).astype(np.float32), np.float32(np.inf))
    return np.flatnonzero(np.all((centres >= low) & (centres <= high), axis=1))


def nearest_on_polyline(
    polyline: np.ndarray, points: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(segment, t, distance) per point, trying every segment in float64 (-1, 0, inf beyond
    `reach`); among equally near segments the lower index."""
    a, b = polyline[:-1].astype(np.float64), polyline[1:].astype(np.float64)
    ab = b - a
    length2 = ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1] + ab[:, 2] * ab[:, 2]
    segment = np.full(len(points), -1, np.int32)
    t_out = np.zeros(len(points), np.float32)
    distance = np.full(len(points), np.inf, np.float32)
    for start in range(0, len(points), 1024):
        p = points[start : start + 1024].astype(np.float64)[:, None, :]
        ap = p - a[None]
        dot = ap[..., 0] * ab[:, 0] + ap[..., 1] * ab[:, 1] + ap[..., 2] * ab[:, 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(length2 > 0, np.clip(dot / length2, 0.0, 1.0), 0.0)
        r = ap - t[..., None] * ab[None]
        d2 = r[..., 0] ** 2 + r[..., 1] ** 2 + r[..., 2] ** 2
        best = np.argmin(d2, axis=1)
        rows = np.arange(len(best))
        found = d2[rows, best] <= reach * reach
        chunk = slice(start, start + len(best))
        segment[chunk] = np.where(found, best, -1)
        t_out[chunk] = np.where(found, t[rows, best], 0.0).astype(np.float32)
        distance[chunk] = np.where(found, np.sqrt(d2[rows, best]), np.inf).astype(np.float32)
    return segment, t_out, distance


def _cells(points: np.ndarray, width: np.float32) -> np.ndarray:
    return np.floor(points / width).astype(np.int64)


def _distance2(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    d = p - q
    return (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]


def _links(a: np.ndarray, b: np.ndarray, width: np.float32, link: np.float32) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i of `a`, j of `b`) linked within `link` in cells `width` wide."""
    pairs = cKDTree(a).query_ball_tree(cKDTree(b), float(link) * (1 + 1e-6))
    i = np.repeat(np.arange(len(a)), [len(p) for p in pairs])
    j = np.concatenate([np.asarray(p, np.int64) for p in pairs]) if len(i) else np.zeros(0, np.int64)
    close = np.all(np.abs(_cells(a[i], width) - _cells(b[j], width)) <= 1, axis=1)
    close &= _distance2(a[i], b[j]) <= link * link
    return i[close], j[close]


def grow_part(
    points: np.ndarray, kind: np.ndarray, spacings: np.float32, link_min: np.float32, link_max: np.float32
) -> tuple[np.float32, np.ndarray, bool]:
    """(link, part, touched) as `proximity::grow`: the link from about 2000 seeds (every n-th in
    (cell, index) order, cells `link_max` wide), 1.5 times their median distance to the 4th
    nearest seed in the cells around; the part, the seeds and the eligible points linked to them
    through eligible points; whether an other point is linked to the part."""
    seeds = np.flatnonzero(kind == SEED)
    cells = _cells(points, link_max)
    order = seeds[np.lexsort((seeds, cells[seeds, 2], cells[seeds, 1], cells[seeds, 0]))]
    sample = order[:: max(len(seeds) // 2000, 1)]
    reach = 2 * np.sqrt(3) * float(link_max) * 1.01  # beyond the 27 cells around
    tree = cKDTree(points[seeds]) if len(seeds) else None
    fourth = []
    for k in sample:
        assert tree is not None
        j = seeds[np.asarray(tree.query_ball_point(points[k], reach), np.int64)]
        j = j[(j != k) & np.all(np.abs(cells[j] - cells[k]) <= 1, axis=1)]
        d2 = np.sort(_distance2(points[j], points[k]))
        fourth.append(np.sqrt(d2[3]) if len(d2) > 3 else np.float32(np.inf))
    if len(fourth) < 5:
        link = link_max
    else:
        median = np.sort(np.asarray(fourth, np.float32))[len(fourth) // 2]
        link = np.clip(np.float32(spacings) * median, link_min, link_max).astype(np.float32)
    i, j = _links(points, points, link_max, link)
    member = kind <= ELIGIBLE
    both = member[i] & member[j]
    graph = coo_matrix((np.ones(both.sum()), (i[both], j[both])), shape=(len(points),) * 2)
    _, component = connected_components(graph, directed=False)
    part = member & np.isin(component, component[kind == SEED])
    touched = bool(np.any((kind[i] == OTHER) & part[j]))
    return np.float32(link), part, touched


def linked_components(points: np.ndarray, link: np.float32) -> np.ndarray:
    """Labels 0, 1, ... of the components of the links among `points`, in order of each one's
    first point."""
    i, j = _links(points, points, link, link)
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(len(points),) * 2)
    _, component = connected_components(graph, directed=False)
    _, first, relabel = np.unique(component, return_index=True, return_inverse=True)
    return np.argsort(np.argsort(first))[relabel]


def linked_to(queries: np.ndarray, points: np.ndarray, member: np.ndarray, link: np.float32) -> np.ndarray:
    """For each query, the lowest row of `points` with `member` linked to it (-1: none)."""
    rows = np.flatnonzero(member)
    i, j = _links(queries, points[rows], link, link)
    lowest = np.full(len(queries), np.iinfo(np.int64).max)
    np.minimum.at(lowest, i, rows[j])
    return np.where(lowest == np.iinfo(np.int64).max, -1, lowest)


def _f32(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float32)
