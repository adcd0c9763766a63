//! Bindings for `sketchrodgs-raster`: `_core.rasterize(...)`.

use numpy::ndarray::{Array, Dimension, ShapeBuilder};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use sketchrodgs_raster::{Camera, RasterError, RenderMode, RenderOptions, RenderOutput, Retained, Splats, TileMask};

use crate::arrays::{check_shape, contiguous};
use crate::errors::SketchRodGSError;
use crate::pool::run_parallel;

fn raster_err(err: RasterError) -> PyErr {
    SketchRodGSError::new_err(err.to_string())
}

/// Renders a Gaussian scene for a pinhole camera (see `sketchrodgs.render` for the public API).
///
/// Arrays are float32 and C-contiguous: means (N, 3), scales (N, 3), quats (N, 4) wxyz,
/// opacities (N,), sh (N, K, 3); world_to_camera is (4, 4) float64. Returns a `Rendered`: rgb
/// (H, W, 3), alpha, depth, index (int32) and index_depth, each (H, W), the stage timings in
/// seconds and the visible and pair counts. `mode` is "all"; "index" (rgb and depth None);
/// "solid" (as "index", with alpha exact only below 0.5: `RenderMode::IndexSolid`); or "color"
/// (rgb and alpha only, the rest None: `RenderMode::Color`).
/// `tiles` (ceil(H / 16), ceil(W / 16)) bool renders only those tiles (the rest is background).
/// `sh_rows` (N,) uint32: the row of `sh` (then (M, K, 3)) each Gaussian takes its SH from.
/// `sort_offsets` (N, 3) float32: where each Gaussian sorts, from its mean in its own axes.
/// `near_plane`: Gaussians at camera z at or below it are culled (the reference's 0.2).
#[pyfunction]
#[pyo3(signature = (means, scales, quats, opacities, sh, world_to_camera, width, height, fx, fy, cx, cy, background = (0.0, 0.0, 0.0), mode = "all", tiles = None, sh_rows = None, sort_offsets = None, near_plane = sketchrodgs_raster::NEAR_PLANE))]
#[allow(clippy::too_many_arguments)]
fn rasterize<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyArray2<f32>>,
    scales: &Bound<'py, PyArray2<f32>>,
    quats: &Bound<'py, PyArray2<f32>>,
    opacities: &Bound<'py, PyArray1<f32>>,
    sh: &Bound<'py, PyArray3<f32>>,
    world_to_camera: &Bound<'py, PyArray2<f64>>,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    background: (f32, f32, f32),
    mode: &str,
    tiles: Option<&Bound<'py, PyArray2<bool>>>,
    sh_rows: Option<&Bound<'py, PyArray1<u32>>>,
    sort_offsets: Option<&Bound<'py, PyArray2<f32>>>,
    near_plane: f64,
) -> PyResult<Rendered> {
    let scene = SceneInput::new(means, scales, quats, opacities, sh, sh_rows, sort_offsets)?;
    let splats = scene.splats()?;
    let camera = camera_from(world_to_camera, width, height, fx, fy, cx, cy, near_plane)?;
    let options = options_of(background, mode)?;

    let mask = tile_mask(&camera, tiles)?;
    let out = run_parallel(py, "rasterize", || match &mask {
        None => sketchrodgs_raster::rasterize(&splats, &camera, &options),
        Some(mask) => sketchrodgs_raster::rasterize_tiles(&splats, &camera, &options, mask),
    })?;
    let out = out.map_err(raster_err)?;
    into_rendered(py, out)
}

/// Depth layers behind `near` ((H, W) float32 camera z) in "solid" mode
/// (`sketchrodgs_raster::rasterize_behind`): `count` `Rendered`, each layer behind the last by
/// `gap_px` pixels' world size. Scene, camera and `tiles` as for `rasterize`.
#[pyfunction]
#[pyo3(signature = (means, scales, quats, opacities, sh, world_to_camera, width, height, fx, fy, cx, cy, near, count, gap_px, tiles = None, sh_rows = None, sort_offsets = None, near_plane = sketchrodgs_raster::NEAR_PLANE))]
#[allow(clippy::too_many_arguments)]
fn rasterize_behind<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyArray2<f32>>,
    scales: &Bound<'py, PyArray2<f32>>,
    quats: &Bound<'py, PyArray2<f32>>,
    opacities: &Bound<'py, PyArray1<f32>>,
    sh: &Bound<'py, PyArray3<f32>>,
    world_to_camera: &Bound<'py, PyArray2<f64>>,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    near: &Bound<'py, PyArray2<f32>>,
    count: usize,
    gap_px: f32,
    tiles: Option<&Bound<'py, PyArray2<bool>>>,
    sh_rows: Option<&Bound<'py, PyArray1<u32>>>,
    sort_offsets: Option<&Bound<'py, PyArray2<f32>>>,
    near_plane: f64,
) -> PyResult<Vec<Rendered>> {
    let scene = SceneInput::new(means, scales, quats, opacities, sh, sh_rows, sort_offsets)?;
    let splats = scene.splats()?;
    let camera = camera_from(world_to_camera, width, height, fx, fy, cx, cy, near_plane)?;
    let mask = tile_mask(&camera, tiles)?;
    let near = near.try_readonly()?;
    check_shape("near", near.shape(), &[Some(height as usize), Some(width as usize)])?;
    let near = contiguous(&near, "near")?;
    if !(gap_px.is_finite() && gap_px >= 0.0) {
        return Err(SketchRodGSError::new_err(format!("gap_px: must be finite and >= 0, got {gap_px}")));
    }
    let layers = run_parallel(py, "rasterize_behind", || {
        sketchrodgs_raster::rasterize_behind(&splats, &camera, mask.as_ref(), near, count, gap_px)
    })?;
    layers.map_err(raster_err)?.into_iter().map(|out| into_rendered(py, out)).collect()
}

/// The `tiles` argument as a mask (None: the whole image).
fn tile_mask(camera: &Camera, tiles: Option<&Bound<'_, PyArray2<bool>>>) -> PyResult<Option<TileMask>> {
    let Some(tiles) = tiles else { return Ok(None) };
    let tiles = tiles.try_readonly()?;
    let (grid_x, grid_y) = camera.tile_grid();
    check_shape("tiles", tiles.shape(), &[Some(grid_y as usize), Some(grid_x as usize)])?;
    Ok(Some(TileMask::new(camera, contiguous(&tiles, "tiles")?.to_vec()).map_err(raster_err)?))
}

/// The scene arrays as Python passes them (see `rasterize`), borrowed read-only, shapes checked.
struct SceneInput<'py> {
    means: PyReadonlyArray2<'py, f32>,
    scales: PyReadonlyArray2<'py, f32>,
    quats: PyReadonlyArray2<'py, f32>,
    opacities: PyReadonlyArray1<'py, f32>,
    sh: PyReadonlyArray3<'py, f32>,
    sh_rows: Option<PyReadonlyArray1<'py, u32>>,
    sort_offsets: Option<PyReadonlyArray2<'py, f32>>,
}

impl<'py> SceneInput<'py> {
    fn new(
        means: &Bound<'py, PyArray2<f32>>,
        scales: &Bound<'py, PyArray2<f32>>,
        quats: &Bound<'py, PyArray2<f32>>,
        opacities: &Bound<'py, PyArray1<f32>>,
        sh: &Bound<'py, PyArray3<f32>>,
        sh_rows: Option<&Bound<'py, PyArray1<u32>>>,
        sort_offsets: Option<&Bound<'py, PyArray2<f32>>>,
    ) -> PyResult<Self> {
        let (means, scales, quats) = (means.try_readonly()?, scales.try_readonly()?, quats.try_readonly()?);
        let (opacities, sh) = (opacities.try_readonly()?, sh.try_readonly()?);
        let n = means.shape()[0];
        check_shape("means", means.shape(), &[None, Some(3)])?;
        check_shape("scales", scales.shape(), &[Some(n), Some(3)])?;
        check_shape("quats", quats.shape(), &[Some(n), Some(4)])?;
        check_shape("opacities", opacities.shape(), &[Some(n)])?;
        let sh_rows = sh_rows.map(|r| r.try_readonly()).transpose()?;
        if let Some(rows) = &sh_rows {
            check_shape("sh_rows", rows.shape(), &[Some(n)])?;
        }
        check_shape("sh", sh.shape(), &[if sh_rows.is_some() { None } else { Some(n) }, None, Some(3)])?;
        let sort_offsets = sort_offsets.map(|o| o.try_readonly()).transpose()?;
        if let Some(offsets) = &sort_offsets {
            check_shape("sort_offsets", offsets.shape(), &[Some(n), Some(3)])?;
        }
        Ok(Self { means, scales, quats, opacities, sh, sh_rows, sort_offsets })
    }

    fn splats(&self) -> PyResult<Splats<'_>> {
        let splats = Splats::from_flat(
            contiguous(&self.means, "means")?,
            contiguous(&self.scales, "scales")?,
            contiguous(&self.quats, "quats")?,
            contiguous(&self.opacities, "opacities")?,
            contiguous(&self.sh, "sh")?,
            self.sh.shape()[1],
            self.sh_rows.as_ref().map(|rows| contiguous(rows, "sh_rows")).transpose()?,
        )
        .map_err(raster_err)?;
        match &self.sort_offsets {
            None => Ok(splats),
            Some(offsets) => splats.with_sort_offsets(contiguous(offsets, "sort_offsets")?).map_err(raster_err),
        }
    }
}

/// The camera from a (4, 4) float64 world-to-camera matrix, the intrinsics and the near plane.
#[allow(clippy::too_many_arguments)]
fn camera_from(
    world_to_camera: &Bound<'_, PyArray2<f64>>,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    near: f64,
) -> PyResult<Camera> {
    let w2c = world_to_camera.try_readonly()?;
    check_shape("world_to_camera", w2c.shape(), &[Some(4), Some(4)])?;
    let mut matrix = [[0.0f64; 4]; 4];
    for (row, values) in matrix.iter_mut().zip(contiguous(&w2c, "world_to_camera")?.chunks_exact(4)) {
        row.copy_from_slice(values);
    }
    Ok(Camera { width, height, fx, fy, cx, cy, world_to_camera: matrix, near })
}

fn options_of(background: (f32, f32, f32), mode: &str) -> PyResult<RenderOptions> {
    let mode = match mode {
        "all" => RenderMode::Full,
        "index" => RenderMode::IndexOnly,
        "solid" => RenderMode::IndexSolid,
        "color" => RenderMode::Color,
        other => {
            return Err(SketchRodGSError::new_err(format!(
                "mode: expected 'all', 'index', 'solid' or 'color', got {other:?}"
            )));
        }
    };
    Ok(RenderOptions { background: [background.0, background.1, background.2], mode })
}

/// A render kept between the frames of an animation (see `sketchrodgs.frames`): built from the
/// scene at rest and the rows that may move (int64); `frame(means, scales, quats)` renders the
/// scene with those rows moved, re-blending only the tiles they touch, and returns a `Rendered`
/// as `rasterize` does.
#[pyclass(module = "sketchrodgs._core", name = "RetainedRender")]
pub struct RetainedRender {
    retained: Retained,
}

#[pymethods]
impl RetainedRender {
    #[new]
    #[pyo3(signature = (means, scales, quats, opacities, sh, world_to_camera, width, height, fx, fy, cx, cy, moving, background = (0.0, 0.0, 0.0), mode = "all", sh_rows = None, sort_offsets = None, near_plane = sketchrodgs_raster::NEAR_PLANE))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        means: &Bound<'_, PyArray2<f32>>,
        scales: &Bound<'_, PyArray2<f32>>,
        quats: &Bound<'_, PyArray2<f32>>,
        opacities: &Bound<'_, PyArray1<f32>>,
        sh: &Bound<'_, PyArray3<f32>>,
        world_to_camera: &Bound<'_, PyArray2<f64>>,
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        moving: &Bound<'_, PyArray1<i64>>,
        background: (f32, f32, f32),
        mode: &str,
        sh_rows: Option<&Bound<'_, PyArray1<u32>>>,
        sort_offsets: Option<&Bound<'_, PyArray2<f32>>>,
        near_plane: f64,
    ) -> PyResult<Self> {
        let scene = SceneInput::new(means, scales, quats, opacities, sh, sh_rows, sort_offsets)?;
        let splats = scene.splats()?;
        let n = splats.len();
        let moving = moving.try_readonly()?;
        let rows = contiguous(&moving, "moving")?
            .iter()
            .map(|&r| u32::try_from(r).ok().filter(|&r| (r as usize) < n))
            .collect::<Option<Vec<u32>>>()
            .ok_or_else(|| SketchRodGSError::new_err(format!("moving: rows must be in 0..{n}")))?;
        let camera = camera_from(world_to_camera, width, height, fx, fy, cx, cy, near_plane)?;
        let options = options_of(background, mode)?;
        let retained = run_parallel(py, "RetainedRender", || Retained::new(&splats, &camera, &options, &rows))?
            .map_err(raster_err)?;
        Ok(Self { retained })
    }

    /// The frame with the moving rows of `means` (N, 3), `scales` (N, 3), `quats` (N, 4) float32.
    fn frame<'py>(
        &mut self,
        py: Python<'py>,
        means: &Bound<'py, PyArray2<f32>>,
        scales: &Bound<'py, PyArray2<f32>>,
        quats: &Bound<'py, PyArray2<f32>>,
    ) -> PyResult<Rendered> {
        let (means, scales, quats) = (means.try_readonly()?, scales.try_readonly()?, quats.try_readonly()?);
        check_shape("means", means.shape(), &[None, Some(3)])?;
        check_shape("scales", scales.shape(), &[None, Some(3)])?;
        check_shape("quats", quats.shape(), &[None, Some(4)])?;
        let (means, scales, quats) =
            (contiguous(&means, "means")?, contiguous(&scales, "scales")?, contiguous(&quats, "quats")?);
        let retained = &mut self.retained;
        let out = run_parallel(py, "RetainedRender.frame", || retained.frame_flat(means, scales, quats).cloned())?
            .map_err(raster_err)?;
        into_rendered(py, out)
    }
}

/// The images and figures of one render (`sketchrodgs.render` wraps them in `RenderResult`). The
/// arrays are the Rust buffers, moved into numpy without a copy.
#[pyclass(module = "sketchrodgs._core", name = "Rendered", frozen, get_all)]
pub struct Rendered {
    /// (H, W, 3) colour, None in the index modes.
    rgb: Option<Py<PyArray3<f32>>>,
    /// (H, W) accumulated opacity.
    alpha: Py<PyArray2<f32>>,
    /// (H, W) expected depth, None in the index modes and in "color".
    depth: Option<Py<PyArray2<f32>>>,
    /// (H, W) the index image K, None in "color".
    index: Option<Py<PyArray2<i32>>>,
    /// (H, W) its depth Z, None in "color".
    index_depth: Option<Py<PyArray2<f32>>>,
    /// Seconds of the stages (project, sort and bin, composite).
    project_s: f64,
    sort_s: f64,
    composite_s: f64,
    n_visible: usize,
    n_tile_pairs: usize,
}

fn into_rendered(py: Python<'_>, out: RenderOutput) -> PyResult<Rendered> {
    let (h, w) = (out.height, out.width);
    let alpha = image(py, (h, w), out.alpha)?.ok_or_else(|| SketchRodGSError::new_err("internal: no alpha"))?;
    Ok(Rendered {
        rgb: image(py, (h, w, 3), out.rgb)?,
        alpha,
        depth: image(py, (h, w), out.depth)?,
        index: image(py, (h, w), out.index)?,
        index_depth: image(py, (h, w), out.index_depth)?,
        project_s: out.timings.project_s,
        sort_s: out.timings.sort_s,
        composite_s: out.timings.composite_s,
        n_visible: out.n_visible,
        n_tile_pairs: out.n_tile_pairs,
    })
}

/// `values` as a numpy array of `shape` (moved, not copied), or None where the render did not make
/// that output (an empty buffer).
fn image<T: numpy::Element, D: Dimension>(
    py: Python<'_>,
    shape: impl ShapeBuilder<Dim = D>,
    values: Vec<T>,
) -> PyResult<Option<Py<numpy::PyArray<T, D>>>> {
    if values.is_empty() {
        return Ok(None);
    }
    let array = Array::from_shape_vec(shape, values)
        .map_err(|e| SketchRodGSError::new_err(format!("internal shape error: {e}")))?;
    Ok(Some(array.into_pyarray(py).unbind()))
}

/// Frees the buffers renders keep for the next one (see `sketchrodgs.render.release_buffers`).
#[pyfunction]
fn release_render_buffers() {
    sketchrodgs_raster::release_kept_buffers();
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(rasterize_behind, m)?)?;
    m.add_function(wrap_pyfunction!(release_render_buffers, m)?)?;
    m.add_class::<RetainedRender>()?;
    m.add_class::<Rendered>()?;
    Ok(())
}
