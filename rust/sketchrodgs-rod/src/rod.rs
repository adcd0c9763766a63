//! One discrete elastic rod: rest shape, state, boundary conditions and the implicit solver.

use crate::banded::BandedMatrix;
use crate::dual::NV;
use crate::energy::{self, BendTwistInput};
use crate::frames::{
    average_rotation, curvature_binormal, frame_matrix, material_frame, perpendicular, signed_angle, transport,
    unwrap_near,
};
use crate::{RodError, RodParams, SolverSettings};
use glam::{DMat3, DQuat, DVec3};

/// Half-bandwidth of the Hessian: a bending stencil spans 11 consecutive unknowns.
const BANDWIDTH: usize = 10;
/// An edge shorter than this fraction of the rod's length is degenerate.
const MIN_EDGE_FRACTION: f64 = 1.0e-9;
/// A rest vertex whose `1 + t0.t1` is below this folds back on itself (turning angle ~ pi).
const MIN_FOLD: f64 = 1.0e-8;
/// Deformed states with an edge below this fraction of its rest length, or a turning angle this
/// close to pi, have infinite energy: the line search never steps there.
const MIN_DEFORMED_EDGE: f64 = 1.0e-9;
const MIN_DEFORMED_FOLD: f64 = 1.0e-10;
/// Armijo sufficient-decrease constant of the line search.
const ARMIJO: f64 = 1.0e-4;
/// Line-search halvings before the direction is given up.
const MAX_BACKTRACKS: usize = 40;
/// A full Newton step smaller than this (relative to the rod length, or in radians) lets the
/// next iterations reuse its factorisation.
const CHORD_AFTER: f64 = 1.0e-3;
/// Chord steps continue while each is this much smaller than the one before.
const CHORD_CONTRACTION: f64 = 0.25;

/// Boundary condition of a vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Boundary {
    /// Moves freely.
    Free,
    /// Position held; the adjacent edges may turn and twist about it.
    Pinned,
    /// Position and frame held. The clamp is a rigid frame at the vertex (the vertex frame
    /// when clamped); each adjacent edge bends and twists against it over half its length, so
    /// the clamp acts at the vertex itself. [`ElasticRod::move_clamp`] moves it rigidly.
    Clamped,
}

/// What one call to [`ElasticRod::step`] (or [`crate::World::step`]) did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepReport {
    /// Substeps the step was finally taken in (1 when it converged at once).
    pub substeps: u32,
    /// Newton iterations over all attempts, rejected ones included.
    pub newton_iterations: u32,
    /// Attempts rejected and retried as two half steps.
    pub rejected: u32,
    /// Whether every substep converged. When `false`, the finest substeps kept their best
    /// iterate: finite, of lower incremental potential than the start, but not converged.
    pub converged: bool,
}

impl StepReport {
    fn merge(self, o: StepReport) -> StepReport {
        StepReport {
            substeps: self.substeps + o.substeps,
            newton_iterations: self.newton_iterations + o.newton_iterations,
            rejected: self.rejected + o.rejected,
            converged: self.converged && o.converged,
        }
    }
}

/// Result of [`ElasticRod::solve_static`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticReport {
    /// Newton iterations taken.
    pub iterations: u32,
    /// Whether the update fell below the tolerance.
    pub converged: bool,
    /// Elastic plus gravitational energy at the end (J).
    pub energy: f64,
}

/// Energy of a rod, split by kind (J).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Energy {
    pub stretch: f64,
    pub bend: f64,
    pub twist: f64,
    /// Translational plus twisting kinetic energy.
    pub kinetic: f64,
    /// Gravitational potential `-sum m g . x` (zero without gravity).
    pub gravity: f64,
}

impl Energy {
    /// Elastic energy: stretch + bend + twist.
    pub fn elastic(&self) -> f64 {
        self.stretch + self.bend + self.twist
    }

    /// Everything: elastic + kinetic + gravitational.
    pub fn total(&self) -> f64 {
        self.elastic() + self.kinetic + self.gravity
    }
}

/// Half of a bending/twisting stencil between a clamp frame and one adjacent edge.
#[derive(Debug, Clone, Copy)]
struct Half {
    edge: usize,
    /// The clamp frame follows the edge (the clamp is at the edge's end vertex).
    ghost_after: bool,
    rest_kappa: [f64; 4],
    rest_twist: f64,
}

#[derive(Debug, Clone)]
struct Clamp {
    vertex: usize,
    anchor_x: DVec3,
    /// Clamp frame (columns `m1, m2, t`) when clamped.
    anchor_frame: DMat3,
    rotation: DMat3,
    translation: DVec3,
    halves: Vec<Half>,
}

/// Prescribed values at the end of a (sub)step: positions per vertex, frames per clamp.
#[derive(Debug, Clone)]
struct Targets {
    x: Vec<Option<DVec3>>,
    frames: Vec<DMat3>,
}

/// Dynamic state. The reference frames `(ref_dir, tangent)` are the chart of the current step:
/// during a step every trial frame is the parallel transport of `ref_dir` from `tangent` to the
/// trial tangent (time-parallel transport, Bergou 2010).
#[derive(Debug, Clone)]
struct State {
    x: Vec<DVec3>,
    v: Vec<DVec3>,
    theta: Vec<f64>,
    omega: Vec<f64>,
    ref_dir: Vec<DVec3>,
    tangent: Vec<DVec3>,
    /// Reference twist per vertex (entries 0 and n-1 unused).
    ref_twist: Vec<f64>,
    /// Frame of each clamp.
    clamp_frame: Vec<DMat3>,
    /// Twist of each clamp's half stencils, the branch the chart tracks.
    half_twist: Vec<[f64; 2]>,
}

/// Per-configuration geometry in the current chart.
#[derive(Debug, Clone, Default)]
struct Geometry {
    len: Vec<f64>,
    t: Vec<DVec3>,
    m1: Vec<DVec3>,
    m2: Vec<DVec3>,
    /// Twist `m_i = theta_i - theta_{i-1} + m_ref_i` per vertex.
    twist: Vec<f64>,
    ref_twist: Vec<f64>,
    /// Transported reference directors.
    a1: Vec<DVec3>,
    half_twist: Vec<[f64; 2]>,
}

/// The backward-Euler terms of a dynamic step of length `h`; absent in a static solve.
#[derive(Debug, Clone)]
struct Inertia {
    h: f64,
    alpha: f64,
    x_hat: Vec<DVec3>,
    th_hat: Vec<f64>,
    x_n: Vec<DVec3>,
    th_n: Vec<f64>,
}

/// Outcome of one Newton solve.
#[derive(Debug, Clone, Copy)]
struct Solve {
    iterations: u32,
    converged: bool,
    /// Some iterate with finite potential was reached (the start at least).
    finite: bool,
}

/// A discrete elastic rod (Bergou et al. 2008, 2010) of `n` vertices and `n - 1` edges, with
/// stretching, bending about the natural curvature of its rest polyline, and twisting.
///
/// Unknowns are the vertex positions and one twist angle per edge, interleaved as
/// `(x_0, theta_0, x_1, theta_1, ..., x_{n-1})`, so the Hessian is banded. Each step is one
/// backward-Euler solve: Newton's method with a backtracking line search on the incremental
/// potential, which makes it stable for any step and never lets the energy blow up.
#[derive(Debug, Clone)]
pub struct ElasticRod {
    params: RodParams,
    rest_x: Vec<DVec3>,
    rest_len: Vec<f64>,
    voronoi_len: Vec<f64>,
    rest_kappa: Vec<[f64; 4]>,
    rest_twist: Vec<f64>,
    /// Rest material frames `(m1, m2, t)` of the edges.
    rest_frames: Vec<DMat3>,
    mass: Vec<f64>,
    twist_inertia: Vec<f64>,
    length: f64,
    state: State,
    boundary: Vec<Boundary>,
    pins: Vec<Option<DVec3>>,
    clamps: Vec<Clamp>,
    grab: Option<(usize, DVec3)>,
    // Workspace, reused between iterations.
    geo: Geometry,
    trial: Geometry,
    hess: BandedMatrix,
    factor: BandedMatrix,
    grad: Vec<f64>,
    dtheta_elastic: Vec<f64>,
    /// Drop the negative (compressive) part of the stretching Hessian; off only in tests
    /// that compare with finite differences.
    project_stretch: bool,
}

fn dof_x(i: usize) -> usize {
    4 * i
}

fn dof_theta(j: usize) -> usize {
    4 * j + 3
}

impl ElasticRod {
    /// Builds a rod at rest in the shape of `polyline` (its natural, curved shape).
    ///
    /// Fails on fewer than 2 vertices, non-finite coordinates, an edge shorter than 1e-9 of the
    /// rod's length (merge coincident vertices first), or a vertex folding back by ~180 degrees.
    pub fn new(polyline: &[[f64; 3]], params: RodParams) -> Result<Self, RodError> {
        params.validate()?;
        let n = polyline.len();
        if n < 2 {
            return Err(RodError::TooFewVertices(n));
        }
        for (i, p) in polyline.iter().enumerate() {
            if p.iter().any(|c| !c.is_finite()) {
                return Err(RodError::NonFiniteVertex { vertex: i, value: *p });
            }
        }
        let x: Vec<DVec3> = polyline.iter().map(|p| DVec3::from_array(*p)).collect();
        let rest_len: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]).length()).collect();
        let length: f64 = rest_len.iter().sum();
        if let Some(edge) = rest_len.iter().position(|l| !l.is_finite()) {
            return Err(RodError::EdgeTooLong { edge });
        }
        let min_length = MIN_EDGE_FRACTION * length.max(f64::MIN_POSITIVE);
        for (j, &l) in rest_len.iter().enumerate() {
            if l.is_nan() || l <= min_length {
                return Err(RodError::DegenerateEdge { edge: j, length: l, min_length });
            }
        }
        let tangent: Vec<DVec3> = x.windows(2).map(|w| (w[1] - w[0]).normalize()).collect();
        for i in 1..n - 1 {
            if 1.0 + tangent[i - 1].dot(tangent[i]) < MIN_FOLD {
                return Err(RodError::FoldedVertex { vertex: i });
            }
        }
        // Reference frames by space-parallel transport along the rest shape: zero rest twist.
        let mut ref_dir = Vec::with_capacity(n - 1);
        ref_dir.push(perpendicular(tangent[0]));
        for j in 1..n - 1 {
            let a = transport(ref_dir[j - 1], tangent[j - 1], tangent[j]);
            ref_dir.push((a - tangent[j] * tangent[j].dot(a)).normalize());
        }
        let rest_frames = ref_dir.iter().zip(&tangent).map(|(a, t)| frame_matrix(*a, t.cross(*a), *t)).collect();
        let mut voronoi_len = vec![0.0; n];
        for i in 1..n - 1 {
            voronoi_len[i] = 0.5 * (rest_len[i - 1] + rest_len[i]);
        }
        let rho_a = params.density * params.area();
        let mut mass = vec![0.0; n];
        for (j, &l) in rest_len.iter().enumerate() {
            mass[j] += 0.5 * rho_a * l;
            mass[j + 1] += 0.5 * rho_a * l;
        }
        // Twist inertia of an edge: rho J l = m r^2 / 2.
        let twist_inertia: Vec<f64> = rest_len.iter().map(|&l| params.density * params.polar_moment() * l).collect();
        let state = State {
            x: x.clone(),
            v: vec![DVec3::ZERO; n],
            theta: vec![0.0; n - 1],
            omega: vec![0.0; n - 1],
            ref_dir,
            tangent,
            ref_twist: vec![0.0; n],
            clamp_frame: Vec::new(),
            half_twist: Vec::new(),
        };
        let ndof = 4 * n - 1;
        let mut rod = Self {
            params,
            rest_x: x,
            rest_len,
            voronoi_len,
            rest_kappa: vec![[0.0; 4]; n],
            rest_twist: vec![0.0; n],
            rest_frames,
            mass,
            twist_inertia,
            length,
            state,
            boundary: vec![Boundary::Free; n],
            pins: vec![None; n],
            clamps: Vec::new(),
            grab: None,
            geo: Geometry::default(),
            trial: Geometry::default(),
            hess: BandedMatrix::new(ndof, BANDWIDTH),
            factor: BandedMatrix::new(ndof, BANDWIDTH),
            grad: vec![0.0; ndof],
            dtheta_elastic: vec![0.0; n - 1],
            project_stretch: true,
        };
        let mut geo = Geometry::default();
        rod.geometry(&rod.state.x, &rod.state.theta, &mut geo);
        for i in 1..n - 1 {
            rod.rest_kappa[i] = energy::material_curvature(
                rod.state.x[i] - rod.state.x[i - 1],
                rod.state.x[i + 1] - rod.state.x[i],
                (geo.m1[i - 1], geo.m2[i - 1]),
                (geo.m1[i], geo.m2[i]),
            );
            rod.rest_twist[i] = geo.twist[i];
        }
        Ok(rod)
    }

    /// Number of vertices `n`.
    pub fn num_vertices(&self) -> usize {
        self.state.x.len()
    }

    /// Material parameters.
    pub fn params(&self) -> &RodParams {
        &self.params
    }

    /// Rest length of the rod (m).
    pub fn rest_length(&self) -> f64 {
        self.length
    }

    /// Rest vertex positions (the polyline the rod was built from).
    pub fn rest_positions(&self) -> &[DVec3] {
        &self.rest_x
    }

    /// Rest edge lengths (m).
    pub fn rest_lengths(&self) -> &[f64] {
        &self.rest_len
    }

    /// Lumped vertex masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }

    /// Current vertex positions (m).
    pub fn positions(&self) -> &[DVec3] {
        &self.state.x
    }

    /// Current vertex velocities (m/s).
    pub fn velocities(&self) -> &[DVec3] {
        &self.state.v
    }

    /// Twist angle of each edge's material frame relative to its reference frame (rad).
    pub fn twist_angles(&self) -> &[f64] {
        &self.state.theta
    }

    /// Internal twisting moment `GJ (m_i - m0_i) / l_i` at each interior vertex (N m) (zero at
    /// the ends).
    pub fn twisting_moment(&self) -> Vec<f64> {
        let mut geo = Geometry::default();
        let n = self.num_vertices();
        if !self.geometry(&self.state.x, &self.state.theta, &mut geo) {
            return vec![f64::NAN; n];
        }
        let gj = self.params.twist_stiffness();
        (0..n)
            .map(|i| {
                if i == 0 || i == n - 1 { 0.0 } else { gj * (geo.twist[i] - self.rest_twist[i]) / self.voronoi_len[i] }
            })
            .collect()
    }

    /// Stretch `|e| / |e_rest| - 1` of each edge.
    pub fn edge_strain(&self) -> Vec<f64> {
        self.state.x.windows(2).zip(&self.rest_len).map(|(w, &l)| (w[1] - w[0]).length() / l - 1.0).collect()
    }

    /// Boundary condition of every vertex.
    pub fn boundaries(&self) -> &[Boundary] {
        &self.boundary
    }

    /// The grabbed vertex and its target, if any.
    pub fn grabbed(&self) -> Option<(usize, DVec3)> {
        self.grab
    }

    fn check_vertex(&self, vertex: usize) -> Result<(), RodError> {
        let len = self.num_vertices();
        if vertex < len { Ok(()) } else { Err(RodError::VertexOutOfRange { vertex, len }) }
    }

    /// Sets the boundary condition of `vertex`, anchored at its current position and frame.
    pub fn set_boundary(&mut self, vertex: usize, boundary: Boundary) -> Result<(), RodError> {
        self.check_vertex(vertex)?;
        self.pins[vertex] = None;
        if let Some(k) = self.clamps.iter().position(|c| c.vertex == vertex) {
            self.clamps.remove(k);
            self.state.clamp_frame.remove(k);
            self.state.half_twist.remove(k);
        }
        match boundary {
            Boundary::Free => {}
            Boundary::Pinned => self.pins[vertex] = Some(self.state.x[vertex]),
            Boundary::Clamped => self.add_clamp(vertex),
        }
        self.boundary[vertex] = boundary;
        Ok(())
    }

    fn add_clamp(&mut self, vertex: usize) {
        let n = self.num_vertices();
        let rest_vertex_frame = vertex_rotation(&self.rest_frames, vertex);
        let now = self.edge_frames();
        let frame = vertex_rotation(&now, vertex);
        let mut halves = Vec::with_capacity(2);
        let mut twist_now = [0.0; 2];
        let sides = [(vertex > 0, vertex.wrapping_sub(1), true), (vertex + 1 < n, vertex, false)];
        for (present, edge, ghost_after) in sides {
            if !present {
                continue;
            }
            // Natural curvature and twist of the half stencil, from the rest shape.
            let rest_edge = self.rest_frames[edge];
            let ev = self.rest_x[edge + 1] - self.rest_x[edge];
            let mut half = Half { edge, ghost_after, rest_kappa: [0.0; 4], rest_twist: 0.0 };
            let rest = half_stencil(&half, ev, rest_edge, rest_vertex_frame, 0.0);
            half.rest_kappa = energy::material_curvature(rest.e, rest.f, rest.me, rest.mf);
            half.rest_twist = rest.twist;
            let ev_now = self.state.x[edge + 1] - self.state.x[edge];
            twist_now[halves.len()] = half_stencil(&half, ev_now, now[edge], frame, half.rest_twist).twist;
            halves.push(half);
        }
        self.clamps.push(Clamp {
            vertex,
            anchor_x: self.state.x[vertex],
            anchor_frame: frame,
            rotation: DMat3::IDENTITY,
            translation: DVec3::ZERO,
            halves,
        });
        self.state.clamp_frame.push(frame);
        self.state.half_twist.push(twist_now);
    }

    /// Frees `vertex`.
    pub fn free(&mut self, vertex: usize) -> Result<(), RodError> {
        self.set_boundary(vertex, Boundary::Free)
    }

    /// Pins `vertex` where it is.
    pub fn pin(&mut self, vertex: usize) -> Result<(), RodError> {
        self.set_boundary(vertex, Boundary::Pinned)
    }

    /// Pins `vertex` and moves the pin to `position` (reached over the next step).
    pub fn pin_at(&mut self, vertex: usize, position: [f64; 3]) -> Result<(), RodError> {
        let p = finite_point("pin position", position)?;
        self.set_boundary(vertex, Boundary::Pinned)?;
        self.pins[vertex] = Some(p);
        Ok(())
    }

    /// Clamps `vertex` where it is: its position and its vertex frame are held.
    pub fn clamp(&mut self, vertex: usize) -> Result<(), RodError> {
        self.set_boundary(vertex, Boundary::Clamped)
    }

    /// Moves the clamp of `vertex` rigidly: its frame when clamped is rotated by `rotation`
    /// (row-major) and the vertex translated by `translation`. Reached over the next step; turn
    /// by less than pi per step (the twist takes the nearest branch).
    pub fn move_clamp(
        &mut self,
        vertex: usize,
        rotation: [[f64; 3]; 3],
        translation: [f64; 3],
    ) -> Result<(), RodError> {
        self.check_vertex(vertex)?;
        let r = finite_rotation(rotation)?;
        let t = finite_point("clamp translation", translation)?;
        let clamp = self.clamps.iter_mut().find(|c| c.vertex == vertex).ok_or(RodError::NotClamped(vertex))?;
        clamp.rotation = r;
        clamp.translation = t;
        Ok(())
    }

    /// Twisting moment the rod exerts on the clamp of `vertex` about the clamp's tangent (N m).
    pub fn clamp_torque(&self, vertex: usize) -> Result<f64, RodError> {
        let k = self.clamps.iter().position(|c| c.vertex == vertex).ok_or(RodError::NotClamped(vertex))?;
        let mut geo = Geometry::default();
        if !self.geometry(&self.state.x, &self.state.theta, &mut geo) {
            return Ok(f64::NAN);
        }
        let mut torque = 0.0;
        for (h, half) in self.clamps[k].halves.iter().enumerate() {
            let inp = self.half_input(&self.state.x, &geo, k, h, half);
            let (_, g, _) = energy::bend_twist(&inp);
            torque -= if half.ghost_after { g[7] } else { g[6] };
        }
        Ok(torque)
    }

    /// Grabs `vertex`: from the next step on it follows `target` exactly (a hard constraint on
    /// its position; its frame stays free). Replaces any previous grab.
    pub fn grab(&mut self, vertex: usize, target: [f64; 3]) -> Result<(), RodError> {
        self.check_vertex(vertex)?;
        // a grab would move a held vertex while `boundaries` still says it is held
        if let Some(&held @ (Boundary::Pinned | Boundary::Clamped)) = self.boundary.get(vertex) {
            return Err(RodError::HeldVertex { vertex, boundary: held });
        }
        self.grab = Some((vertex, finite_point("grab target", target)?));
        Ok(())
    }

    /// Moves the grab target.
    pub fn move_grab(&mut self, target: [f64; 3]) -> Result<(), RodError> {
        let p = finite_point("grab target", target)?;
        match &mut self.grab {
            Some((_, t)) => {
                *t = p;
                Ok(())
            }
            None => Err(RodError::NotGrabbed),
        }
    }

    /// Lets go of the grabbed vertex (it keeps its velocity). No-op without a grab.
    pub fn release(&mut self) {
        self.grab = None;
    }

    /// Moves the whole rod rigidly (state, pins, clamps, grab target): `x -> R x + t`
    /// (`rotation` row-major), velocities and frames rotated. The elastic energy is unchanged.
    /// Clamps keep their current pose moved along; later `move_clamp` calls are relative to it.
    pub fn transform(&mut self, rotation: [[f64; 3]; 3], translation: [f64; 3]) -> Result<(), RodError> {
        let r = finite_rotation(rotation)?;
        let t = finite_point("translation", translation)?;
        let s = &mut self.state;
        s.x.iter_mut().for_each(|x| *x = r * *x + t);
        s.v.iter_mut().for_each(|v| *v = r * *v);
        s.ref_dir.iter_mut().for_each(|a| *a = r * *a);
        s.tangent.iter_mut().for_each(|u| *u = r * *u);
        s.clamp_frame.iter_mut().for_each(|f| *f = r * *f);
        self.pins.iter_mut().flatten().for_each(|p| *p = r * *p + t);
        for c in &mut self.clamps {
            c.anchor_x = r * (c.anchor_x + c.translation) + t;
            c.anchor_frame = r * c.rotation * c.anchor_frame;
            c.rotation = DMat3::IDENTITY;
            c.translation = DVec3::ZERO;
        }
        if let Some((_, p)) = &mut self.grab {
            *p = r * *p + t;
        }
        Ok(())
    }

    /// Sets the vertex positions (velocities zeroed); frames follow by parallel transport.
    pub fn set_positions(&mut self, positions: &[[f64; 3]]) -> Result<(), RodError> {
        let n = self.num_vertices();
        if positions.len() != n {
            return Err(RodError::LengthMismatch { what: "positions", got: positions.len(), expected: n });
        }
        let x: Vec<DVec3> = positions.iter().map(|p| DVec3::from_array(*p)).collect();
        for (i, p) in x.iter().enumerate() {
            if !p.is_finite() {
                return Err(RodError::NonFiniteVertex { vertex: i, value: p.to_array() });
            }
        }
        for j in 0..n - 1 {
            let l = (x[j + 1] - x[j]).length();
            let min_length = MIN_DEFORMED_EDGE * self.rest_len[j];
            if l.is_nan() || l <= min_length {
                return Err(RodError::DegenerateEdge { edge: j, length: l, min_length });
            }
        }
        self.state.x = x;
        self.state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        self.state.omega.iter_mut().for_each(|w| *w = 0.0);
        self.rebase();
        Ok(())
    }

    /// Sets the vertex velocities (m/s).
    pub fn set_velocities(&mut self, velocities: &[[f64; 3]]) -> Result<(), RodError> {
        let n = self.num_vertices();
        if velocities.len() != n {
            return Err(RodError::LengthMismatch { what: "velocities", got: velocities.len(), expected: n });
        }
        if let Some(v) = velocities.iter().find(|v| v.iter().any(|c| !c.is_finite())) {
            return Err(RodError::NonFiniteInput { what: "velocity", value: v.to_vec() });
        }
        self.state.v = velocities.iter().map(|v| DVec3::from_array(*v)).collect();
        Ok(())
    }

    /// Material frame of every edge as a rotation with columns `(m1, m2, t)`.
    pub fn edge_frames(&self) -> Vec<DMat3> {
        let s = &self.state;
        (0..self.num_vertices() - 1)
            .map(|j| {
                let t = s.tangent[j];
                let (m1, m2) = material_frame(s.ref_dir[j], t, s.theta[j]);
                frame_matrix(m1, m2, t)
            })
            .collect()
    }

    /// Per-vertex frames: the average of the adjacent edges' frames (one edge at the ends).
    pub fn vertex_frames(&self) -> Vec<DMat3> {
        let e = self.edge_frames();
        (0..self.num_vertices()).map(|i| vertex_rotation(&e, i)).collect()
    }

    /// Edge frames as unit quaternions.
    pub fn edge_quats(&self) -> Vec<DQuat> {
        self.edge_frames().iter().map(|m| DQuat::from_mat3(m).normalize()).collect()
    }

    /// Vertex frames as unit quaternions.
    pub fn vertex_quats(&self) -> Vec<DQuat> {
        self.vertex_frames().iter().map(|m| DQuat::from_mat3(m).normalize()).collect()
    }

    /// Energy of the current state.
    pub fn energy(&self) -> Energy {
        let mut geo = Geometry::default();
        let mut out = Energy::default();
        if !self.geometry(&self.state.x, &self.state.theta, &mut geo) {
            out.stretch = f64::INFINITY;
            return out;
        }
        let (s, b, t) = self.elastic_parts(&self.state.x, &geo);
        out.stretch = s;
        out.bend = b;
        out.twist = t;
        let g = DVec3::from_array(self.params.gravity);
        for i in 0..self.num_vertices() {
            out.kinetic += 0.5 * self.mass[i] * self.state.v[i].length_squared();
            out.gravity -= self.mass[i] * g.dot(self.state.x[i]);
        }
        for j in 0..self.num_vertices() - 1 {
            out.kinetic += 0.5 * self.twist_inertia[j] * self.state.omega[j] * self.state.omega[j];
        }
        out
    }

    /// Elastic forces `-dE/dx` on the vertices (N) and torques `-dE/dtheta` on the edges' twist
    /// (N m) in the current state (gravity and constraint reactions not included).
    pub fn forces(&mut self) -> (Vec<DVec3>, Vec<f64>) {
        let n = self.num_vertices();
        let x = std::mem::take(&mut self.state.x);
        let mut geo = std::mem::take(&mut self.geo);
        let ok = self.geometry(&x, &self.state.theta, &mut geo);
        self.grad.iter_mut().for_each(|g| *g = 0.0);
        if ok {
            self.assemble_elastic(&x, &geo, Hessian::None);
        }
        self.geo = geo;
        self.state.x = x;
        let f = (0..n)
            .map(|i| -DVec3::new(self.grad[dof_x(i)], self.grad[dof_x(i) + 1], self.grad[dof_x(i) + 2]))
            .collect();
        let tq = (0..n - 1).map(|j| -self.grad[dof_theta(j)]).collect();
        (f, tq)
    }

    // ----- geometry and energy in the chart of the current step -----

    /// Edge lengths, tangents, material frames and twists of `(x, theta)` with frames
    /// transported from the chart. Returns `false` for a degenerate configuration (a vanishing
    /// edge, a fold, a non-finite value): its energy is infinite.
    fn geometry(&self, x: &[DVec3], theta: &[f64], geo: &mut Geometry) -> bool {
        let n = x.len();
        let ne = n - 1;
        geo.len.resize(ne, 0.0);
        geo.t.resize(ne, DVec3::ZERO);
        geo.m1.resize(ne, DVec3::ZERO);
        geo.m2.resize(ne, DVec3::ZERO);
        geo.a1.resize(ne, DVec3::ZERO);
        geo.twist.resize(n, 0.0);
        geo.ref_twist.resize(n, 0.0);
        let s = &self.state;
        for j in 0..ne {
            let e = x[j + 1] - x[j];
            let l = e.length();
            if l.is_nan() || l <= MIN_DEFORMED_EDGE * self.rest_len[j] || l.is_infinite() {
                return false;
            }
            let t = e / l;
            let a = transport(s.ref_dir[j], s.tangent[j], t);
            let (m1, m2) = material_frame(a, t, theta[j]);
            geo.len[j] = l;
            geo.t[j] = t;
            geo.a1[j] = a;
            geo.m1[j] = m1;
            geo.m2[j] = m2;
        }
        for i in 1..n.saturating_sub(1) {
            let (t0, t1) = (geo.t[i - 1], geo.t[i]);
            if 1.0 + t0.dot(t1) < MIN_DEFORMED_FOLD {
                return false;
            }
            let p = transport(geo.a1[i - 1], t0, t1);
            let r = unwrap_near(signed_angle(p, geo.a1[i], t1), s.ref_twist[i]);
            geo.ref_twist[i] = r;
            geo.twist[i] = theta[i] - theta[i - 1] + r;
        }
        geo.half_twist.clear();
        for (k, c) in self.clamps.iter().enumerate() {
            let frame = s.clamp_frame[k];
            let mut tw = [0.0; 2];
            for (h, half) in c.halves.iter().enumerate() {
                let j = half.edge;
                let ghost_t = frame.z_axis;
                if 1.0 + ghost_t.dot(geo.t[j]) < MIN_DEFORMED_FOLD {
                    return false;
                }
                let edge = frame_matrix(geo.m1[j], geo.m2[j], geo.t[j]);
                tw[h] = half_stencil(half, x[j + 1] - x[j], edge, frame, s.half_twist[k][h]).twist;
            }
            geo.half_twist.push(tw);
        }
        true
    }

    fn bend_input(&self, x: &[DVec3], geo: &Geometry, i: usize) -> BendTwistInput {
        let l = self.voronoi_len[i];
        BendTwistInput {
            e: x[i] - x[i - 1],
            f: x[i + 1] - x[i],
            me: (geo.m1[i - 1], geo.m2[i - 1]),
            mf: (geo.m1[i], geo.m2[i]),
            twist: geo.twist[i],
            rest_kappa: self.rest_kappa[i],
            rest_twist: self.rest_twist[i],
            bend_k: self.params.bend_stiffness() / l,
            twist_k: self.params.twist_stiffness() / l,
        }
    }

    /// Half stencil `h` of clamp `k`: bending/twisting between the clamp frame and the edge,
    /// over half the edge's rest length.
    fn half_input(&self, x: &[DVec3], geo: &Geometry, k: usize, h: usize, half: &Half) -> BendTwistInput {
        let j = half.edge;
        let edge = frame_matrix(geo.m1[j], geo.m2[j], geo.t[j]);
        let mut inp = half_stencil(half, x[j + 1] - x[j], edge, self.state.clamp_frame[k], 0.0);
        let l = 0.5 * self.rest_len[j];
        inp.twist = geo.half_twist[k][h];
        inp.rest_kappa = half.rest_kappa;
        inp.rest_twist = half.rest_twist;
        inp.bend_k = self.params.bend_stiffness() / l;
        inp.twist_k = self.params.twist_stiffness() / l;
        inp
    }

    fn is_clamped(&self, vertex: usize) -> bool {
        self.boundary[vertex] == Boundary::Clamped
    }

    /// Stretch, bend and twist energies of a configuration whose geometry is `geo`.
    fn elastic_parts(&self, x: &[DVec3], geo: &Geometry) -> (f64, f64, f64) {
        let n = x.len();
        let ea = self.params.stretch_stiffness();
        let mut es = 0.0;
        for j in 0..n - 1 {
            let s = geo.len[j] / self.rest_len[j] - 1.0;
            es += 0.5 * ea * s * s * self.rest_len[j];
        }
        let (mut eb, mut et) = (0.0, 0.0);
        let (ei, gj) = (self.params.bend_stiffness(), self.params.twist_stiffness());
        for i in 1..n.saturating_sub(1) {
            if self.is_clamped(i) {
                continue;
            }
            let (te, tf) = (geo.t[i - 1], geo.t[i]);
            let kb = 2.0 * te.cross(tf) / (1.0 + te.dot(tf));
            let rk = &self.rest_kappa[i];
            let w = [
                kb.dot(geo.m2[i - 1]) - rk[0],
                -kb.dot(geo.m1[i - 1]) - rk[1],
                kb.dot(geo.m2[i]) - rk[2],
                -kb.dot(geo.m1[i]) - rk[3],
            ];
            let dm = geo.twist[i] - self.rest_twist[i];
            let l = self.voronoi_len[i];
            eb += 0.25 * ei / l * w.iter().map(|v| v * v).sum::<f64>();
            et += 0.5 * gj / l * dm * dm;
        }
        for (k, c) in self.clamps.iter().enumerate() {
            for (h, half) in c.halves.iter().enumerate() {
                let (b, t) = energy::bend_twist_parts(&self.half_input(x, geo, k, h, half));
                eb += b;
                et += t;
            }
        }
        (es, eb, et)
    }

    /// The potential Newton minimises: elastic + gravity (+ backward-Euler inertia and damping).
    fn potential(&self, x: &[DVec3], theta: &[f64], inertia: Option<&Inertia>, geo: &mut Geometry) -> f64 {
        if !self.geometry(x, theta, geo) {
            return f64::INFINITY;
        }
        let (s, b, t) = self.elastic_parts(x, geo);
        let mut phi = s + b + t;
        let g = DVec3::from_array(self.params.gravity);
        for i in 0..x.len() {
            phi -= self.mass[i] * g.dot(x[i]);
        }
        if let Some(inr) = inertia {
            let k = 1.0 / (2.0 * inr.h * inr.h);
            let c = inr.alpha * inr.h;
            for i in 0..x.len() {
                phi += self.mass[i]
                    * k
                    * ((x[i] - inr.x_hat[i]).length_squared() + c * (x[i] - inr.x_n[i]).length_squared());
            }
            for j in 0..theta.len() {
                let a = theta[j] - inr.th_hat[j];
                let b = theta[j] - inr.th_n[j];
                phi += self.twist_inertia[j] * k * (a * a + c * b * b);
            }
        }
        if phi.is_finite() { phi } else { f64::INFINITY }
    }

    /// Adds the elastic gradient (and Hessian when `with_hessian`) of `(x, geo)` into the
    /// workspace, including the holonomy term of the chart so that the gradient is exact.
    fn assemble_elastic(&mut self, x: &[DVec3], geo: &Geometry, hessian: Hessian) {
        let with_hessian = hessian != Hessian::None;
        let n = x.len();
        let ea = self.params.stretch_stiffness();
        self.dtheta_elastic.iter_mut().for_each(|d| *d = 0.0);
        for j in 0..n - 1 {
            let e = x[j + 1] - x[j];
            let project = self.project_stretch || hessian == Hessian::GaussNewton;
            let (_, g, h) = energy::stretch(e, self.rest_len[j], ea, project);
            let (a, b) = (dof_x(j), dof_x(j + 1));
            for r in 0..3 {
                self.grad[a + r] -= g[r];
                self.grad[b + r] += g[r];
            }
            if with_hessian {
                for r in 0..3 {
                    for c in 0..3 {
                        // Blocks (a,a) and (b,b) get +h, (b,a) gets -h.
                        if c <= r {
                            self.hess.add_lower(a + r, a + c, h[r][c]);
                            self.hess.add_lower(b + r, b + c, h[r][c]);
                        }
                        self.hess.add_lower(b + r, a + c, -h[r][c]);
                    }
                }
            }
        }
        for i in 1..n.saturating_sub(1) {
            if self.is_clamped(i) {
                continue;
            }
            let inp = self.bend_input(x, geo, i);
            let (gy, hy) = stencil_derivatives(&inp, hessian);
            self.dtheta_elastic[i - 1] += gy[6];
            self.dtheta_elastic[i] += gy[7];
            self.scatter_stencil(dof_x(i - 1), &gy, &hy, with_hessian);
        }
        for k in 0..self.clamps.len() {
            for h in 0..self.clamps[k].halves.len() {
                let half = self.clamps[k].halves[h];
                let inp = self.half_input(x, geo, k, h, &half);
                let (gy, hy) = stencil_derivatives(&inp, hessian);
                let map = if half.ghost_after { &HALF_MAP_E } else { &HALF_MAP_F };
                self.dtheta_elastic[half.edge] += if half.ghost_after { gy[6] } else { gy[7] };
                self.scatter(dof_x(half.edge), map, &gy, &hy, with_hessian);
            }
        }
        // Holonomy of the chart: away from its base tangent u, a transported frame also turns
        // about t by -kb(u, t) . dt / 2, which moves the energy like a change of theta.
        let s = &self.state;
        for j in 0..n - 1 {
            let dth = self.dtheta_elastic[j];
            if dth == 0.0 {
                continue;
            }
            let kb = curvature_binormal(s.tangent[j], geo.t[j]);
            let c = -dth * kb / (2.0 * geo.len[j]);
            for r in 0..3 {
                self.grad[dof_x(j + 1) + r] += c[r];
                self.grad[dof_x(j) + r] -= c[r];
            }
        }
    }

    /// Adds a full bending stencil's gradient and Hessian (in `y = (e, f, theta_e, theta_f)`)
    /// to its 11 consecutive unknowns from `base`: `x_{i-1}, theta_{i-1}, x_i, theta_i,
    /// x_{i+1}`, with `e = x_i - x_{i-1}` and `f = x_{i+1} - x_i` (block form of `P^T H P`).
    fn scatter_stencil(&mut self, base: usize, gy: &[f64; NV], hy: &[[f64; NV]; NV], with_hessian: bool) {
        for r in 0..3 {
            self.grad[base + r] -= gy[r];
            self.grad[base + 4 + r] += gy[r] - gy[3 + r];
            self.grad[base + 8 + r] += gy[3 + r];
        }
        self.grad[base + 3] += gy[6];
        self.grad[base + 7] += gy[7];
        if !with_hessian {
            return;
        }
        let h = &mut self.hess;
        for r in 0..3 {
            for c in 0..3 {
                let a = hy[r][c];
                let b_rc = hy[r][3 + c];
                let b_cr = hy[c][3 + r];
                let cc = hy[3 + r][3 + c];
                if c <= r {
                    h.add_lower(base + r, base + c, a);
                    h.add_lower(base + 4 + r, base + 4 + c, a - b_rc - b_cr + cc);
                    h.add_lower(base + 8 + r, base + 8 + c, cc);
                }
                h.add_lower(base + 4 + r, base + c, b_cr - a);
                h.add_lower(base + 8 + r, base + c, -b_cr);
                h.add_lower(base + 8 + r, base + 4 + c, b_cr - cc);
            }
            h.add_lower(base + 3, base + r, -hy[6][r]);
            h.add_lower(base + 4 + r, base + 3, hy[r][6] - hy[3 + r][6]);
            h.add_lower(base + 8 + r, base + 3, hy[3 + r][6]);
            h.add_lower(base + 7, base + r, -hy[7][r]);
            h.add_lower(base + 7, base + 4 + r, hy[7][r] - hy[7][3 + r]);
            h.add_lower(base + 8 + r, base + 7, hy[3 + r][7]);
        }
        h.add_lower(base + 3, base + 3, hy[6][6]);
        h.add_lower(base + 7, base + 3, hy[7][6]);
        h.add_lower(base + 7, base + 7, hy[7][7]);
    }

    /// Adds a stencil's gradient `gy` and Hessian `hy` (in its local variables `y`) to the
    /// unknowns `base..base + map.len()`, each a combination of `y` given by `map`.
    fn scatter<const L: usize>(
        &mut self,
        base: usize,
        map: &[[Option<(usize, f64)>; 2]; L],
        gy: &[f64; NV],
        hy: &[[f64; NV]; NV],
        with_hessian: bool,
    ) {
        for (l, m) in map.iter().enumerate() {
            let mut v = 0.0;
            for &(k, c) in m.iter().flatten() {
                v += c * gy[k];
            }
            self.grad[base + l] += v;
        }
        if !with_hessian {
            return;
        }
        for (l1, m1) in map.iter().enumerate() {
            for (l2, m2) in map.iter().enumerate().take(l1 + 1) {
                let mut v = 0.0;
                for &(k1, c1) in m1.iter().flatten() {
                    for &(k2, c2) in m2.iter().flatten() {
                        v += c1 * c2 * hy[k1][k2];
                    }
                }
                if v != 0.0 {
                    self.hess.add_lower(base + l1, base + l2, v);
                }
            }
        }
    }

    // ----- boundary conditions -----

    /// Prescribed positions and clamp frames at the end of the next step.
    fn targets(&self) -> Targets {
        let mut t = Targets { x: self.pins.clone(), frames: Vec::with_capacity(self.clamps.len()) };
        for c in &self.clamps {
            t.x[c.vertex] = Some(c.anchor_x + c.translation);
            t.frames.push(c.rotation * c.anchor_frame);
        }
        if let Some((i, p)) = self.grab {
            t.x[i] = Some(p);
        }
        t
    }

    /// Targets halfway between the current state and `end`.
    fn midpoint(&self, end: &Targets) -> Targets {
        let s = &self.state;
        let x = end.x.iter().enumerate().map(|(i, p)| p.map(|p| 0.5 * (s.x[i] + p))).collect();
        let frames = end
            .frames
            .iter()
            .zip(&s.clamp_frame)
            .map(|(e, now)| {
                let q0 = DQuat::from_mat3(now).normalize();
                let q1 = DQuat::from_mat3(e).normalize();
                DMat3::from_quat(average_rotation(q0, q1))
            })
            .collect();
        Targets { x, frames }
    }

    // ----- time stepping -----

    /// Advances the rod by `dt` seconds with backward Euler. A solve that does not converge
    /// within `settings.max_iterations` is rejected and retried as two half steps (constraint
    /// targets interpolated), down to `2^max_halvings` substeps; the state never becomes NaN.
    pub fn step(&mut self, dt: f64, settings: &SolverSettings) -> Result<StepReport, RodError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(RodError::InvalidTimeStep(dt));
        }
        settings.validate()?;
        let end = self.targets();
        Ok(self.advance(dt, &end, 0, settings))
    }

    fn advance(&mut self, h: f64, end: &Targets, depth: u32, settings: &SolverSettings) -> StepReport {
        let saved = self.state.clone();
        let solve = self.solve(Some(h), end, settings.max_iterations, settings.tolerance);
        if solve.converged || (depth >= settings.max_halvings && solve.finite) {
            self.commit(Some((h, &saved)));
            return StepReport {
                substeps: 1,
                newton_iterations: solve.iterations,
                rejected: 0,
                converged: solve.converged,
            };
        }
        self.state = saved;
        if depth >= settings.max_halvings {
            // Not even a finite start: keep the state, stop the motion, report it.
            self.state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
            self.state.omega.iter_mut().for_each(|w| *w = 0.0);
            return StepReport { substeps: 1, newton_iterations: solve.iterations, rejected: 1, converged: false };
        }
        let mid = self.midpoint(end);
        let first = self.advance(0.5 * h, &mid, depth + 1, settings);
        let second = self.advance(0.5 * h, end, depth + 1, settings);
        let mut r = first.merge(second);
        r.newton_iterations += solve.iterations;
        r.rejected += 1;
        r
    }

    /// Minimises the elastic + gravitational energy with the constraints held (no inertia):
    /// Newton's method with a line search, re-basing the frames after every iteration.
    /// Velocities are zeroed.
    pub fn solve_static(&mut self, settings: &SolverSettings) -> Result<StaticReport, RodError> {
        settings.validate()?;
        let end = self.targets();
        // Constraint motion is applied at once; a start of infinite energy is walked in halves.
        let mut targets = vec![end];
        for _ in 0..settings.max_halvings {
            let Some(last) = targets.last() else { break };
            if self.start_is_finite(last) {
                break;
            }
            let mid = self.midpoint(last);
            targets.push(mid);
        }
        let mut iterations = 0u32;
        let mut converged = false;
        while let Some(t) = targets.pop() {
            converged = false;
            while (iterations as usize) < settings.max_static_iterations {
                let s = self.solve(None, &t, 1, settings.tolerance);
                iterations += s.iterations.max(1);
                self.commit(None);
                if s.converged {
                    converged = true;
                    break;
                }
                if !s.finite {
                    break;
                }
            }
        }
        self.state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        self.state.omega.iter_mut().for_each(|w| *w = 0.0);
        let e = self.energy();
        Ok(StaticReport { iterations, converged, energy: e.elastic() + e.gravity })
    }

    fn start_is_finite(&mut self, t: &Targets) -> bool {
        let mut x = self.state.x.clone();
        apply_targets(t, &mut x);
        let frames = std::mem::replace(&mut self.state.clamp_frame, t.frames.clone());
        let mut geo = Geometry::default();
        let ok = self.geometry(&x, &self.state.theta, &mut geo);
        self.state.clamp_frame = frames;
        ok
    }

    /// Ends a (sub)step: velocities from the positions (dynamic) and frames re-based on the
    /// new tangents (time-parallel transport).
    fn commit(&mut self, dynamic: Option<(f64, &State)>) {
        if let Some((h, old)) = dynamic {
            let s = &mut self.state;
            for i in 0..s.x.len() {
                s.v[i] = (s.x[i] - old.x[i]) / h;
            }
            for j in 0..s.theta.len() {
                s.omega[j] = (s.theta[j] - old.theta[j]) / h;
            }
        }
        self.rebase();
    }

    /// Moves the chart to the current configuration: reference frames transported to the
    /// current tangents, reference twists recomputed. Material frames do not change.
    fn rebase(&mut self) {
        let mut geo = std::mem::take(&mut self.geo);
        let x = std::mem::take(&mut self.state.x);
        let ok = self.geometry(&x, &self.state.theta, &mut geo);
        self.state.x = x;
        if ok {
            let s = &mut self.state;
            for j in 0..s.tangent.len() {
                let t = geo.t[j];
                let a = geo.a1[j];
                s.ref_dir[j] = (a - t * t.dot(a)).normalize();
                s.tangent[j] = t;
            }
            let n = s.x.len();
            if n > 2 {
                s.ref_twist[1..n - 1].copy_from_slice(&geo.ref_twist[1..n - 1]);
            }
            s.half_twist.copy_from_slice(&geo.half_twist);
        }
        self.geo = geo;
    }

    /// Newton's method on the (incremental) potential from the current state towards the
    /// targets `end`. Leaves the last iterate in the state (chart not re-based); the clamp
    /// frames are set to their targets.
    fn solve(&mut self, h: Option<f64>, end: &Targets, max_iter: usize, tol: f64) -> Solve {
        let n = self.num_vertices();
        let ndof = 4 * n - 1;
        let mut fixed = vec![false; ndof];
        for (i, p) in end.x.iter().enumerate() {
            if p.is_some() {
                fixed[dof_x(i)..dof_x(i) + 3].iter_mut().for_each(|f| *f = true);
            }
        }
        self.state.clamp_frame.clone_from(&end.frames);
        let inertia = h.map(|h| {
            let s = &self.state;
            Inertia {
                h,
                alpha: self.params.damping,
                x_hat: s.x.iter().zip(&s.v).map(|(x, v)| *x + h * *v).collect(),
                th_hat: s.theta.iter().zip(&s.omega).map(|(t, w)| t + h * w).collect(),
                x_n: s.x.clone(),
                th_n: s.theta.clone(),
            }
        });

        // Start from the lowest of: the inertial prediction, the current state, and (when a
        // constraint moves) the current state with the constraint displacements spread along
        // the rod, all with the targets applied. The last keeps a far-moved grab from crushing
        // its neighbouring edges.
        let mut trial = std::mem::take(&mut self.trial);
        let mut best: Option<(f64, Vec<DVec3>, Vec<f64>)> = None;
        let moved = end.x.iter().zip(&self.state.x).any(|(p, x)| p.is_some_and(|p| p != *x));
        let mut starts = Vec::with_capacity(3);
        if let Some(inr) = &inertia {
            starts.push((inr.x_hat.clone(), inr.th_hat.clone()));
        }
        starts.push((self.state.x.clone(), self.state.theta.clone()));
        if moved {
            starts.push(self.spread_guess(end));
        }
        for (mut x, th) in starts {
            apply_targets(end, &mut x);
            let phi = self.potential(&x, &th, inertia.as_ref(), &mut trial);
            if phi.is_finite() && best.as_ref().is_none_or(|b| phi < b.0) {
                best = Some((phi, x, th));
            }
        }
        let Some((mut phi, mut x, mut th)) = best else {
            self.trial = trial;
            return Solve { iterations: 0, converged: false, finite: false };
        };

        let mut iterations = 0;
        let mut converged = false;
        let mut geo = std::mem::take(&mut self.geo);
        let mut dir = vec![0.0; ndof];
        let mut x_try = x.clone();
        let mut th_try = th.clone();
        // After a small full Newton step the Hessian barely changes: the next iterations reuse
        // its factorisation (chord steps, gradient only) while they keep contracting.
        let mut reuse = false;
        let mut last_size = f64::INFINITY;
        while (iterations as usize) < max_iter {
            iterations += 1;
            if !self.geometry(&x, &th, &mut geo) {
                break;
            }
            let fresh = !reuse;
            if fresh {
                // Exact Hessian; where it is indefinite (sharp folds), the positive semidefinite
                // Gauss-Newton one, then growing diagonal shifts.
                self.assemble_system(&x, &th, &geo, inertia.as_ref(), &fixed, Hessian::Exact);
                if !self.newton_direction(&mut dir, false) {
                    self.assemble_system(&x, &th, &geo, inertia.as_ref(), &fixed, Hessian::GaussNewton);
                    if !self.newton_direction(&mut dir, true) {
                        break;
                    }
                }
            } else {
                self.assemble_system(&x, &th, &geo, inertia.as_ref(), &fixed, Hessian::None);
                for (d, g) in dir.iter_mut().zip(&self.grad) {
                    *d = -g;
                }
                self.factor.solve_in_place(&mut dir);
            }
            let mut max_dx: f64 = 0.0;
            let mut max_dth: f64 = 0.0;
            for i in 0..n {
                for r in 0..3 {
                    max_dx = max_dx.max(dir[dof_x(i) + r].abs());
                }
            }
            for j in 0..n - 1 {
                max_dth = max_dth.max(dir[dof_theta(j)].abs());
            }
            // Step size relative to the rod length (positions) and in radians (twist).
            let size = (max_dx / self.length).max(max_dth);
            let small = size <= tol;
            // Backtracking line search on the potential (Armijo).
            let slope: f64 = dir.iter().zip(&self.grad).map(|(d, g)| d * g).sum();
            let mut alpha = 1.0;
            let mut accepted = false;
            if small {
                // Below tolerance: take it as is, no line search needed.
                for i in 0..n {
                    x[i] += DVec3::new(dir[dof_x(i)], dir[dof_x(i) + 1], dir[dof_x(i) + 2]);
                }
                for j in 0..n - 1 {
                    th[j] += dir[dof_theta(j)];
                }
                converged = true;
                break;
            }
            for _ in 0..MAX_BACKTRACKS {
                for i in 0..n {
                    x_try[i] = x[i] + alpha * DVec3::new(dir[dof_x(i)], dir[dof_x(i) + 1], dir[dof_x(i) + 2]);
                }
                for j in 0..n - 1 {
                    th_try[j] = th[j] + alpha * dir[dof_theta(j)];
                }
                let p = self.potential(&x_try, &th_try, inertia.as_ref(), &mut trial);
                if p <= phi + ARMIJO * alpha * slope.min(0.0) {
                    phi = p;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if accepted {
                std::mem::swap(&mut x, &mut x_try);
                std::mem::swap(&mut th, &mut th_try);
            }
            if !accepted {
                if fresh {
                    break;
                }
                // A chord step that does not descend: retry with a fresh Hessian.
                reuse = false;
                continue;
            }
            reuse = alpha == 1.0 && if fresh { size < CHORD_AFTER } else { size < CHORD_CONTRACTION * last_size };
            last_size = size;
        }
        self.geo = geo;
        self.trial = trial;
        self.state.x = x;
        self.state.theta = th;
        Solve { iterations, converged, finite: true }
    }

    /// Gradient (and Hessian as asked) of the potential at `(x, th)` into the workspace, with
    /// the fixed unknowns' rows and columns replaced by the identity's.
    fn assemble_system(
        &mut self,
        x: &[DVec3],
        th: &[f64],
        geo: &Geometry,
        inertia: Option<&Inertia>,
        fixed: &[bool],
        hessian: Hessian,
    ) {
        let n = x.len();
        let with_hessian = hessian != Hessian::None;
        self.grad.iter_mut().for_each(|g| *g = 0.0);
        if with_hessian {
            self.hess.clear();
        }
        self.assemble_elastic(x, geo, hessian);
        let gvec = DVec3::from_array(self.params.gravity);
        for i in 0..n {
            for r in 0..3 {
                self.grad[dof_x(i) + r] -= self.mass[i] * gvec[r];
            }
        }
        if let Some(inr) = inertia {
            let k = 1.0 / (inr.h * inr.h);
            let c = inr.alpha * inr.h;
            for i in 0..n {
                let g = self.mass[i] * k * ((x[i] - inr.x_hat[i]) + c * (x[i] - inr.x_n[i]));
                for r in 0..3 {
                    self.grad[dof_x(i) + r] += g[r];
                    if with_hessian {
                        self.hess.add_diag(dof_x(i) + r, self.mass[i] * k * (1.0 + c));
                    }
                }
            }
            for j in 0..n - 1 {
                let g = self.twist_inertia[j] * k * ((th[j] - inr.th_hat[j]) + c * (th[j] - inr.th_n[j]));
                self.grad[dof_theta(j)] += g;
                if with_hessian {
                    self.hess.add_diag(dof_theta(j), self.twist_inertia[j] * k * (1.0 + c));
                }
            }
        }
        for (d, &f) in fixed.iter().enumerate() {
            if f {
                if with_hessian {
                    self.hess.fix(d);
                }
                self.grad[d] = 0.0;
            }
        }
    }

    /// Solves `H d = -g` for the assembled system. With `shift`, adds a growing diagonal
    /// shift until the factorisation is positive definite; without, fails if it is not.
    fn newton_direction(&mut self, dir: &mut [f64], shift: bool) -> bool {
        let ndof = dir.len();
        let max_diag = (0..ndof).map(|i| self.hess.diag(i).abs()).fold(0.0, f64::max);
        let floor = 1.0e-12 * max_diag.max(f64::MIN_POSITIVE);
        let mut mu = 0.0;
        for _ in 0..if shift { 12 } else { 1 } {
            self.factor.clone_from(&self.hess);
            if mu > 0.0 {
                for i in 0..ndof {
                    let d = self.factor.diag(i).abs();
                    self.factor.add_diag(i, mu * (d + floor));
                }
            }
            if self.factor.factorize(1.0e-13).is_ok() {
                for i in 0..ndof {
                    dir[i] = -self.grad[i];
                }
                self.factor.solve_in_place(dir);
                if dir.iter().all(|d| d.is_finite()) {
                    return true;
                }
            }
            mu = if mu == 0.0 { 1.0e-8 } else { mu * 10.0 };
        }
        false
    }

    /// The current state with each constrained vertex's displacement to its target spread
    /// linearly over the free vertices between constrained ones.
    fn spread_guess(&self, end: &Targets) -> (Vec<DVec3>, Vec<f64>) {
        let s = &self.state;
        let n = s.x.len();
        let disp: Vec<Option<DVec3>> = (0..n).map(|i| end.x[i].map(|p| p - s.x[i])).collect();
        let known: Vec<usize> = (0..n).filter(|&i| disp[i].is_some()).collect();
        let mut x = s.x.clone();
        for (i, xi) in x.iter_mut().enumerate() {
            let d = match known.binary_search(&i) {
                Ok(k) => disp[known[k]],
                Err(k) => {
                    let left = if k > 0 { Some(known[k - 1]) } else { None };
                    match (left, known.get(k).copied()) {
                        (Some(a), Some(b)) => {
                            let w = (i - a) as f64 / (b - a) as f64;
                            Some(disp[a].unwrap_or_default() * (1.0 - w) + disp[b].unwrap_or_default() * w)
                        }
                        (Some(a), None) => disp[a],
                        (None, Some(b)) => disp[b],
                        (None, None) => None,
                    }
                }
            };
            *xi += d.unwrap_or_default();
        }
        (x, s.theta.clone())
    }
}

/// What `assemble_elastic` computes besides the gradient.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Hessian {
    None,
    /// The exact Hessian (stretching projected, see [`ElasticRod::project_stretch`]).
    Exact,
    /// Positive semidefinite: Gauss-Newton bending/twisting, projected stretching.
    GaussNewton,
}

/// Gradient, and Hessian as asked (zero otherwise), of a bending/twisting stencil.
fn stencil_derivatives(inp: &BendTwistInput, hessian: Hessian) -> ([f64; NV], [[f64; NV]; NV]) {
    match hessian {
        Hessian::Exact => {
            let (_, g, h) = energy::bend_twist(inp);
            (g, h)
        }
        Hessian::GaussNewton => {
            let (_, g, h) = energy::bend_twist_gauss_newton(inp, true);
            (g, h)
        }
        Hessian::None => (energy::bend_twist_gradient(inp).1, [[0.0; NV]; NV]),
    }
}

/// The 7 unknowns of an edge (`x_j`, `theta_j`, `x_{j+1}`) in a half stencil whose real edge
/// is `e` (the clamp frame plays `f`).
const HALF_MAP_E: [[Option<(usize, f64)>; 2]; 7] = [
    [Some((0, -1.0)), None],
    [Some((1, -1.0)), None],
    [Some((2, -1.0)), None],
    [Some((6, 1.0)), None],
    [Some((0, 1.0)), None],
    [Some((1, 1.0)), None],
    [Some((2, 1.0)), None],
];

/// As [`HALF_MAP_E`] with the real edge playing `f` (the clamp frame plays `e`).
const HALF_MAP_F: [[Option<(usize, f64)>; 2]; 7] = [
    [Some((3, -1.0)), None],
    [Some((4, -1.0)), None],
    [Some((5, -1.0)), None],
    [Some((7, 1.0)), None],
    [Some((3, 1.0)), None],
    [Some((4, 1.0)), None],
    [Some((5, 1.0)), None],
];

/// Stencil between an edge (vector `ev`, material frame `edge`) and a clamp frame. The clamp
/// acts as a virtual edge along its tangent; the twist is the angle from the transported
/// director of the first to that of the second, on the branch nearest `near`. Stiffnesses and
/// rest values are left zero.
fn half_stencil(half: &Half, ev: DVec3, edge: DMat3, clamp: DMat3, near: f64) -> BendTwistInput {
    let gv = clamp.z_axis * ev.length();
    let (first, second) = if half.ghost_after { (edge, clamp) } else { (clamp, edge) };
    let (e, f) = if half.ghost_after { (ev, gv) } else { (gv, ev) };
    let p = transport(first.x_axis, first.z_axis, second.z_axis);
    let twist = unwrap_near(signed_angle(p, second.x_axis, second.z_axis), near);
    BendTwistInput {
        e,
        f,
        me: (first.x_axis, first.y_axis),
        mf: (second.x_axis, second.y_axis),
        twist,
        rest_kappa: [0.0; 4],
        rest_twist: 0.0,
        bend_k: 0.0,
        twist_k: 0.0,
    }
}

/// Rotation of vertex `i`: the average of its edges' frames (one edge at the ends).
fn vertex_rotation(edge_frames: &[DMat3], i: usize) -> DMat3 {
    let ne = edge_frames.len();
    let q = |j: usize| DQuat::from_mat3(&edge_frames[j]).normalize();
    let r = if i == 0 {
        q(0)
    } else if i >= ne {
        q(ne - 1)
    } else {
        average_rotation(q(i - 1), q(i))
    };
    DMat3::from_quat(r)
}

fn apply_targets(t: &Targets, x: &mut [DVec3]) {
    for (xi, p) in x.iter_mut().zip(&t.x) {
        if let Some(p) = p {
            *xi = *p;
        }
    }
}

fn finite_point(what: &'static str, p: [f64; 3]) -> Result<DVec3, RodError> {
    if p.iter().all(|c| c.is_finite()) {
        Ok(DVec3::from_array(p))
    } else {
        Err(RodError::NonFiniteInput { what, value: p.to_vec() })
    }
}

/// Row-major 3x3 rotation, checked orthonormal and re-orthonormalised.
fn finite_rotation(r: [[f64; 3]; 3]) -> Result<DMat3, RodError> {
    let flat: Vec<f64> = r.iter().flatten().copied().collect();
    if flat.iter().any(|c| !c.is_finite()) {
        return Err(RodError::NonFiniteInput { what: "rotation", value: flat });
    }
    let m = DMat3::from_cols_array_2d(&r).transpose();
    let off = (m * m.transpose() - DMat3::IDENTITY).to_cols_array();
    let deviation = off.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    if (m.determinant() - 1.0).abs() > 1.0e-6 || deviation > 1.0e-6 {
        return Err(RodError::NotARotation { deviation, determinant: m.determinant() });
    }
    Ok(DMat3::from_quat(DQuat::from_mat3(&m).normalize()))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;
    use crate::test_rng::lcg;

    /// A curved, twisted test rod with gravity, perturbed away from rest.
    fn test_rod(seed: &mut u64) -> ElasticRod {
        let poly: Vec<[f64; 3]> = (0..7)
            .map(|i| {
                let s = i as f64 * 0.6;
                [s.cos(), s.sin(), 0.2 * s]
            })
            .collect();
        // Light and stiff so that elastic terms dominate the inertia terms being checked.
        let params = RodParams {
            radius: 0.05,
            youngs_modulus: 1.0e5,
            density: 1.0,
            gravity: [0.0, 0.0, -9.8],
            ..RodParams::default()
        };
        let mut rod = ElasticRod::new(&poly, params).unwrap();
        // Clamps at an end and inside, so that their half stencils are checked too.
        rod.clamp(0).unwrap();
        rod.clamp(3).unwrap();
        let x: Vec<[f64; 3]> = rod
            .positions()
            .iter()
            .map(|p| (*p + 0.05 * DVec3::new(lcg(seed), lcg(seed), lcg(seed))).to_array())
            .collect();
        rod.set_positions(&x).unwrap();
        for t in rod.state.theta.iter_mut() {
            *t = 0.3 * lcg(seed);
        }
        for v in rod.state.v.iter_mut() {
            *v = DVec3::new(lcg(seed), lcg(seed), lcg(seed));
        }
        rod
    }

    fn pack(rod: &ElasticRod, x: &[DVec3], th: &[f64]) -> Vec<f64> {
        let n = rod.num_vertices();
        let mut q = vec![0.0; 4 * n - 1];
        for i in 0..n {
            for r in 0..3 {
                q[dof_x(i) + r] = x[i][r];
            }
        }
        for j in 0..n - 1 {
            q[dof_theta(j)] = th[j];
        }
        q
    }

    fn unpack(rod: &ElasticRod, q: &[f64]) -> (Vec<DVec3>, Vec<f64>) {
        let n = rod.num_vertices();
        let x = (0..n).map(|i| DVec3::new(q[dof_x(i)], q[dof_x(i) + 1], q[dof_x(i) + 2])).collect();
        let th = (0..n - 1).map(|j| q[dof_theta(j)]).collect();
        (x, th)
    }

    fn inertia(rod: &ElasticRod, h: f64) -> Inertia {
        let s = &rod.state;
        Inertia {
            h,
            alpha: 0.7,
            x_hat: s.x.iter().zip(&s.v).map(|(x, v)| *x + h * *v).collect(),
            th_hat: s.theta.clone(),
            x_n: s.x.clone(),
            th_n: s.theta.clone(),
        }
    }

    /// Gradient of the potential as `solve` assembles it.
    fn assembled(rod: &mut ElasticRod, q: &[f64], inr: &Inertia) -> (Vec<f64>, BandedMatrix) {
        let (x, th) = unpack(rod, q);
        let n = rod.num_vertices();
        let mut geo = Geometry::default();
        assert!(rod.geometry(&x, &th, &mut geo));
        rod.grad.iter_mut().for_each(|g| *g = 0.0);
        rod.hess.clear();
        rod.assemble_elastic(&x, &geo, Hessian::Exact);
        let g = DVec3::from_array(rod.params.gravity);
        let k = 1.0 / (inr.h * inr.h);
        let c = inr.alpha * inr.h;
        for i in 0..n {
            let gi = rod.mass[i] * k * ((x[i] - inr.x_hat[i]) + c * (x[i] - inr.x_n[i])) - rod.mass[i] * g;
            for r in 0..3 {
                rod.grad[dof_x(i) + r] += gi[r];
                rod.hess.add_diag(dof_x(i) + r, rod.mass[i] * k * (1.0 + c));
            }
        }
        for j in 0..n - 1 {
            rod.grad[dof_theta(j)] += rod.twist_inertia[j] * k * ((th[j] - inr.th_hat[j]) + c * (th[j] - inr.th_n[j]));
            rod.hess.add_diag(dof_theta(j), rod.twist_inertia[j] * k * (1.0 + c));
        }
        (rod.grad.clone(), rod.hess.clone())
    }

    fn phi(rod: &ElasticRod, q: &[f64], inr: &Inertia) -> f64 {
        let (x, th) = unpack(rod, q);
        let mut geo = Geometry::default();
        rod.potential(&x, &th, Some(inr), &mut geo)
    }

    #[test]
    fn rod_gradient_matches_finite_differences_at_and_away_from_the_chart_base() {
        let mut seed = 3;
        let mut rod = test_rod(&mut seed);
        let inr = inertia(&rod, 0.5);
        let q0 = pack(&rod, &rod.state.x, &rod.state.theta);
        // Away from the base the holonomy term matters: move every unknown.
        let q1: Vec<f64> = q0.iter().map(|v| v + 0.08 * lcg(&mut seed)).collect();
        for q in [q0, q1] {
            let (g, _) = assembled(&mut rod, &q, &inr);
            let h = 1e-6;
            for d in 0..q.len() {
                let mut qp = q.clone();
                qp[d] += h;
                let mut qm = q.clone();
                qm[d] -= h;
                let fd = (phi(&rod, &qp, &inr) - phi(&rod, &qm, &inr)) / (2.0 * h);
                assert!((fd - g[d]).abs() < 1e-5 * (1.0 + g[d].abs()), "dof {d}: fd {fd} vs {}", g[d]);
            }
        }
    }

    #[test]
    fn rod_hessian_matches_second_differences_at_the_chart_base() {
        let mut seed = 11;
        let mut rod = test_rod(&mut seed);
        let inr = inertia(&rod, 0.5);
        let q = pack(&rod, &rod.state.x, &rod.state.theta);
        rod.project_stretch = false;
        let (_, hm) = assembled(&mut rod, &q, &inr);
        let h = 1e-4;
        for _ in 0..40 {
            let u: Vec<f64> = q.iter().map(|_| lcg(&mut seed)).collect();
            let w: Vec<f64> = q.iter().map(|_| lcg(&mut seed)).collect();
            let at = |a: f64, b: f64| {
                let p: Vec<f64> = (0..q.len()).map(|k| q[k] + a * u[k] + b * w[k]).collect();
                phi(&rod, &p, &inr)
            };
            let fd = (at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4.0 * h * h);
            let hw = hm.mul_vec(&w);
            let an: f64 = u.iter().zip(&hw).map(|(a, b)| a * b).sum();
            assert!((fd - an).abs() < 1e-4 * (1.0 + an.abs()), "u^T H w: fd {fd} vs {an}");
        }
    }
}
