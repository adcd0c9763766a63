//! What validating a scene needs to know about its arrays, found in one parallel pass: whether
//! each holds only finite values, and the ranges of the values that have limits. A reader (or
//! any caller) checks these few numbers and looks for the offending row only when one is off.

use rayon::prelude::*;

/// Values per parallel task.
const CHUNK: usize = 1 << 16;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneSummary {
    /// means, scales, quats, opacities, sh: no NaN or infinity.
    pub finite: [bool; 5],
    /// Smallest scale (+inf for no rows); only meaningful when the scales are finite.
    pub scale_min: f32,
    /// Smallest and largest opacity.
    pub opacity_range: (f32, f32),
    /// Smallest and largest squared quaternion length.
    pub quat_length_squared_range: (f32, f32),
}

/// Summarise row-major scene arrays (means, scales, quats (N, 4), opacities, sh).
pub fn summarize(means: &[f32], scales: &[f32], quats: &[f32], opacities: &[f32], sh: &[f32]) -> SceneSummary {
    let finite = [means, scales, quats, opacities, sh].map(all_finite);
    let scale_min = scales
        .par_chunks(CHUNK)
        .map(|c| c.iter().fold(f32::INFINITY, |m, &v| m.min(v)))
        .reduce(|| f32::INFINITY, f32::min);
    let opacity_range = opacities
        .par_chunks(CHUNK)
        .map(|c| c.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v))))
        .reduce(|| (f32::INFINITY, f32::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let quat_length_squared_range = quats
        .as_chunks::<4>()
        .0
        .par_chunks(CHUNK / 4)
        .map(|rows| {
            rows.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), q| {
                let squared = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
                (lo.min(squared), hi.max(squared))
            })
        })
        .reduce(|| (f32::INFINITY, f32::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    SceneSummary { finite, scale_min, opacity_range, quat_length_squared_range }
}

fn all_finite(values: &[f32]) -> bool {
    // a fold without early exit, so that the compiler can vectorise it
    values.par_chunks(CHUNK).all(|c| c.iter().fold(true, |ok, v| ok & v.is_finite()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_non_finite_values_and_ranges() {
        let means = vec![0.0; 3 * 100_000];
        let mut sh = vec![0.5; 3 * 100_000];
        let scales = vec![0.25; 3 * 100_000];
        let mut quats = vec![0.0; 4 * 100_000];
        quats.iter_mut().step_by(4).for_each(|w| *w = 1.0);
        quats[4 * 70_000] = 2.0;
        let mut opacities = vec![0.5; 100_000];
        opacities[99_999] = 0.0;
        let summary = summarize(&means, &scales, &quats, &opacities, &sh);
        assert_eq!(summary.finite, [true; 5]);
        assert_eq!(summary.scale_min, 0.25);
        assert_eq!(summary.opacity_range, (0.0, 0.5));
        assert_eq!(summary.quat_length_squared_range, (1.0, 4.0));
        sh[250_000] = f32::NAN;
        assert_eq!(summarize(&means, &scales, &quats, &opacities, &sh).finite, [true, true, true, true, false]);
    }
}
