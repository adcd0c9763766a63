//! Checks shared by the bindings: shapes and contiguity of incoming numpy arrays, named in errors.

use numpy::{PyReadonlyArray, PyReadwriteArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::errors::SketchRodGSError;

/// A C-contiguous view of `array`, or an error that names it. (`as_slice` alone also takes a
/// Fortran-ordered array, whose rows the callers would then read as columns.)
pub fn contiguous<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    array: &'a PyReadonlyArray<'_, T, D>,
    name: &str,
) -> PyResult<&'a [T]> {
    let slice = array.is_c_contiguous().then(|| array.as_slice().ok()).flatten();
    slice.ok_or_else(|| not_contiguous(name))
}

/// A C-contiguous mutable view of `array`, or an error that names it.
pub fn contiguous_mut<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    array: &'a mut PyReadwriteArray<'_, T, D>,
    name: &str,
) -> PyResult<&'a mut [T]> {
    if !array.is_c_contiguous() {
        return Err(not_contiguous(name));
    }
    array.as_slice_mut().map_err(|_| not_contiguous(name))
}

fn not_contiguous(name: &str) -> PyErr {
    SketchRodGSError::new_err(format!("{name}: expected a C-contiguous array"))
}

/// Check `shape` against `expected`, where `None` matches any length.
pub fn check_shape(name: &str, shape: &[usize], expected: &[Option<usize>]) -> PyResult<()> {
    let ok = shape.len() == expected.len() && shape.iter().zip(expected).all(|(s, e)| e.is_none_or(|e| *s == e));
    if ok {
        return Ok(());
    }
    let want: Vec<String> = expected.iter().map(|e| e.map_or("N".into(), |e| e.to_string())).collect();
    Err(SketchRodGSError::new_err(format!("{name}: expected shape ({}), got {shape:?}", want.join(", "))))
}

/// Run `f`, turning a Rust panic into a Python error instead of a `PanicException`.
pub fn no_panic<T>(what: &str, f: impl FnOnce() -> T) -> PyResult<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|_| {
        SketchRodGSError::new_err(format!("{what}: internal error (a bug in sketchrodgs; please report it)"))
    })
}

/// Reinterpret a flat row-major slice as fixed-size rows (the caller checked the shape).
pub fn as_rows<T, const K: usize>(flat: &[T]) -> &[[T; K]] {
    let (rows, _) = flat.as_chunks::<K>();
    rows
}
