//! The one rayon pool of the extension (`SKETCHRODGS_NUM_THREADS` threads, default: all cores).
//!
//! Core crates never build a global pool; every parallel call from Python runs inside this one.
//! A forked child has none of its parent's threads, so Python drops the pool after `fork`
//! (`os.register_at_fork`) and the child builds a fresh one on first use.

use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use rayon::{ThreadPool, ThreadPoolBuilder};

use crate::arrays::no_panic;
use crate::errors::SketchRodGSError;

static POOL: Mutex<Option<Arc<ThreadPool>>> = Mutex::new(None);

fn pool() -> PyResult<Arc<ThreadPool>> {
    let mut slot = POOL.lock().map_err(|_| SketchRodGSError::new_err("thread pool lock poisoned"))?;
    if let Some(pool) = slot.as_ref() {
        return Ok(Arc::clone(pool));
    }
    let threads =
        std::env::var("SKETCHRODGS_NUM_THREADS").ok().and_then(|v| v.trim().parse::<usize>().ok()).unwrap_or(0);
    let pool = Arc::new(
        ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("sketchrodgs-{i}"))
            .build()
            .map_err(|e| SketchRodGSError::new_err(format!("cannot start worker threads: {e}")))?,
    );
    *slot = Some(Arc::clone(&pool));
    Ok(pool)
}

/// Run `f` without the GIL, inside the extension's pool, turning a panic into a Python error.
pub fn run_parallel<T: Send>(py: Python<'_>, what: &str, f: impl FnOnce() -> T + Send) -> PyResult<T> {
    let pool = pool()?;
    py.detach(|| no_panic(what, || pool.install(f)))
}

/// Forget the pool in a forked child (its worker threads were not forked).
#[pyfunction]
fn _reset_pool_after_fork() {
    if let Ok(mut slot) = POOL.lock()
        && let Some(pool) = slot.take()
    {
        // Dropping would signal threads that do not exist in this process; leak it instead.
        std::mem::forget(pool);
    }
}

/// Number of threads the extension's pool uses.
#[pyfunction]
fn num_threads() -> PyResult<usize> {
    Ok(pool()?.current_num_threads())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_reset_pool_after_fork, m)?)?;
    m.add_function(wrap_pyfunction!(num_threads, m)?)?;
    Ok(())
}
