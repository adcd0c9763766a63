//! `sketchrodgs._core`: the compiled half of the Python package.
//!
//! Only glue lives here: each submodule extracts numpy inputs, calls a pure-Rust core crate
//! with the GIL released, and hands the results back as numpy arrays without copying.

use pyo3::prelude::*;

mod arrays;
mod errors;
mod field;
mod formats;
mod image;
mod path;
mod polyline;
mod pool;
mod raster;
mod rod;
mod skin;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    field::register(m)?;
    formats::register(m)?;
    image::register(m)?;
    path::register(m)?;
    polyline::register(m)?;
    pool::register(m)?;
    raster::register(m)?;
    rod::register(m)?;
    skin::register(m)?;
    Ok(())
}
