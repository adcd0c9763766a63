//! One discrete elastic rod: rest shape, state, boundary conditions and the implicit solver.

use crate::banded::BandedMatrix;
use crate::contact::Obstacles;
use crate::dual::NV;
use crate::energy::{self, BendTwistInput};
use crate::frames::{
    average_rotation, curvature_binormal, frame_matrix, material_frame, perpendicular, signed_angle, transport,
    unwrap_near, vertex_rotation,
};
use crate::{RodError, RodParams, SolverSettings};
use glam::{DMat3, DQuat, DVec3};

mod assembly;
mod constraints;
mod contacts;
mod hold;
mod solve;

pub use hold::HoldReport;

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
    /// What the rod touches during the current step (docs/contact.md), and the penalty stiffness.
    obstacles: Obstacles,
    contact_stiffness: f64,
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
        // per unit of mean edge length, so that a contact outweighs the rod's own stretching
        let contact_stiffness =
            crate::contact::CONTACT_STIFFNESS * params.stretch_stiffness() * (n - 1) as f64 / length;
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
            obstacles: Obstacles::default(),
            contact_stiffness,
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
}
