//! Front-to-back blending per tile (INRIA `renderCUDA`), plus the max-weight index image.
//!
//! Each rayon task owns one row of tiles and writes only that band of rows of every output, so
//! the outputs are split into disjoint `&mut` slices up front. Within a tile, Gaussians are taken
//! in depth order and applied to the pixels of their alpha >= 1/255 box that are still live; a
//! pixel therefore sees exactly the sequence of Gaussians the reference loop would blend.

use rayon::prelude::*;

use crate::bin::TileBins;
use crate::camera::Camera;
use crate::project::{Projected, Splat2D};
use crate::simd::{F32x4, LaneMask, Lanes, Simd};
use crate::tiles::TileMask;
use crate::{ALPHA_MAX, ALPHA_MIN, RasterError, RenderMode, RenderOptions, RenderOutput, T_MIN, TILE_SIZE, try_filled};

const TILE: usize = TILE_SIZE as usize;
/// Marks a pixel no Gaussian has contributed to.
const NO_GAUSSIAN: u32 = u32::MAX;

/// One band of `TILE` image rows (fewer at the bottom) of every output.
struct Band<'a> {
    row0: usize,
    rgb: &'a mut [f32],
    alpha: &'a mut [f32],
    depth: &'a mut [f32],
    index: &'a mut [i32],
    index_depth: &'a mut [f32],
}

/// Where compositing finds a tile's Gaussians: per tile, lists of entries front to back, and per
/// entry its projection and scene row.
pub trait Source: Sync {
    /// Tile `tile`'s entries, front to back, as consecutive slices.
    fn lists(&self, tile: usize) -> impl Iterator<Item = &[u32]>;
    /// The projection of entry `k`.
    fn splat(&self, k: u32) -> Splat2D;
    /// The scene row of entry `k`.
    fn row(&self, k: u32) -> u32;
    /// Asks the CPU to bring entry `k`'s projection into cache (a hint; nothing where unsupported).
    fn prefetch(&self, _k: u32) {}
}

/// The Gaussians of one render: projected, and binned into tiles.
pub struct Binned<'a> {
    pub projected: &'a Projected,
    pub bins: &'a TileBins,
}

impl Source for Binned<'_> {
    fn lists(&self, tile: usize) -> impl Iterator<Item = &[u32]> {
        self.bins.tile_lists(tile)
    }

    #[inline]
    fn splat(&self, k: u32) -> Splat2D {
        self.projected.splats.get(k as usize).copied().unwrap_or_default()
    }

    #[inline]
    fn row(&self, k: u32) -> u32 {
        self.projected.id(k as usize)
    }

    #[inline]
    fn prefetch(&self, k: u32) {
        prefetch_splat(&self.projected.splats, k);
    }
}

/// Prefetches the cache lines `splats[k]` lies on (nothing where `k` is out of range).
#[inline(always)]
pub(crate) fn prefetch_splat(splats: &[Splat2D], k: u32) {
    #[cfg(target_arch = "x86_64")]
    if let Some(splat) = splats.get(k as usize) {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let first = std::ptr::from_ref(splat).cast::<i8>();
        // SAFETY: prefetching is a hint that never faults, and both addresses lie inside `splat`.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(first);
            _mm_prefetch::<_MM_HINT_T0>(first.add(std::mem::size_of::<Splat2D>() - 1));
        }
    }
}

/// A new [`RenderOutput`] (timings and counts left at zero), background everywhere, with the
/// tiles of `mask` (all when None) blended from `source`.
pub fn composite<S: Source>(
    camera: &Camera,
    source: &S,
    options: &RenderOptions,
    mask: Option<&TileMask>,
) -> Result<RenderOutput, RasterError> {
    let mut out = blank(camera, options)?;
    composite_into(&mut out, camera, source, options, mask);
    Ok(out)
}

/// As [`composite`] in [`RenderMode::IndexSolid`], with each pixel blending only the Gaussians
/// deeper than its entry of `near` (camera z, row-major (H * W); `f32::INFINITY` leaves a pixel
/// empty): what the camera would see with everything in front of `near` taken away.
pub fn composite_behind<S: Source>(
    camera: &Camera,
    source: &S,
    mask: Option<&TileMask>,
    near: &[f32],
) -> Result<RenderOutput, RasterError> {
    let options = RenderOptions { mode: RenderMode::IndexSolid, ..RenderOptions::default() };
    let mut out = blank(camera, &options)?;
    composite_with(Simd::detect(), &mut out, camera, source, &options, mask, Some(near));
    Ok(out)
}

/// An output of background only (index -1, alpha 0); an error where it does not fit in memory.
pub fn blank(camera: &Camera, options: &RenderOptions) -> Result<RenderOutput, RasterError> {
    let (width, height) = (camera.width as usize, camera.height as usize);
    let pixels = width * height;
    let colour = if options.mode.has_color() { pixels } else { 0 };
    let depth = if options.mode.has_depth() { pixels } else { 0 };
    let index = if options.mode.has_index() { pixels } else { 0 };
    // reserve everything before touching any of it, and report what the whole image needs
    let total = (3 * colour + depth + 2 * index + pixels) * 4;
    let reserve = |len: usize| -> Result<(), RasterError> {
        let mut probe: Vec<f32> = Vec::new();
        probe.try_reserve_exact(len).map_err(|_| RasterError::OutOfMemory { what: "image", bytes: total })
    };
    reserve(total / 4)?;
    let mut rgb = try_filled(colour * 3, 0.0f32, "image")?;
    for (c, out) in rgb.iter_mut().enumerate() {
        *out = options.background[c % 3];
    }
    Ok(RenderOutput {
        width,
        height,
        rgb,
        alpha: try_filled(pixels, 0.0, "image")?, // transmittance is tracked in every mode, so alpha is free
        depth: try_filled(depth, 0.0, "image")?,
        index: try_filled(index, -1, "image")?,
        index_depth: try_filled(index, 0.0, "image")?,
        ..RenderOutput::default()
    })
}

/// Blends the tiles of `mask` (all when None) from `source` into `out` (made for `camera` and
/// `options.mode`); other tiles are left as they are.
pub fn composite_into<S: Source>(
    out: &mut RenderOutput,
    camera: &Camera,
    source: &S,
    options: &RenderOptions,
    mask: Option<&TileMask>,
) {
    composite_with(Simd::detect(), out, camera, source, options, mask, None);
}

/// [`composite_into`] with the lane width `simd` (which the CPU must have: from `Simd::detect`);
/// with `near` (only in [`RenderMode::IndexSolid`]) each pixel takes only the Gaussians deeper
/// than its entry.
pub(crate) fn composite_with<S: Source>(
    simd: Simd,
    out: &mut RenderOutput,
    camera: &Camera,
    source: &S,
    options: &RenderOptions,
    mask: Option<&TileMask>,
    near: Option<&[f32]>,
) {
    debug_assert!(near.is_none() || options.mode == RenderMode::IndexSolid);
    let (width, height) = (camera.width as usize, camera.height as usize);
    let grid_x = camera.tile_grid().0 as usize;
    let n_bands = height.div_ceil(TILE);
    let band_rows = TILE * width;
    let mut rgb = split_bands(&mut out.rgb, band_rows * 3, n_bands).into_iter();
    let mut alpha = split_bands(&mut out.alpha, band_rows, n_bands).into_iter();
    let mut depth = split_bands(&mut out.depth, band_rows, n_bands).into_iter();
    let mut index = split_bands(&mut out.index, band_rows, n_bands).into_iter();
    let mut index_depth = split_bands(&mut out.index_depth, band_rows, n_bands).into_iter();
    let mut bands = Vec::with_capacity(n_bands);
    for b in 0..n_bands {
        let (Some(rgb), Some(alpha), Some(depth), Some(index), Some(index_depth)) =
            (rgb.next(), alpha.next(), depth.next(), index.next(), index_depth.next())
        else {
            break;
        };
        bands.push(Band { row0: b * TILE, rgb, alpha, depth, index, index_depth });
    }
    let render = |band: Band| {
        let job = BandJob { width, height, grid_x, source, background: options.background, mask, near };
        match (simd, options.mode) {
            (Simd::Four, RenderMode::Full) => render_band::<true, true, false, F32x4, S>(band, &job),
            (Simd::Four, RenderMode::IndexOnly) => render_band::<false, true, false, F32x4, S>(band, &job),
            (Simd::Four, RenderMode::IndexSolid) => render_band::<false, true, true, F32x4, S>(band, &job),
            (Simd::Four, RenderMode::Color) => render_band::<true, false, false, F32x4, S>(band, &job),
            #[cfg(target_arch = "x86_64")]
            (Simd::Eight, mode) => render_band_eight(band, &job, mode),
            #[cfg(target_arch = "x86_64")]
            (Simd::Sixteen, mode) => render_band_sixteen(band, &job, mode),
        }
    };
    bands.into_par_iter().with_max_len(1).for_each(render);
}

/// What every band of one render shares.
struct BandJob<'a, S> {
    width: usize,
    height: usize,
    grid_x: usize,
    source: &'a S,
    background: [f32; 3],
    mask: Option<&'a TileMask>,
    /// Per pixel, the camera z a Gaussian must exceed to be blended there (index-solid only).
    near: Option<&'a [f32]>,
}

/// `fn $name(band, job, mode)`: [`render_band`] with the lanes `$lanes`, compiled for the CPU
/// features `$features`, which only [`Simd::detect`] finding them lets `composite_with` call.
macro_rules! render_band_with {
    ($name:ident, $features:literal, $lanes:ty) => {
        #[cfg(target_arch = "x86_64")]
        fn $name<S: Source>(band: Band, job: &BandJob<S>, mode: RenderMode) {
            #[target_feature(enable = $features)]
            fn run<const COLOR: bool, const INDEX: bool, const SOLID: bool, S: Source>(band: Band, job: &BandJob<S>) {
                render_band::<COLOR, INDEX, SOLID, $lanes, S>(band, job);
            }
            // SAFETY: `composite_with` calls this only for the `Simd` width `Simd::detect` chose,
            // which it does only where the CPU has these features.
            unsafe {
                match mode {
                    RenderMode::Full => run::<true, true, false, S>(band, job),
                    RenderMode::IndexOnly => run::<false, true, false, S>(band, job),
                    RenderMode::IndexSolid => run::<false, true, true, S>(band, job),
                    RenderMode::Color => run::<true, false, false, S>(band, job),
                }
            }
        }
    };
}
render_band_with!(render_band_eight, "avx2", crate::simd::F32x8);
render_band_with!(render_band_sixteen, "avx512f,avx2", crate::simd::F32x16);

/// `n` consecutive chunks of `len` (the last shorter), or `n` empty slices for an unused output.
fn split_bands<T>(buf: &mut [T], len: usize, n: usize) -> Vec<&mut [T]> {
    if buf.is_empty() {
        return (0..n).map(|_| <&mut [T]>::default()).collect();
    }
    buf.chunks_mut(len.max(1)).collect()
}

/// How many entries of a tile's list ahead of blending their splats are fetched into cache.
const AHEAD: usize = 32;
/// One tile row per accumulator row; SIMD groups are `V::N` consecutive pixels of it.
type Row = [f32; TILE];

/// Per-pixel accumulators of one tile, indexed `[row][column]`; lives on the stack, reused for
/// every tile of a band. Rows are 64 bytes and aligned so, hence so is every group.
#[repr(C, align(64))]
struct TileState {
    transmittance: [Row; TILE],
    red: [Row; TILE],
    green: [Row; TILE],
    blue: [Row; TILE],
    depth: [Row; TILE],
    max_weight: [Row; TILE],
    max_id: [[u32; TILE]; TILE],
    /// Camera z a Gaussian must exceed to be blended at each pixel (index-solid mode only).
    near: [Row; TILE],
    /// Per row, bit x is set while pixel x still blends: cleared once it stopped (T would drop
    /// below T_MIN) and never set outside the image.
    live: [u16; TILE],
}

impl TileState {
    fn new() -> Self {
        Self {
            transmittance: [[1.0; TILE]; TILE],
            red: [[0.0; TILE]; TILE],
            green: [[0.0; TILE]; TILE],
            blue: [[0.0; TILE]; TILE],
            depth: [[0.0; TILE]; TILE],
            max_weight: [[0.0; TILE]; TILE],
            max_id: [[NO_GAUSSIAN; TILE]; TILE],
            near: [[f32::NEG_INFINITY; TILE]; TILE],
            live: [0; TILE],
        }
    }

    /// Resets for a tile whose image part is `cols x rows` pixels; returns the live pixel count.
    fn reset(&mut self, cols: usize, rows: usize) -> usize {
        *self = Self::new();
        let bits = ((1u32 << cols) - 1) as u16;
        self.live.iter_mut().take(rows).for_each(|l| *l = bits);
        cols * rows
    }

    /// After `reset`: each pixel blends only Gaussians deeper than its entry of `near` (the
    /// image's, `width` wide) and never starts where that is infinite. Returns the live count and
    /// the smallest entry of a live pixel: no Gaussian at or in front of it blends in this tile.
    fn start_behind(
        &mut self,
        near: &[f32],
        width: usize,
        col0: usize,
        row0: usize,
        cols: usize,
        rows: usize,
    ) -> (usize, f32) {
        let (mut live, mut nearest) = (0, f32::INFINITY);
        for y in 0..rows {
            let row = &near[(row0 + y) * width + col0..][..cols];
            self.near[y][..cols].copy_from_slice(row);
            for (x, &z) in row.iter().enumerate() {
                if z == f32::INFINITY {
                    self.live[y] &= !(1 << x);
                } else {
                    live += 1;
                    nearest = nearest.min(z);
                }
            }
        }
        (live, nearest)
    }
}

/// Blends every tile of `band` (those of the job's mask only, when it has one): with `COLOR` the
/// colour, with `INDEX` each pixel's heaviest Gaussian (the index image), with both the expected
/// depth too ([`RenderMode::Full`]); with `SOLID` as [`RenderMode::IndexSolid`].
#[inline(always)] // into `render_band_eight` and `_sixteen` too, so that the lanes compile for their CPU there
fn render_band<const COLOR: bool, const INDEX: bool, const SOLID: bool, V: Lanes, S: Source>(
    band: Band,
    job: &BandJob<S>,
) {
    let &BandJob { width, height, grid_x, source, background, mask, near } = job;
    let row0 = band.row0;
    let rows = TILE.min(height - row0);
    let tile_y = row0 / TILE;
    let mut state = TileState::new();
    for tile_x in 0..grid_x {
        let tile = tile_y * grid_x + tile_x;
        if mask.is_some_and(|m| !m.contains(tile)) {
            continue;
        }
        let col0 = tile_x * TILE;
        let cols = TILE.min(width - col0);
        let columns = Columns::<V>::new(col0);
        let mut live = state.reset(cols, rows);
        // Gaussians at or in front of this depth blend at no pixel of the tile (layers behind)
        let mut in_front = f32::NEG_INFINITY;
        if SOLID && let Some(near) = near {
            (live, in_front) = state.start_behind(near, width, col0, row0, cols, rows);
        }
        // A tile's list comes as many short slices (one per binning chunk, about 16 entries at
        // 2 M Gaussians), so the splats are fetched into cache `AHEAD` entries in front of the
        // one blending, across the slices: they lie at random in memory.
        let mut ahead = source.lists(tile).flatten();
        for &id in ahead.by_ref().take(AHEAD) {
            source.prefetch(id);
        }
        'lists: for list in source.lists(tile) {
            for &id in list {
                if let Some(&next) = ahead.next() {
                    source.prefetch(next);
                }
                let g = source.splat(id);
                if SOLID && g.depth <= in_front {
                    continue;
                }
                live = live.saturating_sub(blend::<COLOR, INDEX, SOLID, V>(&mut state, &g, id, &columns, col0, row0));
                if live == 0 {
                    break 'lists;
                }
            }
        }
        // Write the tile into the band.
        for y in 0..rows {
            for x in 0..cols {
                let o = y * width + col0 + x;
                let t = state.transmittance[y][x];
                if INDEX {
                    let id = state.max_id[y][x];
                    if id == NO_GAUSSIAN {
                        band.index[o] = -1;
                        band.index_depth[o] = 0.0;
                    } else {
                        band.index[o] = source.row(id) as i32;
                        band.index_depth[o] = source.splat(id).depth;
                    }
                }
                let a = 1.0 - t;
                band.alpha[o] = a;
                if COLOR && INDEX {
                    // `RenderMode::has_depth`
                    band.depth[o] = if a > 0.0 { state.depth[y][x] / a } else { 0.0 };
                }
                if COLOR {
                    let color = [state.red[y][x], state.green[y][x], state.blue[y][x]];
                    for ((out, c), bg) in band.rgb[o * 3..o * 3 + 3].iter_mut().zip(color).zip(background) {
                        *out = c + t * bg;
                    }
                }
            }
        }
    }
}

/// Below this base-2 exponent `q`, alpha = 2^q < 1/255 for certain: log2(1/255) = -7.99435,
/// less a 1e-3 margin for rounding. A group whose lanes all lie below it is skipped unevaluated.
const Q_FLOOR: f32 = -7.995_4;

/// Blends Gaussian `g` (index `id`) over the live pixels of its box inside the tile
/// whose top-left pixel is (`col0`, `row0`); returns how many pixels it stopped.
///
/// `V::N` pixels of a row at a time, branch-free within a group; per pixel the decisions are the
/// reference loop's, `alpha = min(0.99, o exp(power))` with `power = -0.5 (A dx² + C dy²) - B dx dy`,
/// skip `alpha < 1/255`, stop (without blending) when `T (1 - alpha) < 1e-4`, else
/// `C += c alpha T`, `T *= 1 - alpha`. The exponent is taken in base 2 with the opacity folded in,
/// `alpha = min(0.99, 2^q)`, `q = dx (qa dx + qb dy) + (qc dy² + log2 o)`: the chain from a pixel's
/// position to its alpha, which blending waits on, is four operations shorter than
/// `o exp(power)` and within 3e-7 of it. (The reference's `power > 0` skip cannot arise: the conic
/// is positive definite, and `2^q` is clamped at 0.99 anyway.) Every lane does the same IEEE
/// operations whatever the width, so four, eight and sixteen lanes give the same bits.
///
/// With `SOLID` ([`RenderMode::IndexSolid`]) a pixel also stops once its index is decided and
/// its alpha reached 0.5. Decided: every later weight is `alpha * T'` with `alpha <= ALPHA_MAX`
/// and `T' <= T`, so (rounding being monotone) at most `ALPHA_MAX * T`; where that is at most the
/// largest weight so far, no later Gaussian is strictly heavier and the index cannot change.
#[inline(always)]
fn blend<const COLOR: bool, const INDEX: bool, const SOLID: bool, V: Lanes>(
    state: &mut TileState,
    g: &Splat2D,
    id: u32,
    columns: &Columns<V>,
    col0: usize,
    row0: usize,
) -> usize {
    let [bx0, by0, bx1, by1] = g.pixel_box.map(usize::from);
    let x_start = bx0.max(col0) - col0;
    let x_end = (bx1 + 1).min(col0 + TILE).saturating_sub(col0);
    let y_start = by0.max(row0) - row0;
    let y_end = (by1 + 1).min(row0 + TILE).saturating_sub(row0);
    if x_start >= x_end {
        return 0;
    }
    let box_bits = (1u32 << x_end) - (1u32 << x_start);
    let s = V::splat;
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    let [ca, cb, cc] = g.conic;
    let (qb, qc) = (-LOG2_E * cb, -0.5 * LOG2_E * cc);
    let lanes = GaussianLanes {
        qa: s(-0.5 * LOG2_E * ca),
        mean_x: s(g.mean[0]),
        color: g.color.map(s),
        z: s(g.depth),
        id: V::splat_bits(id),
    };
    // the row's terms of the exponent: q = dx (qa dx + qb dy) + (qc dy² + log2 o)
    let row_terms = |y: usize| {
        let dy = g.mean[1] - (row0 + y) as u32 as f32;
        (qb * dy, qc * dy * dy + g.log2_opacity)
    };
    let live_bits = |state: &TileState, y: usize, at: usize, width: usize| {
        ((box_bits & u32::from(state.live[y])) >> at) & ((1u32 << width) - 1)
    };
    let half = V::N / 2;
    let mut stopped = 0;
    let mut y = y_start;
    if x_end - x_start <= half {
        // A box at most half the lanes wide (most are about three pixels): two of its rows in one
        // vector, half the chains (see `blend_window`) of one row each.
        let at = x_start.min(TILE - half);
        while y + 1 < y_end {
            let bits = live_bits(state, y, at, half) | live_bits(state, y + 1, at, half) << half;
            if bits != 0 {
                let ((dy0, row0_term), (dy1, row1_term)) = (row_terms(y), row_terms(y + 1));
                let (q_dy, q_row) = (V::halves(dy0, dy1), V::halves(row0_term, row1_term));
                let window = TwoRows { y, at };
                let dx = lanes.mean_x - columns.pairs[at];
                stopped += blend_window::<COLOR, INDEX, SOLID, V, _>(state, window, bits, dx, q_dy, q_row, &lanes);
            }
            y += 2;
        }
    }
    // The windows of `V::N` columns a row of the box needs: where the box is at most `V::N` wide
    // (most are), one that slides to its first column, instead of two aligned groups where it
    // straddles their boundary (fewer groups and loop branches); else the aligned groups.
    let (first, windows) = if x_end - x_start <= V::N {
        (x_start.min(TILE - V::N), 1)
    } else {
        let first = x_start / V::N * V::N;
        (first, (x_end - first).div_ceil(V::N))
    };
    for y in y..y_end {
        if box_bits & u32::from(state.live[y]) == 0 {
            continue;
        }
        let (q_dy, q_row) = row_terms(y);
        for w in 0..windows {
            let at = first + w * V::N;
            let bits = live_bits(state, y, at, V::N);
            if bits != 0 {
                let dx = lanes.mean_x - columns.rows[at];
                let window = OneRow { y, at };
                stopped +=
                    blend_window::<COLOR, INDEX, SOLID, V, _>(state, window, bits, dx, s(q_dy), s(q_row), &lanes);
            }
        }
    }
    stopped
}

/// Per tile, the x of the pixels of the window at each column: one row's (`rows`) and two rows'
/// (`pairs`: half the lanes each).
struct Columns<V> {
    rows: [V; TILE],
    pairs: [V; TILE],
}

impl<V: Lanes> Columns<V> {
    fn new(col0: usize) -> Self {
        let half = V::N / 2;
        let pair_ramp = V::ramp() - V::halves(0.0, half as f32); // 0, 1, .., half - 1 twice
        let x = |at: usize| V::splat((col0 + at) as u32 as f32);
        Self { rows: std::array::from_fn(|at| x(at) + V::ramp()), pairs: std::array::from_fn(|at| x(at) + pair_ramp) }
    }
}

/// One Gaussian's values in every lane.
struct GaussianLanes<V> {
    qa: V,
    mean_x: V,
    color: [V; 3],
    z: V,
    id: V,
}

/// Where a vector's lanes lie in the tile: `V::N` columns of one row from `at`, or `V::N / 2`
/// columns of two rows.
trait Window: Copy {
    fn load<V: Lanes>(self, rows: &[Row; TILE]) -> V;
    fn store<V: Lanes>(self, value: V, rows: &mut [Row; TILE]);
    fn load_bits<V: Lanes>(self, rows: &[[u32; TILE]; TILE]) -> V;
    fn store_bits<V: Lanes>(self, value: V, rows: &mut [[u32; TILE]; TILE]);
    /// Clears the live bits of the pixels of the lanes set in `lanes`.
    fn stop<V: Lanes>(self, live: &mut [u16; TILE], lanes: u32);
}

#[derive(Clone, Copy)]
struct OneRow {
    y: usize,
    at: usize,
}

impl Window for OneRow {
    #[inline(always)]
    fn load<V: Lanes>(self, rows: &[Row; TILE]) -> V {
        V::load(&rows[self.y], self.at)
    }
    #[inline(always)]
    fn store<V: Lanes>(self, value: V, rows: &mut [Row; TILE]) {
        value.store(&mut rows[self.y], self.at);
    }
    #[inline(always)]
    fn load_bits<V: Lanes>(self, rows: &[[u32; TILE]; TILE]) -> V {
        V::load_bits(&rows[self.y], self.at)
    }
    #[inline(always)]
    fn store_bits<V: Lanes>(self, value: V, rows: &mut [[u32; TILE]; TILE]) {
        value.store_bits(&mut rows[self.y], self.at);
    }
    #[inline(always)]
    fn stop<V: Lanes>(self, live: &mut [u16; TILE], lanes: u32) {
        live[self.y] &= !((lanes << self.at) as u16);
    }
}

/// Rows `y` and `y + 1` (`y + 1 < TILE`).
#[derive(Clone, Copy)]
struct TwoRows {
    y: usize,
    at: usize,
}

impl TwoRows {
    fn split<T>(self, rows: &mut [T; TILE]) -> (&mut T, &mut T) {
        let (first, rest) = rows.split_at_mut(self.y + 1);
        (&mut first[self.y], &mut rest[0])
    }
}

impl Window for TwoRows {
    #[inline(always)]
    fn load<V: Lanes>(self, rows: &[Row; TILE]) -> V {
        V::load_pair(&rows[self.y], &rows[self.y + 1], self.at)
    }
    #[inline(always)]
    fn store<V: Lanes>(self, value: V, rows: &mut [Row; TILE]) {
        let (first, second) = self.split(rows);
        value.store_pair(first, second, self.at);
    }
    #[inline(always)]
    fn load_bits<V: Lanes>(self, rows: &[[u32; TILE]; TILE]) -> V {
        V::load_pair_bits(&rows[self.y], &rows[self.y + 1], self.at)
    }
    #[inline(always)]
    fn store_bits<V: Lanes>(self, value: V, rows: &mut [[u32; TILE]; TILE]) {
        let (first, second) = self.split(rows);
        value.store_pair_bits(first, second, self.at);
    }
    #[inline(always)]
    fn stop<V: Lanes>(self, live: &mut [u16; TILE], lanes: u32) {
        let half = V::N / 2;
        live[self.y] &= !(((lanes & ((1 << half) - 1)) << self.at) as u16);
        live[self.y + 1] &= !(((lanes >> half) << self.at) as u16);
    }
}

/// Blends one Gaussian over the pixels of `window` whose lanes are set in `bits`, with `dx` their
/// offsets from its mean and `q_dy`, `q_row` their rows' terms of the exponent; returns how many
/// pixels it stopped. Each lane's operations are those of `blend`'s description, whatever window
/// holds it.
#[inline(always)]
fn blend_window<const COLOR: bool, const INDEX: bool, const SOLID: bool, V: Lanes, W: Window>(
    state: &mut TileState,
    window: W,
    bits: u32,
    dx: V,
    q_dy: V,
    q_row: V,
    g: &GaussianLanes<V>,
) -> usize {
    let s = V::splat;
    let q = dx * (g.qa * dx + q_dy) + q_row;
    let lanes = V::Mask::from_bits(bits);
    if lanes.and(q.ge(s(Q_FLOOR))).bits() == 0 {
        return 0; // every lane would get alpha < 1/255: skipped, T untouched
    }
    let alpha = q.exp2().min(s(ALPHA_MAX));
    let mut valid = lanes.and(alpha.ge(s(ALPHA_MIN)));
    if SOLID {
        valid = valid.and(g.z.gt(window.load(&state.near)));
    }
    let t: V = window.load(&state.transmittance);
    let test_t = t * (s(1.0) - alpha);
    let stop = valid.and(test_t.lt(s(T_MIN)));
    let blended = valid.and_not(stop);
    let weight = blended.keep(alpha * t);
    let new_t = blended.select(test_t, t);
    window.store(new_t, &mut state.transmittance);
    let mut stop_bits = stop.bits();
    if INDEX {
        let max_weight: V = window.load(&state.max_weight);
        let better = weight.gt(max_weight);
        let new_max = better.select(weight, max_weight);
        window.store(new_max, &mut state.max_weight);
        window.store_bits(better.select(g.id, window.load_bits(&state.max_id)), &mut state.max_id);
        if SOLID {
            let decided = lanes.and((s(ALPHA_MAX) * new_t).le(new_max)).and((s(1.0) - new_t).ge(s(0.5)));
            stop_bits |= decided.bits();
        }
    }
    if stop_bits != 0 {
        window.stop::<V>(&mut state.live, stop_bits);
    }
    if COLOR {
        let add = |acc: &mut [Row; TILE], value: V| {
            let sum = window.load::<V>(acc) + value * weight;
            window.store(sum, acc);
        };
        add(&mut state.red, g.color[0]);
        add(&mut state.green, g.color[1]);
        add(&mut state.blue, g.color[2]);
        if INDEX {
            add(&mut state.depth, g.z);
        }
    }
    stop_bits.count_ones() as usize
}
