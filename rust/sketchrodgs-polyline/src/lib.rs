//! Nearest point on a 3D polyline, for many query points, within a reach.
//!
//! Binding Gaussians to a rod (docs/deformation.md: each binds to its nearest point on the rest polyline)
//! and recentring the extracted polyline both ask, for tens of thousands of Gaussian centres,
//! which segment of a polyline is nearest and where on it. A uniform grid of cell size `reach`
//! over the segments makes each query look at a handful of segments; queries run in parallel and
//! the answer does not depend on the thread count.
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

pub mod proximity;

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
    points
        .par_chunks(ROWS_PER_TASK)
        .enumerate()
        .flat_map_iter(|(chunk, rows)| {
            let start = chunk * ROWS_PER_TASK;
            rows.iter().enumerate().filter_map(move |(k, p)| {
                let inside = (0..3).all(|a| p[a] >= low[a] && p[a] <= high[a]);
                inside.then_some((start + k) as u32)
            })
        })
        .collect()
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

/// Cells of the grid are `reach` wide, so a point's nearest segment within `reach` is registered in
/// the point's own cell (each segment is entered in every cell its grown bounding box touches).
/// The grid is dense over the polyline's grown bounding box; points outside it have no candidates.
struct SegmentGrid {
    reach: f64,
    origin: [f64; 3],
    dims: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl SegmentGrid {
    fn new(polyline: &[[f64; 3]], reach: f64) -> Self {
        let low: [f64; 3] =
            std::array::from_fn(|k| polyline.iter().map(|v| v[k]).fold(f64::INFINITY, f64::min) - reach);
        let high: [f64; 3] =
            std::array::from_fn(|k| polyline.iter().map(|v| v[k]).fold(f64::NEG_INFINITY, f64::max) + reach);
        // Keep the grid to a few million cells however small the reach is against the polyline.
        let mut cell = reach;
        while (0..3).map(|k| ((high[k] - low[k]) / cell).floor() + 1.0).product::<f64>() > 4.0e6 {
            cell *= 2.0;
        }
        let dims: [usize; 3] = std::array::from_fn(|k| ((high[k] - low[k]) / cell).floor() as usize + 1);
        let mut grid = Self { reach: cell, origin: low, dims, cells: vec![Vec::new(); dims[0] * dims[1] * dims[2]] };
        for (i, w) in polyline.windows(2).enumerate() {
            let lo = grid.cell_of(std::array::from_fn(|k| w[0][k].min(w[1][k]) - reach));
            let hi = grid.cell_of(std::array::from_fn(|k| w[0][k].max(w[1][k]) + reach));
            if let (Some(lo), Some(hi)) = (lo, hi) {
                for x in lo[0]..=hi[0] {
                    for y in lo[1]..=hi[1] {
                        for z in lo[2]..=hi[2] {
                            grid.cells[(x * dims[1] + y) * dims[2] + z].push(i as u32);
                        }
                    }
                }
            }
        }
        grid
    }

    fn cell_of(&self, p: [f64; 3]) -> Option<[usize; 3]> {
        let mut cell = [0; 3];
        for k in 0..3 {
            let c = ((p[k] - self.origin[k]) / self.reach).floor();
            // clamp by a hair: bounds computed from the same vertices may round just outside
            if !(c >= -1.0 && c <= self.dims[k] as f64) {
                return None;
            }
            cell[k] = (c.max(0.0) as usize).min(self.dims[k] - 1);
        }
        Some(cell)
    }

    fn candidates(&self, p: [f64; 3]) -> &[u32] {
        match self.cell_of(p) {
            Some(c) => &self.cells[(c[0] * self.dims[1] + c[1]) * self.dims[2] + c[2]],
            None => &[],
        }
    }
}

/// For each point, the nearest point on `polyline` if it is within `reach`, else `None`.
/// Among equally near segments the lower index wins.
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
    let grid = SegmentGrid::new(&vertices, reach);
    let reach2 = reach * reach;
    Ok(points
        .par_iter()
        .map(|p| {
            let p = p.map(f64::from);
            let mut best: Option<(f64, u32, f64)> = None;
            for &i in grid.candidates(p) {
                let (a, b) = (vertices[i as usize], vertices[i as usize + 1]);
                let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
                let length2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
                let t = if length2 > 0.0 {
                    ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / length2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let d2: f64 = (0..3).map(|k| (ap[k] - t * ab[k]).powi(2)).sum();
                if d2 <= reach2 && best.is_none_or(|(bd, bi, _)| d2 < bd || (d2 == bd && i < bi)) {
                    best = Some((d2, i, t));
                }
            }
            best.map(|(d2, i, t)| Nearest { segment: i, t: t as f32, distance: d2.sqrt() as f32 })
        })
        .collect())
}

/// Centroid of each polyline vertex's cross-section: the points within `half_width` of the plane
/// through vertex `i` across `tangents[i]` and within `reach` of the vertex. A point is tried
/// against its `nearest_vertex` and that vertex's two neighbours only (-1: no nearest vertex).
/// Vertices with an empty cross-section keep their position. Returns the centroids and counts.
pub fn cross_section_centroids(
    axis: &[[f64; 3]],
    tangents: &[[f64; 3]],
    points: &[[f32; 3]],
    nearest_vertex: &[i32],
    half_width: f64,
    reach: f64,
) -> (Vec<[f64; 3]>, Vec<u32>) {
    let mut sums = vec![[0.0_f64; 3]; axis.len()];
    let mut counts = vec![0_u32; axis.len()];
    for (p, &n) in points.iter().zip(nearest_vertex) {
        let Ok(n) = usize::try_from(n) else { continue };
        let p = p.map(f64::from);
        for i in n.saturating_sub(1)..=(n + 1).min(axis.len().saturating_sub(1)) {
            let (Some(a), Some(t)) = (axis.get(i), tangents.get(i)) else { continue };
            let d = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
            let along = d[0] * t[0] + d[1] * t[1] + d[2] * t[2];
            if along.abs() <= half_width && d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= reach * reach {
                for k in 0..3 {
                    sums[i][k] += p[k];
                }
                counts[i] += 1;
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

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
        let (centroids, counts) = cross_section_centroids(&axis, &tangents, &points, &nearest, 0.25, 2.2);
        for (c, n) in centroids.iter().zip(&counts) {
            assert_eq!(*n, 8); // half width 0.25 < spacing 0.5: only its own ring
            assert!(c[1].abs() < 1e-6 && c[2].abs() < 1e-6, "{c:?}");
        }
        // a vertex with nothing around keeps its place; points without a nearest vertex are skipped
        let (centroids, counts) =
            cross_section_centroids(&axis[..2], &tangents[..2], &[[9.0, 9.0, 9.0]], &[-1], 0.25, 2.2);
        assert_eq!((centroids[0], counts[0]), (axis[0], 0));
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
