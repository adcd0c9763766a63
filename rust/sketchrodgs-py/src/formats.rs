//! Bindings for `sketchrodgs-formats`: `_core.gunzip_into`, `_core.decode_spz`,
//! `_core.decode_compressed_ply`, `_core.decode_splat`, `_core.scene_summary`, `_core.gather_columns`. Decoders write into arrays the caller
//! allocated.

use numpy::{PyArray1, PyArray2, PyArray3, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sketchrodgs_formats::{SplatsMut, compressed_ply, gzip, splat, spz, summary, table};

use crate::arrays::{as_rows, check_shape, contiguous, contiguous_mut};
use crate::errors::SketchRodGSError;
use crate::pool::run_parallel;

fn formats_err(err: impl std::fmt::Display) -> PyErr {
    SketchRodGSError::new_err(err.to_string())
}

/// For each row of `table` (R, W) float32, its values at `columns` in that order into the same row
/// of `out` (R, len(columns)) float32 (`sketchrodgs_formats::table`).
#[pyfunction]
fn gather_columns(
    py: Python<'_>,
    table: &Bound<'_, PyArray2<f32>>,
    columns: Vec<usize>,
    out: &Bound<'_, PyArray2<f32>>,
) -> PyResult<()> {
    let table = table.try_readonly()?;
    let width = table.shape()[1];
    let mut out = out.try_readwrite()?;
    let (table, out) = (contiguous(&table, "table")?, contiguous_mut(&mut out, "out")?);
    run_parallel(py, "gather_columns", || table::gather_columns(table, width, &columns, out))?.map_err(formats_err)
}

/// Inflate the gzip member in `raw` (uint8) into `out` (uint8). Returns (bytes written, whether
/// bytes follow the member), or None when the stream holds more than `out` does.
#[pyfunction]
fn gunzip_into(
    py: Python<'_>,
    raw: &Bound<'_, PyArray1<u8>>,
    out: &Bound<'_, PyArray1<u8>>,
) -> PyResult<Option<(usize, bool)>> {
    let raw = raw.try_readonly()?;
    let mut out = out.try_readwrite()?;
    let raw = contiguous(&raw, "raw")?;
    let out = contiguous_mut(&mut out, "out")?;
    match run_parallel(py, "gunzip_into", || gzip::gunzip_into(raw, out))? {
        Ok(inflated) => Ok(Some((inflated.written, inflated.trailing))),
        Err(gzip::GunzipError::TooLong(_)) => Ok(None),
        Err(error) => Err(formats_err(error)),
    }
}

/// The scene arrays a decoder fills, as Python passes them: means (N, 3), scales (N, 3), quats
/// (N, 4), opacities (N,), sh (N, K, 3), all float32.
type SceneArrays<'py> = (
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray3<f32>>,
);

/// The scene arrays, borrowed for writing and checked for shape.
struct SplatArrays<'py> {
    means: numpy::PyReadwriteArray2<'py, f32>,
    scales: numpy::PyReadwriteArray2<'py, f32>,
    quats: numpy::PyReadwriteArray2<'py, f32>,
    opacities: numpy::PyReadwriteArray1<'py, f32>,
    sh: numpy::PyReadwriteArray3<'py, f32>,
}

impl<'py> SplatArrays<'py> {
    fn new((means, scales, quats, opacities, sh): &SceneArrays<'py>) -> PyResult<Self> {
        let arrays = SplatArrays {
            means: means.try_readwrite()?,
            scales: scales.try_readwrite()?,
            quats: quats.try_readwrite()?,
            opacities: opacities.try_readwrite()?,
            sh: sh.try_readwrite()?,
        };
        let n = arrays.opacities.shape()[0];
        check_shape("means", arrays.means.shape(), &[Some(n), Some(3)])?;
        check_shape("scales", arrays.scales.shape(), &[Some(n), Some(3)])?;
        check_shape("quats", arrays.quats.shape(), &[Some(n), Some(4)])?;
        check_shape("sh", arrays.sh.shape(), &[Some(n), None, Some(3)])?;
        Ok(arrays)
    }

    fn count(&self) -> usize {
        self.opacities.shape()[0]
    }

    fn slices(&mut self) -> PyResult<SplatsMut<'_>> {
        let sh_coefficients = self.sh.shape()[1];
        Ok(SplatsMut {
            means: contiguous_mut(&mut self.means, "means")?,
            scales: contiguous_mut(&mut self.scales, "scales")?,
            quats: contiguous_mut(&mut self.quats, "quats")?,
            opacities: contiguous_mut(&mut self.opacities, "opacities")?,
            sh: contiguous_mut(&mut self.sh, "sh")?,
            sh_coefficients,
        })
    }
}

/// Decode the inflated SPZ attribute blocks in `payload` (uint8, file order, `sh_bytes_per_splat`
/// SH bytes per splat) into the scene arrays `out`; `version` picks the rotation encoding.
#[pyfunction]
fn decode_spz<'py>(
    py: Python<'py>,
    payload: &Bound<'py, PyArray1<u8>>,
    version: u32,
    sh_bytes_per_splat: usize,
    fractional_bits: u8,
    out: SceneArrays<'py>,
) -> PyResult<()> {
    let payload = payload.try_readonly()?;
    let payload = contiguous(&payload, "payload")?;
    let mut arrays = SplatArrays::new(&out)?;
    let rotations = if version == 2 { spz::Rotations::XyzBytes } else { spz::Rotations::SmallestThree };
    let attributes = spz::Attributes::split(payload, arrays.count(), rotations, sh_bytes_per_splat, fractional_bits)
        .map_err(formats_err)?;
    let out = arrays.slices()?;
    run_parallel(py, "decode_spz", || spz::decode(&attributes, out))?.map_err(formats_err)
}

/// Decode a compressed PLY: `bounds` (chunks, 12 or 18) float64, `packed` (N, 16) uint8 (four
/// little-endian uint32: position, rotation, scale, colour), `sh_rest` (N, 3 * (K - 1)) uint8,
/// into the scene arrays `out`.
#[pyfunction]
fn decode_compressed_ply<'py>(
    py: Python<'py>,
    bounds: &Bound<'py, PyArray2<f64>>,
    packed: &Bound<'py, PyArray2<u8>>,
    sh_rest: &Bound<'py, PyArray2<u8>>,
    out: SceneArrays<'py>,
) -> PyResult<()> {
    let (bounds, packed, sh_rest) = (bounds.try_readonly()?, packed.try_readonly()?, sh_rest.try_readonly()?);
    check_shape("packed", packed.shape(), &[None, Some(16)])?;
    let bound_columns = bounds.shape()[1];
    let (bounds, packed, sh_rest) =
        (contiguous(&bounds, "bounds")?, contiguous(&packed, "packed")?, contiguous(&sh_rest, "sh_rest")?);
    let packed = compressed_ply::Packed { bounds, bound_columns, splats: as_rows(packed), sh_rest };
    let mut arrays = SplatArrays::new(&out)?;
    let out = arrays.slices()?;
    run_parallel(py, "decode_compressed_ply", || compressed_ply::decode(&packed, out))?.map_err(formats_err)
}

/// Decode `.splat` records (uint8, 32 bytes each) into the scene arrays `out` (SH of the DC
/// term only).
#[pyfunction]
fn decode_splat<'py>(py: Python<'py>, records: &Bound<'py, PyArray1<u8>>, out: SceneArrays<'py>) -> PyResult<()> {
    let records = records.try_readonly()?;
    let records = contiguous(&records, "records")?;
    let mut arrays = SplatArrays::new(&out)?;
    let out = arrays.slices()?;
    run_parallel(py, "decode_splat", || splat::decode(records, out))?.map_err(formats_err)
}

type Summary = ([bool; 5], f32, (f32, f32), (f32, f32));

/// What validating a scene needs, in one pass over its C-contiguous float32 arrays (means,
/// scales, quats, opacities, sh): (finite per array, smallest scale, (min, max) opacity,
/// (min, max) squared quaternion length).
#[pyfunction]
fn scene_summary<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyArrayDyn<f32>>,
    scales: &Bound<'py, PyArrayDyn<f32>>,
    quats: &Bound<'py, PyArrayDyn<f32>>,
    opacities: &Bound<'py, PyArrayDyn<f32>>,
    sh: &Bound<'py, PyArrayDyn<f32>>,
) -> PyResult<Summary> {
    let arrays = [means, scales, quats, opacities, sh].map(|a| a.try_readonly());
    let [means, scales, quats, opacities, sh] = arrays;
    let (means, scales, quats, opacities, sh) = (means?, scales?, quats?, opacities?, sh?);
    let (means, scales, quats) =
        (contiguous(&means, "means")?, contiguous(&scales, "scales")?, contiguous(&quats, "quats")?);
    let (opacities, sh) = (contiguous(&opacities, "opacities")?, contiguous(&sh, "sh")?);
    let found = run_parallel(py, "scene_summary", || summary::summarize(means, scales, quats, opacities, sh))?;
    Ok((found.finite, found.scale_min, found.opacity_range, found.quat_length_squared_range))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(gunzip_into, m)?)?;
    m.add_function(wrap_pyfunction!(decode_spz, m)?)?;
    m.add_function(wrap_pyfunction!(decode_compressed_ply, m)?)?;
    m.add_function(wrap_pyfunction!(decode_splat, m)?)?;
    m.add_function(wrap_pyfunction!(scene_summary, m)?)?;
    m.add_function(wrap_pyfunction!(gather_columns, m)?)?;
    Ok(())
}
