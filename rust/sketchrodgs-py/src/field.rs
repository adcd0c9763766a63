//! Bindings for `sketchrodgs-field`: `_core.max_alpha(...)`.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sketchrodgs_field::Grid;

use crate::arrays::{as_rows, check_shape, contiguous};
use crate::errors::SketchRodGSError;
use crate::pool::run_parallel;

/// Per cell of the grid (`dims` (nx, ny, nz) cells with centres at `origin + spacing * (i, j, k)`),
/// the largest opacity the Gaussians `rows` (int64) of a scene (means, scales (N, 3), quats (N, 4)
/// wxyz, opacities (N,), float32) reach at its centre: (nx * ny * nz,) float32, x fastest.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn max_alpha<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyArray2<f32>>,
    scales: &Bound<'py, PyArray2<f32>>,
    quats: &Bound<'py, PyArray2<f32>>,
    opacities: &Bound<'py, PyArray1<f32>>,
    rows: &Bound<'py, PyArray1<i64>>,
    origin: [f64; 3],
    spacing: f64,
    dims: [usize; 3],
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let (means, scales, quats, opacities) =
        (means.try_readonly()?, scales.try_readonly()?, quats.try_readonly()?, opacities.try_readonly()?);
    check_shape("means", means.shape(), &[None, Some(3)])?;
    check_shape("scales", scales.shape(), &[None, Some(3)])?;
    check_shape("quats", quats.shape(), &[None, Some(4)])?;
    let means: &[[f32; 3]] = as_rows(contiguous(&means, "means")?);
    let scales: &[[f32; 3]] = as_rows(contiguous(&scales, "scales")?);
    let quats: &[[f32; 4]] = as_rows(contiguous(&quats, "quats")?);
    let opacities = contiguous(&opacities, "opacities")?;
    let rows = rows.try_readonly()?;
    let rows: Vec<usize> = contiguous(&rows, "rows")?
        .iter()
        .map(|&r| usize::try_from(r).map_err(|_| SketchRodGSError::new_err(format!("rows: {r} is negative"))))
        .collect::<PyResult<_>>()?;
    let grid = Grid { origin, spacing, dims };
    let alpha = run_parallel(py, "max_alpha", || {
        sketchrodgs_field::max_alpha_of_rows(&grid, means, scales, quats, opacities, &rows)
    })?
    .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok(alpha.into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(max_alpha, m)?)?;
    Ok(())
}
