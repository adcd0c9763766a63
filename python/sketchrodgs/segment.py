"""Segmentation and binding (docs/deformation.md, "Segmentation"): which Gaussians follow a rod,
and where each sits on the rest polyline.

Three sets, found over a proximity graph of Gaussian centres (centres closer than the link
distance are neighbours, so a gap in the cloud separates parts):
- the part: grown from the Gaussians within R of the axis over neighbours within `grow * R` of
  the axis and within the rod's extent along it, so that a cross-section that is not round (the
  fretboard edge of a guitar neck) goes whole, and a neighbour across a gap stays;
- attached parts: what hangs on the part and is small (every piece of it within `attach_size` of
  where it joins; a leaf on its petiole, the leaves at a branch tip). Each rides rigidly with the
  rod point where it joins. Large bodies the rod joins (a pot, a trunk, a guitar body) reach
  further and stay.

No band of partly moving Gaussians around the part: where the part has a gap around it there is
nothing to blend with, and where it touches something (a crossing branch) a band 1 R wide made
the tears of a real pull three times as many, and the needles six (docs/deformation.md). Motion
eases in at clamped ends instead (`skin.Rig`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core
from .polyline import arc_lengths, near_box, polyline_length
from .scene import GaussianScene

# The part's cross-section reaches this many R from the axis. Surface Gaussians sit at about one
# radius from the axis, and on real captures their centres scatter well past the visible
# half-width (the estimated R): at 1.5 R a pulled plant stem left a ghost of itself behind.
DEFAULT_GROW = 2.5
ATTACH_SHARE = 0.5  # attached parts up to this share of the rod's length,
ATTACH_MIN, ATTACH_MAX = 8.0, 20.0  # and between these many R
END_MARGIN = 3.0  # within this many R of a rod end, only what lies past the end is attached
# Neighbours: centres within LINK_SPACINGS times the part's typical 4th-neighbour spacing, kept
# between LINK_MIN and LINK_MAX radii (real captures range from 0.1 to 0.4 R).
LINK_SPACINGS = 1.5
LINK_MIN, LINK_MAX = 0.2, 0.75


def default_attach_size(length: float, radius: float) -> float:
    """Attached parts up to half the rod's length, between 8 R and 20 R, ride with the rod (a leaf
    on a stem is a third of the stem or more; the body a part joins is longer than the part; the
    cap keeps the search around a long rope small)."""
    return float(np.clip(ATTACH_SHARE * length, ATTACH_MIN * radius, ATTACH_MAX * radius))


@dataclass(frozen=True, eq=False)
class Binding:
    """Where each Gaussian that follows a rod sits on the rest polyline.

    Attributes:
        gaussian_ids: (G,) int64 rows of the scene.
        segment: (G,) int32 polyline segment index i (between vertices i and i + 1).
        t: (G,) float32 parameter on that segment, in [0, 1].
        offset: (G, 3) float32 centre minus the rest point at (segment, t), in world axes at rest.
        distance: (G,) float32 distance from the centre to the rest polyline.
        attached: (G,) bool rides rigidly with the point where its attached part joins the rod
            (not with its own nearest point; such Gaussians are never subdivided).
    """

    gaussian_ids: np.ndarray
    segment: np.ndarray
    t: np.ndarray
    offset: np.ndarray
    distance: np.ndarray
    attached: np.ndarray

    def take(self, rows: np.ndarray) -> Binding:
        """The binding of a subset (rows index this binding)."""
        return Binding(*(getattr(self, f)[rows] for f in Binding.__dataclass_fields__))

    def extend(self, other: Binding) -> Binding:
        """This binding followed by `other`'s entries."""
        return Binding(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in Binding.__dataclass_fields__))


def segment_and_bind(
    polyline: np.ndarray,
    scene: GaussianScene,
    radius: float,
    *,
    grow: float = DEFAULT_GROW,
    attach: bool = True,
    attach_size: float | None = None,
) -> Binding:
    """The Gaussians that follow the rod on `polyline`, bound (see the module docstring).

    Args:
        polyline: (M, 3) rest polyline, M >= 2.
        scene: the scene (its centres are read).
        radius: R.
        grow: the part's cross-section reaches `grow * R` from the axis.
        attach: let small attached parts ride with the rod.
        attach_size: the largest attached part (default `default_attach_size`).
    """
    polyline = np.asarray(polyline, np.float64)
    means = scene.means
    length = polyline_length(polyline)
    if attach_size is None:
        attach_size = default_attach_size(length, radius)
    # The part: exact nearest points of everything within its reach (and a link more, where what
    # touches it from outside lies).
    part_reach = grow * radius
    near_reach = part_reach + LINK_MAX * radius
    rows = near_box(polyline, means, near_reach)
    segment, t, distance = _core.nearest_on_polyline(_f32(polyline), _f32(means[rows]), near_reach)
    near = segment >= 0
    rows, segment, t, distance = rows[near], segment[near], t[near], distance[near]
    points = _f32(means[rows])
    # The rod's extent: a centre past an end vertex is the part's within R of it (the end cap);
    # what continues past that is not.
    at_end = past_an_end(segment, t, len(polyline))
    eligible = (distance <= part_reach) & (~at_end | (distance <= radius))
    kind = np.where(eligible & (distance <= radius), 0, np.where(eligible, 1, 2)).astype(np.uint8)
    link, part, touched = _core.grow_part(points, kind, LINK_SPACINGS, LINK_MIN * radius, LINK_MAX * radius)
    link = float(link)
    home = np.where(part, np.arange(len(rows)), -1)  # whose (segment, t) each row takes
    attached = np.zeros(len(rows), bool)
    if attach and touched:
        # Attached parts: what a part can reach from where it joins, plus two links (a larger body
        # shows itself by coming within a link of the edge).
        reach = part_reach + attach_size + 2 * link
        around = near_box(polyline, means, reach)
        around = around[~np.isin(around, rows)]
        seg_far, t_far, far = _core.nearest_on_polyline(_f32(polyline), _f32(means[around]), reach)
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
        attached_rows, contact = _attached_parts(points, link, part, distance, reach - link, attach_size)
        attached_rows, contact = _not_from_a_neighbour(attached_rows, contact, along, end, length, END_MARGIN * radius)
        home[attached_rows] = contact
        attached[attached_rows] = True
    centres = means[rows].astype(np.float64)

    keep = np.flatnonzero(home >= 0)
    keep = keep[np.argsort(rows[keep], kind="stable")]
    # Part Gaussians sit at their own nearest point; attached ones at the point where they join
    # (every home is a part row, so it has one).
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


def which_end(segment: np.ndarray, t: np.ndarray, vertices: int) -> np.ndarray:
    """Per nearest point `(segment, t)` on a polyline of `vertices`: 0 where the point lies past
    its start, 1 past its end, -1 beside it."""
    start = (segment == 0) & (t <= 0)
    end = (segment == vertices - 2) & (t >= 1)
    return np.where(start, 0, np.where(end, 1, -1))


def past_an_end(segment: np.ndarray, t: np.ndarray, vertices: int) -> np.ndarray:
    """Whether each nearest point is a rod end (the point lies past it)."""
    return which_end(segment, t, vertices) >= 0


def point_at(polyline: np.ndarray, segment: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(G, 3) float64 the points at `(segment, t)` on `polyline`."""
    a = polyline[segment]
    return a + np.asarray(t, np.float64)[:, None] * (polyline[segment + 1] - a)


def _attached_parts(
    points: np.ndarray, link: float, part: np.ndarray, distance: np.ndarray, shell: float, size: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the small parts that touch `part`, and for each the part row it joins at.

    A part is a component of the links among the other points. It is small when none of it comes
    within a link of the searched region's edge (`shell` from the axis; a large body runs on past
    it) and it fits in a ball of `size` around where it joins."""
    others = np.flatnonzero(~part)
    if len(others) == 0 or not part.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    group = np.where(part, 1, 0).astype(np.uint8)
    label = _core.linked_components(points, np.where(part, 255, 0).astype(np.uint8), link)[others]
    touch = _core.linked_to(points, group, 0, 1, link)[others]  # a part row each other row reaches
    count = int(label.max()) + 1
    # where each component joins: the contact of its first row that has one
    joined = np.flatnonzero(touch >= 0)
    first = np.unique(label[joined], return_index=True)
    contact_of = np.full(count, -1)
    contact_of[first[0]] = touch[joined[first[1]]]
    small = contact_of >= 0
    small[np.unique(label[distance[others] > shell])] = False  # reaches the edge
    contact = contact_of[label]
    members = small[label]
    spread = np.linalg.norm(points[others[members]] - points[contact[members]], axis=1)
    small[np.unique(label[members][spread > size])] = False  # does not fit
    chosen = small[label]
    return others[chosen], contact[chosen]


def _not_from_a_neighbour(
    rows: np.ndarray, contact: np.ndarray, along: np.ndarray, end: np.ndarray, length: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """Drop the attached parts that join within `margin` of a rod end but lie beside the rod
    rather than past that end: there the rod meets what it is joined to, and a part touching it
    (a leaf of the main stem at a side stem's base) belongs to that."""
    keep = np.ones(len(rows), bool)
    for k, near_end in enumerate((along[contact] < margin, along[contact] > length - margin)):
        # per part (its contact row), the share of its rows past this end
        parts, index = np.unique(contact[near_end], return_inverse=True)
        if len(parts) == 0:
            continue
        past = np.bincount(index, weights=(end[rows[near_end]] == k).astype(float), minlength=len(parts))
        total = np.bincount(index, minlength=len(parts))
        keep[np.flatnonzero(near_end)[past[index] < 0.5 * total[index]]] = False
    return rows[keep], contact[keep]


def _f32(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float32)
