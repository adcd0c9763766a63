//! The rest shape that holds the captured shape under gravity (docs/contact.md, "Gravity that
//! keeps the captured shape"): an inverse static problem on the rod's own energy. A captured
//! hanging cable or drooping branch is already in equilibrium under its weight; simulated with its
//! captured shape as the rest shape, it would sag further before anyone touched it.
//!
//! Found by fixed-point iteration on the rest polyline: solve the static equilibrium under gravity
//! with the current rest shape, move the rest shape by the difference between the captured shape
//! and that equilibrium, and repeat. The rest curvatures, twists and lengths follow from the rest
//! polyline as for any rod, so the result is an ordinary rod. Where the boundary conditions cannot
//! carry the weight (a pinned end cannot hold a moment, a free rod falls), the equilibrium runs away
//! and the iteration stops with an error instead of a silent sag.

use super::*;

/// Iterations of the fixed point before giving up.
const MAX_HOLD_ITERATIONS: usize = 60;
/// The equilibrium must lie within this many radii of the captured shape.
const HOLD_TOLERANCE_RADII: f64 = 5.0e-3;
/// An update smaller than this share of the offsets makes no more progress: it cannot be held.
const MIN_SHARE: f64 = 1.0 / 64.0;
/// Past iterates Anderson acceleration combines.
const ANDERSON_DEPTH: usize = 5;

/// What [`ElasticRod::hold_under_gravity`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldReport {
    /// Fixed-point iterations (static solves) it took.
    pub iterations: usize,
    /// Largest distance of the equilibrium from the captured shape (m).
    pub deviation: f64,
}

impl ElasticRod {
    /// Changes the rest shape so that the rod, in its current shape and with its current pins and
    /// clamps, is in static equilibrium under its gravity: it then stays where it is until pulled,
    /// and returns there after a release. Velocities are zeroed. Without gravity nothing changes.
    ///
    /// Errors with [`RodError::CannotHold`] where no rest shape holds the current one (the
    /// boundary conditions cannot carry the weight); the rod is then left as it was.
    pub fn hold_under_gravity(&mut self, settings: &SolverSettings) -> Result<HoldReport, RodError> {
        settings.validate()?;
        if DVec3::from_array(self.params.gravity) == DVec3::ZERO {
            return Ok(HoldReport { iterations: 0, deviation: 0.0 });
        }
        if self.grab.is_some() {
            return Err(RodError::InvalidParameter {
                name: "grab",
                value: 1.0,
                reason: "release the grab before holding the shape under gravity",
            });
        }
        let captured: Vec<[f64; 3]> = self.state.x.iter().map(|p| p.to_array()).collect();
        let tolerance = HOLD_TOLERANCE_RADII * self.params.radius;
        // Anderson acceleration of the fixed point rest <- rest + offsets (the plain iteration
        // converges linearly, slowly where the rod slides along itself); where an update makes
        // things worse, back to the best rest shape with a plain, halved update.
        let mut rest: Vec<DVec3> = self.state.x.clone();
        let mut history: Vec<(Vec<DVec3>, Vec<DVec3>)> = Vec::new(); // (rest, offsets)
        let mut best: Option<(Vec<DVec3>, f64, Vec<DVec3>)> = None;
        let mut share = 1.0;
        for iteration in 1..=MAX_HOLD_ITERATIONS {
            let mut trial = self.with_rest_shape(&rest, &captured)?;
            trial.solve_static(settings)?;
            let (deviation, offsets) = trial.offsets_from(&captured);
            if deviation <= tolerance {
                *self = trial;
                return Ok(HoldReport { iterations: iteration, deviation });
            }
            if !deviation.is_finite() {
                break;
            }
            if best.as_ref().is_some_and(|(_, d, _)| deviation >= *d) {
                share *= 0.5;
                history.clear();
                if share < MIN_SHARE {
                    break;
                }
                let Some((base, _, step)) = &best else { break };
                rest = base.iter().zip(step).map(|(r, o)| *r + *o * share).collect();
                continue;
            }
            best = Some((rest.clone(), deviation, offsets.clone()));
            history.push((rest.clone(), offsets.clone()));
            if history.len() > ANDERSON_DEPTH + 1 {
                history.remove(0);
            }
            rest = anderson_update(&history, share);
        }
        let deviation = best.map_or(f64::INFINITY, |(_, d, _)| d);
        Err(RodError::CannotHold { deviation, radius: self.params.radius })
    }

    /// This rod with `rest` as its rest polyline, in the shape `captured`, with its pins and clamps
    /// at their captured positions. A clamp keeps the orientation of the rest shape there: the
    /// captured shape's end direction includes the droop under the weight, which the clamp must
    /// hold against.
    fn with_rest_shape(&self, rest: &[DVec3], captured: &[[f64; 3]]) -> Result<Self, RodError> {
        let polyline: Vec<[f64; 3]> = rest.iter().map(|p| p.to_array()).collect();
        let mut rod = ElasticRod::new(&polyline, self.params)?;
        let held: Vec<(usize, Boundary)> =
            self.boundary.iter().copied().enumerate().filter(|(_, b)| *b != Boundary::Free).collect();
        for &(vertex, boundary) in &held {
            rod.set_boundary(vertex, boundary)?; // at the rest shape: its frame there
        }
        rod.set_positions(captured)?;
        for &(vertex, boundary) in &held {
            let to = captured[vertex];
            match boundary {
                Boundary::Clamped => {
                    let by = (DVec3::from_array(to) - rest[vertex]).to_array();
                    rod.move_clamp(vertex, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], by)?;
                }
                _ => rod.pin_at(vertex, to)?,
            }
        }
        rod.obstacles = self.obstacles.clone();
        Ok(rod)
    }

    /// The largest distance of the current shape from `target`, and per vertex `target - x`.
    fn offsets_from(&self, target: &[[f64; 3]]) -> (f64, Vec<DVec3>) {
        let offsets: Vec<DVec3> = self.state.x.iter().zip(target).map(|(x, t)| DVec3::from_array(*t) - *x).collect();
        let deviation = offsets.iter().fold(0.0_f64, |m, o| m.max(o.length()));
        (deviation, offsets)
    }
}

/// The next rest shape from the last iterates `(rest, offsets)` (oldest first), by Anderson
/// acceleration (type II): the combination of the last steps that best cancels the offsets, then
/// the (`share` of the) plain update from it. With one iterate it is the plain update.
fn anderson_update(history: &[(Vec<DVec3>, Vec<DVec3>)], share: f64) -> Vec<DVec3> {
    let Some((rest, offsets)) = history.last() else { return Vec::new() };
    let m = history.len() - 1;
    let flat = |v: &[DVec3]| v.iter().flat_map(|p| p.to_array()).collect::<Vec<f64>>();
    let f = flat(offsets);
    // columns: differences of successive offsets (dF) and rests (dX)
    let diff = |a: &[DVec3], b: &[DVec3]| a.iter().zip(b).flat_map(|(x, y)| (*x - *y).to_array()).collect::<Vec<f64>>();
    let d_f: Vec<Vec<f64>> = history.windows(2).map(|w| diff(&w[1].1, &w[0].1)).collect();
    let d_x: Vec<Vec<f64>> = history.windows(2).map(|w| diff(&w[1].0, &w[0].0)).collect();
    // gamma = argmin |f - dF gamma|, by the normal equations (tiny, regularised)
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut a = vec![vec![0.0; m]; m];
    let mut b = vec![0.0; m];
    for i in 0..m {
        for j in 0..m {
            a[i][j] = dot(&d_f[i], &d_f[j]);
        }
        b[i] = dot(&d_f[i], &f);
    }
    let scale = (0..m).map(|i| a[i][i]).fold(0.0_f64, f64::max);
    for (i, row) in a.iter_mut().enumerate() {
        row[i] += 1e-10 * scale.max(f64::MIN_POSITIVE);
    }
    let gamma = solve_small(a, b).unwrap_or_else(|| vec![0.0; m]);
    let mut next: Vec<f64> = flat(rest).iter().zip(&f).map(|(r, o)| r + share * o).collect();
    for (k, g) in gamma.iter().enumerate() {
        for (i, n) in next.iter_mut().enumerate() {
            *n -= g * (d_x[k][i] + share * d_f[k][i]);
        }
    }
    next.chunks_exact(3).map(|c| DVec3::new(c[0], c[1], c[2])).collect()
}

/// Solves the small dense system `a x = b` by Gaussian elimination with partial pivoting; None
/// when it is singular.
fn solve_small(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..n {
            let factor = a[row][col] / a[col][col];
            for k in col..n {
                a[row][k] -= factor * a[col][k];
            }
            b[row] -= factor * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let sum: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - sum) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}
