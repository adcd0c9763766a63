//! Symmetric banded matrices and their LDL^T factorisation, the linear algebra of every Newton
//! step. A rod's Hessian couples only degrees of freedom within one bending stencil (11
//! consecutive unknowns), so a factorisation costs `O(N * bw^2)` with half-bandwidth `bw = 10`.

/// Lower band of a symmetric `n x n` matrix: entry `(i, j)` with `j <= i <= j + bw` is stored at
/// `data[i * (bw + 1) + (i - j)]`.
#[derive(Debug, Clone)]
pub struct BandedMatrix {
    n: usize,
    bw: usize,
    data: Vec<f64>,
}

/// Why a factorisation stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotPositiveDefinite {
    /// Row whose pivot was not positive.
    pub row: usize,
}

impl BandedMatrix {
    /// Zero matrix of size `n` with half-bandwidth `bw` (capped at `n - 1`).
    pub fn new(n: usize, bw: usize) -> Self {
        let bw = bw.min(n.saturating_sub(1));
        Self { n, bw, data: vec![0.0; n * (bw + 1)] }
    }

    pub fn size(&self) -> usize {
        self.n
    }

    pub fn bandwidth(&self) -> usize {
        self.bw
    }

    pub fn clear(&mut self) {
        self.data.iter_mut().for_each(|v| *v = 0.0);
    }

    /// Entry `(i, j)` of the symmetric matrix (zero outside the band).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        if i - j > self.bw { 0.0 } else { self.data[i * (self.bw + 1) + (i - j)] }
    }

    /// Adds `v` to entry `(i, j)` with `i >= j`, `i - j <= bw`.
    #[inline]
    pub fn add_lower(&mut self, i: usize, j: usize, v: f64) {
        debug_assert!(i >= j && i - j <= self.bw);
        self.data[i * (self.bw + 1) + (i - j)] += v;
    }

    /// Adds `v` to the diagonal entry `i`.
    #[inline]
    pub fn add_diag(&mut self, i: usize, v: f64) {
        self.data[i * (self.bw + 1)] += v;
    }

    pub fn diag(&self, i: usize) -> f64 {
        self.data[i * (self.bw + 1)]
    }

    /// Replaces row and column `i` by those of the identity (a fixed degree of freedom).
    pub fn fix(&mut self, i: usize) {
        let w = self.bw + 1;
        for k in 1..w {
            if k <= i {
                self.data[i * w + k] = 0.0;
            }
            if i + k < self.n {
                self.data[(i + k) * w + k] = 0.0;
            }
        }
        self.data[i * w] = 1.0;
    }

    /// `y = A x`.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        let w = self.bw + 1;
        for i in 0..self.n {
            y[i] += self.data[i * w] * x[i];
            for k in 1..w.min(i + 1) {
                let a = self.data[i * w + k];
                y[i] += a * x[i - k];
                y[i - k] += a * x[i];
            }
        }
        y
    }

    /// In-place LDL^T factorisation: afterwards the band holds the unit lower factor below the
    /// diagonal and `D` on it. Fails on a pivot below `min_pivot` times the original diagonal
    /// (the matrix is not positive definite enough to give a descent direction).
    pub fn factorize(&mut self, min_pivot: f64) -> Result<(), NotPositiveDefinite> {
        let w = self.bw + 1;
        let n = self.n;
        let mut tmp = vec![0.0; w];
        for j in 0..n {
            let first = j.saturating_sub(self.bw);
            // tmp[k] = L[j][k] * D[k] for k in first..j, using the row of j.
            let orig = self.data[j * w];
            let mut d = orig;
            for k in first..j {
                let l = self.data[j * w + (j - k)];
                let dk = self.data[k * w];
                tmp[j - k] = l * dk;
                d -= l * l * dk;
            }
            if d.is_nan() || d <= min_pivot * orig.abs().max(f64::MIN_POSITIVE) || d.is_infinite() {
                return Err(NotPositiveDefinite { row: j });
            }
            self.data[j * w] = d;
            for i in (j + 1)..(j + w).min(n) {
                let i_first = i.saturating_sub(self.bw);
                let mut s = self.data[i * w + (i - j)];
                for k in i_first.max(first)..j {
                    s -= self.data[i * w + (i - k)] * tmp[j - k];
                }
                self.data[i * w + (i - j)] = s / d;
            }
        }
        Ok(())
    }

    /// Solves `A x = b` in place after [`Self::factorize`].
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let w = self.bw + 1;
        let n = self.n;
        for i in 0..n {
            let first = i.saturating_sub(self.bw);
            let mut s = b[i];
            for k in first..i {
                s -= self.data[i * w + (i - k)] * b[k];
            }
            b[i] = s;
        }
        for i in 0..n {
            b[i] /= self.data[i * w];
        }
        for i in (0..n).rev() {
            let mut s = b[i];
            for k in (i + 1)..(i + w).min(n) {
                s -= self.data[k * w + (k - i)] * b[k];
            }
            b[i] = s;
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;
    use crate::test_rng::lcg;

    #[test]
    fn solves_random_banded_spd_system_like_dense() {
        let mut seed = 7;
        for (n, bw) in [(1, 10), (2, 10), (7, 10), (11, 10), (60, 10), (40, 3)] {
            let mut a = BandedMatrix::new(n, bw);
            let bw = a.bandwidth();
            // Diagonally dominant symmetric band matrix.
            for i in 0..n {
                for j in i.saturating_sub(bw)..i {
                    a.add_lower(i, j, lcg(&mut seed));
                }
            }
            for i in 0..n {
                let row: f64 = (0..n).filter(|&j| j != i).map(|j| a.get(i, j).abs()).sum();
                a.add_diag(i, row + 1.0);
            }
            let x: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
            let mut b = a.mul_vec(&x);
            let mut f = a.clone();
            f.factorize(1e-14).unwrap();
            f.solve_in_place(&mut b);
            for i in 0..n {
                assert!((b[i] - x[i]).abs() < 1e-10, "n={n} i={i}");
            }
        }
    }

    #[test]
    fn rejects_indefinite_and_fixes_rows() {
        let mut a = BandedMatrix::new(3, 2);
        a.add_diag(0, 1.0);
        a.add_diag(1, -1.0);
        a.add_diag(2, 1.0);
        assert_eq!(a.clone().factorize(1e-14), Err(NotPositiveDefinite { row: 1 }));
        a.add_lower(1, 0, 5.0);
        a.fix(1);
        assert_eq!(a.get(1, 0), 0.0);
        assert_eq!(a.get(1, 1), 1.0);
        assert!(a.factorize(1e-14).is_ok());
    }
}
