//! Bindings for `sketchrodgs-polyline`: `_core.nearest_on_polyline(...)`, `_core.cross_section_centroids(...)`,
//! `_core.crowding(...)`,
//! `_core.segment_and_bind(...)`, `_core.rows_in_box(...)`, `_core.continuation(...)`,
//! `_core.detours(...)`, `_core.median_neighbour_distance(...)`, `_core.small_clusters(...)`, `_core.clusters_inside(...)`.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sketchrodgs_polyline::continuation as past_end;
use sketchrodgs_polyline::detours::{BumpLimits, DetourLimits};
use sketchrodgs_polyline::proximity;
use sketchrodgs_polyline::segment::{self, SegmentParams};

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
/// neighbours, within `reach` of each vertex, times its `reach_scale` (M,) float64 where given;
/// a cross-section of fewer than two points is taken again within `wide_half_width`.
/// Returns (centroids (M, 3) float64, counts (M,) uint32).
#[pyfunction]
#[pyo3(signature = (axis, tangents, points, nearest_vertex, half_width, wide_half_width, reach, reach_scale=None))]
#[allow(clippy::too_many_arguments)]
fn cross_section_centroids<'py>(
    py: Python<'py>,
    axis: &Bound<'py, PyArray2<f64>>,
    tangents: &Bound<'py, PyArray2<f64>>,
    points: &Bound<'py, PyArray2<f32>>,
    nearest_vertex: &Bound<'py, PyArray1<i32>>,
    half_width: f64,
    wide_half_width: f64,
    reach: f64,
    reach_scale: Option<&Bound<'py, PyArray1<f64>>>,
) -> PyResult<Centroids<'py>> {
    let (axis, tangents) = (axis.try_readonly()?, tangents.try_readonly()?);
    let (points, nearest) = (points.try_readonly()?, nearest_vertex.try_readonly()?);
    let m = axis.shape()[0];
    check_shape("axis", axis.shape(), &[None, Some(3)])?;
    check_shape("tangents", tangents.shape(), &[Some(m), Some(3)])?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    check_shape("nearest_vertex", nearest.shape(), &[Some(points.shape()[0])])?;
    let reach: Vec<f64> = match reach_scale {
        None => vec![reach; m],
        Some(scale) => {
            let scale = scale.try_readonly()?;
            check_shape("reach_scale", scale.shape(), &[Some(m)])?;
            let scale = contiguous(&scale, "reach_scale")?;
            if let Some(i) = scale.iter().position(|s| !(s.is_finite() && *s >= 0.0)) {
                return Err(SketchRodGSError::new_err(format!(
                    "reach_scale: entry {i} must be finite and >= 0, got {}",
                    scale[i]
                )));
            }
            scale.iter().map(|s| reach * s).collect()
        }
    };
    let axis: &[[f64; 3]] = contiguous(&axis, "axis")?.as_chunks::<3>().0;
    let tangents: &[[f64; 3]] = contiguous(&tangents, "tangents")?.as_chunks::<3>().0;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let nearest = contiguous(&nearest, "nearest_vertex")?;
    let (centroids, counts) = run_parallel(py, "cross_section_centroids", || {
        sketchrodgs_polyline::cross_section_centroids(
            axis,
            tangents,
            points,
            nearest,
            half_width,
            wide_half_width,
            &reach,
        )
    })?;
    let centroids = numpy::ndarray::Array2::from_shape_vec((m, 3), centroids.into_iter().flatten().collect())
        .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok((centroids.into_pyarray(py), counts.into_pyarray(py)))
}

/// How crowded the cross-section of each vertex of `axis` (M, 3) float64 with unit `tangents`
/// (M, 3) float64 is (`sketchrodgs_polyline::crowding`): of `points` (N, 3) float32 within
/// `half_width` of its plane, those `inner` to `outer` off the axis over those within `inner`.
/// Returns (M,) float64.
#[pyfunction]
fn crowding<'py>(
    py: Python<'py>,
    axis: &Bound<'py, PyArray2<f64>>,
    tangents: &Bound<'py, PyArray2<f64>>,
    points: &Bound<'py, PyArray2<f32>>,
    half_width: f64,
    inner: f64,
    outer: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (axis, tangents, points) = (axis.try_readonly()?, tangents.try_readonly()?, points.try_readonly()?);
    check_shape("axis", axis.shape(), &[None, Some(3)])?;
    check_shape("tangents", tangents.shape(), &[Some(axis.shape()[0]), Some(3)])?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let axis: &[[f64; 3]] = contiguous(&axis, "axis")?.as_chunks::<3>().0;
    let tangents: &[[f64; 3]] = contiguous(&tangents, "tangents")?.as_chunks::<3>().0;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let crowding = run_parallel(py, "crowding", || {
        sketchrodgs_polyline::crowding(axis, tangents, points, half_width, inner, outer)
    })?;
    Ok(crowding.into_pyarray(py))
}

/// (gaussian_ids (G,) int64, segment (G,) int32, t (G,) float32, offset (G, 3) float32,
/// distance (G,) float32, attached (G,) bool).
type BindingArrays<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i32>>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray1<bool>>,
    Option<([f32; 3], [f32; 3])>,
);

/// The Gaussians of `means` (N, 3) float32 that follow the rod on `polyline` (M, 3) float64, bound
/// (`sketchrodgs_polyline::segment`): `arc` (M,) float64 arc lengths at the vertices, `length` the
/// rod's length, `radius` R; `grow`, `link_min`, `link_max` and `end_margin` in radii;
/// `attach_size` None attaches nothing, `attach_size_fewer` (None: `attach_size`) the largest
/// attached part that holds no more centres than the part. With `colours` (N, 3) float32, a surface of another colour
/// under the part is left out of it; the last entry is then (the part's colour, the surface's),
/// else None.
#[pyfunction]
#[pyo3(signature = (polyline, arc, length, means, radius, grow, link_spacings, link_min, link_max, attach_size, end_margin, colours=None, attach_size_fewer=None))]
#[allow(clippy::too_many_arguments)]
fn segment_and_bind<'py>(
    py: Python<'py>,
    polyline: &Bound<'py, PyArray2<f64>>,
    arc: &Bound<'py, PyArray1<f64>>,
    length: f64,
    means: &Bound<'py, PyArray2<f32>>,
    radius: f64,
    grow: f64,
    link_spacings: f32,
    link_min: f64,
    link_max: f64,
    attach_size: Option<f64>,
    end_margin: f64,
    colours: Option<&Bound<'py, PyArray2<f32>>>,
    attach_size_fewer: Option<f64>,
) -> PyResult<BindingArrays<'py>> {
    let (polyline, arc, means) = (polyline.try_readonly()?, arc.try_readonly()?, means.try_readonly()?);
    check_shape("polyline", polyline.shape(), &[None, Some(3)])?;
    check_shape("arc", arc.shape(), &[Some(polyline.shape()[0])])?;
    check_shape("means", means.shape(), &[None, Some(3)])?;
    let colours = colours.map(|c| c.try_readonly()).transpose()?;
    if let Some(colours) = &colours {
        check_shape("colours", colours.shape(), &[Some(means.shape()[0]), Some(3)])?;
    }
    let polyline: &[[f64; 3]] = as_rows(contiguous(&polyline, "polyline")?);
    let arc = contiguous(&arc, "arc")?;
    let means: &[[f32; 3]] = as_rows(contiguous(&means, "means")?);
    let colours: Option<&[[f32; 3]]> = colours.as_ref().map(|c| contiguous(c, "colours")).transpose()?.map(as_rows);
    let params =
        SegmentParams { radius, grow, link_spacings, link_min, link_max, attach_size, attach_size_fewer, end_margin };
    let binding = run_parallel(py, "segment_and_bind", || {
        segment::segment_and_bind(polyline, arc, length, means, colours, &params)
    })?
    .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    let count = binding.rows.len();
    let offset = numpy::ndarray::Array2::from_shape_vec((count, 3), binding.offset.into_flattened())
        .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok((
        binding.rows.into_iter().map(i64::from).collect::<Vec<i64>>().into_pyarray(py),
        binding.segment.into_iter().map(|s| s as i32).collect::<Vec<i32>>().into_pyarray(py),
        binding.t.into_pyarray(py),
        offset.into_pyarray(py),
        binding.distance.into_pyarray(py),
        binding.attached.into_pyarray(py),
        binding.surface.map(|s| (s.part_colour, s.colour)),
    ))
}

/// The rows of `points` (N, 3) float32 that continue a part past an end
/// (`sketchrodgs_polyline::continuation`): the components of links `link` apart that hold one of
/// `seeds` (int64 rows), fit within `size` of the end `vertex` and lie mostly past it (along
/// `outward`): (K,) int64, ascending.
#[pyfunction]
fn continuation<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    seeds: &Bound<'py, PyArray1<i64>>,
    vertex: [f64; 3],
    outward: [f64; 3],
    size: f64,
    link: f32,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (points, seeds) = (points.try_readonly()?, seeds.try_readonly()?);
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let seeds: Vec<u32> = seed_rows(contiguous(&seeds, "seeds")?, points.len())?;
    check_size(size)?;
    let rows =
        run_parallel(py, "continuation", || past_end::continuation(points, &seeds, vertex, outward, size, link))?
            .map_err(|e| SketchRodGSError::new_err(e.to_string()))?;
    Ok(rows.into_iter().map(i64::from).collect::<Vec<i64>>().into_pyarray(py))
}

/// The `seeds` (int64 rows of `count` points; the continuations' and the strays'), each checked to
/// be one of them.
fn seed_rows<T: TryFrom<i64>>(seeds: &[i64], count: usize) -> PyResult<Vec<T>> {
    seeds
        .iter()
        .map(|&s| match T::try_from(s) {
            Ok(row) if usize::try_from(s).is_ok_and(|u| u < count) => Ok(row),
            _ => Err(SketchRodGSError::new_err(format!("seeds: seed {s} is not one of the {count} points"))),
        })
        .collect()
}

/// A cluster's `size` (the continuations' and the strays'): finite and >= 0.
fn check_size(size: f64) -> PyResult<()> {
    if size.is_finite() && size >= 0.0 {
        Ok(())
    } else {
        Err(SketchRodGSError::new_err(format!("size: must be finite and >= 0, got {size}")))
    }
}

/// The median over a sample of `points` (N, 3) float32 (every `N // samples`-th) of the distance
/// to each one's `k`-th nearest other point, in float64
/// (`sketchrodgs_polyline::proximity::median_neighbour_distance`); None for N <= k.
#[pyfunction]
fn median_neighbour_distance<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    k: usize,
    samples: usize,
) -> PyResult<Option<f64>> {
    let points = points.try_readonly()?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(SketchRodGSError::new_err(format!("points: row {i} is not finite")));
    }
    run_parallel(py, "median_neighbour_distance", || proximity::median_neighbour_distance(points, k, samples))
}

/// Per point of `points` (N, 3) float32, whether it lies in a cluster of points linked within
/// `link` that holds one of `seeds` (K,) int64 and spans at most `size`
/// (`sketchrodgs_polyline::proximity::small_clusters`). Returns (N,) bool.
#[pyfunction]
fn small_clusters<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    link: f32,
    seeds: &Bound<'py, PyArray1<i64>>,
    size: f64,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (points, seeds) = (points.try_readonly()?, seeds.try_readonly()?);
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let seeds: Vec<usize> = seed_rows(contiguous(&seeds, "seeds")?, points.len())?;
    check_size(size)?;
    let small = run_parallel(py, "small_clusters", || proximity::small_clusters(points, link, &seeds, size))?
        .map_err(|err| SketchRodGSError::new_err(format!("small_clusters: {err}")))?;
    Ok(small.into_pyarray(py))
}

/// Per point of `points` (N, 3) float32, the number of the cluster of points linked within `link`
/// that holds one of `seeds` (K,) int64 and lies wholly `inside` (N,) bool, or -1
/// (`sketchrodgs_polyline::proximity::clusters_inside`). Returns (N,) int64.
#[pyfunction]
fn clusters_inside<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f32>>,
    link: f32,
    seeds: &Bound<'py, PyArray1<i64>>,
    inside: &Bound<'py, PyArray1<bool>>,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (points, seeds, inside) = (points.try_readonly()?, seeds.try_readonly()?, inside.try_readonly()?);
    check_shape("points", points.shape(), &[None, Some(3)])?;
    check_shape("inside", inside.shape(), &[Some(points.shape()[0])])?;
    let points: &[[f32; 3]] = as_rows(contiguous(&points, "points")?);
    let seeds: Vec<usize> = seed_rows(contiguous(&seeds, "seeds")?, points.len())?;
    let inside = contiguous(&inside, "inside")?;
    let cluster = run_parallel(py, "clusters_inside", || proximity::clusters_inside(points, link, &seeds, inside))?
        .map_err(|err| SketchRodGSError::new_err(format!("clusters_inside: {err}")))?;
    Ok(cluster.into_iter().map(|c| c.map_or(-1, i64::from)).collect::<Vec<i64>>().into_pyarray(py))
}

/// The detours of the axis `points` (M, 3) float64 seen at `uv` (M, 2) float64 with `radius_px`
/// (M,) float64 (`sketchrodgs_polyline::detours::detours`; the limits in radii, `back_ratio` a
/// ratio): (K, 2) int64, each row the first and last point of a stretch to put onto its chord.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn detours<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f64>>,
    uv: &Bound<'py, PyArray2<f64>>,
    radius_px: &Bound<'py, PyArray1<f64>>,
    radius: f64,
    span: f64,
    depth: f64,
    screen: f64,
    back_ratio: f64,
    back: f64,
    end: f64,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let (points, uv, radius_px) = (points.try_readonly()?, uv.try_readonly()?, radius_px.try_readonly()?);
    let m = points.shape()[0];
    check_shape("points", points.shape(), &[None, Some(3)])?;
    check_shape("uv", uv.shape(), &[Some(m), Some(2)])?;
    check_shape("radius_px", radius_px.shape(), &[Some(m)])?;
    let limits = [
        ("radius", radius),
        ("span", span),
        ("depth", depth),
        ("screen", screen),
        ("back_ratio", back_ratio),
        ("back", back),
        ("end", end),
    ];
    check_limits(&limits)?;
    let points: &[[f64; 3]] = contiguous(&points, "points")?.as_chunks::<3>().0;
    let uv: &[[f64; 2]] = contiguous(&uv, "uv")?.as_chunks::<2>().0;
    let radius_px = contiguous(&radius_px, "radius_px")?;
    let limits = DetourLimits { span, depth, screen, back_ratio, back, end };
    let found = py.detach(|| sketchrodgs_polyline::detours::detours(points, uv, radius_px, radius, limits));
    stretches_array(py, &found)
}

/// The bumps of the axis `points` (M, 3) float64, about R apart (`sketchrodgs_polyline::detours::bumps`;
/// the limits in radii, the angle in degrees): (K, 2) int64, each row the first and last point of
/// a stretch to put onto its chord.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn bumps<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f64>>,
    radius: f64,
    span: f64,
    off: f64,
    angle_deg: f64,
    lead: f64,
    end: f64,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let points = points.try_readonly()?;
    check_shape("points", points.shape(), &[None, Some(3)])?;
    let limits =
        [("radius", radius), ("span", span), ("off", off), ("angle_deg", angle_deg), ("lead", lead), ("end", end)];
    check_limits(&limits)?;
    let points: &[[f64; 3]] = contiguous(&points, "points")?.as_chunks::<3>().0;
    if let Some(k) = points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(SketchRodGSError::new_err(format!("points: row {k} is not finite")));
    }
    let limits = BumpLimits { span, off, angle_deg, lead, end };
    let found = py.detach(|| sketchrodgs_polyline::detours::bumps(points, radius, limits));
    stretches_array(py, &found)
}

/// Each named limit must be finite and positive.
fn check_limits(limits: &[(&str, f64)]) -> PyResult<()> {
    match limits.iter().find(|(_, value)| !(value.is_finite() && *value > 0.0)) {
        Some((name, value)) => Err(SketchRodGSError::new_err(format!("{name}: must be finite and > 0, got {value}"))),
        None => Ok(()),
    }
}

/// Stretches `(i, j)` as a (K, 2) int64 array.
fn stretches_array<'py>(py: Python<'py>, found: &[(usize, usize)]) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let flat: Vec<i64> = found.iter().flat_map(|&(i, j)| [i as i64, j as i64]).collect();
    Ok(numpy::ndarray::Array2::from_shape_vec((found.len(), 2), flat)
        .map_err(|e| SketchRodGSError::new_err(e.to_string()))?
        .into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(nearest_on_polyline, m)?)?;
    m.add_function(wrap_pyfunction!(cross_section_centroids, m)?)?;
    m.add_function(wrap_pyfunction!(crowding, m)?)?;
    m.add_function(wrap_pyfunction!(segment_and_bind, m)?)?;
    m.add_function(wrap_pyfunction!(rows_in_box, m)?)?;
    m.add_function(wrap_pyfunction!(continuation, m)?)?;
    m.add_function(wrap_pyfunction!(detours, m)?)?;
    m.add_function(wrap_pyfunction!(bumps, m)?)?;
    m.add_function(wrap_pyfunction!(median_neighbour_distance, m)?)?;
    m.add_function(wrap_pyfunction!(small_clusters, m)?)?;
    m.add_function(wrap_pyfunction!(clusters_inside, m)?)?;
    Ok(())
}
