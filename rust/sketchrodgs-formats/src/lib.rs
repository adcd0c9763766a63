//! Decoders for the quantised Gaussian-splat formats: Niantic SPZ, the PlayCanvas compressed
//! PLY and antimatter15 `.splat`. They turn the packed bytes of a file into activated float
//! arrays (means, linear scales, unit w-first quaternions, opacities, SH coefficients), a block of
//! splats per task in parallel.
//!
//! `summary` gives, in one parallel pass, what validating any scene's arrays needs; `table`
//! gathers the columns of a binary PLY's rows.
//!
//! Only the per-splat arithmetic and gzip inflation live here; reading headers, checking sizes
//! and naming what is wrong with a file are the caller's (the Python package's) work. Every
//! decoded value comes from a byte through a finite formula, so the outputs are always finite.

use rayon::prelude::*;

pub mod compressed_ply;
pub mod gzip;
pub mod splat;
pub mod spz;
pub mod summary;
pub mod table;

/// Splats per parallel task: a task's inputs and outputs (about 1 MB at SH degree 3) stay in
/// cache, and a million splats make enough tasks to keep every core busy.
const BLOCK: usize = 16 * 1024;

/// The degree-0 SH basis constant: rgb = 0.5 + SH_C0 * dc.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;

/// Inputs whose sizes disagree with each other (a caller's bug, not a bad file).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{name}: expected {expected} values, got {got}")]
pub struct SizeError {
    pub name: &'static str,
    pub expected: usize,
    pub got: usize,
}

/// Check that `got` equals `expected`.
pub(crate) fn check_len(name: &'static str, got: usize, expected: usize) -> Result<(), SizeError> {
    if got == expected { Ok(()) } else { Err(SizeError { name, expected, got }) }
}

/// Where decoded splats go: row-major arrays of one scene, `sh_coefficients` (1, 4, 9 or 16)
/// coefficients of 3 channels per splat in `sh`.
pub struct SplatsMut<'a> {
    pub means: &'a mut [f32],
    pub scales: &'a mut [f32],
    pub quats: &'a mut [f32],
    pub opacities: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub sh_coefficients: usize,
}

/// The outputs of one block of consecutive splats, starting at splat `start`.
pub(crate) struct Block<'a> {
    pub start: usize,
    pub means: &'a mut [[f32; 3]],
    pub scales: &'a mut [[f32; 3]],
    pub quats: &'a mut [[f32; 4]],
    pub opacities: &'a mut [f32],
    pub sh: &'a mut [f32],
}

impl SplatsMut<'_> {
    /// Number of splats, after checking that every array holds that many rows.
    pub fn count(&self) -> Result<usize, SizeError> {
        let n = self.opacities.len();
        check_len("means", self.means.len(), 3 * n)?;
        check_len("scales", self.scales.len(), 3 * n)?;
        check_len("quats", self.quats.len(), 4 * n)?;
        if ![1, 4, 9, 16].contains(&self.sh_coefficients) {
            return Err(SizeError { name: "sh coefficients per channel", expected: 16, got: self.sh_coefficients });
        }
        check_len("sh", self.sh.len(), 3 * self.sh_coefficients * n)?;
        Ok(n)
    }

    /// Run `decode` on blocks of `block` splats in parallel (the caller checked the sizes).
    pub(crate) fn for_each_block(self, block: usize, decode: impl Fn(Block<'_>) + Sync + Send) {
        let sh_row = 3 * self.sh_coefficients;
        (
            self.means.as_chunks_mut::<3>().0.par_chunks_mut(block),
            self.scales.as_chunks_mut::<3>().0.par_chunks_mut(block),
            self.quats.as_chunks_mut::<4>().0.par_chunks_mut(block),
            self.opacities.par_chunks_mut(block),
            self.sh.par_chunks_mut(block * sh_row),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(i, (means, scales, quats, opacities, sh))| {
                decode(Block { start: i * block, means, scales, quats, opacities, sh });
            });
    }
}

/// `(0..size).map(f)` evaluated in f64 and rounded to f32: the value of each byte (or bit field)
/// worked out once per file.
pub(crate) fn table(size: usize, f: impl Fn(f64) -> f64) -> Vec<f32> {
    (0..size).map(|i| f(i as f64) as f32).collect()
}

/// A unit quaternion from the "smallest three" encoding: `stored` holds the three kept
/// components in increasing component order, `largest` the index of the dropped one, and
/// `wxyz[c]` the format's index of output component c (w, x, y, z). The dropped component is
/// rebuilt as sqrt(1 - |stored|^2) (encoders make it positive); quantised components can have
/// |stored| > 1, and then it is 0 and the rest is scaled back to unit length.
#[inline]
pub(crate) fn smallest_three(stored: [f32; 3], largest: usize, wxyz: [usize; 4]) -> [f32; 4] {
    let squared = stored[0] * stored[0] + stored[1] * stored[1] + stored[2] * stored[2];
    let rebuilt = (1.0 - squared).max(0.0).sqrt();
    let mut q = [0.0_f32; 4];
    for (out, &component) in q.iter_mut().zip(&wxyz) {
        *out = match component.cmp(&largest) {
            std::cmp::Ordering::Less => stored[component],
            std::cmp::Ordering::Equal => rebuilt,
            std::cmp::Ordering::Greater => stored[component - 1],
        };
    }
    if squared > 1.0 {
        let norm = squared.sqrt();
        q.iter_mut().for_each(|c| *c /= norm);
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smallest_three_rebuilds_the_dropped_component() {
        // x, y, z, w order (SPZ): w dropped
        let q = smallest_three([0.5, -0.5, 0.25], 3, [3, 0, 1, 2]);
        assert_eq!(q, [0.661_437_8, 0.5, -0.5, 0.25]);
        // w, x, y, z order (compressed PLY): x dropped, stored w, y, z
        let q = smallest_three([0.5, 0.5, 0.5], 1, [0, 1, 2, 3]);
        assert_eq!(q, [0.5, 0.5, 0.5, 0.5]);
        // too long: dropped component 0, rest unit length
        let q = smallest_three([0.8, 0.8, 0.0], 0, [0, 1, 2, 3]);
        let norm: f32 = q.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-6 && q[0] == 0.0);
    }

    #[test]
    fn blocks_cover_every_splat_once() {
        let n = 2 * BLOCK + 17;
        let (mut means, mut scales, mut quats, mut opacities) =
            (vec![0.0; 3 * n], vec![0.0; 3 * n], vec![0.0; 4 * n], vec![0.0; n]);
        let mut sh = vec![0.0; 12 * n];
        let out = SplatsMut {
            means: &mut means,
            scales: &mut scales,
            quats: &mut quats,
            opacities: &mut opacities,
            sh: &mut sh,
            sh_coefficients: 4,
        };
        assert_eq!(out.count(), Ok(n));
        out.for_each_block(BLOCK, |block| {
            for (i, o) in block.opacities.iter_mut().enumerate() {
                *o += (block.start + i) as f32;
            }
            block.sh.iter_mut().for_each(|v| *v += 1.0);
        });
        assert!(opacities.iter().enumerate().all(|(i, &o)| o == i as f32));
        assert!(sh.iter().all(|&v| v == 1.0));
    }

    #[test]
    fn sizes_that_disagree_are_named() {
        let (mut a, mut b, mut c, mut d, mut e) =
            (vec![0.0; 6], vec![0.0; 6], vec![0.0; 8], vec![0.0; 2], vec![0.0; 5]);
        let out = SplatsMut {
            means: &mut a,
            scales: &mut b,
            quats: &mut c,
            opacities: &mut d,
            sh: &mut e,
            sh_coefficients: 1,
        };
        assert_eq!(out.count(), Err(SizeError { name: "sh", expected: 6, got: 5 }));
    }
}
