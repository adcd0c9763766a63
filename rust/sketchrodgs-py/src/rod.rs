//! Bindings for `sketchrodgs-rod`: `_core.RodWorld`, a world of discrete elastic rods, and
//! `_core.Rod`, a handle on one of its rods (the base class of `sketchrodgs.rod.Rod`). The public
//! API is `sketchrodgs.rod` (`World`, `Rod`).

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayLikeDyn, PyArrayMethods, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sketchrodgs_rod::{
    Boundary, ContactSettings, DMat3, DQuat, DVec3, DistanceField, ElasticRod, RodError, RodParams, SolverSettings,
    World,
};

use crate::arrays::{contiguous, no_panic};
use crate::errors::SimulationError;

fn rod_err(err: RodError) -> PyErr {
    SimulationError::new_err(err.to_string())
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

/// Several discrete elastic rods stepped together (see `sketchrodgs.rod.World`). Each rod is a
/// `Rod` handle that holds the world and the rod's id; removing a rod renumbers none of the others.
#[pyclass(module = "sketchrodgs._core", name = "RodWorld")]
pub struct RodWorld {
    world: World,
    /// The id of the rod at each index of `world`.
    ids: Vec<u64>,
    next_id: u64,
}

impl RodWorld {
    fn index_of(&self, id: u64) -> Option<usize> {
        self.ids.iter().position(|&k| k == id)
    }
}

#[pymethods]
impl RodWorld {
    #[new]
    fn new() -> Self {
        Self { world: World::new(), ids: Vec::new(), next_id: 0 }
    }

    fn __len__(&self) -> usize {
        self.world.len()
    }

    /// Removes `rod` from the world; its handle is then detached.
    fn remove(mut slf: PyRefMut<'_, Self>, rod: PyRef<'_, Rod>) -> PyResult<()> {
        if rod.world.as_ptr() != slf.as_ptr() {
            return Err(SimulationError::new_err("this rod belongs to another world"));
        }
        let index = slf.index_of(rod.id).ok_or_else(removed)?;
        slf.world.remove(index).map_err(rod_err)?;
        slf.ids.remove(index);
        Ok(())
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

    /// Advances every rod by `dt` seconds, `count` times, with the GIL released. Returns per rod,
    /// in the order they were added, `(substeps, newton_iterations, rejected, converged)` summed
    /// over the calls.
    #[pyo3(signature = (dt, count = 1))]
    fn step(&mut self, py: Python<'_>, dt: f64, count: usize) -> PyResult<Vec<(u32, u32, u32, bool)>> {
        let world = &mut self.world;
        let reports = py.detach(|| no_panic("rod step", || world.step_many(dt, count)))?.map_err(rod_err)?;
        Ok(reports.iter().map(|r| (r.substeps, r.newton_iterations, r.rejected, r.converged)).collect())
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
}

fn removed() -> PyErr {
    SimulationError::new_err("this rod was removed from its world")
}

fn busy(what: &str) -> PyErr {
    SimulationError::new_err(format!(
        "{what}: this World (and its rods) is in use by another thread; a World is not shared across threads: \
         give each thread its own, or hold a lock"
    ))
}

/// A discrete elastic rod in a `RodWorld` (the base of `sketchrodgs.rod.Rod`, which documents
/// it). The handle holds the world and the rod's id, so it stays valid while other rods of the
/// world are added or removed.
#[pyclass(module = "sketchrodgs._core", name = "Rod", subclass)]
pub struct Rod {
    world: Py<RodWorld>,
    id: u64,
    vertices: usize,
}

impl Rod {
    /// Runs `f` on the rod, the world borrowed for reading.
    fn with<T>(&self, py: Python<'_>, what: &str, f: impl FnOnce(&ElasticRod) -> PyResult<T>) -> PyResult<T> {
        let world = self.world.try_borrow(py).map_err(|_| busy(what))?;
        let index = world.index_of(self.id).ok_or_else(removed)?;
        f(world.world.rod(index).map_err(rod_err)?)
    }

    /// Runs `f` on the rod, the world borrowed for writing.
    fn with_mut<T>(
        &self,
        py: Python<'_>,
        what: &str,
        f: impl FnOnce(&mut ElasticRod, &SolverSettings) -> PyResult<T>,
    ) -> PyResult<T> {
        let mut world = self.world.try_borrow_mut(py).map_err(|_| busy(what))?;
        let index = world.index_of(self.id).ok_or_else(removed)?;
        let settings = world.world.settings;
        f(world.world.rod_mut(index).map_err(rod_err)?, &settings)
    }

    /// `vertex` (an integer) as an index into the rod; negative counts from the end.
    fn vertex(&self, vertex: &Bound<'_, PyAny>) -> PyResult<usize> {
        let n = self.vertices as i64;
        let shown = || vertex.repr().map_or_else(|_| "?".to_string(), |r| r.to_string());
        let out_of_range =
            || SimulationError::new_err(format!("vertex {} is out of range for a rod of {n} vertices", shown()));
        match vertex.extract::<i64>() {
            Ok(v) if (-n..n).contains(&v) => Ok(v.rem_euclid(n) as usize),
            Ok(_) => Err(out_of_range()),
            // an integer too large for i64 is out of range too; anything else is not a vertex
            Err(_) if vertex.hasattr("__index__").unwrap_or(false) => Err(out_of_range()),
            Err(_) => Err(SimulationError::new_err(format!("vertex: expected an integer index, got {}", shown()))),
        }
    }
}

#[pymethods]
impl Rod {
    /// Adds a rod at rest in the shape of `polyline` (N, 3) to `world`.
    #[new]
    #[pyo3(signature = (world, polyline, radius, youngs_modulus, shear_modulus, poisson_ratio, density, damping, gravity))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        world: Bound<'_, RodWorld>,
        polyline: &Bound<'_, PyAny>,
        radius: f64,
        youngs_modulus: f64,
        shear_modulus: Option<f64>,
        poisson_ratio: f64,
        density: f64,
        damping: f64,
        gravity: [f64; 3],
    ) -> PyResult<Self> {
        let poly = rows3(polyline, "polyline")?;
        let params = RodParams { radius, youngs_modulus, shear_modulus, poisson_ratio, density, damping, gravity };
        let rod = ElasticRod::new(&poly, params).map_err(rod_err)?;
        let vertices = rod.num_vertices();
        let mut w = world.try_borrow_mut().map_err(|_| busy("Rod"))?;
        let id = w.next_id;
        w.next_id += 1;
        w.world.add(rod);
        w.ids.push(id);
        drop(w);
        Ok(Self { world: world.unbind(), id, vertices })
    }

    fn __len__(&self) -> usize {
        self.vertices
    }

    #[getter]
    fn num_vertices(&self) -> usize {
        self.vertices
    }

    /// Index of the rod in its world (the order of `World.step`'s reports).
    #[getter]
    fn index(&self, py: Python<'_>) -> PyResult<usize> {
        let world = self.world.try_borrow(py).map_err(|_| busy("index"))?;
        world.index_of(self.id).ok_or_else(removed)
    }

    // ----- boundary conditions and interaction -----

    /// Holds `vertex`'s position and frame where they are (both ends: the app's default).
    fn clamp(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>) -> PyResult<()> {
        self.set(py, vertex, Boundary::Clamped)
    }

    /// Holds `vertex`'s position (at `position` if given, reached over the next step).
    #[pyo3(signature = (vertex, position = None))]
    fn pin(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>, position: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
        let v = self.vertex(vertex)?;
        match position {
            None => self.set(py, vertex, Boundary::Pinned),
            Some(p) => {
                let p = vec3(p, "position")?;
                self.with_mut(py, "pin", |rod, _| rod.pin_at(v, p).map_err(rod_err))
            }
        }
    }

    /// Removes any pin or clamp of `vertex`.
    fn free(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>) -> PyResult<()> {
        self.set(py, vertex, Boundary::Free)
    }

    /// Sets `vertex`'s boundary condition: "free", "pinned" or "clamped".
    fn set_boundary(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>, kind: &str) -> PyResult<()> {
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
        self.set(py, vertex, b)
    }

    /// Per vertex: "free", "pinned" or "clamped".
    #[getter]
    fn boundaries(&self, py: Python<'_>) -> PyResult<Vec<&'static str>> {
        self.with(py, "boundaries", |rod| {
            Ok(rod
                .boundaries()
                .iter()
                .map(|b| match b {
                    Boundary::Free => "free",
                    Boundary::Pinned => "pinned",
                    Boundary::Clamped => "clamped",
                })
                .collect())
        })
    }

    /// Moves the clamp of `vertex` rigidly from its pose when clamped: its frame rotated by
    /// `rotation` (3, 3), the vertex translated by `translation`. Turn less than pi per step.
    #[pyo3(signature = (vertex, rotation = None, translation = None))]
    fn move_clamp(
        &self,
        py: Python<'_>,
        vertex: &Bound<'_, PyAny>,
        rotation: Option<&Bound<'_, PyAny>>,
        translation: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let (v, r, t) = (self.vertex(vertex)?, rotation3(rotation)?, translation3(translation)?);
        self.with_mut(py, "move_clamp", |rod, _| rod.move_clamp(v, r, t).map_err(rod_err))
    }

    /// Twisting moment [N m] the rod exerts on the clamp of `vertex` about its tangent.
    fn clamp_torque(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>) -> PyResult<f64> {
        let v = self.vertex(vertex)?;
        self.with(py, "clamp_torque", |rod| rod.clamp_torque(v).map_err(rod_err))
    }

    /// From the next step on, `vertex` follows `target` exactly (a hard position constraint;
    /// the frame stays free). The motion to the target happens within the next step.
    fn grab(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>, target: &Bound<'_, PyAny>) -> PyResult<()> {
        let (v, t) = (self.vertex(vertex)?, vec3(target, "target")?);
        self.with_mut(py, "grab", |rod, _| rod.grab(v, t).map_err(rod_err))
    }

    /// Moves the grab target. Raises SimulationError if nothing is grabbed.
    fn move_grab(&self, py: Python<'_>, target: &Bound<'_, PyAny>) -> PyResult<()> {
        let t = vec3(target, "target")?;
        self.with_mut(py, "move_grab", |rod, _| rod.move_grab(t).map_err(rod_err))
    }

    /// Lets go; the vertex keeps its velocity.
    fn release(&self, py: Python<'_>) -> PyResult<()> {
        self.with_mut(py, "release", |rod, _| {
            rod.release();
            Ok(())
        })
    }

    /// (vertex, target) of the current grab, or None.
    #[getter]
    fn grabbed<'py>(&self, py: Python<'py>) -> PyResult<Option<(usize, Bound<'py, PyArray1<f64>>)>> {
        let grab = self.with(py, "grabbed", |rod| Ok(rod.grabbed()))?;
        Ok(grab.map(|(v, t)| (v, f64_array(py, t.to_array().to_vec()))))
    }

    /// Moves the rod rigidly, x -> R x + t, with its frames, pins, clamps and grab target.
    #[pyo3(signature = (rotation = None, translation = None))]
    fn transform(
        &self,
        py: Python<'_>,
        rotation: Option<&Bound<'_, PyAny>>,
        translation: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let (r, t) = (rotation3(rotation)?, translation3(translation)?);
        self.with_mut(py, "transform", |rod, _| rod.transform(r, t).map_err(rod_err))
    }

    /// Teleports the vertices (N, 3); velocities zeroed, frames parallel-transported.
    fn set_positions(&self, py: Python<'_>, positions: &Bound<'_, PyAny>) -> PyResult<()> {
        let p = rows3(positions, "positions")?;
        self.with_mut(py, "set_positions", |rod, _| rod.set_positions(&p).map_err(rod_err))
    }

    /// Sets the vertex velocities (N, 3) [m/s].
    fn set_velocities(&self, py: Python<'_>, velocities: &Bound<'_, PyAny>) -> PyResult<()> {
        let v = rows3(velocities, "velocities")?;
        self.with_mut(py, "set_velocities", |rod, _| rod.set_velocities(&v).map_err(rod_err))
    }

    // ----- simulation (wrapped by `sketchrodgs.rod.Rod` into its reports) -----

    /// Quasi-static solve: `(iterations, converged, energy)`, with the GIL released.
    fn _solve_static(&self, py: Python<'_>) -> PyResult<(u32, bool, f64)> {
        self.with_mut(py, "solve_static", |rod, settings| {
            let out = py.detach(|| no_panic("rod static solve", || rod.solve_static(settings)))?.map_err(rod_err)?;
            Ok((out.iterations, out.converged, out.energy))
        })
    }

    /// Makes the rest shape hold the current shape under gravity: `(iterations, deviation)`
    /// (docs/contact.md); SimulationError where nothing can hold it.
    fn _hold_under_gravity(&self, py: Python<'_>) -> PyResult<(usize, f64)> {
        self.with_mut(py, "hold_under_gravity", |rod, settings| {
            let out = py
                .detach(|| no_panic("rod hold under gravity", || rod.hold_under_gravity(settings)))?
                .map_err(rod_err)?;
            Ok((out.iterations, out.deviation))
        })
    }

    /// Energies in joules: stretch, bend, twist, kinetic, gravity.
    fn _energy<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let e = self.with(py, "energy", |rod| Ok(rod.energy()))?;
        let d = PyDict::new(py);
        d.set_item("stretch", e.stretch)?;
        d.set_item("bend", e.bend)?;
        d.set_item("twist", e.twist)?;
        d.set_item("kinetic", e.kinetic)?;
        d.set_item("gravity", e.gravity)?;
        Ok(d)
    }

    /// The material as the solver holds it, as a dict (shear modulus resolved).
    fn _material<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = self.with(py, "params", |rod| Ok(*rod.params()))?;
        params_dict(py, &p)
    }

    // ----- state -----

    /// (N, 3) float64 vertex positions [m].
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.with(py, "positions", |rod| Ok(vec3_array(py, rod.positions())))
    }

    /// (N, 3) float64 vertex velocities [m/s].
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.with(py, "velocities", |rod| Ok(vec3_array(py, rod.velocities())))
    }

    /// (N, 3) float64: the polyline the rod was built from (its rest shape).
    #[getter]
    fn rest_positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.with(py, "rest_positions", |rod| Ok(vec3_array(py, rod.rest_positions())))
    }

    /// (N-1,) rest edge lengths [m].
    #[getter]
    fn rest_lengths<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.with(py, "rest_lengths", |rod| Ok(f64_array(py, rod.rest_lengths().to_vec())))
    }

    /// (N,) lumped vertex masses [kg].
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.with(py, "masses", |rod| Ok(f64_array(py, rod.masses().to_vec())))
    }

    /// (N-1,) twist angle of each edge's material frame from its reference frame [rad].
    #[getter]
    fn twist<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.with(py, "twist", |rod| Ok(f64_array(py, rod.twist_angles().to_vec())))
    }

    /// (N-1,) edge stretch |e| / |e_rest| - 1.
    #[getter]
    fn strain<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.with(py, "strain", |rod| Ok(f64_array(py, rod.edge_strain())))
    }

    /// (N,) internal twisting moment GJ (m_i - m0_i) / l_i [N m] (zero at the ends).
    fn twisting_moment<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.with(py, "twisting_moment", |rod| Ok(f64_array(py, rod.twisting_moment())))
    }

    /// (N-1, 3, 3) material frame of each edge, a rotation with columns (m1, m2, t).
    #[getter]
    fn edge_frames<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.with(py, "edge_frames", |rod| Ok(mat_array(py, &rod.edge_frames())))
    }

    /// (N, 3, 3) per-vertex frame: the average of the adjacent edges' frames.
    #[getter]
    fn vertex_frames<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.with(py, "vertex_frames", |rod| Ok(mat_array(py, &rod.vertex_frames())))
    }

    /// (N-1, 4) edge frames as unit quaternions w, x, y, z (w >= 0).
    #[getter]
    fn edge_quats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.with(py, "edge_quats", |rod| Ok(quat_array(py, &rod.edge_quats())))
    }

    /// (N, 4) vertex frames as unit quaternions w, x, y, z (w >= 0).
    #[getter]
    fn vertex_quats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.with(py, "vertex_quats", |rod| Ok(quat_array(py, &rod.vertex_quats())))
    }

    /// Elastic forces on the vertices (N, 3) [N] and torques on the edges' twist (N-1,) [N m].
    #[allow(clippy::type_complexity)]
    fn forces<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
        let (f, t) = self.with_mut(py, "forces", |rod, _| Ok(rod.forces()))?;
        Ok((vec3_array(py, &f), f64_array(py, t)))
    }
}

impl Rod {
    fn set(&self, py: Python<'_>, vertex: &Bound<'_, PyAny>, boundary: Boundary) -> PyResult<()> {
        let v = self.vertex(vertex)?;
        self.with_mut(py, "set_boundary", |rod, _| rod.set_boundary(v, boundary).map_err(rod_err))
    }
}

/// `value` as a float64 array of any shape (lists and other array-likes converted).
fn float_array<'py>(value: &Bound<'py, PyAny>, name: &str) -> PyResult<PyArrayLikeDyn<'py, f64, AllowTypeChange>> {
    value.extract().map_err(|_| SimulationError::new_err(format!("{name}: expected an array of numbers")))
}

/// A shape written as Python writes a tuple: `(3,)`, `(2, 4)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!("({})", shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// Rows of an `(N, 3)` array-like.
fn rows3(value: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<[f64; 3]>> {
    let array = float_array(value, name)?;
    let view = array.as_array();
    if view.ndim() != 2 || view.shape()[1] != 3 {
        return Err(SimulationError::new_err(format!(
            "{name}: expected shape (N, 3), got {}",
            shape_text(view.shape())
        )));
    }
    Ok(view.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// Three numbers, of any shape holding exactly three.
fn vec3(value: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
    let array = float_array(value, name)?;
    let view = array.as_array();
    let values: Vec<f64> = view.iter().copied().collect();
    <[f64; 3]>::try_from(values).map_err(|_| {
        SimulationError::new_err(format!("{name}: expected 3 values, got shape {}", shape_text(view.shape())))
    })
}

fn translation3(value: Option<&Bound<'_, PyAny>>) -> PyResult<[f64; 3]> {
    value.map_or(Ok([0.0; 3]), |v| vec3(v, "translation"))
}

/// A (3, 3) rotation as row-major rows; None is the identity.
fn rotation3(value: Option<&Bound<'_, PyAny>>) -> PyResult<[[f64; 3]; 3]> {
    let Some(value) = value else { return Ok([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) };
    let array = float_array(value, "rotation")?;
    let view = array.as_array();
    if view.shape() != [3, 3] {
        return Err(SimulationError::new_err(format!(
            "rotation: expected a (3, 3) rotation matrix, got shape {}",
            shape_text(view.shape())
        )));
    }
    Ok([0, 1, 2].map(|i| [view[[i, 0]], view[[i, 1]], view[[i, 2]]]))
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
    m.add_class::<Rod>()?;
    m.add_function(wrap_pyfunction!(default_rod_params, m)?)?;
    m.add_function(wrap_pyfunction!(default_solver_settings, m)?)?;
    Ok(())
}
