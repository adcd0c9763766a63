//! Bindings for `sketchrodgs-field`: `_core.max_alpha(...)`, `_core.max_alpha_along_edges(...)`.

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use sketchrodgs_field::{Edge, Grid};

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
    let scene = SceneArrays::read(&means, &scales, &quats, &opacities)?;
    let rows = read_rows(rows)?;
    let grid = Grid { origin, spacing, dims };
    let alpha = run_parallel(py, "max_alpha", || {
        sketchrodgs_field::max_alpha_of_rows(&grid, scene.means, scene.scales, scene.quats, scene.opacities, &rows)
    })?
    .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok(alpha.into_pyarray(py))
}

/// Per grid line of `edges` ((E, 4) int64: the node's i, j, k and the axis, 0 = x, along which
/// the line runs to the next node), the largest opacity the Gaussians `rows` reach at
/// `samples + 1` points evenly spaced along it, both nodes included: (E, samples + 1) float32.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn max_alpha_along_edges<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyArray2<f32>>,
    scales: &Bound<'py, PyArray2<f32>>,
    quats: &Bound<'py, PyArray2<f32>>,
    opacities: &Bound<'py, PyArray1<f32>>,
    rows: &Bound<'py, PyArray1<i64>>,
    origin: [f64; 3],
    spacing: f64,
    dims: [usize; 3],
    edges: &Bound<'py, PyArray2<i64>>,
    samples: usize,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (means, scales, quats, opacities) =
        (means.try_readonly()?, scales.try_readonly()?, quats.try_readonly()?, opacities.try_readonly()?);
    let scene = SceneArrays::read(&means, &scales, &quats, &opacities)?;
    let rows = read_rows(rows)?;
    let edges = edges.try_readonly()?;
    check_shape("edges", edges.shape(), &[None, Some(4)])?;
    let edges: Vec<Edge> = as_rows::<i64, 4>(contiguous(&edges, "edges")?)
        .iter()
        .map(|e| {
            let index =
                |v: i64| usize::try_from(v).map_err(|_| SketchRodGSError::new_err(format!("edges: {v} is negative")));
            Ok(Edge { node: [index(e[0])?, index(e[1])?, index(e[2])?], axis: index(e[3])? })
        })
        .collect::<PyResult<_>>()?;
    let grid = Grid { origin, spacing, dims };
    let values = run_parallel(py, "max_alpha_along_edges", || {
        sketchrodgs_field::max_alpha_along_edges(
            &grid,
            scene.means,
            scene.scales,
            scene.quats,
            scene.opacities,
            &rows,
            &edges,
            samples,
        )
    })?
    .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    let count = edges.len();
    values.into_pyarray(py).reshape([count, samples + 1])
}

/// The scene's arrays as the field reads them, their shapes checked.
struct SceneArrays<'a> {
    means: &'a [[f32; 3]],
    scales: &'a [[f32; 3]],
    quats: &'a [[f32; 4]],
    opacities: &'a [f32],
}

impl<'a> SceneArrays<'a> {
    fn read(
        means: &'a PyReadonlyArray2<'_, f32>,
        scales: &'a PyReadonlyArray2<'_, f32>,
        quats: &'a PyReadonlyArray2<'_, f32>,
        opacities: &'a PyReadonlyArray1<'_, f32>,
    ) -> PyResult<Self> {
        check_shape("means", means.shape(), &[None, Some(3)])?;
        check_shape("scales", scales.shape(), &[None, Some(3)])?;
        check_shape("quats", quats.shape(), &[None, Some(4)])?;
        Ok(SceneArrays {
            means: as_rows(contiguous(means, "means")?),
            scales: as_rows(contiguous(scales, "scales")?),
            quats: as_rows(contiguous(quats, "quats")?),
            opacities: contiguous(opacities, "opacities")?,
        })
    }
}

fn read_rows(rows: &Bound<'_, PyArray1<i64>>) -> PyResult<Vec<usize>> {
    let rows = rows.try_readonly()?;
    contiguous(&rows, "rows")?
        .iter()
        .map(|&r| usize::try_from(r).map_err(|_| SketchRodGSError::new_err(format!("rows: {r} is negative"))))
        .collect()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(max_alpha, m)?)?;
    m.add_function(wrap_pyfunction!(max_alpha_along_edges, m)?)?;
    Ok(())
}
