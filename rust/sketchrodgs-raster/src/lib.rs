//! CPU rasteriser for 3D Gaussian Splatting scenes, following the reference 3DGS rasteriser
//! (graphdeco-inria `diff-gaussian-rasterization`) equation for equation: EWA projection with
//! a 0.3 px² low-pass, 3-sigma tile footprint, 16x16 tiles, front-to-back blending sorted by
//! view-space depth, alpha capped at 0.99, contributions below 1/255 skipped, and a stop once the
//! transmittance would drop below 1e-4.
//!
//! Besides colour it renders what the sketch needs: the index image K (the Gaussian with the
//! largest blending weight `alpha_i * T_i` at each pixel) and its camera depth Z.
//!
//! Stages, each deterministic (the output never depends on the thread count): [`project`] every
//! Gaussian (parallel), sort the visible ones by depth (a stable radix sort) and bin them into
//! per-tile lists (parallel, [`bin`]), then [`composite`] each row of tiles (parallel) into
//! disjoint parts of the outputs. Compositing works on SIMD groups of 16 pixels (AVX-512F), 8
//! (AVX2; both detected at run time) or 4 (SSE2, portable fallback elsewhere), bit-identical at
//! every width, and allocates nothing per pixel or per tile.
//!
//! ```
//! use glam::Vec3;
//! use sketchrodgs_raster::{rasterize, Camera, RenderOptions, Splats};
//!
//! let camera = Camera {
//!     width: 64, height: 48, fx: 50.0, fy: 50.0, cx: 32.0, cy: 24.0,
//!     world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
//!     near: 0.2,
//! };
//! let means = [Vec3::new(0.0, 0.0, 2.0)];
//! let scales = [Vec3::splat(0.05)];
//! let quats = [[1.0, 0.0, 0.0, 0.0]];
//! let opacities = [0.9];
//! let sh = [1.0, 0.0, -1.0]; // degree 0: one RGB coefficient per Gaussian
//! let splats = Splats {
//!     means: &means, scales: &scales, quats: &quats, opacities: &opacities, sh: &sh, sh_coeffs: 1,
//!     sh_rows: None, sort_offsets: None,
//! };
//! let out = rasterize(&splats, &camera, &RenderOptions::default()).unwrap();
//! assert_eq!(out.index[24 * 64 + 32], 0); // the pixel under the mean sees Gaussian 0
//! assert_eq!(out.index[0], -1);           // a corner sees nothing
//! ```

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

pub mod bin;
pub mod camera;
pub mod composite;
mod kept;
pub mod project;
pub mod retained;
mod simd;
#[cfg(test)]
mod tests;
pub mod tiles;

pub use camera::{Camera, MAX_IMAGE_SIDE};
pub use kept::release_kept_buffers;
pub use retained::Retained;
pub use tiles::TileMask;

/// Tiles are `TILE_SIZE x TILE_SIZE` pixels (INRIA's BLOCK_X = BLOCK_Y = 16).
pub const TILE_SIZE: u32 = 16;
/// The reference's near plane (INRIA `in_frustum`): Gaussians whose centre has camera z at or below
/// it are culled. Our cameras default to it ([`Camera::near`]).
pub const NEAR_PLANE: f64 = 0.2;
/// Low-pass filter added to both diagonal entries of the 2D covariance, in px².
pub const LOW_PASS: f32 = 0.3;
/// Footprint radius in standard deviations of the major axis.
pub const SIGMA_EXTENT: f32 = 3.0;
/// Per-Gaussian alpha is capped here so that one Gaussian never makes a pixel fully opaque.
pub const ALPHA_MAX: f32 = 0.99;
/// Contributions with a smaller alpha are skipped (they do not touch the transmittance).
pub const ALPHA_MIN: f32 = 1.0 / 255.0;
/// Most (tile, Gaussian) pairs binned in one render (4 bytes each).
pub const MAX_TILE_PAIRS: usize = 1 << 30;
/// A pixel stops once blending the next Gaussian would leave less transmittance than this.
pub const T_MIN: f32 = 1e-4;

/// Everything that can be wrong with a render request.
#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    /// A camera field is degenerate; `field` names it.
    #[error("camera {field}: {reason}")]
    InvalidCamera { field: &'static str, reason: String },
    /// An input array has the wrong length for the number of Gaussians.
    #[error("{name}: expected {expected} values, got {got}")]
    LengthMismatch { name: &'static str, expected: usize, got: usize },
    /// `sh_coeffs` is not (d+1)² for a degree d in 0..=3.
    #[error("sh: {0} coefficients per channel is not (d+1)^2 for a degree d in 0..=3")]
    UnsupportedShDegree(usize),
    /// The footprints cover more (tile, Gaussian) pairs than we are willing to allocate.
    #[error("{0} (tile, Gaussian) pairs exceed the limit of {max}; render a smaller image or fewer huge Gaussians", max = MAX_TILE_PAIRS)]
    TooManyTilePairs(usize),
    /// A buffer could not be allocated (the image, or the tile lists, would not fit in memory).
    #[error("the {what} needs {:.2} GB, more memory than can be had: render a smaller image", *bytes as f64 / 1e9)]
    OutOfMemory { what: &'static str, bytes: usize },
    /// A Gaussian's SH row is not in the table.
    #[error("sh_rows: Gaussian {index} takes SH row {row}, but sh has {rows} rows")]
    ShRowOutOfRange { index: usize, row: u32, rows: usize },
    /// More Gaussians than a 32-bit index can name.
    #[error("too many Gaussians ({0}); at most {max} are supported", max = u32::MAX)]
    TooManyGaussians(usize),
}

/// `len` copies of `value`, or an error naming `what` where the memory is not there (instead of
/// the abort an infallible allocation makes).
pub(crate) fn try_filled<T: Clone>(len: usize, value: T, what: &'static str) -> Result<Vec<T>, RasterError> {
    let mut buffer = Vec::new();
    buffer
        .try_reserve_exact(len)
        .map_err(|_| RasterError::OutOfMemory { what, bytes: len.saturating_mul(std::mem::size_of::<T>()) })?;
    buffer.resize(len, value);
    Ok(buffer)
}

/// The Gaussians to render, as borrowed slices (activated values, see docs/conventions.md).
#[derive(Clone, Copy, Debug)]
pub struct Splats<'a> {
    /// (N) centres in world units.
    pub means: &'a [Vec3],
    /// (N) standard deviations along the local axes, linear.
    pub scales: &'a [Vec3],
    /// (N) rotations `[w, x, y, z]`; normalised here (a zero quaternion acts as the identity).
    pub quats: &'a [[f32; 4]],
    /// (N) opacities in [0, 1].
    pub opacities: &'a [f32],
    /// (N * sh_coeffs * 3) SH coefficients laid out `[gaussian][coefficient][rgb]`; coefficient 0 is DC.
    /// With `sh_rows`, a table of any number of such rows.
    pub sh: &'a [f32],
    /// Coefficients per channel K = (d+1)², d in 0..=3.
    pub sh_coeffs: usize,
    /// (N) the row of `sh` each Gaussian takes its coefficients from, or None: row i. The pieces of
    /// a split needle share their parent's row, so a split scene need not copy the SH of all.
    pub sh_rows: Option<&'a [u32]>,
    /// (N) where each Gaussian sorts, from its mean in its own axes (turned by its rotation),
    /// or None: at the mean. The pieces of a split needle sort where their parent's centre is,
    /// so that at rest they composite as the parent did (docs/rendering.md, "Sort points").
    pub sort_offsets: Option<&'a [Vec3]>,
}

impl<'a> Splats<'a> {
    /// Views flat row-major arrays (means and scales N*3, quats N*4, sh N*K*3, or M*K*3 rows that
    /// `sh_rows` picks from) as [`Splats`].
    pub fn from_flat(
        means: &'a [f32],
        scales: &'a [f32],
        quats: &'a [f32],
        opacities: &'a [f32],
        sh: &'a [f32],
        sh_coeffs: usize,
        sh_rows: Option<&'a [u32]>,
    ) -> Result<Self, RasterError> {
        // The slices are f32-aligned and Vec3/[f32; 4] need no more, so only a length that is
        // not a whole number of rows can fail.
        let whole_rows = |name: &'static str, width: usize, len: usize| RasterError::LengthMismatch {
            name,
            expected: len / width * width,
            got: len,
        };
        let splats = Self {
            means: bytemuck::try_cast_slice(means).map_err(|_| whole_rows("means", 3, means.len()))?,
            scales: bytemuck::try_cast_slice(scales).map_err(|_| whole_rows("scales", 3, scales.len()))?,
            quats: bytemuck::try_cast_slice(quats).map_err(|_| whole_rows("quats", 4, quats.len()))?,
            opacities,
            sh,
            sh_coeffs,
            sh_rows,
            sort_offsets: None,
        };
        splats.validate()?;
        Ok(splats)
    }

    /// These splats sorting at `offsets` (N*3, row-major; see [`Splats::sort_offsets`]).
    pub fn with_sort_offsets(self, offsets: &'a [f32]) -> Result<Self, RasterError> {
        let wrong =
            || RasterError::LengthMismatch { name: "sort_offsets", expected: self.len() * 3, got: offsets.len() };
        let rows: &[Vec3] = bytemuck::try_cast_slice(offsets).map_err(|_| wrong())?;
        if rows.len() != self.len() {
            return Err(wrong());
        }
        Ok(Self { sort_offsets: Some(rows), ..self })
    }

    /// The SH coefficients of Gaussian `i` (K*3 values), from its row of `sh` (see `sh_rows`);
    /// None where the row is not in `sh` (splats that [`Splats::validate`] refuses).
    #[inline]
    pub fn sh_of(&self, i: usize) -> Option<&'a [f32]> {
        let row = self.sh_rows.map_or(Some(i), |rows| rows.get(i).map(|&r| r as usize))?;
        let k = self.sh_coeffs * 3;
        self.sh.get(row * k..(row + 1) * k)
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// Whether there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Checks that every slice matches the number of Gaussians and that K is supported.
    pub fn validate(&self) -> Result<(), RasterError> {
        let n = self.len();
        if u32::try_from(n).is_err() {
            return Err(RasterError::TooManyGaussians(n));
        }
        if ![1, 4, 9, 16].contains(&self.sh_coeffs) {
            return Err(RasterError::UnsupportedShDegree(self.sh_coeffs));
        }
        let row = self.sh_coeffs * 3;
        let sh_rows = self.sh.len() / row;
        let lengths = [
            ("scales", self.scales.len(), n),
            ("quats", self.quats.len(), n),
            ("opacities", self.opacities.len(), n),
            ("sh", self.sh.len(), if self.sh_rows.is_some() { sh_rows * row } else { n * row }),
            ("sh_rows", self.sh_rows.map_or(n, <[u32]>::len), n),
        ];
        for (name, got, expected) in lengths {
            if got != expected {
                return Err(RasterError::LengthMismatch { name, expected, got });
            }
        }
        if let Some(rows) = self.sh_rows
            && let Some(index) = rows.iter().position(|&r| r as usize >= sh_rows)
        {
            return Err(RasterError::ShRowOutOfRange { index, row: rows[index], rows: sh_rows });
        }
        if let Some(offsets) = self.sort_offsets
            && offsets.len() != n
        {
            return Err(RasterError::LengthMismatch { name: "sort_offsets", expected: n, got: offsets.len() });
        }
        Ok(())
    }
}

/// Which outputs to compute.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RenderMode {
    /// rgb, alpha, expected depth, index and index depth.
    #[default]
    Full,
    /// Only the index image and its depth (no SH evaluation, no colour or depth accumulation).
    IndexOnly,
    /// The index image and its depth, exactly as [`RenderMode::IndexOnly`] gives them, and of
    /// alpha only whether it reaches 0.5: a pixel stops blending once no later Gaussian can take
    /// its index (`ALPHA_MAX * T` is at most its largest weight) and its alpha has reached 0.5.
    /// `alpha` is then exact below 0.5 and at least 0.5 where the full alpha is. What a sketch
    /// reads (docs/rendering.md, "Index and solid only"); over opaque objects far cheaper.
    IndexSolid,
    /// rgb and alpha only, exactly as [`RenderMode::Full`] gives them: no index image and no
    /// expected depth, so blending does not track each pixel's heaviest Gaussian. What a picture
    /// or an animation frame needs (docs/rendering.md, "Colour only").
    Color,
}

impl RenderMode {
    /// Whether the Gaussians' colours are evaluated and `rgb` blended.
    pub fn has_color(self) -> bool {
        matches!(self, Self::Full | Self::Color)
    }

    /// Whether the index image and its depth are made.
    pub fn has_index(self) -> bool {
        self != Self::Color
    }

    /// Whether the expected depth is made: with both the colour and the index ([`RenderMode::Full`]).
    pub fn has_depth(self) -> bool {
        self.has_color() && self.has_index()
    }
}

/// Render settings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderOptions {
    /// Colour added behind everything as `T_final * background` (default black).
    pub background: [f32; 3],
    /// Which outputs to compute (default all).
    pub mode: RenderMode,
}

/// Wall-clock seconds spent in each stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimings {
    /// Projection, covariance, SH colour and footprint of every Gaussian.
    pub project_s: f64,
    /// Depth sort of the visible Gaussians and binning into tiles.
    pub sort_s: f64,
    /// Per-tile front-to-back blending into the output images.
    pub composite_s: f64,
}

/// A rendered image set. Images are row-major `[row][col]`; `rgb` and `depth` are empty in the
/// index modes, `depth`, `index` and `index_depth` in [`RenderMode::Color`].
#[derive(Clone, Debug, Default)]
pub struct RenderOutput {
    pub width: usize,
    pub height: usize,
    /// (H * W * 3) colour, not clamped (SH colours may exceed 1).
    pub rgb: Vec<f32>,
    /// (H * W) accumulated opacity `1 - T_final` ([`RenderMode::IndexSolid`]: exact below 0.5).
    pub alpha: Vec<f32>,
    /// (H * W) expected camera z, `sum(w_i z_i) / alpha` (0 where nothing contributes).
    pub depth: Vec<f32>,
    /// (H * W) index of the Gaussian with the largest `alpha_i * T_i`, -1 where none.
    pub index: Vec<i32>,
    /// (H * W) camera z of that Gaussian (0 where none).
    pub index_depth: Vec<f32>,
    /// Gaussians that survived culling.
    pub n_visible: usize,
    /// (tile, Gaussian) pairs blended over.
    pub n_tile_pairs: usize,
    pub timings: StageTimings,
}

/// Renders `splats` for `camera`.
///
/// Returns an error for a degenerate camera or inconsistent inputs; an empty scene, or one
/// entirely behind the camera, renders as the background with index -1 everywhere.
pub fn rasterize(splats: &Splats, camera: &Camera, options: &RenderOptions) -> Result<RenderOutput, RasterError> {
    render(splats, camera, options, None)
}

/// Renders only the tiles of `tiles`, each exactly as [`rasterize`] renders it; the rest of the
/// image is background with index -1. Gaussians that cannot reach those tiles are dropped before
/// their projection, so the cost follows the part of the image rendered.
pub fn rasterize_tiles(
    splats: &Splats,
    camera: &Camera,
    options: &RenderOptions,
    tiles: &TileMask,
) -> Result<RenderOutput, RasterError> {
    check_tile_grid(camera, tiles)?;
    render(splats, camera, options, Some(tiles))
}

/// An error unless `tiles` is a mask over `camera`'s grid of tiles.
fn check_tile_grid(camera: &Camera, tiles: &TileMask) -> Result<(), RasterError> {
    let (grid_x, grid_y) = camera.tile_grid();
    if tiles.grid() != (grid_x as usize, grid_y as usize) {
        let (x, y) = tiles.grid();
        return Err(RasterError::LengthMismatch { name: "tiles", expected: (grid_x * grid_y) as usize, got: x * y });
    }
    Ok(())
}

/// The visible Gaussians' count and their per-tile lists, front to back (the tiles of `tiles`
/// only, when given); an error past `MAX_TILE_PAIRS`.
fn sort_and_bin(
    camera: &Camera,
    projected: &project::Projected,
    tiles: Option<&TileMask>,
) -> Result<(usize, bin::TileBins), RasterError> {
    let order = bin::sort_by_depth(projected);
    // every non-empty rectangle is in `order`: sum in row order (sequential reads, parallel)
    let n_pairs: usize =
        projected.rects.par_iter().with_min_len(project::MIN_GAUSSIANS_PER_TASK).map(|r| r.area()).sum();
    if n_pairs > MAX_TILE_PAIRS {
        return Err(RasterError::TooManyTilePairs(n_pairs));
    }
    Ok((order.len(), bin::TileBins::new(camera, &projected.rects, &order, tiles)?))
}

/// Depth layers behind `near` (camera z per pixel, row-major (H * W)), in
/// [`RenderMode::IndexSolid`], of the tiles of `tiles` (all when None): layer 0 blends at each
/// pixel only the Gaussians deeper than `near` there, and each further layer only those deeper
/// than the last layer's index depth plus `gap_px` pixels' world size at that depth (nothing
/// where the last layer had no Gaussian). `count` layers; the Gaussians are projected and sorted
/// once for all of them. What lies behind a leaf in front of a stem (docs/extraction.md,
/// "What lies behind").
pub fn rasterize_behind(
    splats: &Splats,
    camera: &Camera,
    tiles: Option<&TileMask>,
    near: &[f32],
    count: usize,
    gap_px: f32,
) -> Result<Vec<RenderOutput>, RasterError> {
    camera.validate()?;
    splats.validate()?;
    let pixels = camera.width as usize * camera.height as usize;
    if near.len() != pixels {
        return Err(RasterError::LengthMismatch { name: "near", expected: pixels, got: near.len() });
    }
    if let Some(tiles) = tiles {
        check_tile_grid(camera, tiles)?;
    }
    let projected = project::project(splats, camera, false, tiles);
    let (_, bins) = sort_and_bin(camera, &projected, tiles)?;
    let source = composite::Binned { projected: &projected, bins: &bins };
    let step = 1.0 + gap_px / camera.fx as f32;
    let mut layers: Vec<RenderOutput> = Vec::with_capacity(count);
    let mut near = near.to_vec();
    for _ in 0..count {
        if let Some(last) = layers.last() {
            near.par_iter_mut().zip(&last.index).zip(&last.index_depth).for_each(|((n, &k), &z)| {
                *n = if k >= 0 { z * step } else { f32::INFINITY };
            });
        }
        layers.push(composite::composite_behind(camera, &source, tiles, &near)?);
    }
    projected.give_back();
    Ok(layers)
}

fn render(
    splats: &Splats,
    camera: &Camera,
    options: &RenderOptions,
    tiles: Option<&TileMask>,
) -> Result<RenderOutput, RasterError> {
    camera.validate()?;
    splats.validate()?;

    let start = Instant::now();
    let projected = project::project(splats, camera, options.mode.has_color(), tiles);
    let projected_at = Instant::now();
    let (n_visible, bins) = sort_and_bin(camera, &projected, tiles)?;
    let sorted_at = Instant::now();
    let mut out =
        composite::composite(camera, &composite::Binned { projected: &projected, bins: &bins }, options, tiles)?;
    let end = Instant::now();
    projected.give_back();

    out.n_visible = n_visible;
    out.n_tile_pairs = bins.len();
    out.timings = StageTimings {
        project_s: (projected_at - start).as_secs_f64(),
        sort_s: (sorted_at - projected_at).as_secs_f64(),
        composite_s: (end - sorted_at).as_secs_f64(),
    };
    Ok(out)
}
