//! SIMD lanes for blending, behind one trait ([`Lanes`]) so that the blend is written once: four
//! f32 lanes (SSE2 on x86_64, part of its baseline so always there; plain arrays elsewhere), on
//! x86_64 CPUs that have AVX2 eight ([`F32x8`]), and on those that also have AVX-512F sixteen
//! ([`F32x16`]: a whole tile row, or two half rows, per vector), the widest picked at run time by
//! [`Simd::detect`]. All give bit-identical results: every operation is a single IEEE operation
//! per lane in the same order, and nothing is fused (none of these includes FMA, and Rust never
//! contracts).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::{
    __m128, __m128i, _mm_add_epi32, _mm_add_ps, _mm_and_ps, _mm_andnot_ps, _mm_castps_si128, _mm_castsi128_ps,
    _mm_cmpeq_epi32, _mm_cmpge_ps, _mm_cmpgt_ps, _mm_cmple_ps, _mm_cmplt_ps, _mm_max_ps, _mm_min_ps, _mm_movemask_ps,
    _mm_mul_ps, _mm_or_ps, _mm_set1_epi32, _mm_set1_ps, _mm_slli_epi32, _mm_sub_epi32, _mm_sub_ps,
};
use std::ops::{Add, Mul, Sub};

/// The lane width blending runs with: chosen once per render from what the CPU has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Simd {
    /// Four lanes ([`F32x4`]); every CPU.
    Four,
    /// Eight lanes ([`F32x8`]); x86_64 with AVX2 only.
    #[cfg(target_arch = "x86_64")]
    Eight,
    /// Sixteen lanes ([`F32x16`]) for blending (the projection runs eight); x86_64 with AVX-512F
    /// and AVX2 only.
    #[cfg(target_arch = "x86_64")]
    Sixteen,
}

impl Simd {
    /// The widest lanes this CPU runs.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            if std::arch::is_x86_feature_detected!("avx512f") {
                return Self::Sixteen;
            }
            return Self::Eight;
        }
        Self::Four
    }

    /// Every lane width this CPU runs, narrowest first (for tests that compare them).
    #[cfg(test)]
    pub fn available() -> Vec<Self> {
        let widest = Self::detect();
        let all = [
            Self::Four,
            #[cfg(target_arch = "x86_64")]
            Self::Eight,
            #[cfg(target_arch = "x86_64")]
            Self::Sixteen,
        ];
        let last = all.iter().position(|&s| s == widest).unwrap_or(0);
        all[..=last].to_vec()
    }
}

/// A vector of `N` f32 lanes, and the few operations blending needs on it. Loads and stores work
/// on 16-wide rows (a tile row): the window at `at` is elements `at .. at + N` (`at <= 16 - N`;
/// a window past the row's end loads zeros and stores nothing).
pub trait Lanes: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> {
    const N: usize;
    type Mask: LaneMask<Self>;
    fn splat(v: f32) -> Self;
    /// `0, 1, .., N - 1`.
    fn ramp() -> Self;
    fn load(row: &[f32; 16], at: usize) -> Self;
    fn store(self, row: &mut [f32; 16], at: usize);
    /// u32 lanes, reinterpreted (for selecting integers with a mask).
    fn load_bits(row: &[u32; 16], at: usize) -> Self;
    fn store_bits(self, row: &mut [u32; 16], at: usize);
    fn splat_bits(v: u32) -> Self;
    /// Elements `at .. at + N / 2` of `first` in the low half of the lanes, of `second` in the
    /// high half (two rows of a narrow footprint in one vector).
    fn load_pair(first: &[f32; 16], second: &[f32; 16], at: usize) -> Self;
    fn store_pair(self, first: &mut [f32; 16], second: &mut [f32; 16], at: usize);
    fn load_pair_bits(first: &[u32; 16], second: &[u32; 16], at: usize) -> Self;
    fn store_pair_bits(self, first: &mut [u32; 16], second: &mut [u32; 16], at: usize);
    /// `low` in the low half of the lanes, `high` in the high half.
    fn halves(low: f32, high: f32) -> Self;
    /// Lane-wise minimum; `other` where `self` is NaN (`minps`).
    fn min(self, other: Self) -> Self;
    /// Lane-wise maximum; `other` where `self` is NaN (`maxps`).
    fn max(self, other: Self) -> Self;
    fn lt(self, other: Self) -> Self::Mask;
    fn le(self, other: Self) -> Self::Mask;
    fn ge(self, other: Self) -> Self::Mask;
    fn gt(self, other: Self) -> Self::Mask;
    /// `2^k` for the integers `k` held in the low mantissa bits of `self` (see `exp2`).
    fn pow2_from_rounded(self, round_bits: u32) -> Self;

    /// `2^x` (range reduction to `r` in [-0.5, 0.5] and the Cephes `exp2f` polynomial, relative
    /// error below 2.5e-7), for `x` up to 127; inputs below -126 (NaN included) give `2^-126`, far
    /// below any alpha that counts. The polynomial is evaluated by Estrin's scheme: three levels
    /// instead of Horner's five, since blending waits on this chain (docs/rendering.md, "Speed at
    /// capture size").
    #[inline(always)]
    fn exp2(self) -> Self {
        // Adding 1.5 * 2^23 rounds to an integer, which then sits in the low mantissa bits.
        const ROUND: f32 = 12_582_912.0;
        const P: [f32; 6] =
            [1.535_336_2e-4, 1.339_887_4e-3, 9.618_437e-3, 5.550_332_5e-2, 2.402_264_8e-1, 6.931_472e-1];
        let s = Self::splat;
        let x = self.max(s(-126.0));
        let shifted = x + s(ROUND);
        let r = x - (shifted - s(ROUND));
        // Estrin's scheme: 1 + r P(r) = (1 + P5 r) + r² (P4 + P3 r) + r⁴ (P2 + P1 r + P0 r²), so that
        // no term waits on more than five operations before the scaling (Horner's: eleven)
        let r2 = r * r;
        let r4 = r2 * r2;
        let first = s(1.0) + s(P[5]) * r;
        let second = s(P[4]) + s(P[3]) * r;
        let third = (s(P[2]) + s(P[1]) * r) + s(P[0]) * r2;
        let e_r = (first + r2 * second) + r4 * third;
        e_r * shifted.pow2_from_rounded(ROUND.to_bits())
    }
}

/// Elements `at .. at + N` of a tile row (zeros past its end, which blending never asks for).
#[inline(always)]
fn window<const N: usize, T: Copy + bytemuck::Zeroable>(row: &[T; 16], at: usize) -> [T; N] {
    row.get(at..at + N).and_then(|w| w.try_into().ok()).unwrap_or([T::zeroed(); N])
}

/// Writes `values` over elements `at .. at + N` of a tile row (nothing past its end).
#[inline(always)]
fn put_window<const N: usize, T: Copy>(row: &mut [T; 16], at: usize, values: [T; N]) {
    if let Some(w) = row.get_mut(at..at + N) {
        w.copy_from_slice(&values);
    }
}

/// `window(first, at)` of half the lanes, then `window(second, at)`.
#[inline(always)]
fn pair_window<const N: usize, const H: usize, T: Copy + bytemuck::Zeroable>(
    first: &[T; 16],
    second: &[T; 16],
    at: usize,
) -> [T; N] {
    let (low, high) = (window::<H, T>(first, at), window::<H, T>(second, at));
    std::array::from_fn(|i| if i < H { low[i] } else { high[i - H] })
}

/// Writes the low half of `values` as `put_window(first, at)`, the high half into `second`.
#[inline(always)]
fn put_pair_window<const N: usize, const H: usize, T: Copy + bytemuck::Zeroable>(
    first: &mut [T; 16],
    second: &mut [T; 16],
    at: usize,
    values: [T; N],
) {
    put_window::<H, T>(first, at, std::array::from_fn(|i| values[i]));
    put_window::<H, T>(second, at, std::array::from_fn(|i| values[H + i]));
}

/// A per-lane mask of a [`Lanes`] (all bits of a lane set or clear).
pub trait LaneMask<V>: Copy {
    /// Lanes whose bit is set in `bits` (bit i = lane i).
    fn from_bits(bits: u32) -> Self;
    /// Bit i set where lane i is.
    fn bits(self) -> u32;
    fn and(self, other: Self) -> Self;
    /// `self & !other`.
    fn and_not(self, other: Self) -> Self;
    /// `a` where set, `b` elsewhere.
    fn select(self, a: V, b: V) -> V;
    /// `a` where set, zero elsewhere.
    fn keep(self, a: V) -> V;
}

/// Four f32 lanes.
#[derive(Clone, Copy, Debug)]
pub struct F32x4(#[cfg(target_arch = "x86_64")] __m128, #[cfg(not(target_arch = "x86_64"))] [f32; 4]);

/// A per-lane mask (all bits set or clear), as produced by the comparisons.
#[derive(Clone, Copy, Debug)]
pub struct Mask4(F32x4);

#[cfg(not(target_arch = "x86_64"))]
use portable as imp;
#[cfg(target_arch = "x86_64")]
use sse as imp;

#[cfg(target_arch = "x86_64")]
mod sse {
    //! Every `unsafe` here only calls an SSE/SSE2 intrinsic; SSE2 is part of the x86_64
    //! baseline, so the instructions always exist.
    use super::*;

    #[inline(always)]
    pub fn splat(v: f32) -> __m128 {
        unsafe { _mm_set1_ps(v) }
    }
    #[inline(always)]
    pub fn from_array(a: [f32; 4]) -> __m128 {
        bytemuck::cast(a)
    }
    #[inline(always)]
    pub fn to_array(v: __m128) -> [f32; 4] {
        bytemuck::cast(v)
    }
    #[inline(always)]
    pub fn from_bits(a: [u32; 4]) -> __m128 {
        bytemuck::cast(a)
    }
    #[inline(always)]
    pub fn to_bits(v: __m128) -> [u32; 4] {
        bytemuck::cast(v)
    }
    #[inline(always)]
    pub fn add(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_add_ps(a, b) }
    }
    #[inline(always)]
    pub fn sub(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_sub_ps(a, b) }
    }
    #[inline(always)]
    pub fn mul(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_mul_ps(a, b) }
    }
    /// `b` where `a` or `b` is NaN, like `minps`.
    #[inline(always)]
    pub fn min(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_min_ps(a, b) }
    }
    #[inline(always)]
    pub fn max(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_max_ps(a, b) }
    }
    #[inline(always)]
    pub fn lt(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_cmplt_ps(a, b) }
    }
    #[inline(always)]
    pub fn le(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_cmple_ps(a, b) }
    }
    #[inline(always)]
    pub fn ge(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_cmpge_ps(a, b) }
    }
    #[inline(always)]
    pub fn gt(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_cmpgt_ps(a, b) }
    }
    #[inline(always)]
    pub fn and(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_and_ps(a, b) }
    }
    #[inline(always)]
    pub fn and_not(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_andnot_ps(a, b) } // !a & b
    }
    #[inline(always)]
    pub fn or(a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_or_ps(a, b) }
    }
    #[inline(always)]
    pub fn bits(mask: __m128) -> u32 {
        unsafe { _mm_movemask_ps(mask) as u32 }
    }
    #[inline(always)]
    fn _mm_castsi128_ps_(v: __m128i) -> __m128 {
        bytemuck::cast(v)
    }
    /// All bits of lane i set where bit i of `bits` is.
    #[inline(always)]
    pub fn mask_from_bits(bits: u32) -> __m128 {
        let lane_bits: __m128i = bytemuck::cast([1u32, 2, 4, 8]);
        let set = and(_mm_castsi128_ps_(unsafe { _mm_set1_epi32(bits as i32) }), _mm_castsi128_ps_(lane_bits));
        unsafe { _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_castps_si128(set), lane_bits)) }
    }
    /// `2^k` for the integers `k` held in the low mantissa bits of `shifted` (see `exp`).
    #[inline(always)]
    pub fn pow2_from_rounded(shifted: __m128, round_bits: u32) -> __m128 {
        // SAFETY: SSE2 is part of the x86_64 baseline, so these instructions always exist.
        let k: __m128i = unsafe { _mm_sub_epi32(_mm_castps_si128(shifted), _mm_set1_epi32(round_bits as i32)) };
        unsafe { _mm_castsi128_ps(_mm_slli_epi32::<23>(_mm_add_epi32(k, _mm_set1_epi32(127)))) }
    }
}

/// The same operations on plain arrays (compiled on x86_64 too, for the test that both agree).
#[cfg(any(not(target_arch = "x86_64"), test))]
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
mod portable {
    type V = [f32; 4];
    #[inline(always)]
    fn zip(a: V, b: V, f: impl Fn(f32, f32) -> f32) -> V {
        [f(a[0], b[0]), f(a[1], b[1]), f(a[2], b[2]), f(a[3], b[3])]
    }
    #[inline(always)]
    fn mask(c: bool) -> f32 {
        f32::from_bits(if c { u32::MAX } else { 0 })
    }
    #[inline(always)]
    fn bitwise(a: V, b: V, f: impl Fn(u32, u32) -> u32) -> V {
        zip(a, b, |x, y| f32::from_bits(f(x.to_bits(), y.to_bits())))
    }
    pub fn splat(v: f32) -> V {
        [v; 4]
    }
    pub fn from_array(a: V) -> V {
        a
    }
    pub fn to_array(v: V) -> V {
        v
    }
    pub fn from_bits(a: [u32; 4]) -> V {
        a.map(f32::from_bits)
    }
    pub fn to_bits(v: V) -> [u32; 4] {
        v.map(f32::to_bits)
    }
    pub fn add(a: V, b: V) -> V {
        zip(a, b, |x, y| x + y)
    }
    pub fn sub(a: V, b: V) -> V {
        zip(a, b, |x, y| x - y)
    }
    pub fn mul(a: V, b: V) -> V {
        zip(a, b, |x, y| x * y)
    }
    pub fn min(a: V, b: V) -> V {
        zip(a, b, |x, y| if x < y { x } else { y })
    }
    pub fn max(a: V, b: V) -> V {
        zip(a, b, |x, y| if x > y { x } else { y })
    }
    pub fn lt(a: V, b: V) -> V {
        zip(a, b, |x, y| mask(x < y))
    }
    pub fn le(a: V, b: V) -> V {
        zip(a, b, |x, y| mask(x <= y))
    }
    pub fn ge(a: V, b: V) -> V {
        zip(a, b, |x, y| mask(x >= y))
    }
    pub fn gt(a: V, b: V) -> V {
        zip(a, b, |x, y| mask(x > y))
    }
    pub fn and(a: V, b: V) -> V {
        bitwise(a, b, |x, y| x & y)
    }
    pub fn and_not(a: V, b: V) -> V {
        bitwise(a, b, |x, y| !x & y)
    }
    pub fn or(a: V, b: V) -> V {
        bitwise(a, b, |x, y| x | y)
    }
    pub fn bits(mask: V) -> u32 {
        (0..4).map(|i| (mask[i].to_bits() >> 31) << i).sum()
    }
    pub fn mask_from_bits(bits: u32) -> V {
        [0, 1, 2, 3].map(|i| f32::from_bits(if bits >> i & 1 == 1 { u32::MAX } else { 0 }))
    }
    pub fn pow2_from_rounded(shifted: V, round_bits: u32) -> V {
        shifted.map(|s| f32::from_bits(s.to_bits().wrapping_sub(round_bits).wrapping_add(127) << 23))
    }
}

impl Lanes for F32x4 {
    const N: usize = 4;
    type Mask = Mask4;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Self(imp::splat(v))
    }
    #[inline(always)]
    fn ramp() -> Self {
        Self(imp::from_array([0.0, 1.0, 2.0, 3.0]))
    }
    #[inline(always)]
    fn load(row: &[f32; 16], at: usize) -> Self {
        Self(imp::from_array(window(row, at)))
    }
    #[inline(always)]
    fn store(self, row: &mut [f32; 16], at: usize) {
        put_window(row, at, imp::to_array(self.0));
    }
    #[inline(always)]
    fn load_bits(row: &[u32; 16], at: usize) -> Self {
        Self(imp::from_bits(window(row, at)))
    }
    #[inline(always)]
    fn store_bits(self, row: &mut [u32; 16], at: usize) {
        put_window(row, at, imp::to_bits(self.0));
    }
    #[inline(always)]
    fn splat_bits(v: u32) -> Self {
        Self(imp::from_bits([v; 4]))
    }
    #[inline(always)]
    fn load_pair(first: &[f32; 16], second: &[f32; 16], at: usize) -> Self {
        Self(imp::from_array(pair_window::<4, 2, f32>(first, second, at)))
    }
    #[inline(always)]
    fn store_pair(self, first: &mut [f32; 16], second: &mut [f32; 16], at: usize) {
        put_pair_window::<4, 2, f32>(first, second, at, imp::to_array(self.0));
    }
    #[inline(always)]
    fn load_pair_bits(first: &[u32; 16], second: &[u32; 16], at: usize) -> Self {
        Self(imp::from_bits(pair_window::<4, 2, u32>(first, second, at)))
    }
    #[inline(always)]
    fn store_pair_bits(self, first: &mut [u32; 16], second: &mut [u32; 16], at: usize) {
        put_pair_window::<4, 2, u32>(first, second, at, imp::to_bits(self.0));
    }
    #[inline(always)]
    fn halves(low: f32, high: f32) -> Self {
        Self(imp::from_array([low, low, high, high]))
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        Self(imp::min(self.0, other.0))
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        Self(imp::max(self.0, other.0))
    }
    #[inline(always)]
    fn lt(self, other: Self) -> Mask4 {
        Mask4(Self(imp::lt(self.0, other.0)))
    }
    #[inline(always)]
    fn le(self, other: Self) -> Mask4 {
        Mask4(Self(imp::le(self.0, other.0)))
    }
    #[inline(always)]
    fn ge(self, other: Self) -> Mask4 {
        Mask4(Self(imp::ge(self.0, other.0)))
    }
    #[inline(always)]
    fn gt(self, other: Self) -> Mask4 {
        Mask4(Self(imp::gt(self.0, other.0)))
    }
    #[inline(always)]
    fn pow2_from_rounded(self, round_bits: u32) -> Self {
        Self(imp::pow2_from_rounded(self.0, round_bits))
    }
}

impl Add for F32x4 {
    type Output = Self;
    #[inline(always)]
    fn add(self, other: Self) -> Self {
        Self(imp::add(self.0, other.0))
    }
}

impl Sub for F32x4 {
    type Output = Self;
    #[inline(always)]
    fn sub(self, other: Self) -> Self {
        Self(imp::sub(self.0, other.0))
    }
}

impl Mul for F32x4 {
    type Output = Self;
    #[inline(always)]
    fn mul(self, other: Self) -> Self {
        Self(imp::mul(self.0, other.0))
    }
}

impl LaneMask<F32x4> for Mask4 {
    #[inline(always)]
    fn from_bits(bits: u32) -> Self {
        Self(F32x4(imp::mask_from_bits(bits)))
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        imp::bits(self.0.0)
    }
    #[inline(always)]
    fn and(self, other: Self) -> Self {
        Self(F32x4(imp::and(self.0.0, other.0.0)))
    }
    #[inline(always)]
    fn and_not(self, other: Self) -> Self {
        Self(F32x4(imp::and_not(other.0.0, self.0.0)))
    }
    #[inline(always)]
    fn select(self, a: F32x4, b: F32x4) -> F32x4 {
        F32x4(imp::or(imp::and(self.0.0, a.0), imp::and_not(self.0.0, b.0)))
    }
    #[inline(always)]
    fn keep(self, a: F32x4) -> F32x4 {
        F32x4(imp::and(self.0.0, a.0))
    }
}

/// Array conversions for the tests.
#[cfg(test)]
impl F32x4 {
    pub fn from_array(a: [f32; 4]) -> Self {
        Self(imp::from_array(a))
    }
    pub fn to_array(self) -> [f32; 4] {
        imp::to_array(self.0)
    }
    pub fn from_bits(a: [u32; 4]) -> Self {
        Self(imp::from_bits(a))
    }
    pub fn to_bits(self) -> [u32; 4] {
        imp::to_bits(self.0)
    }
}

#[cfg(target_arch = "x86_64")]
pub use avx2::F32x8;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! Eight lanes on AVX2.
    //!
    //! SAFETY, for every `unsafe` block here: each only calls an AVX or AVX2 intrinsic, and these
    //! types are only ever created inside `composite::render_band_eight`, which runs only where
    //! `Simd::detect` found AVX2 (`is_x86_feature_detected!("avx2")`), so the instructions exist.
    //! Loads and stores go through arrays (bytemuck casts), never through raw pointers.
    use std::arch::x86_64::{
        __m256, _CMP_GE_OQ, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _mm256_add_epi32, _mm256_add_ps, _mm256_and_ps,
        _mm256_and_si256, _mm256_andnot_ps, _mm256_castps_si256, _mm256_castsi256_ps, _mm256_cmp_ps,
        _mm256_cmpeq_epi32, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps, _mm256_mul_ps, _mm256_or_ps,
        _mm256_set1_epi32, _mm256_set1_ps, _mm256_slli_epi32, _mm256_sub_epi32, _mm256_sub_ps,
    };
    use std::ops::{Add, Mul, Sub};

    use super::{LaneMask, Lanes, pair_window, put_pair_window, put_window, window};

    /// Eight f32 lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F32x8(__m256);

    /// A per-lane mask of [`F32x8`].
    #[derive(Clone, Copy, Debug)]
    pub struct Mask8(__m256);

    impl Lanes for F32x8 {
        const N: usize = 8;
        type Mask = Mask8;
        #[inline(always)]
        fn splat(v: f32) -> Self {
            Self(unsafe { _mm256_set1_ps(v) })
        }
        #[inline(always)]
        fn ramp() -> Self {
            Self(bytemuck::cast([0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]))
        }
        #[inline(always)]
        fn load(row: &[f32; 16], at: usize) -> Self {
            Self(bytemuck::cast(window::<8, f32>(row, at)))
        }
        #[inline(always)]
        fn store(self, row: &mut [f32; 16], at: usize) {
            put_window::<8, f32>(row, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn load_bits(row: &[u32; 16], at: usize) -> Self {
            Self(bytemuck::cast(window::<8, u32>(row, at)))
        }
        #[inline(always)]
        fn store_bits(self, row: &mut [u32; 16], at: usize) {
            put_window::<8, u32>(row, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn splat_bits(v: u32) -> Self {
            Self(unsafe { _mm256_castsi256_ps(_mm256_set1_epi32(v as i32)) })
        }
        #[inline(always)]
        fn load_pair(first: &[f32; 16], second: &[f32; 16], at: usize) -> Self {
            Self(bytemuck::cast(pair_window::<8, 4, f32>(first, second, at)))
        }
        #[inline(always)]
        fn store_pair(self, first: &mut [f32; 16], second: &mut [f32; 16], at: usize) {
            put_pair_window::<8, 4, f32>(first, second, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn load_pair_bits(first: &[u32; 16], second: &[u32; 16], at: usize) -> Self {
            Self(bytemuck::cast(pair_window::<8, 4, u32>(first, second, at)))
        }
        #[inline(always)]
        fn store_pair_bits(self, first: &mut [u32; 16], second: &mut [u32; 16], at: usize) {
            put_pair_window::<8, 4, u32>(first, second, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn halves(low: f32, high: f32) -> Self {
            Self(bytemuck::cast([low, low, low, low, high, high, high, high]))
        }
        #[inline(always)]
        fn min(self, other: Self) -> Self {
            Self(unsafe { _mm256_min_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn max(self, other: Self) -> Self {
            Self(unsafe { _mm256_max_ps(self.0, other.0) })
        }
        // Ordered, non-signalling predicates: false on NaN, as `cmpltps` and friends.
        #[inline(always)]
        fn lt(self, other: Self) -> Mask8 {
            Mask8(unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn le(self, other: Self) -> Mask8 {
            Mask8(unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn ge(self, other: Self) -> Mask8 {
            Mask8(unsafe { _mm256_cmp_ps::<_CMP_GE_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn gt(self, other: Self) -> Mask8 {
            Mask8(unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn pow2_from_rounded(self, round_bits: u32) -> Self {
            Self(unsafe {
                let k = _mm256_sub_epi32(_mm256_castps_si256(self.0), _mm256_set1_epi32(round_bits as i32));
                _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(k, _mm256_set1_epi32(127))))
            })
        }
    }

    impl Add for F32x8 {
        type Output = Self;
        #[inline(always)]
        fn add(self, other: Self) -> Self {
            Self(unsafe { _mm256_add_ps(self.0, other.0) })
        }
    }

    impl Sub for F32x8 {
        type Output = Self;
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            Self(unsafe { _mm256_sub_ps(self.0, other.0) })
        }
    }

    impl Mul for F32x8 {
        type Output = Self;
        #[inline(always)]
        fn mul(self, other: Self) -> Self {
            Self(unsafe { _mm256_mul_ps(self.0, other.0) })
        }
    }

    impl LaneMask<F32x8> for Mask8 {
        #[inline(always)]
        fn from_bits(bits: u32) -> Self {
            let lane_bits: [u32; 8] = [1, 2, 4, 8, 16, 32, 64, 128];
            Self(unsafe {
                let lane_bits = bytemuck::cast(lane_bits);
                let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bits);
                _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bits))
            })
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn and(self, other: Self) -> Self {
            Self(unsafe { _mm256_and_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn and_not(self, other: Self) -> Self {
            Self(unsafe { _mm256_andnot_ps(other.0, self.0) })
        }
        #[inline(always)]
        fn select(self, a: F32x8, b: F32x8) -> F32x8 {
            F32x8(unsafe { _mm256_or_ps(_mm256_and_ps(self.0, a.0), _mm256_andnot_ps(self.0, b.0)) })
        }
        #[inline(always)]
        fn keep(self, a: F32x8) -> F32x8 {
            F32x8(unsafe { _mm256_and_ps(self.0, a.0) })
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub use avx512::F32x16;

#[cfg(target_arch = "x86_64")]
mod avx512 {
    //! Sixteen lanes on AVX-512F: a whole tile row, or two half rows, in one vector.
    //!
    //! SAFETY, for every `unsafe` block here: each only calls an AVX-512F intrinsic, and these
    //! types are only ever created inside `composite::render_band_sixteen`, which runs only where
    //! `Simd::detect` found AVX-512F, so the instructions exist.
    use std::arch::x86_64::{
        __m512, __mmask16, _CMP_GE_OQ, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _mm512_add_epi32, _mm512_add_ps,
        _mm512_castps_si512, _mm512_castsi512_ps, _mm512_cmp_ps_mask, _mm512_mask_blend_ps, _mm512_maskz_mov_ps,
        _mm512_max_ps, _mm512_min_ps, _mm512_mul_ps, _mm512_set1_epi32, _mm512_set1_ps, _mm512_slli_epi32,
        _mm512_sub_epi32, _mm512_sub_ps,
    };
    use std::ops::{Add, Mul, Sub};

    use super::{LaneMask, Lanes, pair_window, put_pair_window, put_window, window};

    /// Sixteen f32 lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F32x16(__m512);

    /// A per-lane mask of [`F32x16`]: one bit a lane.
    #[derive(Clone, Copy, Debug)]
    pub struct Mask16(__mmask16);

    impl Lanes for F32x16 {
        const N: usize = 16;
        type Mask = Mask16;
        #[inline(always)]
        fn splat(v: f32) -> Self {
            Self(unsafe { _mm512_set1_ps(v) })
        }
        #[inline(always)]
        fn ramp() -> Self {
            Self(bytemuck::cast(std::array::from_fn::<f32, 16, _>(|i| i as f32)))
        }
        #[inline(always)]
        fn load(row: &[f32; 16], at: usize) -> Self {
            Self(bytemuck::cast(window::<16, f32>(row, at)))
        }
        #[inline(always)]
        fn store(self, row: &mut [f32; 16], at: usize) {
            put_window::<16, f32>(row, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn load_bits(row: &[u32; 16], at: usize) -> Self {
            Self(bytemuck::cast(window::<16, u32>(row, at)))
        }
        #[inline(always)]
        fn store_bits(self, row: &mut [u32; 16], at: usize) {
            put_window::<16, u32>(row, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn splat_bits(v: u32) -> Self {
            Self(unsafe { _mm512_castsi512_ps(_mm512_set1_epi32(v as i32)) })
        }
        #[inline(always)]
        fn load_pair(first: &[f32; 16], second: &[f32; 16], at: usize) -> Self {
            Self(bytemuck::cast(pair_window::<16, 8, f32>(first, second, at)))
        }
        #[inline(always)]
        fn store_pair(self, first: &mut [f32; 16], second: &mut [f32; 16], at: usize) {
            put_pair_window::<16, 8, f32>(first, second, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn load_pair_bits(first: &[u32; 16], second: &[u32; 16], at: usize) -> Self {
            Self(bytemuck::cast(pair_window::<16, 8, u32>(first, second, at)))
        }
        #[inline(always)]
        fn store_pair_bits(self, first: &mut [u32; 16], second: &mut [u32; 16], at: usize) {
            put_pair_window::<16, 8, u32>(first, second, at, bytemuck::cast(self.0));
        }
        #[inline(always)]
        fn halves(low: f32, high: f32) -> Self {
            Self(bytemuck::cast(std::array::from_fn::<f32, 16, _>(|i| if i < 8 { low } else { high })))
        }
        #[inline(always)]
        fn min(self, other: Self) -> Self {
            Self(unsafe { _mm512_min_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn max(self, other: Self) -> Self {
            Self(unsafe { _mm512_max_ps(self.0, other.0) })
        }
        // Ordered, non-signalling predicates: false on NaN, as `cmpltps` and friends.
        #[inline(always)]
        fn lt(self, other: Self) -> Mask16 {
            Mask16(unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn le(self, other: Self) -> Mask16 {
            Mask16(unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn ge(self, other: Self) -> Mask16 {
            Mask16(unsafe { _mm512_cmp_ps_mask::<_CMP_GE_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn gt(self, other: Self) -> Mask16 {
            Mask16(unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(self.0, other.0) })
        }
        #[inline(always)]
        fn pow2_from_rounded(self, round_bits: u32) -> Self {
            Self(unsafe {
                let k = _mm512_sub_epi32(_mm512_castps_si512(self.0), _mm512_set1_epi32(round_bits as i32));
                _mm512_castsi512_ps(_mm512_slli_epi32::<23>(_mm512_add_epi32(k, _mm512_set1_epi32(127))))
            })
        }
    }

    impl Add for F32x16 {
        type Output = Self;
        #[inline(always)]
        fn add(self, other: Self) -> Self {
            Self(unsafe { _mm512_add_ps(self.0, other.0) })
        }
    }

    impl Sub for F32x16 {
        type Output = Self;
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            Self(unsafe { _mm512_sub_ps(self.0, other.0) })
        }
    }

    impl Mul for F32x16 {
        type Output = Self;
        #[inline(always)]
        fn mul(self, other: Self) -> Self {
            Self(unsafe { _mm512_mul_ps(self.0, other.0) })
        }
    }

    impl LaneMask<F32x16> for Mask16 {
        #[inline(always)]
        fn from_bits(bits: u32) -> Self {
            Self(bits as __mmask16)
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            u32::from(self.0)
        }
        #[inline(always)]
        fn and(self, other: Self) -> Self {
            Self(self.0 & other.0)
        }
        #[inline(always)]
        fn and_not(self, other: Self) -> Self {
            Self(self.0 & !other.0)
        }
        #[inline(always)]
        fn select(self, a: F32x16, b: F32x16) -> F32x16 {
            F32x16(unsafe { _mm512_mask_blend_ps(self.0, b.0, a.0) })
        }
        #[inline(always)]
        fn keep(self, a: F32x16) -> F32x16 {
            F32x16(unsafe { _mm512_maskz_mov_ps(self.0, a.0) })
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn exp2_matches_std_to_a_few_ulp() {
        let mut worst = 0.0f32;
        let mut x = 0.5f32;
        while x > -126.0 {
            let xs = [x, x * 0.5, x * 0.25, x * 0.125];
            let fast = F32x4::from_array(xs).exp2().to_array();
            for (f, v) in fast.iter().zip(xs) {
                worst = worst.max((f - v.exp2()).abs() / v.exp2());
            }
            x -= 0.000_731;
        }
        assert!(worst < 2.5e-7, "worst relative error {worst}");
        let edge = F32x4::from_array([0.0, -1e30, f32::NEG_INFINITY, f32::NAN]).exp2().to_array();
        assert_eq!(edge[0], 1.0);
        assert!(edge[1..].iter().all(|&e| e == 2f32.powi(-126)), "{edge:?}");
    }

    /// The portable lanes give the SSE results bit for bit, NaN and infinities included.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn portable_lanes_match_sse_bit_for_bit() {
        let specials = [0.0, -0.0, 1.0, -1.5, 1e-40, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 3.4e38, -87.3];
        let mut values: Vec<f32> = specials.to_vec();
        let mut state = 12345u32;
        for _ in 0..400 {
            state = state.wrapping_mul(1664525).wrapping_add(1013904223);
            values.push(f32::from_bits(state) % 1e3);
        }
        let bits = |v: [f32; 4]| v.map(f32::to_bits);
        for quad in values.chunks_exact(4).zip(values.chunks_exact(4).rev()) {
            let a: [f32; 4] = quad.0.try_into().unwrap();
            let b: [f32; 4] = quad.1.try_into().unwrap();
            let (sa, sb) = (sse::from_array(a), sse::from_array(b));
            type Pair = (fn(__m128, __m128) -> __m128, fn([f32; 4], [f32; 4]) -> [f32; 4]);
            let pairs: [Pair; 11] = [
                (sse::add, portable::add),
                (sse::sub, portable::sub),
                (sse::mul, portable::mul),
                (sse::min, portable::min),
                (sse::max, portable::max),
                (sse::lt, portable::lt),
                (sse::le, portable::le),
                (sse::ge, portable::ge),
                (sse::gt, portable::gt),
                (sse::and, portable::and),
                (sse::and_not, portable::and_not),
            ];
            for (fast, slow) in pairs {
                assert_eq!(bits(sse::to_array(fast(sa, sb))), bits(slow(a, b)), "{a:?} {b:?}");
            }
            assert_eq!(bits(sse::to_array(sse::or(sa, sb))), bits(portable::or(a, b)));
            assert_eq!(sse::bits(sse::lt(sa, sb)), portable::bits(portable::lt(a, b)));
            let rounded = sse::add(
                sse::mul(sse::min(sse::max(sa, sse::splat(-126.0)), sse::splat(127.0)), sse::splat(1.0)),
                sse::splat(12_582_912.0),
            );
            let round_bits = 12_582_912.0f32.to_bits();
            assert_eq!(
                bits(sse::to_array(sse::pow2_from_rounded(rounded, round_bits))),
                bits(portable::pow2_from_rounded(sse::to_array(rounded), round_bits))
            );
        }
    }

    #[test]
    fn masks_select_and_count_lanes() {
        let a = F32x4::from_array([1.0, 2.0, 3.0, 4.0]);
        let b = F32x4::splat(2.5);
        let lt = a.lt(b);
        assert_eq!(lt.bits(), 0b0011);
        assert_eq!(a.ge(b).bits(), 0b1100);
        assert_eq!(a.le(F32x4::splat(2.0)).bits(), 0b0011);
        assert_eq!(a.gt(F32x4::splat(2.0)).bits(), 0b1100);
        assert_eq!(lt.select(a, b).to_array(), [1.0, 2.0, 2.5, 2.5]);
        assert_eq!(lt.keep(a).to_array(), [1.0, 2.0, 0.0, 0.0]);
        assert_eq!(Mask4::from_bits(0b1010).bits(), 0b1010);
        for bits in 0..16 {
            assert_eq!(Mask4::from_bits(bits).bits(), bits);
        }
        assert_eq!(Mask4::from_bits(0b0110).and(lt).bits(), 0b0010);
        assert_eq!(Mask4::from_bits(0b0110).and_not(lt).bits(), 0b0100);
        let ints = F32x4::from_bits([7, 8, 9, 10]);
        assert_eq!(lt.select(ints, F32x4::from_bits([0; 4])).to_bits(), [7, 8, 0, 0]);
    }

    /// Eight (AVX2) and sixteen (AVX-512F) lanes give what groups of four give, bit for bit, for
    /// every operation blending uses (each width skipped on CPUs without it).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn wide_lanes_match_four_bit_for_bit() {
        let widths = Simd::available();
        if widths.contains(&Simd::Eight) {
            wide_matches_four::<F32x8>();
        }
        if widths.contains(&Simd::Sixteen) {
            wide_matches_four::<F32x16>();
        }
    }

    #[cfg(target_arch = "x86_64")]
    fn wide_matches_four<V: Lanes>() {
        let n = V::N;
        let specials = [0.0, -0.0, 1.0, -1.5, 1e-40, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 3.4e38, -87.3];
        let mut values: Vec<f32> = specials.to_vec();
        let mut state = 777u32;
        for _ in 0..1000 {
            state = state.wrapping_mul(1664525).wrapping_add(1013904223);
            values.push(f32::from_bits(state) % 1e3);
            values.push(-((state >> 8) as f32) / 1e5); // exp's range
        }
        let row = |v: &[f32]| -> [f32; 16] { std::array::from_fn(|i| v[i % v.len()]) };
        // Bits, except that every NaN is one: which operand's payload an operation on two NaNs
        // returns is not defined (the compiler may swap a sum's operands), and blending never
        // makes a NaN from finite inputs.
        let bits = |v: &[f32]| v.iter().map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() }).collect::<Vec<_>>();
        for (a, b) in values.chunks_exact(16).zip(values.chunks_exact(16).rev()) {
            let (a, b) = (row(a), row(b));
            for at in (0..16).step_by(n) {
                let (wa, wb) = (V::load(&a, at), V::load(&b, at));
                let quads = |r: &[f32; 16]| (at..at + n).step_by(4).map(|k| (k, F32x4::load(r, k))).collect::<Vec<_>>();
                let (qa, qb) = (quads(&a), quads(&b));
                let same = |fw: &dyn Fn(V, V) -> V, f4: &dyn Fn(F32x4, F32x4) -> F32x4| {
                    let (mut wide, mut narrow) = ([0.0f32; 16], [0.0f32; 16]);
                    fw(wa, wb).store(&mut wide, at);
                    for ((k, x), (_, y)) in qa.iter().zip(&qb) {
                        f4(*x, *y).store(&mut narrow, *k);
                    }
                    assert_eq!(bits(&wide[at..at + n]), bits(&narrow[at..at + n]), "{n} lanes");
                };
                same(&|x, y| x + y, &|x, y| x + y);
                same(&|x, y| x - y, &|x, y| x - y);
                same(&|x, y| x * y, &|x, y| x * y);
                same(&|x, y| x.min(y), &|x, y| x.min(y));
                same(&|x, y| x.max(y), &|x, y| x.max(y));
                same(&|x, _| x.exp2(), &|x, _| x.exp2());
                same(&|x, y| x.lt(y).select(x, y), &|x, y| x.lt(y).select(x, y));
                same(&|x, y| x.le(y).keep(x), &|x, y| x.le(y).keep(x));
                same(&|x, y| x.ge(y).and_not(y.gt(x)).select(y, x), &|x, y| x.ge(y).and_not(y.gt(x)).select(y, x));
                let wide_bits = wa.lt(wb).bits();
                let narrow_bits = qa
                    .iter()
                    .zip(&qb)
                    .enumerate()
                    .fold(0, |acc, (i, ((_, x), (_, y)))| acc | x.lt(*y).bits() << (4 * i));
                assert_eq!(wide_bits, narrow_bits);
            }
            // two half rows in one vector: the pair loads and stores
            let (pair, mut first, mut second) = (V::load_pair(&a, &b, 3), [0.0f32; 16], [0.0f32; 16]);
            pair.store_pair(&mut first, &mut second, 3);
            assert_eq!(bits(&first[3..3 + n / 2]), bits(&a[3..3 + n / 2]));
            assert_eq!(bits(&second[3..3 + n / 2]), bits(&b[3..3 + n / 2]));
        }
        for bits in (0..1u32 << n).step_by(if n > 8 { 97 } else { 1 }) {
            assert_eq!(V::Mask::from_bits(bits).bits(), bits);
        }
        let mut ids = [0u32; 16];
        let ramp: [u32; 16] = std::array::from_fn(|i| i as u32);
        let at = 16 - n;
        let lt = V::ramp().lt(V::splat(3.0));
        lt.select(V::splat_bits(9), V::load_bits(&ramp, at)).store_bits(&mut ids, at);
        let expected: Vec<u32> = (0..n).map(|i| if i < 3 { 9 } else { (at + i) as u32 }).collect();
        assert_eq!(ids[at..], expected[..]);
    }
}
