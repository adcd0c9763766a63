//! Bindings for `sketchrodgs-skin`: `_core.skin_scatter(...)`.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rayon::prelude::*;
use sketchrodgs_skin::{Binding, Pose, frame_rotations, skin_in_place};

use crate::arrays::{as_rows, check_shape, contiguous, contiguous_mut};
use crate::errors::SketchRodGSError;
use crate::pool::run_parallel;

/// Skin one rod's bound Gaussians and write them into the scene arrays, in place.
///
/// rest (M, 3) and deformed (M, 3) positions, and rest_frames and frames (M, 4) float64 w, x, y, z
/// (the rod's vertex frames at rest and now, `vertex_quats`) describe the rod; segment (G,) int32,
/// t (G,), offset (G, 3), rest_quats (G, 4), rest_scales (G, 3) and weight (G,) the binding; ids
/// (G,) int64 the rows of `means` (N, 3), `quats` (N, 4) and `scales` (N, 3) to overwrite. All
/// float32 but the frames.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn skin_scatter<'py>(
    py: Python<'py>,
    rest: &Bound<'py, PyArray2<f32>>,
    deformed: &Bound<'py, PyArray2<f32>>,
    rest_frames: &Bound<'py, PyArray2<f64>>,
    frames: &Bound<'py, PyArray2<f64>>,
    segment: &Bound<'py, PyArray1<i32>>,
    t: &Bound<'py, PyArray1<f32>>,
    offset: &Bound<'py, PyArray2<f32>>,
    rest_quats: &Bound<'py, PyArray2<f32>>,
    rest_scales: &Bound<'py, PyArray2<f32>>,
    weight: &Bound<'py, PyArray1<f32>>,
    ids: &Bound<'py, PyArray1<i64>>,
    means: &Bound<'py, PyArray2<f32>>,
    quats: &Bound<'py, PyArray2<f32>>,
    scales: &Bound<'py, PyArray2<f32>>,
) -> PyResult<()> {
    let (rest, deformed) = (rest.try_readonly()?, deformed.try_readonly()?);
    let (rest_frames, frames) = (rest_frames.try_readonly()?, frames.try_readonly()?);
    let (segment, t, offset, rest_quats, rest_scales, weight, ids) = (
        segment.try_readonly()?,
        t.try_readonly()?,
        offset.try_readonly()?,
        rest_quats.try_readonly()?,
        rest_scales.try_readonly()?,
        weight.try_readonly()?,
        ids.try_readonly()?,
    );
    let m = deformed.shape()[0];
    let g = segment.shape()[0];
    check_shape("deformed", deformed.shape(), &[None, Some(3)])?;
    check_shape("rest", rest.shape(), &[Some(m), Some(3)])?;
    check_shape("rest_frames", rest_frames.shape(), &[Some(m), Some(4)])?;
    check_shape("frames", frames.shape(), &[Some(m), Some(4)])?;
    let rotation =
        frame_rotations(as_rows(contiguous(&rest_frames, "rest_frames")?), as_rows(contiguous(&frames, "frames")?));
    check_shape("t", t.shape(), &[Some(g)])?;
    check_shape("offset", offset.shape(), &[Some(g), Some(3)])?;
    check_shape("rest_quats", rest_quats.shape(), &[Some(g), Some(4)])?;
    check_shape("rest_scales", rest_scales.shape(), &[Some(g), Some(3)])?;
    check_shape("weight", weight.shape(), &[Some(g)])?;
    check_shape("ids", ids.shape(), &[Some(g)])?;
    let mut means = means.try_readwrite()?;
    let mut quats = quats.try_readwrite()?;
    let mut scales = scales.try_readwrite()?;
    let n = means.shape()[0];
    check_shape("means", means.shape(), &[None, Some(3)])?;
    check_shape("quats", quats.shape(), &[Some(n), Some(4)])?;
    check_shape("scales", scales.shape(), &[Some(n), Some(3)])?;
    let ids = contiguous(&ids, "ids")?;
    if let Some(bad) = ids.iter().find(|&&i| i < 0 || i as usize >= n) {
        return Err(SketchRodGSError::new_err(format!("ids: row {bad} is outside the scene's {n} Gaussians")));
    }
    let segment = contiguous(&segment, "segment")?;
    if let Some(bad) = segment.iter().find(|&&s| s < 0) {
        return Err(SketchRodGSError::new_err(format!("segment: negative value {bad}")));
    }
    let segment: Vec<u32> = segment.iter().map(|&s| s as u32).collect();
    let binding = Binding {
        segment: &segment,
        t: contiguous(&t, "t")?,
        offset: as_rows(contiguous(&offset, "offset")?),
        rotation: as_rows(contiguous(&rest_quats, "rest_quats")?),
        scale: as_rows(contiguous(&rest_scales, "rest_scales")?),
        weight: contiguous(&weight, "weight")?,
    };
    let pose = Pose {
        rest: as_rows(contiguous(&rest, "rest")?),
        deformed: as_rows(contiguous(&deformed, "deformed")?),
        rotation: &rotation,
    };
    let means_out = contiguous_mut(&mut means, "means")?;
    let quats_out = contiguous_mut(&mut quats, "quats")?;
    let scales_out = contiguous_mut(&mut scales, "scales")?;
    run_parallel(py, "skin", || -> Result<(), sketchrodgs_skin::SkinError> {
        let mut new_means = vec![[0.0_f32; 3]; g];
        let mut new_quats = vec![[0.0_f32; 4]; g];
        let mut new_scales = vec![[0.0_f32; 3]; g];
        skin_in_place(&pose, &binding, &mut new_means, &mut new_quats, &mut new_scales)?;
        // Scattered in parallel: each thread owns a contiguous range of the scene's rows and writes
        // the bound rows in it, in binding order (a row bound twice takes the later, as serially).
        let part = n.div_ceil(rayon::current_num_threads().max(1)).max(1);
        let means_out = means_out.as_chunks_mut::<3>().0;
        let quats_out = quats_out.as_chunks_mut::<4>().0;
        let scales_out = scales_out.as_chunks_mut::<3>().0;
        means_out
            .par_chunks_mut(part)
            .zip(quats_out.par_chunks_mut(part))
            .zip(scales_out.par_chunks_mut(part))
            .enumerate()
            .for_each(|(p, ((means, quats), scales))| {
                let rows = p * part..p * part + means.len();
                for (k, &row) in ids.iter().enumerate() {
                    let row = row as usize;
                    if rows.contains(&row) {
                        means[row - rows.start] = new_means[k];
                        quats[row - rows.start] = new_quats[k];
                        scales[row - rows.start] = new_scales[k];
                    }
                }
            });
        Ok(())
    })?
    .map_err(|e| SketchRodGSError::new_err(e.to_string()))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(skin_scatter, m)?)?;
    Ok(())
}
