//! The static scene as solid matter for contact (docs/contact.md): per cell of a regular grid,
//! the largest opacity any Gaussian reaches at the cell's centre, `o exp(-q/2)` with `q` the
//! Mahalanobis distance squared. A Gaussian smaller than a cell is not missed: the cell that holds
//! its centre counts its full opacity. The caller thresholds this into solid cells and turns them
//! into a signed distance field (`sketchrodgs.contact`).
//!
//! ```
//! use sketchrodgs_field::{Grid, max_alpha};
//! // one opaque round Gaussian at the origin, sigma 0.1, on a grid of 0.05 cells around it
//! let grid = Grid { origin: [-0.5; 3], spacing: 0.05, dims: [21, 21, 21] };
//! let alpha = max_alpha(&grid, &[[0.0; 3]], &[[0.1; 3]], &[[1.0, 0.0, 0.0, 0.0]], &[0.9]).unwrap();
//! assert!((alpha[10 + 21 * (10 + 21 * 10)] - 0.9).abs() < 1e-6); // the centre's cell
//! assert_eq!(alpha[0], 0.0); // a corner, 8 sigma away
//! ```

use rayon::prelude::*;

/// Cells a Gaussian reaches: its centre's and those within this many sigma of it.
pub const SIGMA_EXTENT: f64 = 3.0;
/// The most cells a grid may have (about 256 MB of f32).
pub const MAX_CELLS: usize = 64 << 20;

/// Things that make a field impossible. Each names what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FieldError {
    #[error("grid: spacing must be finite and > 0, got {0}")]
    Spacing(f64),
    #[error("grid: origin must be finite, got {0:?}")]
    Origin([f64; 3]),
    #[error("grid: {dims:?} cells is more than the {max} allowed; use a larger spacing")]
    TooManyCells { dims: [usize; 3], max: usize },
    #[error("{name}: {got} rows but means has {want}")]
    Lengths { name: &'static str, got: usize, want: usize },
    #[error("row {row} is not one of the {count} Gaussians")]
    Row { row: usize, count: usize },
    #[error("samples: expected 1 to {MAX_EDGE_SAMPLES} per edge, got {0}")]
    Samples(usize),
    #[error("edges: the edge from node {node:?} along axis {axis} leaves the grid of {dims:?} nodes")]
    Edge { node: [usize; 3], axis: usize, dims: [usize; 3] },
}

/// A regular grid: cell `(i, j, k)` has its centre at `origin + spacing * (i, j, k)`; cells are
/// stored `i` fastest, then `j`, then `k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub origin: [f64; 3],
    pub spacing: f64,
    pub dims: [usize; 3],
}

impl Grid {
    fn cells(&self) -> Result<usize, FieldError> {
        if !(self.spacing.is_finite() && self.spacing > 0.0) {
            return Err(FieldError::Spacing(self.spacing));
        }
        if self.origin.iter().any(|c| !c.is_finite()) {
            return Err(FieldError::Origin(self.origin));
        }
        let count = self.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        match count {
            Some(c) if c <= MAX_CELLS => Ok(c),
            _ => Err(FieldError::TooManyCells { dims: self.dims, max: MAX_CELLS }),
        }
    }
}

/// Per cell of `grid`, the largest `o exp(-q/2)` of the Gaussians (means, scales, unit quaternions
/// `w, x, y, z`, opacities) at its centre; the cell holding a Gaussian's centre counts at least
/// its opacity. Results do not depend on the thread count (a maximum).
pub fn max_alpha(
    grid: &Grid,
    means: &[[f32; 3]],
    scales: &[[f32; 3]],
    quats: &[[f32; 4]],
    opacities: &[f32],
) -> Result<Vec<f32>, FieldError> {
    check_lengths(means, scales, quats, opacities)?;
    splat_rows(grid, means, scales, quats, opacities, (0..means.len()).into_par_iter())
}

/// [`max_alpha`] of the Gaussians `rows` only (of a whole scene's arrays: nothing is copied).
pub fn max_alpha_of_rows(
    grid: &Grid,
    means: &[[f32; 3]],
    scales: &[[f32; 3]],
    quats: &[[f32; 4]],
    opacities: &[f32],
    rows: &[usize],
) -> Result<Vec<f32>, FieldError> {
    check_lengths(means, scales, quats, opacities)?;
    check_rows(rows, means.len())?;
    splat_rows(grid, means, scales, quats, opacities, rows.par_iter().copied())
}

fn check_lengths(
    means: &[[f32; 3]],
    scales: &[[f32; 3]],
    quats: &[[f32; 4]],
    opacities: &[f32],
) -> Result<(), FieldError> {
    for (name, got) in [("scales", scales.len()), ("quats", quats.len()), ("opacities", opacities.len())] {
        if got != means.len() {
            return Err(FieldError::Lengths { name, got, want: means.len() });
        }
    }
    Ok(())
}

fn check_rows(rows: &[usize], count: usize) -> Result<(), FieldError> {
    match rows.iter().find(|&&r| r >= count) {
        Some(&row) => Err(FieldError::Row { row, count }),
        None => Ok(()),
    }
}

/// `len` values, each the largest that `add` (a row's contribution, as a maximum into the values)
/// gives over `rows`: every thread its own values, merged by maximum, so the result does not
/// depend on the thread count.
fn max_over_rows(
    rows: impl IndexedParallelIterator<Item = usize>,
    len: usize,
    add: impl Fn(&mut [f32], usize) + Sync + Send,
) -> Vec<f32> {
    let fold = |mut values: Vec<f32>, row: usize| {
        add(&mut values, row);
        values
    };
    rows.with_min_len(4096).fold(|| vec![0.0f32; len], fold).reduce(
        || vec![0.0f32; len],
        |mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x = x.max(y));
            a
        },
    )
}

/// Every row's Gaussian splatted into the grid, in parallel (each thread its own grid, merged by
/// maximum).
fn splat_rows(
    grid: &Grid,
    means: &[[f32; 3]],
    scales: &[[f32; 3]],
    quats: &[[f32; 4]],
    opacities: &[f32],
    rows: impl IndexedParallelIterator<Item = usize>,
) -> Result<Vec<f32>, FieldError> {
    let cells = grid.cells()?;
    Ok(max_over_rows(rows, cells, |alpha, g| splat_one(grid, means[g], scales[g], quats[g], opacities[g], alpha)))
}

/// One Gaussian as the field sees it: `o exp(-q/2)` around its mean, reaching `half` per world
/// axis (its 3-sigma box).
struct Kernel {
    mean: [f64; 3],
    inverse: [[f64; 3]; 3],
    half: [f64; 3],
    opacity: f32,
}

impl Kernel {
    /// None for a Gaussian that reaches nothing (no opacity, or not finite).
    fn new(mean: [f32; 3], scale: [f32; 3], quat: [f32; 4], opacity: f32) -> Option<Self> {
        if opacity.is_nan() || opacity <= 0.0 || mean.iter().chain(&scale).chain(&quat).any(|v| !v.is_finite()) {
            return None;
        }
        let r = rotation(quat.map(f64::from));
        let s = scale.map(|v| f64::from(v).abs().max(1e-12));
        // the inverse covariance R S^-2 R^T, and the half extent of the 3-sigma box per world axis
        let mut inverse = [[0.0; 3]; 3];
        let mut half = [0.0; 3];
        for a in 0..3 {
            for b in 0..3 {
                inverse[a][b] = (0..3).map(|k| r[a][k] * r[b][k] / (s[k] * s[k])).sum();
            }
            half[a] = SIGMA_EXTENT * (0..3).map(|k| (r[a][k] * s[k]).powi(2)).sum::<f64>().sqrt();
        }
        Some(Kernel { mean: mean.map(f64::from), inverse, half, opacity })
    }

    /// Its opacity at `p`.
    fn alpha_at(&self, p: [f64; 3]) -> f32 {
        let d = [p[0] - self.mean[0], p[1] - self.mean[1], p[2] - self.mean[2]];
        let q: f64 = (0..3).map(|a| (0..3).map(|b| d[a] * self.inverse[a][b] * d[b]).sum::<f64>()).sum();
        (f64::from(self.opacity) * (-0.5 * q).exp()) as f32
    }

    /// Its `q` along the line from `p` along `axis`, as `(q0, b, c)` of `q0 + 2 b u + c u^2`.
    fn along(&self, p: [f64; 3], axis: usize) -> (f64, f64, f64) {
        let d = [p[0] - self.mean[0], p[1] - self.mean[1], p[2] - self.mean[2]];
        let row = |a: usize| (0..3).map(|k| self.inverse[a][k] * d[k]).sum::<f64>();
        let q0 = (0..3).map(|a| d[a] * row(a)).sum::<f64>();
        (q0, row(axis), self.inverse[axis][axis])
    }

    /// The nodes of `grid` its box covers along `axis`, from `below` nodes lower (None: none).
    fn nodes(&self, grid: &Grid, axis: usize, below: f64) -> Option<(usize, usize)> {
        let low = (grid.cell_of(self.mean[axis] - self.half[axis], axis) - below).max(0.0);
        let high = grid.cell_of(self.mean[axis] + self.half[axis], axis).min(grid.dims[axis] as f64 - 1.0);
        (low <= high).then_some((low as usize, high as usize))
    }
}

impl Grid {
    /// The (unrounded to an index, possibly outside) node nearest `v` along `axis`.
    fn cell_of(&self, v: f64, axis: usize) -> f64 {
        ((v - self.origin[axis]) / self.spacing).round()
    }

    fn node(&self, node: [usize; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| self.origin[a] + node[a] as f64 * self.spacing)
    }
}

/// Adds one Gaussian to `alpha`.
fn splat_one(grid: &Grid, mean: [f32; 3], scale: [f32; 3], quat: [f32; 4], opacity: f32, alpha: &mut [f32]) {
    let Some(kernel) = Kernel::new(mean, scale, quat, opacity) else { return };
    let [nx, ny, _] = grid.dims;
    if let (Some((i0, i1)), Some((j0, j1)), Some((k0, k1))) =
        (kernel.nodes(grid, 0, 0.0), kernel.nodes(grid, 1, 0.0), kernel.nodes(grid, 2, 0.0))
    {
        for k in k0..=k1 {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let cell = &mut alpha[i + nx * (j + ny * k)];
                    *cell = cell.max(kernel.alpha_at(grid.node([i, j, k])));
                }
            }
        }
    }
    // the cell holding the centre, whatever the Gaussian's size
    let centre = [0, 1, 2].map(|a| grid.cell_of(kernel.mean[a], a));
    if centre.iter().zip(grid.dims).all(|(c, n)| *c >= 0.0 && *c < n as f64) {
        let cell = &mut alpha[centre[0] as usize + nx * (centre[1] as usize + ny * centre[2] as usize)];
        *cell = cell.max(opacity);
    }
}

/// A grid line from a node to the next node along `axis` (0: x, 1: y, 2: z).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    pub node: [usize; 3],
    pub axis: usize,
}

/// The most samples along an edge.
pub const MAX_EDGE_SAMPLES: usize = 64;

/// Per edge, the largest `o exp(-q/2)` (within 3 sigma) of the Gaussians `rows` at `samples + 1` points evenly
/// spaced from its node to the next, both included: `(samples + 1)` values per edge, in the order
/// of `edges`. Where the boundary of the solid crosses an edge is then found along it instead of
/// interpolated between two nodes (docs/contact.md: linear in alpha, a cell of about a radius put
/// a rod 0.07 R into a slab). Unlike [`max_alpha`] a Gaussian smaller than the spacing counts
/// only where it reaches. Results do not depend on the thread count.
#[allow(clippy::too_many_arguments)]
pub fn max_alpha_along_edges(
    grid: &Grid,
    means: &[[f32; 3]],
    scales: &[[f32; 3]],
    quats: &[[f32; 4]],
    opacities: &[f32],
    rows: &[usize],
    edges: &[Edge],
    samples: usize,
) -> Result<Vec<f32>, FieldError> {
    check_lengths(means, scales, quats, opacities)?;
    grid.cells()?;
    check_rows(rows, means.len())?;
    if !(1..=MAX_EDGE_SAMPLES).contains(&samples) {
        return Err(FieldError::Samples(samples));
    }
    if let Some(edge) =
        edges.iter().find(|e| e.axis > 2 || (0..3).any(|a| e.node[a] + usize::from(a == e.axis) >= grid.dims[a]))
    {
        return Err(FieldError::Edge { node: edge.node, axis: edge.axis, dims: grid.dims });
    }
    let values = edges.len().checked_mul(samples + 1).filter(|&v| v <= MAX_CELLS);
    let Some(values) = values else {
        return Err(FieldError::TooManyCells { dims: [edges.len(), samples + 1, 1], max: MAX_CELLS });
    };
    // the edges by node, x fastest: those from one row of nodes (j, k) lie together
    let [nx, ny, _] = grid.dims;
    let linear = |n: [usize; 3]| n[0] + nx * (n[1] + ny * n[2]);
    let mut order: Vec<u32> = (0..edges.len() as u32).collect();
    order.sort_unstable_by_key(|&e| (linear(edges[e as usize].node), edges[e as usize].axis));
    let keys: Vec<usize> = order.iter().map(|&e| linear(edges[e as usize].node)).collect();
    let step = grid.spacing / samples as f64;
    let splat = |out: &mut [f32], g: usize| {
        let Some(kernel) = Kernel::new(means[g], scales[g], quats[g], opacities[g]) else { return };
        // an edge from one node below the box can reach into it
        let (Some((i0, i1)), Some((j0, j1)), Some((k0, k1))) =
            (kernel.nodes(grid, 0, 1.0), kernel.nodes(grid, 1, 1.0), kernel.nodes(grid, 2, 1.0))
        else {
            return;
        };
        for k in k0..=k1 {
            for j in j0..=j1 {
                let first = keys.partition_point(|&key| key < linear([i0, j, k]));
                let last = keys.partition_point(|&key| key <= linear([i1, j, k]));
                for &e in &order[first..last] {
                    let Edge { node, axis } = edges[e as usize];
                    // q along the line, u from its node: q0 + 2 b u + c u^2
                    let (q0, b, c) = kernel.along(grid.node(node), axis);
                    // c > 0: the inverse covariance is positive definite
                    let closest = (-b / c).clamp(0.0, grid.spacing);
                    if q0 + closest * (2.0 * b + c * closest) > SIGMA_EXTENT * SIGMA_EXTENT {
                        continue; // beyond 3 sigma all along
                    }
                    let base = e as usize * (samples + 1);
                    for s in 0..=samples {
                        let u = s as f64 * step;
                        let q = q0 + u * (2.0 * b + c * u);
                        let value = &mut out[base + s];
                        *value = value.max((f64::from(kernel.opacity) * (-0.5 * q).exp()) as f32);
                    }
                }
            }
        }
    };
    Ok(max_over_rows(rows.par_iter().copied(), values, splat))
}

/// Row-major rotation matrix of a quaternion `w, x, y, z` (normalised here).
fn rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_gaussian_fills_a_slab_of_cells() {
        // a disc in the x-y plane (sigma 0.2 across, 0.01 thick), tilted 90 degrees about x: it
        // then lies in the x-z plane, thin along y
        let grid = Grid { origin: [-0.5; 3], spacing: 0.05, dims: [21, 21, 21] };
        let turn = std::f32::consts::FRAC_PI_4; // half the angle
        let quat = [turn.cos(), turn.sin(), 0.0, 0.0];
        let alpha = max_alpha(&grid, &[[0.0; 3]], &[[0.2, 0.2, 0.01]], &[quat], &[1.0]).unwrap();
        let at = |i: usize, j: usize, k: usize| alpha[i + 21 * (j + 21 * k)];
        assert!(at(14, 10, 10) > 0.5 && at(10, 10, 14) > 0.5); // 0.2 along x and along z
        assert!(at(10, 12, 10) < 1e-3); // 0.1 along y: ten sigma
    }

    #[test]
    fn a_gaussian_smaller_than_a_cell_still_counts() {
        let grid = Grid { origin: [0.0; 3], spacing: 1.0, dims: [4, 4, 4] };
        let alpha = max_alpha(&grid, &[[1.3, 2.2, 0.6]], &[[0.01; 3]], &[[1.0, 0.0, 0.0, 0.0]], &[0.7]).unwrap();
        assert_eq!(alpha[1 + 4 * (2 + 4)], 0.7);
        assert_eq!(alpha.iter().filter(|&&a| a > 0.0).count(), 1);
    }

    #[test]
    fn samples_along_edges_run_from_node_to_node() {
        let grid = Grid { origin: [0.0; 3], spacing: 0.1, dims: [8, 8, 8] };
        let (means, scales) = ([[0.33f32, 0.36, 0.31], [0.56, 0.3, 0.3]], [[0.08f32, 0.05, 0.06], [0.04; 3]]);
        let (quats, opacities) = ([[0.9f32, 0.1, 0.3, -0.2], [1.0, 0.0, 0.0, 0.0]], [0.8f32, 0.95]);
        let at_nodes = max_alpha(&grid, &means, &scales, &quats, &opacities).unwrap();
        let node = |n: [usize; 3]| at_nodes[n[0] + 8 * (n[1] + 8 * n[2])];
        let edges =
            [Edge { node: [2, 3, 3], axis: 0 }, Edge { node: [4, 2, 3], axis: 1 }, Edge { node: [5, 3, 2], axis: 2 }];
        let along = max_alpha_along_edges(&grid, &means, &scales, &quats, &opacities, &[0, 1], &edges, 4).unwrap();
        assert_eq!(along.len(), 15);
        for (e, edge) in edges.iter().enumerate() {
            let mut next = edge.node;
            next[edge.axis] += 1;
            // the ends are the nodes' values (none of these nodes holds a centre)
            assert!((along[5 * e] - node(edge.node)).abs() < 1e-6);
            assert!((along[5 * e + 4] - node(next)).abs() < 1e-6);
            // the middle is the Gaussians' own value there
            let mut p = grid.node(edge.node);
            p[edge.axis] += 0.05;
            let want = (0..2)
                .filter_map(|g| Kernel::new(means[g], scales[g], quats[g], opacities[g]))
                .map(|k| k.alpha_at(p))
                .fold(0.0f32, f32::max);
            assert!((along[5 * e + 2] - want).abs() < 1e-6, "{} {want}", along[5 * e + 2]);
            assert!(want > 0.01, "edge {e}: {want}");
        }
        // a Gaussian between two nodes, thinner than the spacing, is seen on the edge between them
        let thin = max_alpha_along_edges(
            &grid,
            &[[0.35, 0.3, 0.3]],
            &[[0.01; 3]],
            &[[1.0, 0.0, 0.0, 0.0]],
            &[1.0],
            &[0],
            &[Edge { node: [3, 3, 3], axis: 0 }],
            2,
        )
        .unwrap();
        assert!(thin[0] < 1e-3 && thin[1] > 0.99 && thin[2] < 1e-3);
        // bad edges and sample counts are errors
        let one = |edges: &[Edge], samples: usize| {
            max_alpha_along_edges(&grid, &means, &scales, &quats, &opacities, &[0], edges, samples)
        };
        assert!(matches!(one(&[Edge { node: [7, 0, 0], axis: 0 }], 4), Err(FieldError::Edge { .. })));
        assert!(matches!(one(&[Edge { node: [0, 0, 0], axis: 3 }], 4), Err(FieldError::Edge { .. })));
        assert!(matches!(one(&edges, 0), Err(FieldError::Samples(0))));
        assert!(one(&[], 4).unwrap().is_empty());
    }

    #[test]
    fn bad_grids_and_inputs_are_errors() {
        let ok = Grid { origin: [0.0; 3], spacing: 1.0, dims: [2, 2, 2] };
        let one = |grid: &Grid| max_alpha(grid, &[[0.0; 3]], &[[1.0; 3]], &[[1.0, 0.0, 0.0, 0.0]], &[1.0]);
        assert!(matches!(one(&Grid { spacing: 0.0, ..ok }), Err(FieldError::Spacing(_))));
        assert!(matches!(one(&Grid { origin: [f64::NAN, 0.0, 0.0], ..ok }), Err(FieldError::Origin(_))));
        assert!(matches!(one(&Grid { dims: [1 << 20, 1 << 20, 2], ..ok }), Err(FieldError::TooManyCells { .. })));
        assert!(matches!(max_alpha(&ok, &[[0.0; 3]], &[], &[], &[]), Err(FieldError::Lengths { .. })));
        let (m, s, q, o) = ([[0.0f32; 3]], [[1.0f32; 3]], [[1.0f32, 0.0, 0.0, 0.0]], [1.0f32]);
        assert!(matches!(max_alpha_of_rows(&ok, &m, &s, &q, &o, &[1]), Err(FieldError::Row { row: 1, .. })));
        assert_eq!(max_alpha_of_rows(&ok, &m, &s, &q, &o, &[0]).unwrap(), max_alpha(&ok, &m, &s, &q, &o).unwrap());
        assert!(max_alpha_of_rows(&ok, &m, &s, &q, &o, &[]).unwrap().iter().all(|&a| a == 0.0));
        // a NaN Gaussian is skipped, not spread
        let alpha = max_alpha(&ok, &[[f32::NAN; 3]], &[[1.0; 3]], &[[1.0, 0.0, 0.0, 0.0]], &[1.0]).unwrap();
        assert!(alpha.iter().all(|&a| a == 0.0));
    }
}
