//! Bindings for `sketchrodgs-skin`: `_core.skin_scatter(...)`.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sketchrodgs_skin::{Binding, skin_in_place};

use crate::arrays::{as_rows, check_shape, contiguous, contiguous_mut};
use crate::errors::SketchRodGSError;
use crate::pool::run_parallel;

/// Skin one rod's bound Gaussians and write them into the scene arrays, in place.
///
/// deformed (M, 3) and vertex_rotation (M, 4) wxyz describe the rod now (rotations from the rest
/// vertex frames); segment (G,) int32, t (G,), offset (G, 3) and rest_quats (G, 4) the binding;
/// ids (G,) int64 the rows of `means` (N, 3) and `quats` (N, 4) to overwrite. All float32.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn skin_scatter<'py>(
    py: Python<'py>,
    deformed: &Bound<'py, PyArray2<f32>>,
    vertex_rotation: &Bound<'py, PyArray2<f32>>,
    segment: &Bound<'py, PyArray1<i32>>,
    t: &Bound<'py, PyArray1<f32>>,
    offset: &Bound<'py, PyArray2<f32>>,
    rest_quats: &Bound<'py, PyArray2<f32>>,
    ids: &Bound<'py, PyArray1<i64>>,
    means: &Bound<'py, PyArray2<f32>>,
    quats: &Bound<'py, PyArray2<f32>>,
) -> PyResult<()> {
    let (deformed, vertex_rotation) = (deformed.try_readonly()?, vertex_rotation.try_readonly()?);
    let (segment, t, offset, rest_quats, ids) =
        (segment.try_readonly()?, t.try_readonly()?, offset.try_readonly()?, rest_quats.try_readonly()?, ids.try_readonly()?);
    let m = deformed.shape()[0];
    let g = segment.shape()[0];
    check_shape("deformed", deformed.shape(), &[None, Some(3)])?;
    check_shape("vertex_rotation", vertex_rotation.shape(), &[Some(m), Some(4)])?;
    check_shape("t", t.shape(), &[Some(g)])?;
    check_shape("offset", offset.shape(), &[Some(g), Some(3)])?;
    check_shape("rest_quats", rest_quats.shape(), &[Some(g), Some(4)])?;
    check_shape("ids", ids.shape(), &[Some(g)])?;
    let mut means = means.try_readwrite()?;
    let mut quats = quats.try_readwrite()?;
    let n = means.shape()[0];
    check_shape("means", means.shape(), &[None, Some(3)])?;
    check_shape("quats", quats.shape(), &[Some(n), Some(4)])?;
    let ids = contiguous(&ids, "ids")?;
    if let Some(bad) = ids.iter().find(|&&i| i < 0 || i as usize >= n) {
        return Err(SketchRodGSError::new_err(format!("ids: row {bad} is outside the scene's {n} Gaussians")));
    }
    let segment: Vec<u32> = contiguous(&segment, "segment")?
        .iter()
        .map(|&s| u32::try_from(s).map_err(|_| SketchRodGSError::new_err(format!("segment: negative value {s}"))))
        .collect::<PyResult<_>>()?;
    let binding = Binding {
        segment: &segment,
        t: contiguous(&t, "t")?,
        offset: as_rows(contiguous(&offset, "offset")?),
        rotation: as_rows(contiguous(&rest_quats, "rest_quats")?),
    };
    let deformed: &[[f32; 3]] = as_rows(contiguous(&deformed, "deformed")?);
    let vertex_rotation: &[[f32; 4]] = as_rows(contiguous(&vertex_rotation, "vertex_rotation")?);
    let means_out = contiguous_mut(&mut means, "means")?;
    let quats_out = contiguous_mut(&mut quats, "quats")?;
    run_parallel(py, "skin", || -> Result<(), sketchrodgs_skin::SkinError> {
        let mut new_means = vec![[0.0_f32; 3]; g];
        let mut new_quats = vec![[0.0_f32; 4]; g];
        skin_in_place(deformed, vertex_rotation, &binding, &mut new_means, &mut new_quats)?;
        let (means_out, quats_out) = (means_out.as_chunks_mut::<3>().0, quats_out.as_chunks_mut::<4>().0);
        for ((&row, mean), quat) in ids.iter().zip(new_means).zip(new_quats) {
            means_out[row as usize] = mean;
            quats_out[row as usize] = quat;
        }
        Ok(())
    })?
    .map_err(|e| SketchRodGSError::new_err(e.to_string()))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(skin_scatter, m)?)?;
    Ok(())
}
