//! Bindings for `sketchrodgs-polyline`: `_core.nearest_on_polyline(...)`, `_core.cross_section_centroids(...)`,
//! `_core.linked_components(...)`, `_core.linked_to(...)`, `_core.grow_part(...)`, `_core.rows_in_box(...)`.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sketchrodgs_polyline::proximity::{self, ProximityError};

use crate::arrays::{as_rows, check_shape, contiguous};
use crate::errors::SketchRodGSError;
use crate::pool::run_parallel;

type NearestArrays<'py> = (Bound<'py, PyArray1<i32>>, Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>);

/// Nearest point on `polyline` (M, 3) float32 for each of `points` (N, 3) float32 within `reach`.
///
/// Returns (segment (N,) int32, -1 where nothing is within reach; t (N,) float32 in [0, 1];
/// distance (N,) float32, inf where nothing is within reach).
#[pyfunction]
fn nearest_on_polyline<'py>(
    py: Python<'py>,
    polyline: &Bound<'py, PyArray2<f32>>,
    points: &Bound<'py, PyArray2<f32>>,
    reach: f64,
) -> PyResult<NearestArrays<'py>> {
    let (polyline, points) = (polyline.try_readonly()?, points.try_readonly()?);
    check_shape("polyline", polyline.shape(), &[None, Some(3)])?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let polyline: &[[f32; 3]] = as_rows(contiguous(&polyline, "polyline")?);
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let found =
        run_parallel(py, "nearest_on_polyline", || sketchrodgs_polyline::nearest_on_polyline(polyline, points, reach))?
            .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    let segment: Vec<i32> = found.iter().map(|n| n.map_or(-1, |n| n.segment as i32)).collect();
    let t: Vec<f32> = found.iter().map(|n| n.map_or(0.0, |n| n.t)).collect();
    let distance: Vec<f32> = found.iter().map(|n| n.map_or(f32::INFINITY, |n| n.distance)).collect();
    Ok((segment.into_pyarray(py), t.into_pyarray(py), distance.into_pyarray(py)))
}

/// Rows of `points` (N, 3) float32 inside the box [low, high] (bounds included), ascending int64.
#[pyfunction]
fn rows_in_box<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    low: [f32; 3],
    high: [f32; 3],
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let points = points.try_readonly()?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let rows = run_parallel(py, "rows_in_box", || sketchrodgs_polyline::rows_in_box(points, low, high))?;
    Ok(rows.into_iter().map(i64::from).collect::<Vec<i64>>().into_pyarray(py))
}

/// (centroids (M, 3), counts (M,)).
type Centroids<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u32>>);

/// Centroids of the cross-sections of `axis` (M, 3) float64 with unit `tangents` (M, 3) float64,
/// from `points` (N, 3) float32 tried against their `nearest_vertex` (N,) int32 (-1: none) and its
/// neighbours. Returns (centroids (M, 3) float64, counts (M,) uint32).
#[pyfunction]
fn cross_section_centroids<'py>(
    py: Python<'py>,
    axis: &Bound<'py, PyArray2<f64>>,
    tangents: &Bound<'py, PyArray2<f64>>,
    points: &Bound<'py, PyArray2<f32>>,
    nearest_vertex: &Bound<'py, PyArray1<i32>>,
    half_width: f64,
    reach: f64,
) -> PyResult<Centroids<'py>> {
    let (axis, tangents) = (axis.try_readonly()?, tangents.try_readonly()?);
    let (points, nearest) = (points.try_readonly()?, nearest_vertex.try_readonly()?);
    let m = axis.shape()[0];
    check_shape("axis", axis.shape(), &[None, Some(3)])?;
    check_shape("tangents", tangents.shape(), &[Some(m), Some(3)])?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    check_shape("nearest_vertex", nearest.shape(), &[Some(points.shape()[0])])?;
    let axis: &[[f64; 3]] = contiguous(&axis, "axis")?.as_chunks::<3>().0;
    let tangents: &[[f64; 3]] = contiguous(&tangents, "tangents")?.as_chunks::<3>().0;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let nearest = contiguous(&nearest, "nearest_vertex")?;
    let (centroids, counts) = run_parallel(py, "cross_section_centroids", || {
        sketchrodgs_polyline::cross_section_centroids(axis, tangents, points, nearest, half_width, reach)
    })?;
    let centroids = numpy::ndarray::Array2::from_shape_vec((m, 3), centroids.into_iter().flatten().collect())
        .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok((centroids.into_pyarray(py), counts.into_pyarray(py)))
}

/// Run a proximity query on `points` (N, 3) float32 and a per-point uint8 array (`name`).
fn on_points<'py, T: Send>(
    py: Python<'py>,
    what: &str,
    points: &Bound<'py, PyArray2<f32>>,
    per_point: &Bound<'py, PyArray1<u8>>,
    name: &str,
    query: impl FnOnce(&[[f32; 3]], &[u8]) -> Result<T, ProximityError> + Send,
) -> PyResult<T> {
    let (points, per_point) = (points.try_readonly()?, per_point.try_readonly()?);
    check_shape("points", points.shape(), &[None, Some(3)])?;
    check_shape(name, per_point.shape(), &[Some(points.shape()[0])])?;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let per_point = contiguous(&per_point, name)?;
    run_parallel(py, what, || query(points, per_point))?.map_err(|e| SketchRodGSError::new_err(e.to_string()))
}

/// Components of the links between `points` (N, 3) float32 at most `link` apart within the same
/// `group` (N,) uint8 (255: no links). Returns (N,) int64 labels 0, 1, ... (-1 for group 255).
#[pyfunction]
fn linked_components<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    group: &Bound<'py, PyArray1<u8>>,
    link: f32,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let labels =
        on_points(py, "linked_components", points, group, "group", |p, g| proximity::linked_components(p, g, link))?;
    Ok(labels.iter().map(|&l| if l == u32::MAX { -1 } else { i64::from(l) }).collect::<Vec<i64>>().into_pyarray(py))
}

/// For each of `points` in group `source`, the lowest-numbered point of group `target` within
/// `link` (see `linked_components`). Returns (N,) int64, -1 where there is none.
#[pyfunction]
fn linked_to<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    group: &Bound<'py, PyArray1<u8>>,
    source: u8,
    target: u8,
    link: f32,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let found =
        on_points(py, "linked_to", points, group, "group", |p, g| proximity::linked_to(p, g, source, target, link))?;
    Ok(found.iter().map(|n| n.map_or(-1, i64::from)).collect::<Vec<i64>>().into_pyarray(py))
}

/// Grow a part from its seeds: `points` (N, 3) float32, `kind` (N,) uint8 (0 seed, 1 eligible,
/// 2 other). Returns (link, part (N,) bool, touched) (see `sketchrodgs_polyline::proximity::grow`).
#[pyfunction]
fn grow_part<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    kind: &Bound<'py, PyArray1<u8>>,
    spacings: f32,
    link_min: f32,
    link_max: f32,
) -> PyResult<(f32, Bound<'py, PyArray1<bool>>, bool)> {
    let grown =
        on_points(py, "grow_part", points, kind, "kind", |p, k| proximity::grow(p, k, spacings, link_min, link_max))?;
    Ok((grown.link, grown.part.into_pyarray(py), grown.touched))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(nearest_on_polyline, m)?)?;
    m.add_function(wrap_pyfunction!(cross_section_centroids, m)?)?;
    m.add_function(wrap_pyfunction!(linked_components, m)?)?;
    m.add_function(wrap_pyfunction!(linked_to, m)?)?;
    m.add_function(wrap_pyfunction!(grow_part, m)?)?;
    m.add_function(wrap_pyfunction!(rows_in_box, m)?)?;
    Ok(())
}
