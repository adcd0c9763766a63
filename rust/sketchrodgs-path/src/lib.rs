//! Screen-space path search of SketchRodGS (paper: "Path Optimization", "Occlusion").
//!
//! Given the per-pixel index image `K` (which Gaussian contributes most to each pixel), its depth
//! image `Z`, the Gaussian centres and a user stroke, find the pixel path that follows the stroke
//! while minimising the 3D length of the chain of Gaussians it crosses (paper Eq. 1). Depth gaps
//! larger than `3R` are never crossed; where that cuts the path, the search resumes further along
//! the stroke (occlusion handling). docs/extraction.md is the specification.
//!
//! ```
//! use sketchrodgs_path::{IndexImage, TraceParams, trace_stroke};
//! // A 1-pixel-high image: Gaussians 0..8 in a row, one per pixel, 1 unit apart.
//! let index: Vec<i32> = (0..8).collect();
//! let depth = vec![5.0_f32; 8];
//! let centres: Vec<[f32; 3]> = (0..8).map(|i| [i as f32, 0.0, 5.0]).collect();
//! let image = IndexImage::new(8, 1, &index, &depth).unwrap();
//! let stroke = [[0.5_f32, 0.5], [7.5, 0.5]];
//! let params = TraceParams { radius: 1.0, ..TraceParams::default() };
//! let trace = trace_stroke(&image, &centres, &stroke, &params).unwrap();
//! assert_eq!(trace.pieces[0].gaussian_ids, (0..8).collect::<Vec<u32>>());
//! ```

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

mod band;
mod order;
mod radius;
mod search;
mod stroke;
mod width;

pub use order::forward_along_stroke;
pub use radius::{RadiusEstimate, estimate_radius};
pub use search::{Piece, PieceEnd, SurfaceColours, Trace, trace_stroke};

/// Things that make a trace impossible. Each names what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("index image is {width}x{height} but has {index} index and {depth} depth values")]
    ImageSize { width: usize, height: usize, index: usize, depth: usize },
    #[error("index image refers to Gaussian {id} but there are only {count} centres")]
    IndexOutOfRange { id: i32, count: usize },
    #[error("stroke vertex {vertex} has a non-finite coordinate")]
    NonFiniteStroke { vertex: usize },
    #[error(
        "stroke needs at least 2 distinct points inside the {width}x{height} image, got {inside} ({outside} outside the image)"
    )]
    StrokeTooShort { inside: usize, outside: usize, width: usize, height: usize },
    #[error("{}: draw it over the object", background_message(*outside, *width, *height))]
    StrokeOnBackground { outside: usize, width: usize, height: usize },
    #[error("the stroke meets an object at only {samples} of its samples: draw it along the object, end to end")]
    StrokeBarelyOnObject { samples: usize },
    #[error("rendered tiles: expected {grid_x}x{grid_y} tiles, got {tiles}")]
    TileGrid { tiles: usize, grid_x: usize, grid_y: usize },
    #[error(
        "layers behind: expected a whole number of {pixels}-pixel layers, got {index} index, {depth} depth and {alpha} alpha values"
    )]
    BehindSize { pixels: usize, index: usize, depth: usize, alpha: usize },
    #[error("parameter {name} must be finite and > 0, got {value}")]
    BadParameter { name: &'static str, value: f64 },
    #[error("colours: expected ascending Gaussian ids, one per colour row, got {ids} ids and {rows} rows")]
    Colours { ids: usize, rows: usize },
    #[error(
        "radius {radius} is {radius_px:.0} pixels at the stroke's depth, wider than the {width}x{height} image: give a smaller radius (in the scene's units)"
    )]
    RadiusWiderThanImage { radius: f32, radius_px: f32, width: usize, height: usize },
    #[error("band_px {band_px} is wider than the {width}x{height} image: give a smaller band")]
    BandWiderThanImage { band_px: f32, width: usize, height: usize },
    #[error(
        "{image}: the depth at pixel ({col}, {row}) is {depth} where a Gaussian is shown; it must be finite and > 0"
    )]
    BadDepth { image: String, col: usize, row: usize, depth: f32 },
}

/// Where a stroke on background lies: its points outside the image are said to be outside it, not
/// on background (docs/extraction.md, "Failures").
fn background_message(outside: usize, width: usize, height: usize) -> String {
    match outside {
        0 => "stroke lies entirely on background (no Gaussian near any of its points)".to_string(),
        _ => format!(
            "stroke lies on background inside the {width}x{height} image (no Gaussian near its points there), \
             and {outside} of its points {} outside the image",
            if outside == 1 { "lies" } else { "lie" }
        ),
    }
}

/// An error naming the first pixel (of the layers behind if `layers`) where `index` shows a
/// Gaussian at a depth that is not finite and positive: a cost made of such depths could be
/// negative, and the search's predecessors then run in a circle (a depth of -2 made the path's
/// walk back grow until memory ran out).
fn check_depths(layers: bool, width: usize, height: usize, index: &[i32], depth: &[f32]) -> Result<(), PathError> {
    let bad = |(&i, &z): (&i32, &f32)| (i >= 0) & !((z > 0.0) & (z < f32::INFINITY));
    // blocks folded without a branch, so that the pass vectorises, on both cores: a search for
    // the first bad pixel took 1.3 ms on a 960x540 image, more than a tenth of a whole trace
    let block = |(i, z): (&[i32], &[f32])| i.iter().zip(z).fold(false, |a, p| a | bad(p));
    if !index.par_chunks(1 << 14).zip(depth.par_chunks(1 << 14)).any(block) {
        return Ok(());
    }
    match index.iter().zip(depth).position(bad) {
        None => Ok(()),
        Some(p) => {
            let (layer, col, row) = (p / (width * height), p % width, p / width % height);
            let image = if layers { format!("layer {layer} behind the index image") } else { "index image".into() };
            Err(PathError::BadDepth { image, col, row, depth: depth[p] })
        }
    }
}

/// The rendered index image `K` and its depth `Z` (row-major, `[row * width + col]`).
#[derive(Debug, Clone, Copy)]
pub struct IndexImage<'a> {
    pub width: usize,
    pub height: usize,
    /// Gaussian with the largest blending weight at each pixel, -1 where none.
    index: &'a [i32],
    /// Camera z of that Gaussian.
    depth: &'a [f32],
    /// Accumulated opacity per pixel, if known: widths are measured where it is at least 0.5.
    alpha: Option<&'a [f32]>,
    /// Where only part of the image was rendered: which tiles, and the record of reads outside.
    rendered: Option<&'a Rendered>,
    /// What lies behind: further depth layers, each made like the image (docs/extraction.md,
    /// "What lies behind").
    behind: Option<Behind<'a>>,
    /// Where the image is read from behind a depth, the depth per pixel (see [`Floor`]).
    floor: Floor<'a>,
    /// Each Gaussian's view-independent colour (its SH DC term), if known: the radius estimate's
    /// widths stop where the surface's colour is not the part's (docs/extraction.md, "Radius").
    colours: Option<Colours<'a>>,
}

/// The colours of some Gaussians: `ids` ascending, `rgb` one row each.
#[derive(Debug, Clone, Copy)]
struct Colours<'a> {
    ids: &'a [u32],
    rgb: &'a [[f32; 3]],
}

/// Depth layers behind an index image, each peeled from the one before it (the renderer's
/// `rasterize_behind`), `count` images of the same size stacked layer after layer.
#[derive(Debug, Clone, Copy)]
struct Behind<'a> {
    count: usize,
    index: &'a [i32],
    depth: &'a [f32],
    alpha: &'a [f32],
}

/// The depth an image is read from: at each pixel, the first of its layers (front first) that has
/// a Gaussian at or behind the floor shows; nothing shows where none has.
#[derive(Debug, Clone, Copy)]
enum Floor<'a> {
    /// The front layer everywhere.
    Front,
    /// One depth for every pixel.
    Depth(f32),
    /// One depth per square cell of `FLOOR_CELL` pixels, row-major over `grid_x` cells a row.
    Cells { grid_x: usize, depths: &'a [f32] },
}

/// Side of the square cells of a per-cell floor, in pixels.
pub(crate) const FLOOR_CELL: usize = 8;

/// Which layer shows at a pixel: the front image, a layer behind it, or nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Shown {
    Front,
    Behind(usize),
    Nothing,
}

impl<'a> IndexImage<'a> {
    /// Wrap the buffers, checking their sizes.
    pub fn new(width: usize, height: usize, index: &'a [i32], depth: &'a [f32]) -> Result<Self, PathError> {
        let pixels = width.checked_mul(height);
        if width == 0 || height == 0 || pixels != Some(index.len()) || pixels != Some(depth.len()) {
            return Err(PathError::ImageSize { width, height, index: index.len(), depth: depth.len() });
        }
        check_depths(false, width, height, index, depth)?;
        Ok(Self {
            width,
            height,
            index,
            depth,
            alpha: None,
            rendered: None,
            behind: None,
            floor: Floor::Front,
            colours: None,
        })
    }

    /// Add the layers behind the image: `index`, `depth` and `alpha` each hold a whole number of
    /// images of this size, layer after layer, front to back (alpha as for `with_alpha`).
    pub fn with_behind(self, index: &'a [i32], depth: &'a [f32], alpha: &'a [f32]) -> Result<Self, PathError> {
        let pixels = self.width * self.height;
        let count = index.len() / pixels;
        if index.len() != count * pixels || depth.len() != index.len() || alpha.len() != index.len() {
            return Err(PathError::BehindSize { pixels, index: index.len(), depth: depth.len(), alpha: alpha.len() });
        }
        check_depths(true, self.width, self.height, index, depth)?;
        Ok(Self { behind: Some(Behind { count, index, depth, alpha }), ..self })
    }

    /// Add the colours of the Gaussians `ids` (ascending, as many as `rgb` has rows): those the image
    /// and its layers show, at least; a Gaussian not among them has no colour.
    pub fn with_colours(self, ids: &'a [u32], rgb: &'a [[f32; 3]]) -> Result<Self, PathError> {
        if ids.len() != rgb.len() || ids.windows(2).any(|w| w[0] >= w[1]) {
            return Err(PathError::Colours { ids: ids.len(), rows: rgb.len() });
        }
        Ok(Self { colours: Some(Colours { ids, rgb }), ..self })
    }

    /// The colour of the Gaussian at pixel `p`, if colours are known and there is one.
    pub(crate) fn colour(&self, p: usize) -> Option<[f32; 3]> {
        let colours = self.colours?;
        colours.ids.binary_search(&self.gaussian(p)?).ok().map(|k| colours.rgb[k])
    }

    /// Whether the Gaussians' colours are known.
    pub(crate) fn has_colours(&self) -> bool {
        self.colours.is_some()
    }

    /// Whether layers behind the image are known.
    pub(crate) fn has_behind(&self) -> bool {
        self.behind.is_some_and(|b| b.count > 0)
    }

    /// The image read from behind `depth`: each pixel shows the first layer with a Gaussian at or
    /// behind it (the front image where it is there already).
    pub(crate) fn seen_from_depth(&self, depth: f32) -> Self {
        Self { floor: if self.has_behind() { Floor::Depth(depth) } else { Floor::Front }, ..*self }
    }

    /// The image read from behind a depth per cell of `FLOOR_CELL` pixels (`-inf`: the front; no
    /// depths: the front everywhere).
    pub(crate) fn seen_from_cells<'b>(&self, depths: &'b [f32]) -> IndexImage<'b>
    where
        'a: 'b,
    {
        let grid_x = self.width.div_ceil(FLOOR_CELL);
        let floor =
            if self.has_behind() && !depths.is_empty() { Floor::Cells { grid_x, depths } } else { Floor::Front };
        IndexImage { floor, ..*self }
    }

    /// The layer that shows at pixel `p` (see [`Floor`]).
    #[inline]
    fn shown(&self, p: usize) -> Shown {
        let floor = match self.floor {
            Floor::Front => return Shown::Front,
            Floor::Depth(z) => z,
            Floor::Cells { grid_x, depths } => {
                depths[(p / self.width) / FLOOR_CELL * grid_x + (p % self.width) / FLOOR_CELL]
            }
        };
        if self.index[p] < 0 || self.depth[p] >= floor {
            return Shown::Front;
        }
        let Some(behind) = self.behind else { return Shown::Nothing };
        let pixels = self.width * self.height;
        for layer in 0..behind.count {
            let q = layer * pixels + p;
            if behind.index[q] < 0 {
                return Shown::Nothing;
            }
            if behind.depth[q] >= floor {
                return Shown::Behind(q);
            }
        }
        Shown::Nothing
    }

    /// Add the accumulated opacity image (same size), used to measure the object's width.
    pub fn with_alpha(self, alpha: &'a [f32]) -> Result<Self, PathError> {
        if alpha.len() != self.index.len() {
            return Err(PathError::ImageSize {
                width: self.width,
                height: self.height,
                index: self.index.len(),
                depth: alpha.len(),
            });
        }
        Ok(Self { alpha: Some(alpha), ..self })
    }

    /// Say that only the tiles of `rendered` hold the render (the rest reads as background), so
    /// that reads outside them are recorded in it.
    pub fn with_rendered(self, rendered: &'a Rendered) -> Result<Self, PathError> {
        if rendered.width != self.width || rendered.height != self.height {
            return Err(PathError::ImageSize {
                width: rendered.width,
                height: rendered.height,
                index: self.index.len(),
                depth: self.depth.len(),
            });
        }
        Ok(Self { rendered: Some(rendered), ..self })
    }

    /// Records a read of pixel `p` outside the rendered tiles.
    #[inline]
    fn note(&self, p: usize) {
        self.known(p);
    }

    /// Whether pixel `p` was rendered; a read of one that was not is recorded.
    #[inline]
    pub(crate) fn known(&self, p: usize) -> bool {
        self.rendered.is_none_or(|r| r.note(p))
    }

    /// The Gaussian index at pixel `p`, -1 where none.
    #[inline]
    pub(crate) fn id_at(&self, p: usize) -> i32 {
        self.note(p);
        match self.shown(p) {
            Shown::Front => self.index[p],
            Shown::Behind(q) => self.behind.map_or(-1, |b| b.index[q]),
            Shown::Nothing => -1,
        }
    }

    /// The camera z at pixel `p`.
    #[inline]
    pub(crate) fn depth(&self, p: usize) -> f32 {
        self.note(p);
        match self.shown(p) {
            Shown::Front => self.depth[p],
            Shown::Behind(q) => self.behind.map_or(0.0, |b| b.depth[q]),
            Shown::Nothing => 0.0,
        }
    }

    /// Whether pixel `p` shows the object solidly: a Gaussian, and opacity >= 0.5 where known.
    #[inline]
    pub(crate) fn covered(&self, p: usize) -> bool {
        self.note(p);
        match self.shown(p) {
            Shown::Front => self.index[p] >= 0 && self.alpha.is_none_or(|a| a[p] >= 0.5),
            Shown::Behind(q) => self.behind.is_some_and(|b| b.index[q] >= 0 && b.alpha[q] >= 0.5),
            Shown::Nothing => false,
        }
    }

    /// Every layer's Gaussian at pixel `p`, front first, as (layer, depth): 0 the front image, then
    /// the solid ones of the layers behind it, until one has none.
    pub(crate) fn layers_at(&self, p: usize, mut each: impl FnMut(usize, f32)) {
        self.note(p);
        if self.index[p] < 0 {
            return;
        }
        each(0, self.depth[p]);
        if let Some(behind) = self.behind {
            let pixels = self.width * self.height;
            for layer in 0..behind.count {
                let q = layer * pixels + p;
                if behind.index[q] < 0 {
                    return;
                }
                // behind the front, only a solid layer is a surface: a faint haze of big
                // Gaussians behind a leaf would otherwise pass for one
                if behind.alpha[q] >= 0.5 {
                    each(layer + 1, behind.depth[q]);
                }
            }
        }
    }

    /// Gaussian at pixel `p` (flat index), if any.
    #[inline]
    pub(crate) fn gaussian(&self, p: usize) -> Option<u32> {
        u32::try_from(self.id_at(p)).ok()
    }

    /// The largest Gaussian index in the image and its layers behind (-1 when none).
    pub(crate) fn max_id(&self) -> i32 {
        let behind = self.behind.map_or(&[][..], |b| b.index);
        self.index.iter().chain(behind).copied().max().unwrap_or(-1)
    }

    /// Flat pixel index of continuous coordinates, if inside the image.
    #[inline]
    pub(crate) fn pixel_at(&self, x: f32, y: f32) -> Option<usize> {
        if x >= 0.0 && y >= 0.0 && (x as usize) < self.width && (y as usize) < self.height {
            Some(y as usize * self.width + x as usize)
        } else {
            None
        }
    }
}

/// Which square tiles of the image were rendered, for a search over a render of only part of the
/// image (the band around a stroke). Every read outside them is recorded, so that the caller
/// renders those tiles too and searches again: the result then equals a full render's.
#[derive(Debug)]
pub struct Rendered {
    width: usize,
    height: usize,
    tile: usize,
    grid_x: usize,
    /// Whether each pixel's tile was rendered: a read tests one byte, where finding its tile takes
    /// four divisions (the reads are a tenth of a trace's time otherwise)
    pixel_on: Vec<bool>,
    missed: Vec<AtomicBool>,
}

impl Rendered {
    /// `on` is row-major over the `ceil(width / tile) x ceil(height / tile)` grid of tiles.
    pub fn new(width: usize, height: usize, tile: usize, on: Vec<bool>) -> Result<Self, PathError> {
        let (grid_x, grid_y) = (width.div_ceil(tile.max(1)), height.div_ceil(tile.max(1)));
        if tile == 0 || on.len() != grid_x * grid_y {
            return Err(PathError::TileGrid { tiles: on.len(), grid_x, grid_y });
        }
        let missed = on.iter().map(|_| AtomicBool::new(false)).collect();
        let mut pixel_on = Vec::with_capacity(width * height);
        for row in 0..height {
            for (k, &tile_on) in on[row / tile * grid_x..][..grid_x].iter().enumerate() {
                pixel_on.extend(std::iter::repeat_n(tile_on, tile.min(width - k * tile)));
            }
        }
        Ok(Self { width, height, tile, grid_x, pixel_on, missed })
    }

    /// Whether pixel `p` is rendered, recording it when not.
    #[inline]
    fn note(&self, p: usize) -> bool {
        let on = self.pixel_on[p];
        if !on {
            let tile = (p / self.width) / self.tile * self.grid_x + (p % self.width) / self.tile;
            self.missed[tile].store(true, Ordering::Relaxed);
        }
        on
    }

    /// The tiles read but not rendered (row-major, as `on`).
    pub fn missed(&self) -> Vec<bool> {
        self.missed.iter().map(|m| m.load(Ordering::Relaxed)).collect()
    }
}

/// Parameters of the search. Symbols are the paper's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceParams {
    /// `R`: radius of the slender object in world units. Depth gaps over `3R` are not crossed.
    pub radius: f32,
    /// `alpha`: weight of the squared distance to the stroke in Eq. 1. Default 1. With the focal
    /// length known, the term is in units of `search::STROKE_TERM_PX` pixels' world size, so that the
    /// path does not depend on the scene's units.
    pub stroke_weight: f64,
    /// `b`: half-width in pixels of the band around the stroke that the path may use.
    /// 0 here means the default: 1 % of the image width, or 1.25 `R` in pixels at the stroke's depth
    /// where that is wider, so that a stroke anywhere over a thick part reaches its middle
    /// ([`TraceParams::default_band_px`]).
    pub band_px: f32,
    /// A stroke vertex this close (pixels) to a path found so far counts as covered. Default 10.
    pub cover_px: f32,
    /// The camera's focal length in pixels. It turns pixels into world distance at a depth, which
    /// lets the stroke's depth change with its length (a receding part), the path avoid surfaces
    /// much wider than `2R` (a leaf or body beside the part) and the stroke term weigh the same in
    /// any units. 0: unknown, none of these is done.
    pub focal_px: f32,
}

impl Default for TraceParams {
    fn default() -> Self {
        Self { radius: 0.01, stroke_weight: 1.0, band_px: 0.0, cover_px: 10.0, focal_px: 0.0 }
    }
}

impl TraceParams {
    /// The default band half-width for an image `width` pixels wide: 1 % of the width, at least 2 px,
    /// and at least `BAND_RADII` times the part's radius in pixels (`radius_px`, 0 when unknown).
    pub fn default_band_px(width: usize, radius_px: f32) -> f32 {
        (0.01 * width as f32).max(2.0).max(BAND_RADII * radius_px)
    }

    /// The parameters checked, with the default band filled in (`radius_px`: the part's radius in
    /// pixels at the stroke's depth, 0 when unknown). A radius or a band wider than the image is an
    /// error: the band's labelling and the stroke's surfaces would read the whole image at every
    /// sample (a radius of 1e6 in a scene of unit size took minutes).
    fn validated(&self, width: usize, height: usize, radius_px: f32) -> Result<Self, PathError> {
        let check = |name: &'static str, value: f64| {
            if value.is_finite() && value > 0.0 { Ok(()) } else { Err(PathError::BadParameter { name, value }) }
        };
        check("radius", f64::from(self.radius))?;
        check("cover_px", f64::from(self.cover_px))?;
        if !(self.focal_px.is_finite() && self.focal_px >= 0.0) {
            return Err(PathError::BadParameter { name: "focal_px", value: f64::from(self.focal_px) });
        }
        if !(self.stroke_weight.is_finite() && self.stroke_weight >= 0.0) {
            return Err(PathError::BadParameter { name: "stroke_weight", value: self.stroke_weight });
        }
        let side = width.max(height) as f32;
        // (the default band reaches `BAND_RADII` radii: past the image, the radius is the cause)
        if BAND_RADII * radius_px > side {
            return Err(PathError::RadiusWiderThanImage { radius: self.radius, radius_px, width, height });
        }
        let band_px = if self.band_px == 0.0 { Self::default_band_px(width, radius_px) } else { self.band_px };
        check("band_px", f64::from(band_px))?;
        if band_px > side {
            return Err(PathError::BandWiderThanImage { band_px, width, height });
        }
        Ok(Self { band_px, ..*self })
    }
}

/// The default band reaches this many radii (in pixels) from the stroke, where that is wider than 1 %
/// of the image: a stroke drawn anywhere over a thick part then still reaches its middle.
const BAND_RADII: f32 = 1.25;

/// Depth gaps under this many pixels' world size are never taken for an occlusion: the centres of
/// a real capture's Gaussians scatter in depth by a few pixels, whatever the part's radius.
pub(crate) const GAP_FLOOR_PX: f32 = 8.0;

/// The depth gap that separates surfaces: `3R`, but at least `GAP_FLOOR_PX` pixels' world size at
/// the median depth under the stroke (when the focal length is known).
pub(crate) fn depth_gap(image: &IndexImage, stroke: &[[f32; 2]], radius: f32, focal_px: f32) -> f32 {
    match depth_under(image, stroke) {
        Some(z) if focal_px > 0.0 => (3.0 * radius).max(GAP_FLOOR_PX * z / focal_px),
        _ => 3.0 * radius,
    }
}

/// The median depth of the object under the stroke's points, if any is on it.
pub(crate) fn depth_under(image: &IndexImage, stroke: &[[f32; 2]]) -> Option<f32> {
    let mut under: Vec<f32> = stroke
        .iter()
        .filter_map(|p| image.pixel_at(p[0], p[1]))
        .filter(|&q| image.id_at(q) >= 0)
        .map(|q| image.depth(q))
        .collect();
    (!under.is_empty()).then(|| width::median(&mut under))
}

#[cfg(test)]
mod tests;
