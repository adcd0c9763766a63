//! Exception types shared by every binding. All subclass `ValueError` so that callers who
//! catch bad input the usual Python way also catch ours.

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

create_exception!(sketchrodgs._core, SketchRodGSError, PyValueError, "Base class of every sketchrodgs error.");
create_exception!(sketchrodgs._core, PathNotFoundError, SketchRodGSError, "The stroke did not lead to a usable path.");
create_exception!(sketchrodgs._core, SimulationError, SketchRodGSError, "The rod simulation could not proceed.");

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("SketchRodGSError", py.get_type::<SketchRodGSError>())?;
    m.add("PathNotFoundError", py.get_type::<PathNotFoundError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    Ok(())
}
