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
use crate::simd::{F32x4, Mask4};
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

/// An output of background only (index -1, alpha 0); an error where it does not fit in memory.
pub fn blank(camera: &Camera, options: &RenderOptions) -> Result<RenderOutput, RasterError> {
    let (width, height) = (camera.width as usize, camera.height as usize);
    let pixels = width * height;
    let with_color = options.mode == RenderMode::Full;
    let colour = if with_color { pixels } else { 0 };
    // reserve everything before touching any of it, and report what the whole image needs
    let total = (4 * colour + 3 * pixels) * 4;
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
        alpha: try_filled(pixels, 0.0, "image")?, // transmittance is tracked in both modes, so alpha is free
        depth: try_filled(colour, 0.0, "image")?,
        index: try_filled(pixels, -1, "image")?,
        index_depth: try_filled(pixels, 0.0, "image")?,
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
    let (width, height) = (camera.width as usize, camera.height as usize);
    let with_color = options.mode == RenderMode::Full;
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
    let render_band = |band: Band| {
        if with_color {
            render_band::<true, S>(band, width, height, grid_x, source, options.background, mask)
        } else {
            render_band::<false, S>(band, width, height, grid_x, source, options.background, mask)
        }
    };
    bands.into_par_iter().with_max_len(1).for_each(render_band);
}

/// `n` consecutive chunks of `len` (the last shorter), or `n` empty slices for an unused output.
fn split_bands<T>(buf: &mut [T], len: usize, n: usize) -> Vec<&mut [T]> {
    if buf.is_empty() {
        return (0..n).map(|_| <&mut [T]>::default()).collect();
    }
    buf.chunks_mut(len.max(1)).collect()
}

/// Gaussians fetched ahead of blending, per tile.
const BATCH: usize = 64;
/// Lanes per SIMD group; a tile row is `GROUPS` groups.
const LANES: usize = 4;
const GROUPS: usize = TILE / LANES;
type Row = [[f32; LANES]; GROUPS];

/// Per-pixel accumulators of one tile, indexed `[row][group][lane]` so that a group is one
/// 4-lane vector; lives on the stack, reused for every tile of a band.
struct TileState {
    transmittance: [Row; TILE],
    red: [Row; TILE],
    green: [Row; TILE],
    blue: [Row; TILE],
    depth: [Row; TILE],
    max_weight: [Row; TILE],
    max_id: [[[u32; LANES]; GROUPS]; TILE],
    /// Per row, bit x is set while pixel x still blends: cleared once it stopped (T would drop
    /// below T_MIN) and never set outside the image.
    live: [u16; TILE],
}

impl TileState {
    fn new() -> Self {
        Self {
            transmittance: [[[1.0; LANES]; GROUPS]; TILE],
            red: [[[0.0; LANES]; GROUPS]; TILE],
            green: [[[0.0; LANES]; GROUPS]; TILE],
            blue: [[[0.0; LANES]; GROUPS]; TILE],
            depth: [[[0.0; LANES]; GROUPS]; TILE],
            max_weight: [[[0.0; LANES]; GROUPS]; TILE],
            max_id: [[[NO_GAUSSIAN; LANES]; GROUPS]; TILE],
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
}

#[allow(clippy::too_many_arguments)]
fn render_band<const COLOR: bool, S: Source>(
    band: Band,
    width: usize,
    height: usize,
    grid_x: usize,
    source: &S,
    background: [f32; 3],
    mask: Option<&TileMask>,
) {
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
        let mut live = state.reset(cols, rows);
        'lists: for list in source.lists(tile) {
            for batch in list.chunks(BATCH) {
                // Copy the batch first: the loads are independent, so their cache misses overlap
                // instead of stalling the blend loop one by one.
                let mut fetched = [Splat2D::default(); BATCH];
                for (dst, &id) in fetched.iter_mut().zip(batch) {
                    *dst = source.splat(id);
                }
                for (g, &id) in fetched.iter().zip(batch) {
                    live = live.saturating_sub(blend::<COLOR>(&mut state, g, id, col0, row0));
                    if live == 0 {
                        break 'lists;
                    }
                }
            }
        }
        // Write the tile into the band.
        for y in 0..rows {
            for x in 0..cols {
                let (gi, lane) = (x / LANES, x % LANES);
                let o = y * width + col0 + x;
                let t = state.transmittance[y][gi][lane];
                let id = state.max_id[y][gi][lane];
                if id == NO_GAUSSIAN {
                    band.index[o] = -1;
                    band.index_depth[o] = 0.0;
                } else {
                    band.index[o] = source.row(id) as i32;
                    band.index_depth[o] = source.splat(id).depth;
                }
                let a = 1.0 - t;
                band.alpha[o] = a;
                if COLOR {
                    band.depth[o] = if a > 0.0 { state.depth[y][gi][lane] / a } else { 0.0 };
                    let color = [state.red[y][gi][lane], state.green[y][gi][lane], state.blue[y][gi][lane]];
                    for ((out, c), bg) in band.rgb[o * 3..o * 3 + 3].iter_mut().zip(color).zip(background) {
                        *out = c + t * bg;
                    }
                }
            }
        }
    }
}

/// Blends Gaussian `g` (index `id`) over the live pixels of its box inside the tile
/// whose top-left pixel is (`col0`, `row0`); returns how many pixels it stopped.
///
/// Four pixels of a row at a time, branch-free within a group; per pixel the decisions and the
/// arithmetic are exactly the reference loop's: `power = -0.5 (A dx² + C dy²) - B dx dy`, skip
/// `power > 0`, `alpha = min(0.99, o exp(power))`, skip `alpha < 1/255`, stop (without blending)
/// when `T (1 - alpha) < 1e-4`, else `C += c alpha T`, `T *= 1 - alpha`.
#[inline]
fn blend<const COLOR: bool>(state: &mut TileState, g: &Splat2D, id: u32, col0: usize, row0: usize) -> usize {
    let [bx0, by0, bx1, by1] = g.pixel_box.map(usize::from);
    let x_start = bx0.max(col0) - col0;
    let x_end = (bx1 + 1).min(col0 + TILE).saturating_sub(col0);
    let y_start = by0.max(row0) - row0;
    let y_end = (by1 + 1).min(row0 + TILE).saturating_sub(row0);
    if x_start >= x_end {
        return 0;
    }
    let box_bits = (1u32 << x_end) - (1u32 << x_start);
    let s = F32x4::splat;
    let [ca, cb, cc] = g.conic;
    let (conic_a, conic_b) = (s(ca), s(cb));
    let (opacity, mean_x, power_floor) = (s(g.opacity), s(g.mean[0]), s(g.power_floor));
    let [red, green, blue] = g.color.map(s);
    let (z, id_lanes) = (s(g.depth), F32x4::from_bits([id; LANES]));
    let lane_offsets = F32x4::from_array([0.0, 1.0, 2.0, 3.0]);
    let mut stopped = 0;
    for y in y_start..y_end {
        let row_bits = box_bits & u32::from(state.live[y]);
        if row_bits == 0 {
            continue;
        }
        let dy = g.mean[1] - (row0 + y) as f32;
        let (cc_dy2, dy) = (s(cc * dy * dy), s(dy));
        for gi in x_start / LANES..x_end.div_ceil(LANES) {
            let bits = (row_bits >> (gi * LANES)) & 0xf;
            if bits == 0 {
                continue;
            }
            // Pixel x is sampled at x (INRIA coordinates, mean already shifted by -0.5).
            let dx = mean_x - (s((col0 + gi * LANES) as f32) + lane_offsets);
            let power = s(-0.5) * (conic_a * dx * dx + cc_dy2) - conic_b * dx * dy;
            let lanes = Mask4::from_bits(bits);
            if lanes.and(power.ge(power_floor)).bits() == 0 {
                continue; // every lane would get alpha < 1/255: skipped, T untouched
            }
            let alpha = (opacity * power.exp_nonpositive()).min(s(ALPHA_MAX));
            let valid = lanes.and(power.le(s(0.0))).and(alpha.ge(s(ALPHA_MIN)));
            let t = F32x4::from_array(state.transmittance[y][gi]);
            let test_t = t * (s(1.0) - alpha);
            let stop = valid.and(test_t.lt(s(T_MIN)));
            let blended = valid.and_not(stop);
            let weight = blended.keep(alpha * t);
            state.transmittance[y][gi] = blended.select(test_t, t).to_array();
            let stop_bits = stop.bits();
            if stop_bits != 0 {
                state.live[y] &= !((stop_bits << (gi * LANES)) as u16);
                stopped += stop_bits.count_ones() as usize;
            }
            let max_weight = F32x4::from_array(state.max_weight[y][gi]);
            let better = weight.gt(max_weight);
            state.max_weight[y][gi] = better.select(weight, max_weight).to_array();
            state.max_id[y][gi] = better.select(id_lanes, F32x4::from_bits(state.max_id[y][gi])).to_bits();
            if COLOR {
                let add =
                    |acc: &mut [f32; LANES], value: F32x4| *acc = (F32x4::from_array(*acc) + value * weight).to_array();
                add(&mut state.red[y][gi], red);
                add(&mut state.green[y][gi], green);
                add(&mut state.blue[y][gi], blue);
                add(&mut state.depth[y][gi], z);
            }
        }
    }
    stopped
}
