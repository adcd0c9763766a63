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
    if let Some(&row) = rows.iter().find(|&&r| r >= means.len()) {
        return Err(FieldError::Row { row, count: means.len() });
    }
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
    let splat = |mut alpha: Vec<f32>, g: usize| {
        splat_one(grid, means[g], scales[g], quats[g], opacities[g], &mut alpha);
        alpha
    };
    Ok(rows.with_min_len(4096).fold(|| vec![0.0f32; cells], splat).reduce(
        || vec![0.0f32; cells],
        |mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x = x.max(y));
            a
        },
    ))
}

/// Adds one Gaussian to `alpha`.
fn splat_one(grid: &Grid, mean: [f32; 3], scale: [f32; 3], quat: [f32; 4], opacity: f32, alpha: &mut [f32]) {
    if opacity.is_nan() || opacity <= 0.0 || mean.iter().chain(&scale).chain(&quat).any(|v| !v.is_finite()) {
        return;
    }
    let m = mean.map(f64::from);
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
    let h = grid.spacing;
    let cell_of = |v: f64, axis: usize| ((v - grid.origin[axis]) / h).round();
    let range = |axis: usize| {
        let low = cell_of(m[axis] - half[axis], axis).max(0.0);
        let high = cell_of(m[axis] + half[axis], axis).min(grid.dims[axis] as f64 - 1.0);
        (low as usize, high as usize, low <= high)
    };
    let [(i0, i1, ok_x), (j0, j1, ok_y), (k0, k1, ok_z)] = [range(0), range(1), range(2)];
    let [nx, ny, _] = grid.dims;
    if ok_x && ok_y && ok_z {
        for k in k0..=k1 {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let d = [
                        grid.origin[0] + i as f64 * h - m[0],
                        grid.origin[1] + j as f64 * h - m[1],
                        grid.origin[2] + k as f64 * h - m[2],
                    ];
                    let q: f64 = (0..3).map(|a| (0..3).map(|b| d[a] * inverse[a][b] * d[b]).sum::<f64>()).sum();
                    let value = (f64::from(opacity) * (-0.5 * q).exp()) as f32;
                    let cell = &mut alpha[i + nx * (j + ny * k)];
                    *cell = cell.max(value);
                }
            }
        }
    }
    // the cell holding the centre, whatever the Gaussian's size
    let centre = [cell_of(m[0], 0), cell_of(m[1], 1), cell_of(m[2], 2)];
    if centre.iter().zip(grid.dims).all(|(c, n)| *c >= 0.0 && *c < n as f64) {
        let cell = &mut alpha[centre[0] as usize + nx * (centre[1] as usize + ny * centre[2] as usize)];
        *cell = cell.max(opacity);
    }
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
