//! Bindings for `sketchrodgs-path`: `_core.trace_stroke(...)`, and `_core.shown_ids(...)` for its colours.

use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyReadonlyArrayDyn, PyReadwriteArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use sketchrodgs_path::{IndexImage, PathError, PieceEnd, Rendered, TraceParams};

use crate::arrays::{as_rows, check_shape, contiguous, contiguous_mut};
use crate::errors::{PathNotFoundError, SketchRodGSError};
use crate::pool::run_parallel;

fn path_err(err: PathError) -> PyErr {
    match err {
        PathError::StrokeOnBackground { .. }
        | PathError::StrokeBarelyOnObject { .. }
        | PathError::StrokeTooShort { .. } => PathNotFoundError::new_err(err.to_string()),
        _ => SketchRodGSError::new_err(err.to_string()),
    }
}

/// Screen-space path under a stroke (see `sketchrodgs.extract_rod` for the public API).
///
/// index (H, W) int32 and depth (H, W) float32 are the index image K and its depth Z; centres
/// (N, 3) float32; stroke (M, 2) float32 pixel coordinates. `band_px = 0` means 1 % of the width or 1.25 R in pixels, the wider;
/// `focal_px` is the camera's focal length in pixels (0: unknown); `alpha` (H, W) float32 or None.
/// Returns a `Trace` (its `pieces`, `clean_stroke` and `coverage`). `colours`, if known, as for
/// `estimate_radius`: the path keeps off the colour of a surface the part lies on. `rendered`
/// (tiles, see `RenderedTiles`) says that only those 16x16 tiles were rendered; reads outside them
/// are set in `missed` (same shape, bool), also when the trace fails.
#[pyfunction]
#[pyo3(signature = (index, depth, centres, stroke, radius, stroke_weight = 1.0, band_px = 0.0, cover_px = 10.0, focal_px = 0.0, alpha = None, rendered = None, missed = None, behind = None, colours = None))]
#[allow(clippy::too_many_arguments)]
fn trace_stroke<'py>(
    py: Python<'py>,
    index: &Bound<'py, PyArray2<i32>>,
    depth: &Bound<'py, PyArray2<f32>>,
    centres: &Bound<'py, PyArray2<f32>>,
    stroke: &Bound<'py, PyArray2<f32>>,
    radius: f32,
    stroke_weight: f64,
    band_px: f32,
    cover_px: f32,
    focal_px: f32,
    alpha: Option<Bound<'py, PyArray2<f32>>>,
    rendered: Option<Bound<'py, PyArray2<bool>>>,
    missed: Option<Bound<'py, PyArray2<bool>>>,
    behind: Option<BehindArgs<'py>>,
    colours: Option<ColourArgs<'py>>,
) -> PyResult<Trace> {
    let (index, depth, centres, stroke) =
        (index.try_readonly()?, depth.try_readonly()?, centres.try_readonly()?, stroke.try_readonly()?);
    let colours = colours.map(ColourArrays::read).transpose()?;
    let alpha = alpha.as_ref().map(|a| a.try_readonly()).transpose()?;
    let (height, width) = (index.shape()[0], index.shape()[1]);
    check_shape("depth", depth.shape(), &[Some(height), Some(width)])?;
    check_shape("centres", centres.shape(), &[None, Some(3)])?;
    check_shape("stroke", stroke.shape(), &[None, Some(2)])?;
    let mut image =
        IndexImage::new(width, height, contiguous(&index, "index")?, contiguous(&depth, "depth")?).map_err(path_err)?;
    if let Some(alpha) = &alpha {
        check_shape("alpha", alpha.shape(), &[Some(height), Some(width)])?;
        image = image.with_alpha(contiguous(alpha, "alpha")?).map_err(path_err)?;
    }
    let behind = behind.map(|b| BehindArrays::read(b, height, width)).transpose()?;
    if let Some(b) = &behind {
        image = b.attach(image)?;
    }
    if let Some(c) = &colours {
        image = c.attach(image)?;
    }
    let centres: &[[f32; 3]] = as_rows(contiguous(&centres, "centres")?);
    let stroke: &[[f32; 2]] = as_rows(contiguous(&stroke, "stroke")?);
    let params = TraceParams { radius, stroke_weight, band_px, cover_px, focal_px };
    let region = RegionArgs::new(rendered.as_ref(), missed.as_ref(), width, height)?;
    let image = region.attach(image)?;
    let trace = run_parallel(py, "trace_stroke", || sketchrodgs_path::trace_stroke(&image, centres, stroke, &params));
    region.report()?;
    let trace = trace?.map_err(path_err)?;

    let pieces = trace
        .pieces
        .into_iter()
        .map(|piece| {
            let count = piece.pixels.len();
            let pixels = Array2::from_shape_vec((count, 2), piece.pixels.into_iter().flatten().collect())
                .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
            let (reached_goal, lost_pixel, lost_progress) = match piece.end {
                PieceEnd::Goal => (true, None, None),
                PieceEnd::Lost { pixel, progress } => (false, Some((pixel[0], pixel[1])), Some(progress)),
            };
            Py::new(
                py,
                TracePiece {
                    pixels: pixels.into_pyarray(py).unbind(),
                    pixel_ids: piece.pixel_ids.into_pyarray(py).unbind(),
                    gaussian_ids: piece.gaussian_ids.into_pyarray(py).unbind(),
                    reached_goal,
                    lost_pixel,
                    lost_progress,
                },
            )
        })
        .collect::<PyResult<Vec<_>>>()?;
    let kept = trace.clean_stroke.len();
    let clean = Array2::from_shape_vec((kept, 2), trace.clean_stroke.into_iter().flatten().collect())
        .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok(Trace {
        pieces,
        clean_stroke: clean.into_pyarray(py).unbind(),
        coverage: trace.coverage,
        wants_behind: trace.wants_behind,
        colours: trace.colours.map(|c| (c.part, c.surround)),
    })
}

/// One piece of a trace: its pixels (P, 2) uint32 (col, row), the Gaussian the search saw at each
/// (P,) uint32 (of the front image or a layer behind it), its Gaussians in order, and how it
/// ended (at the stroke's end, or lost at a pixel, that far along the stroke).
#[pyclass(module = "sketchrodgs._core", name = "TracePiece", frozen, get_all)]
pub struct TracePiece {
    pixels: Py<PyArray2<u32>>,
    pixel_ids: Py<PyArray1<u32>>,
    gaussian_ids: Py<PyArray1<u32>>,
    reached_goal: bool,
    lost_pixel: Option<(u32, u32)>,
    lost_progress: Option<f32>,
}

/// A trace: its pieces, the stroke as cleaned up (M', 2) float32, the share of it covered,
/// whether the layers behind the image, not given, could change it (`wants_behind`), and where the
/// part lies on a surface of another colour, (the part's colour, the surface's) RGB (`colours`).
#[pyclass(module = "sketchrodgs._core", name = "Trace", frozen, get_all)]
pub struct Trace {
    pieces: Vec<Py<TracePiece>>,
    clean_stroke: Py<PyArray2<f32>>,
    coverage: f32,
    wants_behind: bool,
    colours: Option<([f32; 3], [f32; 3])>,
}

/// The object's radius from its visible width under a stroke (`sketchrodgs_path::estimate_radius`):
/// index, depth, alpha (H, W); stroke (M, 2) float32; focal_px > 0; band_px 0 = 1 % of the width;
/// `rendered`, `missed` and `behind` as for `trace_stroke`; `colours`, if known, (ids (M,) uint32
/// ascending, rgb (M, 3) float32): the colours of the Gaussians the images show. Returns (R,
/// whether the layers behind, not given, could change it).
#[pyfunction]
#[pyo3(signature = (index, depth, alpha, stroke, focal_px, band_px = 0.0, rendered = None, missed = None, behind = None, colours = None))]
#[allow(clippy::too_many_arguments)]
fn estimate_radius<'py>(
    py: Python<'py>,
    index: &Bound<'py, PyArray2<i32>>,
    depth: &Bound<'py, PyArray2<f32>>,
    alpha: &Bound<'py, PyArray2<f32>>,
    stroke: &Bound<'py, PyArray2<f32>>,
    focal_px: f32,
    band_px: f32,
    rendered: Option<Bound<'py, PyArray2<bool>>>,
    missed: Option<Bound<'py, PyArray2<bool>>>,
    behind: Option<BehindArgs<'py>>,
    colours: Option<ColourArgs<'py>>,
) -> PyResult<(f32, bool)> {
    let (index, depth, alpha, stroke) =
        (index.try_readonly()?, depth.try_readonly()?, alpha.try_readonly()?, stroke.try_readonly()?);
    let colours = colours.map(ColourArrays::read).transpose()?;
    let (height, width) = (index.shape()[0], index.shape()[1]);
    check_shape("depth", depth.shape(), &[Some(height), Some(width)])?;
    check_shape("alpha", alpha.shape(), &[Some(height), Some(width)])?;
    check_shape("stroke", stroke.shape(), &[None, Some(2)])?;
    let alpha = contiguous(&alpha, "alpha")?;
    let image = IndexImage::new(width, height, contiguous(&index, "index")?, contiguous(&depth, "depth")?)
        .and_then(|image| image.with_alpha(alpha))
        .map_err(path_err)?;
    let behind = behind.map(|b| BehindArrays::read(b, height, width)).transpose()?;
    let image = match &behind {
        Some(b) => b.attach(image)?,
        None => image,
    };
    let image = match &colours {
        Some(c) => c.attach(image)?,
        None => image,
    };
    let stroke: &[[f32; 2]] = as_rows(contiguous(&stroke, "stroke")?);
    let params = TraceParams { band_px, focal_px, ..TraceParams::default() };
    let region = RegionArgs::new(rendered.as_ref(), missed.as_ref(), width, height)?;
    let image = region.attach(image)?;
    let estimate = run_parallel(py, "estimate_radius", || sketchrodgs_path::estimate_radius(&image, stroke, &params));
    region.report()?;
    let estimate = estimate?.map_err(path_err)?;
    Ok((estimate.radius, estimate.wants_behind))
}

/// The colours of some Gaussians: ids (M,) uint32 ascending, rgb (M, 3) float32.
type ColourArgs<'py> = (Bound<'py, PyArray1<u32>>, Bound<'py, PyArray2<f32>>);

/// The `colours` argument, borrowed.
struct ColourArrays<'py>(PyReadonlyArray1<'py, u32>, PyReadonlyArray2<'py, f32>);

impl<'py> ColourArrays<'py> {
    /// Borrow the arrays, checking that the colours are rows of 3.
    fn read((ids, rgb): ColourArgs<'py>) -> PyResult<Self> {
        check_shape("colours", rgb.shape(), &[None, Some(3)])?;
        Ok(Self(ids.try_readonly()?, rgb.try_readonly()?))
    }

    /// The image with these colours.
    fn attach<'a>(&'a self, image: IndexImage<'a>) -> PyResult<IndexImage<'a>> {
        image
            .with_colours(contiguous(&self.0, "colour ids")?, as_rows(contiguous(&self.1, "colours")?))
            .map_err(path_err)
    }
}

/// The layers behind the image, (index, depth, alpha) each (L, H, W): int32, float32, float32
/// (`sketchrodgs.render.render_behind`, stacked).
type BehindArgs<'py> = (Bound<'py, PyArray3<i32>>, Bound<'py, PyArray3<f32>>, Bound<'py, PyArray3<f32>>);

/// The layers behind, borrowed read-only.
struct BehindArrays<'py>(PyReadonlyArray3<'py, i32>, PyReadonlyArray3<'py, f32>, PyReadonlyArray3<'py, f32>);

impl<'py> BehindArrays<'py> {
    /// Borrow the arrays, checking that each holds layers of `height x width`.
    fn read((index, depth, alpha): BehindArgs<'py>, height: usize, width: usize) -> PyResult<Self> {
        let (index, depth, alpha) = (index.try_readonly()?, depth.try_readonly()?, alpha.try_readonly()?);
        let layers = index.shape()[0];
        for (name, shape) in
            [("behind index", index.shape()), ("behind depth", depth.shape()), ("behind alpha", alpha.shape())]
        {
            check_shape(name, shape, &[Some(layers), Some(height), Some(width)])?;
        }
        Ok(Self(index, depth, alpha))
    }

    /// The image with these layers behind it.
    fn attach<'a>(&'a self, image: IndexImage<'a>) -> PyResult<IndexImage<'a>> {
        let index = contiguous(&self.0, "behind index")?;
        let depth = contiguous(&self.1, "behind depth")?;
        let alpha = contiguous(&self.2, "behind alpha")?;
        image.with_behind(index, depth, alpha).map_err(path_err)
    }
}

/// Side of the tiles of `rendered` (the rasteriser's).
const TILE: usize = 16;

/// The `rendered` and `missed` arguments: the rendered tiles, and where to report reads outside.
struct RegionArgs<'py> {
    rendered: Option<Rendered>,
    missed: Option<PyReadwriteArray2<'py, bool>>,
}

impl<'py> RegionArgs<'py> {
    fn new(
        rendered: Option<&Bound<'py, PyArray2<bool>>>,
        missed: Option<&Bound<'py, PyArray2<bool>>>,
        width: usize,
        height: usize,
    ) -> PyResult<Self> {
        let (Some(rendered), Some(missed)) = (rendered, missed) else {
            if rendered.is_some() || missed.is_some() {
                return Err(SketchRodGSError::new_err("rendered and missed: give both or neither"));
            }
            return Ok(Self { rendered: None, missed: None });
        };
        let grid = [Some(height.div_ceil(TILE)), Some(width.div_ceil(TILE))];
        let on = rendered.try_readonly()?;
        check_shape("rendered", on.shape(), &grid)?;
        let missed = missed.try_readwrite()?;
        check_shape("missed", missed.shape(), &grid)?;
        let on = contiguous(&on, "rendered")?.to_vec();
        let rendered = Rendered::new(width, height, TILE, on).map_err(path_err)?;
        Ok(Self { rendered: Some(rendered), missed: Some(missed) })
    }

    fn attach<'a>(&'a self, image: IndexImage<'a>) -> PyResult<IndexImage<'a>> {
        match &self.rendered {
            Some(r) => image.with_rendered(r).map_err(path_err),
            None => Ok(image),
        }
    }

    /// Write the reads outside the rendered tiles into `missed`.
    fn report(mut self) -> PyResult<()> {
        if let (Some(rendered), Some(missed)) = (&self.rendered, &mut self.missed) {
            let out = contiguous_mut(missed, "missed")?;
            for (o, m) in out.iter_mut().zip(rendered.missed()) {
                *o |= m;
            }
        }
        Ok(())
    }
}

/// Which of the path's Gaussians to keep so that none goes back along the stroke
/// (`sketchrodgs_path::forward_along_stroke`): `points` (L, 2) float32 their centres on screen in
/// visiting order, `radius_px` (L,) float32 R on screen at each, `stroke` (K, 2) float32 the
/// cleaned stroke. Returns (L,) bool.
#[pyfunction]
fn forward_along_stroke<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    radius_px: &Bound<'py, PyArray1<f32>>,
    stroke: &Bound<'py, PyArray2<f32>>,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (points, radius_px, stroke) = (points.try_readonly()?, radius_px.try_readonly()?, stroke.try_readonly()?);
    check_shape("points", points.shape(), &[None, Some(2)])?;
    check_shape("radius_px", radius_px.shape(), &[Some(points.shape()[0])])?;
    check_shape("stroke", stroke.shape(), &[None, Some(2)])?;
    let points: &[[f32; 2]] = as_rows(contiguous(&points, "points")?);
    let stroke: &[[f32; 2]] = as_rows(contiguous(&stroke, "stroke")?);
    let radius_px = contiguous(&radius_px, "radius_px")?;
    Ok(sketchrodgs_path::forward_along_stroke(points, radius_px, stroke).into_pyarray(py))
}

/// The ids (ascending, uint32) that `images` (each (H, W) or (L, H, W) int32, -1 where nothing is
/// shown) show in the pixel box `low` to `high` (x, y; `high` excluded), of `count` Gaussians: one
/// pass over the pixels and a bit per Gaussian, where NumPy's mask over all rows took a millisecond
/// or two on a whole 960x540 view.
#[pyfunction]
fn shown_ids<'py>(
    py: Python<'py>,
    images: Vec<PyReadonlyArrayDyn<'py, i32>>,
    low: [usize; 2],
    high: [usize; 2],
    count: usize,
) -> PyResult<Bound<'py, PyArray1<u32>>> {
    let mut shown = vec![0u64; count.div_ceil(64)];
    for image in &images {
        let shape = image.shape();
        let (layers, height, width) = match *shape {
            [h, w] => (1, h, w),
            [l, h, w] => (l, h, w),
            _ => {
                return Err(SketchRodGSError::new_err(format!(
                    "index image: expected (H, W) or (L, H, W), got {shape:?}"
                )));
            }
        };
        let pixels = contiguous(image, "index image")?;
        let (x0, x1) = (low[0].min(width), high[0].min(width));
        for row in (0..layers).flat_map(|l| (low[1].min(height)..high[1].min(height)).map(move |r| l * height + r)) {
            for &id in &pixels[row * width + x0..row * width + x1.max(x0)] {
                if id < 0 {
                    continue;
                }
                let id = id as usize;
                if id >= count {
                    return Err(SketchRodGSError::new_err(format!(
                        "index image: Gaussian id {id} out of range for {count} Gaussians"
                    )));
                }
                shown[id / 64] |= 1 << (id % 64);
            }
        }
    }
    let mut ids = Vec::new();
    for (word, &bits) in shown.iter().enumerate() {
        let mut bits = bits;
        while bits != 0 {
            ids.push((word * 64 + bits.trailing_zeros() as usize) as u32);
            bits &= bits - 1; // the lowest set bit cleared
        }
    }
    Ok(ids.into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(shown_ids, m)?)?;
    m.add_function(wrap_pyfunction!(forward_along_stroke, m)?)?;
    m.add_function(wrap_pyfunction!(trace_stroke, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_radius, m)?)?;
    m.add_class::<Trace>()?;
    m.add_class::<TracePiece>()?;
    Ok(())
}
