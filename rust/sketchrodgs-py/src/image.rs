//! PNG encoding for `sketchrodgs.images.save_png` (the `png` crate; its fast level deflates with
//! `fdeflate`, an order of magnitude faster than zlib's fastest level at a similar size).

use numpy::{PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::arrays::{check_shape, contiguous, no_panic};
use crate::errors::SketchRodGSError;

/// The PNG file of an (H, W, 3) uint8 RGB image at zlib-like `level` 0-9: 0 stores, 1 is the fast
/// level (`fdeflate`), 2-6 balanced, 7-9 smallest.
#[pyfunction]
#[pyo3(signature = (rgb, level = 1))]
fn encode_png<'py>(py: Python<'py>, rgb: PyReadonlyArray3<'py, u8>, level: u8) -> PyResult<Bound<'py, PyBytes>> {
    check_shape("image", rgb.shape(), &[None, None, Some(3)])?;
    let (height, width) = (rgb.shape()[0], rgb.shape()[1]);
    let size = |side: usize, name: &str| {
        u32::try_from(side)
            .ok()
            .filter(|&s| s > 0)
            .ok_or_else(|| SketchRodGSError::new_err(format!("image: {name} must be 1 to {}, got {side}", u32::MAX)))
    };
    let (width, height) = (size(width, "width")?, size(height, "height")?);
    let compression = match level {
        0 => png::Compression::NoCompression,
        1 => png::Compression::Fast,
        2..=6 => png::Compression::Balanced,
        7..=9 => png::Compression::High,
        _ => return Err(SketchRodGSError::new_err(format!("compress_level: expected 0 to 9, got {level}"))),
    };
    let pixels = contiguous(&rgb, "image")?;
    let encoded = py.detach(|| {
        no_panic("encode_png", || {
            let mut out = Vec::with_capacity(pixels.len() / 4);
            let mut encoder = png::Encoder::new(&mut out, width, height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            encoder.set_compression(compression);
            encoder.write_header().and_then(|mut writer| writer.write_image_data(pixels))?;
            Ok::<_, png::EncodingError>(out)
        })
    })?;
    let bytes = encoded.map_err(|e| SketchRodGSError::new_err(format!("image: cannot encode as PNG: {e}")))?;
    Ok(PyBytes::new(py, &bytes))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(encode_png, m)?)?;
    Ok(())
}
