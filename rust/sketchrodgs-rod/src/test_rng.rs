//! Deterministic pseudo-random numbers for the unit tests (no dependency for a test-only need).

/// The next number in [-1, 1) of a 64-bit LCG whose state is `seed`.
pub(crate) fn lcg(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}
