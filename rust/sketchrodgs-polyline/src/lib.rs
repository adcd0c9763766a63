//! Nearest point on a 3D polyline, for many query points, within a reach.
//!
//! Binding Gaussians to a rod (docs/deformation.md: each binds to its nearest point on the rest polyline)
//! and recentring the extracted polyline both ask, for tens of thousands of Gaussian centres,
//! which segment of a polyline is nearest and where on it. A uniform grid over the segments
//! (cells about the reach wide) makes each query look at a handful of segments, nearest to its
//! cell's centre first; queries run in parallel and the answer does not depend on the thread
//! count. `proximity` links centres to their neighbours, and `segment` decides with both which
//! Gaussians follow a rod.
//!
//! ```
//! use sketchrodgs_polyline::{nearest_on_polyline, Nearest};
//! let polyline = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
//! let points = [[0.25, 0.1, 0.0], [1.1, 0.5, 0.0], [5.0, 5.0, 5.0]];
//! let found = nearest_on_polyline(&polyline, &points, 0.5).unwrap();
//! assert_eq!(found[0], Some(Nearest { segment: 0, t: 0.25, distance: 0.1 }));
//! assert_eq!(found[1].map(|n| n.segment), Some(1));
//! assert_eq!(found[2], None); // farther than the reach
//! ```

use rayon::prelude::*;

pub mod continuation;
pub mod detours;
pub mod proximity;
pub mod segment;

/// What makes a query impossible.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolylineError {
    #[error("polyline needs at least 2 vertices, got {0}")]
    TooFewVertices(usize),
    #[error("polyline vertex {0} is not finite")]
    NonFiniteVertex(usize),
    #[error("reach must be finite and > 0, got {0}")]
    BadReach(f64),
}

/// Rows of `points` inside the axis-aligned box `[low, high]` (bounds included), ascending: the
/// cheap first cut of every query around a rod on a scene of millions of Gaussians.
pub fn rows_in_box(points: &[[f32; 3]], low: [f32; 3], high: [f32; 3]) -> Vec<u32> {
    const ROWS_PER_TASK: usize = 1 << 16;
    // Two passes without branches, each of which vectorises: whether each row is inside, then the
    // rows inside (28,777 rows: 0.17 to 0.07 ms, docs/extraction.md, "Speed").
    let rows_in = |start: usize, chunk: &[[f32; 3]]| -> Vec<u32> {
        let inside: Vec<u8> = chunk
            .iter()
            .map(|p| {
                u8::from(
                    (p[0] >= low[0])
                        & (p[0] <= high[0])
                        & (p[1] >= low[1])
                        & (p[1] <= high[1])
                        & (p[2] >= low[2])
                        & (p[2] <= high[2]),
                )
            })
            .collect();
        let mut rows = Vec::with_capacity(inside.iter().map(|&i| usize::from(i)).sum());
        rows.extend((start..).zip(&inside).filter(|(_, i)| **i == 1).map(|(row, _)| row as u32));
        rows
    };
    if points.len() <= ROWS_PER_TASK {
        return rows_in(0, points); // (a scene around a rod: one task, no parallel plumbing)
    }
    points.par_chunks(ROWS_PER_TASK).enumerate().flat_map_iter(|(k, chunk)| rows_in(k * ROWS_PER_TASK, chunk)).collect()
}

/// The nearest point of the polyline to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    /// Segment index `i` (between vertices `i` and `i + 1`).
    pub segment: u32,
    /// Parameter along the segment, in `[0, 1]`.
    pub t: f32,
    /// Distance from the query point.
    pub distance: f32,
}

/// A polyline segment, with what every query of it needs.
struct Segment {
    a: [f64; 3],
    /// From `a` to the other end, and its squared length.
    ab: [f64; 3],
    length2: f64,
    /// Its bounding box.
    low: [f64; 3],
    high: [f64; 3],
}

impl Segment {
    fn new(a: [f64; 3], b: [f64; 3]) -> Self {
        let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        Self {
            a,
            ab,
            length2: ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2],
            low: std::array::from_fn(|k| a[k].min(b[k])),
            high: std::array::from_fn(|k| a[k].max(b[k])),
        }
    }

    /// The parameter of the nearest point to `p` and the squared distance to it.
    fn nearest(&self, p: [f64; 3]) -> (f64, f64) {
        let (a, ab) = (self.a, self.ab);
        let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
        let t = if self.length2 > 0.0 {
            ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / self.length2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d2: f64 = (0..3).map(|k| (ap[k] - t * ab[k]).powi(2)).sum();
        (t, d2)
    }

    /// The squared distance from `p` to the bounding box: at most the squared distance to the
    /// segment, and a fraction of the cost.
    fn box_distance2(&self, p: [f64; 3]) -> f64 {
        let outside = |k: usize| {
            // at most one of the two is positive
            let (below, above) = (self.low[k] - p[k], p[k] - self.high[k]);
            (if below > 0.0 { below } else { 0.0 }) + (if above > 0.0 { above } else { 0.0 })
        };
        let (x, y, z) = (outside(0), outside(1), outside(2));
        x * x + y * y + z * z
    }
}

/// The segments near each cell of a uniform grid: a point's nearest segment within `reach` is
/// registered in the point's own cell (each segment is entered in every cell its grown bounding
/// box touches). The grid is dense over the polyline's grown bounding box; points outside it
/// have no candidates.
struct SegmentGrid {
    cell: f64,
    origin: [f64; 3],
    dims: [usize; 3],
    /// `dims + 1`, for `cell_of`.
    past: [f64; 3],
    /// Each cell's segments, in index order (`starts` has one more entry: the end).
    starts: Vec<u32>,
    registered: Vec<u32>,
}

impl SegmentGrid {
    fn new(segments: &[Segment], reach: f64) -> Self {
        let low: [f64; 3] =
            std::array::from_fn(|k| segments.iter().map(|s| s.low[k]).fold(f64::INFINITY, f64::min) - reach);
        let high: [f64; 3] =
            std::array::from_fn(|k| segments.iter().map(|s| s.high[k]).fold(f64::NEG_INFINITY, f64::max) + reach);
        // Cells as wide as the reach, but not much wider than the segments: in cells many
        // segments wide the lists grow long and the stop test of `nearest` loose (a point lies
        // far from its cell's centre); narrower ones cost more to fill than they save. And the
        // grid kept to a few million cells however small the reach is against the polyline.
        let longest = segments.iter().map(|s| s.length2.sqrt()).fold(0.0, f64::max);
        let mut cell = reach.min((8.0 * longest).max(reach / 1.5));
        while (0..3).map(|k| ((high[k] - low[k]) / cell).floor() + 1.0).product::<f64>() > 4.0e6 {
            cell *= 2.0;
        }
        let dims: [usize; 3] = std::array::from_fn(|k| ((high[k] - low[k]) / cell).floor() as usize + 1);
        let past = dims.map(|d| d as f64 + 1.0);
        let mut grid = Self { cell, origin: low, dims, past, starts: Vec::new(), registered: Vec::new() };
        let boxes: Vec<Option<([usize; 3], [usize; 3])>> = segments
            .iter()
            .map(|s| {
                let lo = grid.cell_of(std::array::from_fn(|k| s.low[k] - reach))?;
                let hi = grid.cell_of(std::array::from_fn(|k| s.high[k] + reach))?;
                Some((lo, hi))
            })
            .collect();
        let each_cell = |(lo, hi): ([usize; 3], [usize; 3]), visit: &mut dyn FnMut([usize; 3])| {
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        visit([x, y, z]);
                    }
                }
            }
        };
        // counted, then filled in segment order
        let cells = dims[0] * dims[1] * dims[2];
        let mut starts = vec![0_u32; cells + 1];
        for &b in boxes.iter().flatten() {
            each_cell(b, &mut |cell| starts[grid.index(cell) + 1] += 1);
        }
        for c in 0..cells {
            starts[c + 1] += starts[c];
        }
        let mut filled: Vec<u32> = starts[..cells].to_vec();
        let mut registered = vec![0; starts[cells] as usize];
        for (i, b) in boxes.iter().enumerate() {
            if let Some(b) = *b {
                each_cell(b, &mut |cell| {
                    let c = grid.index(cell);
                    registered[filled[c] as usize] = i as u32;
                    filled[c] += 1;
                });
            }
        }
        (grid.starts, grid.registered) = (starts, registered);
        grid
    }

    fn cell_of(&self, p: [f64; 3]) -> Option<[usize; 3]> {
        let mut cell = [0; 3];
        for k in 0..3 {
            let c = (p[k] - self.origin[k]) / self.cell;
            // clamp by a hair: bounds computed from the same vertices may round just outside
            // (c in [-1, dims + 1) is floor(c) in [-1, dims]; truncation is the floor from 0 up)
            if !(c >= -1.0 && c < self.past[k]) {
                return None;
            }
            cell[k] = if c < 1.0 { 0 } else { (c as u32 as usize).min(self.dims[k] - 1) };
        }
        Some(cell)
    }

    fn index(&self, cell: [usize; 3]) -> usize {
        (cell[0] * self.dims[1] + cell[1]) * self.dims[2] + cell[2]
    }

    fn cell_at(&self, index: usize) -> [usize; 3] {
        [index / (self.dims[1] * self.dims[2]), index / self.dims[2] % self.dims[1], index % self.dims[2]]
    }

    fn centre(&self, cell: [usize; 3]) -> [f64; 3] {
        std::array::from_fn(|k| self.origin[k] + (cell[k] as f64 + 0.5) * self.cell)
    }

    /// A cell's candidates ranked for its points: each registered segment with its distance from
    /// the cell's centre, nearest first, less those that no point of the cell can have within
    /// `reach` (a point of a cell lies within `spread` of its centre; an edge cell also takes
    /// the points up to a cell beyond the grid).
    fn ranked(&self, segments: &[Segment], cell: [usize; 3], reach: f64, slack: f64) -> RankedCell {
        let centre = self.centre(cell);
        let spread = (0..3)
            .map(|k| {
                let edges = usize::from(cell[k] == 0) + usize::from(cell[k] + 1 == self.dims[k]);
                (self.cell * (0.5 + edges as f64)).powi(2)
            })
            .sum::<f64>()
            .sqrt();
        let c = self.index(cell);
        let mut ranked: Vec<(u32, f64)> = self.registered[self.starts[c] as usize..self.starts[c + 1] as usize]
            .iter()
            .map(|&i| (i, segments[i as usize].nearest(centre).1.sqrt()))
            .filter(|&(_, from_centre)| from_centre - spread <= reach + slack)
            .collect();
        ranked.sort_unstable_by(|a, b| a.1.total_cmp(&b.1));
        RankedCell { centre, segments: ranked }
    }
}

/// A cell's segments, each with its distance from the cell's centre, nearest first.
struct RankedCell {
    centre: [f64; 3],
    segments: Vec<(u32, f64)>,
}

impl RankedCell {
    /// The nearest point to `p` (in this cell) within `reach` (see `nearest_on_polyline`).
    fn nearest(&self, segments: &[Segment], p: [f64; 3], reach: f64, slack: f64) -> Option<Nearest> {
        let off_centre = (0..3).map(|k| (p[k] - self.centre[k]).powi(2)).sum::<f64>().sqrt();
        // the best so far: squared distance, segment (u32::MAX: none yet), parameter
        let (mut best_d2, mut best, mut best_t) = (f64::INFINITY, u32::MAX, 0.0);
        let mut bound = reach + slack; // no segment farther than this can be the answer
        for &(s, from_centre) in &self.segments {
            if from_centre - off_centre > bound + slack {
                break; // the rest lie farther from the centre still
            }
            let segment = &segments[s as usize];
            if segment.box_distance2(p) > bound * bound {
                continue;
            }
            let (t, d2) = segment.nearest(p);
            if d2 <= reach * reach && (d2 < best_d2 || (d2 == best_d2 && s < best)) {
                (best_d2, best, best_t) = (d2, s, t);
                bound = d2.sqrt() + slack;
            }
        }
        (best != u32::MAX).then(|| Nearest { segment: best, t: best_t as f32, distance: best_d2.sqrt() as f32 })
    }
}

/// How far past a bound a segment must be to be skipped: the computed distances carry rounding
/// errors of about 1e-16 of the lengths involved, the slack is 1e-9 of them.
fn slack(segments: &[Segment], cell: f64, reach: f64) -> f64 {
    let longest = segments.iter().map(|s| s.length2.sqrt()).fold(0.0, f64::max);
    1e-9 * (cell + reach + longest)
}

/// For each point, the nearest point on `polyline` if it is within `reach`, else `None`.
/// Among equally near segments the lower index wins.
///
/// A segment is a candidate for the points of the grid cells around it (`SegmentGrid`). A
/// cell's candidates are ranked by their distance from its centre once, for all its points, and
/// a point stops at the first that is provably farther than the best so far, or skips one whose
/// bounding box is: the answers are those of trying every candidate.
pub fn nearest_on_polyline(
    polyline: &[[f32; 3]],
    points: &[[f32; 3]],
    reach: f64,
) -> Result<Vec<Option<Nearest>>, PolylineError> {
    if polyline.len() < 2 {
        return Err(PolylineError::TooFewVertices(polyline.len()));
    }
    if let Some(i) = polyline.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        return Err(PolylineError::NonFiniteVertex(i));
    }
    if !(reach.is_finite() && reach > 0.0) {
        return Err(PolylineError::BadReach(reach));
    }
    let vertices: Vec<[f64; 3]> = polyline.iter().map(|v| v.map(f64::from)).collect();
    let segments: Vec<Segment> = vertices.windows(2).map(|w| Segment::new(w[0], w[1])).collect();
    let grid = SegmentGrid::new(&segments, reach);
    let slack = slack(&segments, grid.cell, reach);
    // each point's cell, and the cells that hold points ranked once
    let cell_of: Vec<u32> =
        points.par_iter().map(|p| grid.cell_of(p.map(f64::from)).map_or(u32::MAX, |c| grid.index(c) as u32)).collect();
    let mut rank_of = vec![u32::MAX; grid.starts.len() - 1];
    let mut occupied = Vec::new();
    for &c in cell_of.iter().filter(|&&c| c != u32::MAX) {
        if rank_of[c as usize] == u32::MAX {
            rank_of[c as usize] = occupied.len() as u32;
            occupied.push(c as usize);
        }
    }
    let ranked: Vec<RankedCell> =
        occupied.par_iter().map(|&c| grid.ranked(&segments, grid.cell_at(c), reach, slack)).collect();
    Ok(points
        .par_iter()
        .zip(&cell_of)
        .map(|(p, &c)| {
            let cell = ranked.get(*rank_of.get(c as usize)? as usize)?;
            cell.nearest(&segments, p.map(f64::from), reach, slack)
        })
        .collect())
}

/// A cross-section of fewer points than this is at most one point's centre: on a part of few
/// Gaussians (a sprinkle, about two per radius) a Gaussian on the part's surface, anywhere across
/// it, and the axis hooked towards it at an end (docs/extraction.md, "A cross-section of one
/// Gaussian").
const LEAST_MEMBERS: u32 = 2;

/// Centroid of each polyline vertex's cross-section: the points within `half_width` of the plane
/// through vertex `i` across `tangents[i]` and within `reach[i]` of the vertex (a vertex without
/// a reach takes none). A point is tried against its `nearest_vertex` and that vertex's two
/// neighbours only (-1: no nearest vertex). A cross-section of fewer than `LEAST_MEMBERS` points is
/// taken again within `wide_half_width` of the plane, from the points whose nearest vertex lies
/// within `2 reach[i]` along the axis. A vertex whose cross-section is empty even then keeps its
/// position. Returns the centroids and the number of points each was taken over.
pub fn cross_section_centroids(
    axis: &[[f64; 3]],
    tangents: &[[f64; 3]],
    points: &[[f32; 3]],
    nearest_vertex: &[i32],
    half_width: f64,
    wide_half_width: f64,
    reach: &[f64],
) -> (Vec<[f64; 3]>, Vec<u32>) {
    // whether `p` lies in vertex `i`'s cross-section of half width `half`
    let inside = |i: usize, p: [f64; 3], half: f64| {
        let (Some(a), Some(t), Some(&r)) = (axis.get(i), tangents.get(i), reach.get(i)) else { return false };
        let d = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
        let along = d[0] * t[0] + d[1] * t[1] + d[2] * t[2];
        along.abs() <= half && d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= r * r
    };
    // The vertices in one run per thread, in parallel: each run reads every point and sums those of
    // its own vertices, in point order as one pass over the points would, so the sums do not
    // depend on the runs (docs/extraction.md, "Speed").
    let last = axis.len().saturating_sub(1);
    let run = axis.len().div_ceil(rayon::current_num_threads()).max(1);
    let runs: Vec<(Vec<[f64; 3]>, Vec<u32>)> = (0..axis.len())
        .step_by(run)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|low| {
            let high = (low + run).min(axis.len()) - 1;
            let (mut sums, mut counts) = (vec![[0.0_f64; 3]; high + 1 - low], vec![0_u32; high + 1 - low]);
            for (p, &n) in points.iter().zip(nearest_vertex) {
                let Ok(n) = usize::try_from(n) else { continue };
                let (from, to) = (n.saturating_sub(1).max(low), (n + 1).min(last).min(high));
                if from > to {
                    continue;
                }
                let p = p.map(f64::from);
                for i in from..=to {
                    if inside(i, p, half_width) {
                        for k in 0..3 {
                            sums[i - low][k] += p[k];
                        }
                        counts[i - low] += 1;
                    }
                }
            }
            (sums, counts)
        })
        .collect();
    let (mut sums, mut counts): (Vec<[f64; 3]>, Vec<u32>) = (Vec::new(), Vec::new());
    for (run_sums, run_counts) in runs {
        sums.extend(run_sums);
        counts.extend(run_counts);
    }
    let sparse: Vec<usize> = (0..axis.len()).filter(|&i| counts[i] < LEAST_MEMBERS).collect();
    if !sparse.is_empty() && wide_half_width > half_width {
        let mut by_vertex: Vec<Vec<usize>> = vec![Vec::new(); axis.len()];
        for (k, &n) in nearest_vertex.iter().enumerate().take(points.len()) {
            if let Some(members) = usize::try_from(n).ok().and_then(|n| by_vertex.get_mut(n)) {
                members.push(k);
            }
        }
        let arc = detours::arc_in_radii(axis, 1.0);
        for i in sparse {
            // the vertices within 2 reaches along the axis (the arc only grows)
            let reach = reach.get(i).copied().unwrap_or(0.0);
            let from = arc.partition_point(|&s| s < arc[i] - 2.0 * reach);
            let to = arc.partition_point(|&s| s <= arc[i] + 2.0 * reach).max(from);
            let (mut sum, mut count) = ([0.0_f64; 3], 0_u32);
            for members in &by_vertex[from..to] {
                for p in members.iter().map(|&k| points[k].map(f64::from)) {
                    if inside(i, p, wide_half_width) {
                        for k in 0..3 {
                            sum[k] += p[k];
                        }
                        count += 1;
                    }
                }
            }
            if count > counts[i] {
                (sums[i], counts[i]) = (sum, count);
            }
        }
    }
    let centroids = axis
        .iter()
        .zip(sums.iter().zip(&counts))
        .map(|(a, (sum, &count))| if count > 0 { sum.map(|s| s / f64::from(count)) } else { *a })
        .collect();
    (centroids, counts)
}

/// How crowded the axis is at each vertex: of the `points` within `half_width` of the plane
/// through vertex `i` across `tangents[i]`, those `inner` to `outer` from the axis line over those
/// within `inner` (divided by 1 where none is). A free stem's cross-section holds its own Gaussians
/// only (0 to 0.1); at a node, a fork or where a thicker part is joined, what the part meets lies
/// around it (0.5 to 1.5; docs/extraction.md, "Ends at a junction"). Every point is tried against
/// every vertex: the caller passes the few vertices of an end and the points near them.
pub fn crowding(
    axis: &[[f64; 3]],
    tangents: &[[f64; 3]],
    points: &[[f32; 3]],
    half_width: f64,
    inner: f64,
    outer: f64,
) -> Vec<f64> {
    axis.par_iter()
        .zip(tangents)
        .map(|(a, t)| {
            let (mut near, mut around) = (0_u32, 0_u32);
            for p in points {
                let d = [f64::from(p[0]) - a[0], f64::from(p[1]) - a[1], f64::from(p[2]) - a[2]];
                let along = d[0] * t[0] + d[1] * t[1] + d[2] * t[2];
                if along.abs() > half_width {
                    continue;
                }
                let lateral2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - along * along;
                if lateral2 <= inner * inner {
                    near += 1;
                } else if lateral2 <= outer * outer {
                    around += 1;
                }
            }
            f64::from(around) / f64::from(near.max(1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_cross_section_beside_another_part_counts_it_and_a_free_one_is_empty() {
        // a tube of radius 1 along x (points on rings every 0.25), and beside its second half a
        // second tube 2 off the axis
        let ring = |x: f64, centre: [f64; 2]| {
            (0..12).map(move |k| {
                let angle = f64::from(k) * std::f64::consts::TAU / 12.0;
                [x as f32, (centre[0] + angle.cos()) as f32, (centre[1] + angle.sin()) as f32]
            })
        };
        let mut points: Vec<[f32; 3]> = (0..80).flat_map(|i| ring(f64::from(i) * 0.25, [0.0, 0.0])).collect();
        points.extend((40..80).flat_map(|i| ring(f64::from(i) * 0.25, [2.0, 0.0])));
        let axis = [[5.0, 0.0, 0.0], [15.0, 0.0, 0.0]];
        let tangents = [[1.0, 0.0, 0.0]; 2];
        let crowding = super::crowding(&axis, &tangents, &points, 0.5, 1.25, 2.5);
        // free: every ring point lies 1 off the axis. Beside the other tube, 5 rings of each
        // within the slab: the own tube's 12 points and 3 of the other's within 1.25, 4 of the
        // other's 1.25 to 2.5 off (the rest of it farther)
        assert_eq!(crowding[0], 0.0);
        assert!((crowding[1] - 20.0 / 75.0).abs() < 1e-12, "{crowding:?}");
        assert!(super::crowding(&axis, &tangents, &[], 0.5, 1.25, 2.5).iter().all(|&c| c == 0.0));
    }

    #[test]
    fn rows_in_box_are_those_inside_in_order() {
        let points: Vec<[f32; 3]> =
            (0..200_000).map(|i| [(i % 100) as f32, (i / 100 % 50) as f32, f32::NAN.min(i as f32)]).collect();
        let rows = super::rows_in_box(&points, [10.0, 5.0, -1.0], [12.0, 5.0, 1e9]);
        let expected: Vec<u32> =
            (0..200_000u32).filter(|&i| (10..=12).contains(&(i % 100)) && i / 100 % 50 == 5).collect();
        assert_eq!(rows, expected);
        let nan = [[f32::NAN, 0.0, 0.0]];
        assert!(super::rows_in_box(&nan, [-1.0; 3], [1.0; 3]).is_empty());
    }

    /// The obvious answer: every segment, every point.
    fn brute(polyline: &[[f32; 3]], p: [f32; 3], reach: f64) -> Option<(u32, f32)> {
        let mut best: Option<(f64, u32)> = None;
        for i in 0..polyline.len() - 1 {
            let (a, b) = (polyline[i].map(f64::from), polyline[i + 1].map(f64::from));
            let p = p.map(f64::from);
            let ab: Vec<f64> = (0..3).map(|k| b[k] - a[k]).collect();
            let ap: Vec<f64> = (0..3).map(|k| p[k] - a[k]).collect();
            let l2: f64 = ab.iter().map(|x| x * x).sum();
            let t = if l2 > 0.0 { ((0..3).map(|k| ap[k] * ab[k]).sum::<f64>() / l2).clamp(0.0, 1.0) } else { 0.0 };
            let d = (0..3).map(|k| (ap[k] - t * ab[k]).powi(2)).sum::<f64>().sqrt();
            if d <= reach && best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, i as u32));
            }
        }
        best.map(|(d, i)| (i, d as f32))
    }

    #[test]
    fn matches_brute_force_on_a_winding_polyline() {
        let polyline: Vec<[f32; 3]> = (0..200)
            .map(|i| {
                let s = i as f32 * 0.05;
                [s.cos() * (1.0 + 0.1 * s), s.sin(), 0.2 * (3.0 * s).sin()]
            })
            .collect();
        // a deterministic scatter of points around it
        let mut state = 12345_u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let points: Vec<[f32; 3]> = (0..3000).map(|_| [2.6 * next(), 2.4 * next(), 0.8 * next()]).collect();
        for reach in [0.05, 0.2, 1.0] {
            let found = nearest_on_polyline(&polyline, &points, reach).unwrap();
            for (p, f) in points.iter().zip(&found) {
                let expected = brute(&polyline, *p, reach);
                match (f, expected) {
                    (None, None) => {}
                    (Some(n), Some((_, d))) => assert!((n.distance - d).abs() < 1e-5, "{p:?}: {n:?} vs {d}"),
                    other => unreachable!("found and brute force disagree at {p:?}: {other:?}"),
                }
            }
        }
    }

    /// Every segment tried, as `Segment::nearest` computes each: (segment, t, squared distance);
    /// among equals the lower index.
    fn exhaustive(polyline: &[[f32; 3]], p: [f32; 3], reach: f64) -> Option<(u32, f64, f64)> {
        let p = p.map(f64::from);
        let mut best: Option<(u32, f64, f64)> = None;
        for (i, w) in polyline.windows(2).enumerate() {
            let (t, d2) = Segment::new(w[0].map(f64::from), w[1].map(f64::from)).nearest(p);
            if d2 <= reach * reach && best.is_none_or(|(_, _, bd)| d2 < bd) {
                best = Some((i as u32, t, d2));
            }
        }
        best
    }

    #[test]
    fn the_answers_are_those_of_trying_every_segment() {
        // a winding polyline of short segments (a reach of many segments makes the cells finer
        // than the reach), a V whose bisector is as near to both arms (the lower index wins), a
        // repeated vertex; points around, past the ends and outside the grid
        let winding: Vec<[f32; 3]> = (0..300)
            .map(|i| {
                let s = i as f32 * 0.02;
                [s.cos() * (1.0 + 0.1 * s), s.sin(), 0.2 * (3.0 * s).sin()]
            })
            .collect();
        let vee = vec![[-1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let mut state = 99_u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let mut points: Vec<[f32; 3]> = (0..4000).map(|_| [3.0 * next(), 3.0 * next(), 1.0 * next()]).collect();
        points.extend((0..50).map(|i| [0.0, i as f32 * 0.05, 0.0])); // on the V's bisector
        for polyline in [&winding, &vee] {
            for reach in [0.01, 0.07, 0.3, 1.5] {
                let found = nearest_on_polyline(polyline, &points, reach).unwrap();
                for (p, f) in points.iter().zip(&found) {
                    let expected = exhaustive(polyline, *p, reach).map(|(segment, t, d2)| Nearest {
                        segment,
                        t: t as f32,
                        distance: d2.sqrt() as f32,
                    });
                    assert_eq!(*f, expected, "{p:?} within {reach}");
                }
            }
        }
    }

    #[test]
    fn cross_sections_of_a_ring_sampled_tube_centre_on_the_axis() {
        // a straight tube of radius 1 along x, 8 points around each of 21 rings; the "axis" guess
        // starts on the surface at y = 1
        let axis: Vec<[f64; 3]> = (0..21).map(|i| [i as f64 * 0.5, 1.0, 0.0]).collect();
        let tangents = vec![[1.0, 0.0, 0.0]; 21];
        let mut points = Vec::new();
        let mut nearest = Vec::new();
        for i in 0..21 {
            for k in 0..8 {
                let a = k as f32 * std::f32::consts::FRAC_PI_4;
                points.push([i as f32 * 0.5, a.cos(), a.sin()]);
                nearest.push(i);
            }
        }
        let (centroids, counts) =
            cross_section_centroids(&axis, &tangents, &points, &nearest, 0.25, 0.25, &vec![2.2; axis.len()]);
        for (c, n) in centroids.iter().zip(&counts) {
            assert_eq!(*n, 8); // half width 0.25 < spacing 0.5: only its own ring
            assert!(c[1].abs() < 1e-6 && c[2].abs() < 1e-6, "{c:?}");
        }
        // a vertex with nothing around keeps its place; points without a nearest vertex are skipped
        let (centroids, counts) =
            cross_section_centroids(&axis[..2], &tangents[..2], &[[9.0, 9.0, 9.0]], &[-1], 0.25, 1.0, &[2.2; 2]);
        assert_eq!((centroids[0], counts[0]), (axis[0], 0));
    }

    #[test]
    fn each_vertex_reaches_as_far_as_its_own_reach() {
        // a ring-sampled tube of radius 0.4 along x, and beside it (1.4 off the axis) a second
        // tube: within 2.2 of the axis a cross-section takes both, within 0.9 its own only
        let axis: Vec<[f64; 3]> = (0..5).map(|i| [i as f64 * 0.5, 0.0, 0.0]).collect();
        let tangents = vec![[1.0, 0.0, 0.0]; 5];
        let (mut points, mut nearest) = (Vec::new(), Vec::new());
        for (i, centre) in (0..5).flat_map(|i| [(i, 0.0_f32), (i, 1.4)]) {
            for k in 0..8 {
                let a = k as f32 * std::f32::consts::FRAC_PI_4;
                points.push([i as f32 * 0.5, centre + 0.4 * a.cos(), 0.4 * a.sin()]);
                nearest.push(i);
            }
        }
        let reach = [2.2, 2.2, 0.9, 0.9, 2.2];
        let (centroids, counts) = cross_section_centroids(&axis, &tangents, &points, &nearest, 0.2, 0.2, &reach);
        for i in 0..5 {
            let (own_only, y) = if reach[i] < 1.0 { (8, 0.0) } else { (16, 0.7) };
            assert_eq!(counts[i], own_only);
            assert!((centroids[i][1] - y).abs() < 1e-5, "{i}: {:?}", centroids[i]);
        }
    }

    #[test]
    fn a_cross_section_of_one_point_is_taken_over_the_wider_slab() {
        // a part of few Gaussians: an axis along x, points 0.5 apart; one Gaussian on each side in
        // turn, about one per radius (1)
        let axis: Vec<[f64; 3]> = (0..11).map(|i| [i as f64 * 0.5, 0.0, 0.0]).collect();
        let tangents = vec![[1.0, 0.0, 0.0]; 11];
        let points = [[1.2, -1.0, 0.0], [2.0, 1.0, 0.0], [2.8, -1.0, 0.0]];
        let nearest = [2, 4, 6];
        let (narrow, narrow_counts) =
            cross_section_centroids(&axis, &tangents, &points, &nearest, 0.5, 0.5, &vec![2.2; axis.len()]);
        let (centroids, counts) =
            cross_section_centroids(&axis, &tangents, &points, &nearest, 0.5, 1.0, &vec![2.2; axis.len()]);
        // at x = 2 the slab of half width 0.5 holds one Gaussian, and the axis went to its side
        assert_eq!((narrow[4], narrow_counts[4]), ([2.0, 1.0, 0.0], 1));
        // within 1 of the plane it holds all three
        assert_eq!(counts[4], 3);
        assert!((centroids[4][0] - 2.0).abs() < 1e-6 && (centroids[4][1] + 1.0 / 3.0).abs() < 1e-6);
        // a cross-section of two is kept as it was, and an empty one keeps its vertex
        assert_eq!((centroids[3], counts[3]), (narrow[3], 2));
        assert!((centroids[3][0] - 1.6).abs() < 1e-6 && centroids[3][1].abs() < 1e-6);
        assert_eq!((centroids[10], counts[10]), (axis[10], 0));
        // nearest vertices past the axis, or more of them than points, are skipped
        let (_, counts) =
            cross_section_centroids(&axis, &tangents, &points[..1], &[2, 40, -1], 0.5, 1.0, &vec![2.2; axis.len()]);
        assert_eq!(counts[2], 1);
    }

    #[test]
    fn bad_input_is_an_error() {
        assert_eq!(nearest_on_polyline(&[[0.0; 3]], &[], 1.0), Err(PolylineError::TooFewVertices(1)));
        assert_eq!(
            nearest_on_polyline(&[[0.0; 3], [f32::NAN, 0.0, 0.0]], &[], 1.0),
            Err(PolylineError::NonFiniteVertex(1))
        );
        assert_eq!(nearest_on_polyline(&[[0.0; 3], [1.0, 0.0, 0.0]], &[], 0.0), Err(PolylineError::BadReach(0.0)));
        // a repeated vertex (zero-length segment) is fine
        let found = nearest_on_polyline(&[[0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]], &[[0.5, 0.1, 0.0]], 1.0).unwrap();
        assert_eq!(found[0].map(|n| n.segment), Some(1));
    }
}
