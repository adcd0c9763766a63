//! Bindings for `sketchrodgs-rod`: `_core.RodWorld`, a world of discrete elastic rods addressed
//! by index. The public API is `sketchrodgs.rod` (`World`, `Rod`); this is its glue.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sketchrodgs_rod::{
    Boundary, ContactSettings, DMat3, DQuat, DVec3, DistanceField, ElasticRod, RodError, RodParams, SolverSettings,
    World,
};

use crate::arrays::{check_shape, contiguous, no_panic};
use crate::errors::SimulationError;

fn rod_err(err: RodError) -> PyErr {
    SimulationError::new_err(err.to_string())
}

/// Rows of a C-contiguous float64 `(N, 3)` array.
fn points(array: &Bound<'_, PyArray2<f64>>, name: &str) -> PyResult<Vec<[f64; 3]>> {
    let ro = array.try_readonly()?;
    check_shape(name, ro.shape(), &[None, Some(3)])?;
    let flat = contiguous(&ro, name)?;
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// A C-contiguous float64 `(3, 3)` array as row-major rows.
fn matrix(array: &Bound<'_, PyArray2<f64>>, name: &str) -> PyResult<[[f64; 3]; 3]> {
    let ro = array.try_readonly()?;
    check_shape(name, ro.shape(), &[Some(3), Some(3)])?;
    let f = contiguous(&ro, name)?;
    Ok([[f[0], f[1], f[2]], [f[3], f[4], f[5]], [f[6], f[7], f[8]]])
}

fn vec3_array<'py>(py: Python<'py>, v: &[DVec3]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = v.iter().flat_map(|p| p.to_array()).collect();
    Array2::from_shape_vec((v.len(), 3), flat).unwrap_or_default().into_pyarray(py)
}

fn mat_array<'py>(py: Python<'py>, m: &[DMat3]) -> Bound<'py, PyArray3<f64>> {
    // Row-major 3x3 blocks: [k, row, col].
    let flat: Vec<f64> = m.iter().flat_map(|r| r.transpose().to_cols_array()).collect();
    Array3::from_shape_vec((m.len(), 3, 3), flat).unwrap_or_default().into_pyarray(py)
}

fn quat_array<'py>(py: Python<'py>, q: &[DQuat]) -> Bound<'py, PyArray2<f64>> {
    // w, x, y, z with w >= 0.
    let flat: Vec<f64> = q
        .iter()
        .flat_map(|q| {
            let q = if q.w < 0.0 { -*q } else { *q };
            [q.w, q.x, q.y, q.z]
        })
        .collect();
    Array2::from_shape_vec((q.len(), 4), flat).unwrap_or_default().into_pyarray(py)
}

fn f64_array<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyArray1<f64>> {
    Array1::from_vec(v).into_pyarray(py)
}

/// Several discrete elastic rods stepped together (see `sketchrodgs.rod.World`).
#[pyclass(module = "sketchrodgs._core", name = "RodWorld")]
pub struct RodWorld {
    world: World,
}

impl RodWorld {
    fn rod(&self, rod: usize) -> PyResult<&ElasticRod> {
        self.world.rod(rod).map_err(rod_err)
    }

    fn rod_mut(&mut self, rod: usize) -> PyResult<&mut ElasticRod> {
        self.world.rod_mut(rod).map_err(rod_err)
    }
}

#[pymethods]
impl RodWorld {
    #[new]
    fn new() -> Self {
        Self { world: World::new() }
    }

    fn __len__(&self) -> usize {
        self.world.len()
    }

    /// Adds a rod at rest in the shape of `polyline` (N, 3) float64; returns its index.
    #[pyo3(signature = (polyline, radius, youngs_modulus, shear_modulus, poisson_ratio, density, damping, gravity))]
    #[allow(clippy::too_many_arguments)]
    fn add_rod(
        &mut self,
        polyline: &Bound<'_, PyArray2<f64>>,
        radius: f64,
        youngs_modulus: f64,
        shear_modulus: Option<f64>,
        poisson_ratio: f64,
        density: f64,
        damping: f64,
        gravity: [f64; 3],
    ) -> PyResult<usize> {
        let poly = points(polyline, "polyline")?;
        let params = RodParams { radius, youngs_modulus, shear_modulus, poisson_ratio, density, damping, gravity };
        let rod = ElasticRod::new(&poly, params).map_err(rod_err)?;
        Ok(self.world.add(rod))
    }

    /// Removes rod `rod`; later indices shift down by one.
    fn remove_rod(&mut self, rod: usize) -> PyResult<()> {
        self.world.remove(rod).map(|_| ()).map_err(rod_err)
    }

    fn num_vertices(&self, rod: usize) -> PyResult<usize> {
        Ok(self.rod(rod)?.num_vertices())
    }

    /// Solver settings as a dict.
    fn solver<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        settings_dict(py, &self.world.settings)
    }

    fn set_solver(
        &mut self,
        tolerance: f64,
        max_iterations: usize,
        max_halvings: u32,
        max_static_iterations: usize,
    ) -> PyResult<()> {
        let s = SolverSettings { tolerance, max_iterations, max_halvings, max_static_iterations };
        s.validate().map_err(rod_err)?;
        self.world.settings = s;
        Ok(())
    }

    /// `kind` is "free", "pinned" or "clamped".
    fn set_boundary(&mut self, rod: usize, vertex: usize, kind: &str) -> PyResult<()> {
        let b = match kind {
            "free" => Boundary::Free,
            "pinned" => Boundary::Pinned,
            "clamped" => Boundary::Clamped,
            other => {
                return Err(SimulationError::new_err(format!(
                    "boundary kind {other:?}: expected 'free', 'pinned' or 'clamped'"
                )));
            }
        };
        self.rod_mut(rod)?.set_boundary(vertex, b).map_err(rod_err)
    }

    fn boundaries(&self, rod: usize) -> PyResult<Vec<&'static str>> {
        Ok(self
            .rod(rod)?
            .boundaries()
            .iter()
            .map(|b| match b {
                Boundary::Free => "free",
                Boundary::Pinned => "pinned",
                Boundary::Clamped => "clamped",
            })
            .collect())
    }

    fn pin_at(&mut self, rod: usize, vertex: usize, position: [f64; 3]) -> PyResult<()> {
        self.rod_mut(rod)?.pin_at(vertex, position).map_err(rod_err)
    }

    fn move_clamp(
        &mut self,
        rod: usize,
        vertex: usize,
        rotation: &Bound<'_, PyArray2<f64>>,
        translation: [f64; 3],
    ) -> PyResult<()> {
        let r = matrix(rotation, "rotation")?;
        self.rod_mut(rod)?.move_clamp(vertex, r, translation).map_err(rod_err)
    }

    fn clamp_torque(&self, rod: usize, vertex: usize) -> PyResult<f64> {
        self.rod(rod)?.clamp_torque(vertex).map_err(rod_err)
    }

    fn grab(&mut self, rod: usize, vertex: usize, target: [f64; 3]) -> PyResult<()> {
        self.rod_mut(rod)?.grab(vertex, target).map_err(rod_err)
    }

    fn move_grab(&mut self, rod: usize, target: [f64; 3]) -> PyResult<()> {
        self.rod_mut(rod)?.move_grab(target).map_err(rod_err)
    }

    fn release(&mut self, rod: usize) -> PyResult<()> {
        self.rod_mut(rod)?.release();
        Ok(())
    }

    /// The grabbed vertex and target, or None.
    fn grabbed(&self, rod: usize) -> PyResult<Option<(usize, [f64; 3])>> {
        Ok(self.rod(rod)?.grabbed().map(|(v, t)| (v, t.to_array())))
    }

    fn transform(&mut self, rod: usize, rotation: &Bound<'_, PyArray2<f64>>, translation: [f64; 3]) -> PyResult<()> {
        let r = matrix(rotation, "rotation")?;
        self.rod_mut(rod)?.transform(r, translation).map_err(rod_err)
    }

    fn set_positions(&mut self, rod: usize, positions: &Bound<'_, PyArray2<f64>>) -> PyResult<()> {
        let p = points(positions, "positions")?;
        self.rod_mut(rod)?.set_positions(&p).map_err(rod_err)
    }

    fn set_velocities(&mut self, rod: usize, velocities: &Bound<'_, PyArray2<f64>>) -> PyResult<()> {
        let v = points(velocities, "velocities")?;
        self.rod_mut(rod)?.set_velocities(&v).map_err(rod_err)
    }

    /// Advances every rod by `dt` seconds, `count` times, with the GIL released. Returns per rod
    /// `(substeps, newton_iterations, rejected, converged)` summed over the calls.
    #[pyo3(signature = (dt, count = 1))]
    fn step(&mut self, py: Python<'_>, dt: f64, count: usize) -> PyResult<Vec<(u32, u32, u32, bool)>> {
        let world = &mut self.world;
        let reports = py.detach(|| no_panic("rod step", || world.step_many(dt, count)))?.map_err(rod_err)?;
        Ok(reports.iter().map(|r| (r.substeps, r.newton_iterations, r.rejected, r.converged)).collect())
    }

    /// Makes rod `rod`'s rest shape hold its current shape under its gravity:
    /// `(iterations, deviation)` (docs/contact.md); SimulationError where nothing can hold it.
    fn hold_under_gravity(&mut self, py: Python<'_>, rod: usize) -> PyResult<(usize, f64)> {
        let settings = self.world.settings;
        let r = self.rod_mut(rod)?;
        let out =
            py.detach(|| no_panic("rod hold under gravity", || r.hold_under_gravity(&settings)))?.map_err(rod_err)?;
        Ok((out.iterations, out.deviation))
    }

    /// The scene's signed distance field the rods do not enter: `values` (nz, ny, nx) float32 at
    /// the nodes `origin + spacing * (i, j, k)`; None clears it.
    #[pyo3(signature = (values, origin, spacing))]
    fn set_field(&mut self, values: Option<&Bound<'_, PyArray3<f32>>>, origin: [f64; 3], spacing: f64) -> PyResult<()> {
        let Some(values) = values else {
            self.world.set_field(None);
            return Ok(());
        };
        let ro = values.try_readonly()?;
        let shape = ro.shape();
        let field =
            DistanceField::new(origin, spacing, [shape[2], shape[1], shape[0]], contiguous(&ro, "values")?.to_vec())
                .map_err(rod_err)?;
        self.world.set_field(Some(field));
        Ok(())
    }

    fn has_field(&self) -> bool {
        self.world.field().is_some()
    }

    /// Contact settings: (scene, rods, friction).
    fn contact(&self) -> (bool, bool, f64) {
        let c = self.world.contact;
        (c.scene, c.rods, c.friction)
    }

    fn set_contact(&mut self, scene: bool, rods: bool, friction: f64) -> PyResult<()> {
        if !(friction.is_finite() && friction >= 0.0) {
            return Err(SimulationError::new_err(format!("friction: must be finite and >= 0, got {friction}")));
        }
        self.world.contact = ContactSettings { scene, rods, friction };
        Ok(())
    }

    /// Quasi-static solve of rod `rod`: `(iterations, converged, energy)`.
    fn solve_static(&mut self, py: Python<'_>, rod: usize) -> PyResult<(u32, bool, f64)> {
        let settings = self.world.settings;
        let r = self.rod_mut(rod)?;
        let out = py.detach(|| no_panic("rod static solve", || r.solve_static(&settings)))?.map_err(rod_err)?;
        Ok((out.iterations, out.converged, out.energy))
    }

    fn positions<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(vec3_array(py, self.rod(rod)?.positions()))
    }

    fn velocities<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(vec3_array(py, self.rod(rod)?.velocities()))
    }

    fn rest_positions<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(vec3_array(py, self.rod(rod)?.rest_positions()))
    }

    fn rest_lengths<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(f64_array(py, self.rod(rod)?.rest_lengths().to_vec()))
    }

    fn masses<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(f64_array(py, self.rod(rod)?.masses().to_vec()))
    }

    fn twist_angles<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(f64_array(py, self.rod(rod)?.twist_angles().to_vec()))
    }

    fn edge_strain<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(f64_array(py, self.rod(rod)?.edge_strain()))
    }

    fn twisting_moment<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(f64_array(py, self.rod(rod)?.twisting_moment()))
    }

    /// Row-major rotations (N-1, 3, 3) with columns (m1, m2, t).
    fn edge_frames<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray3<f64>>> {
        Ok(mat_array(py, &self.rod(rod)?.edge_frames()))
    }

    fn vertex_frames<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray3<f64>>> {
        Ok(mat_array(py, &self.rod(rod)?.vertex_frames()))
    }

    fn edge_quats<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(quat_array(py, &self.rod(rod)?.edge_quats()))
    }

    fn vertex_quats<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(quat_array(py, &self.rod(rod)?.vertex_quats()))
    }

    /// Energies in joules: stretch, bend, twist, kinetic, gravity.
    fn energy<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyDict>> {
        let e = self.rod(rod)?.energy();
        let d = PyDict::new(py);
        d.set_item("stretch", e.stretch)?;
        d.set_item("bend", e.bend)?;
        d.set_item("twist", e.twist)?;
        d.set_item("kinetic", e.kinetic)?;
        d.set_item("gravity", e.gravity)?;
        Ok(d)
    }

    /// Elastic forces (N, 3) [N] and twist torques (N-1,) [N m].
    #[allow(clippy::type_complexity)]
    fn forces<'py>(
        &mut self,
        py: Python<'py>,
        rod: usize,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
        let (f, t) = self.rod_mut(rod)?.forces();
        Ok((vec3_array(py, &f), f64_array(py, t)))
    }

    /// Material parameters of rod `rod` as a dict (shear modulus resolved).
    fn params<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyDict>> {
        params_dict(py, self.rod(rod)?.params())
    }
}

fn params_dict<'py>(py: Python<'py>, p: &RodParams) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("radius", p.radius)?;
    d.set_item("youngs_modulus", p.youngs_modulus)?;
    d.set_item("shear_modulus", p.shear_modulus)?;
    d.set_item("poisson_ratio", p.poisson_ratio)?;
    d.set_item("density", p.density)?;
    d.set_item("damping", p.damping)?;
    d.set_item("gravity", p.gravity)?;
    Ok(d)
}

fn settings_dict<'py>(py: Python<'py>, s: &SolverSettings) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("tolerance", s.tolerance)?;
    d.set_item("max_iterations", s.max_iterations)?;
    d.set_item("max_halvings", s.max_halvings)?;
    d.set_item("max_static_iterations", s.max_static_iterations)?;
    Ok(d)
}

/// The rod crate's default material (the one source of the defaults `RodParams` shows).
#[pyfunction]
fn default_rod_params(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    params_dict(py, &RodParams::default())
}

/// The rod crate's default solver settings (the one source of `SolverSettings`'s defaults).
#[pyfunction]
fn default_solver_settings(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    settings_dict(py, &SolverSettings::default())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RodWorld>()?;
    m.add_function(wrap_pyfunction!(default_rod_params, m)?)?;
    m.add_function(wrap_pyfunction!(default_solver_settings, m)?)?;
    Ok(())
}
