//! Discrete elastic rods (Bergou et al. 2008, *Discrete Elastic Rods*; 2010, *Discrete Viscous
//! Threads*) for SketchRodGS: the extracted polyline becomes a rod the user pulls and releases.
//!
//! * Energy: stretching `EA/2 (|e|/|e0| - 1)^2 |e0|`; bending `EI/(4 l_i) sum_j |w_i^j -
//!   w0_i^j|^2` with the material curvatures `w_i^j = (kb_i . m2^j, -kb_i . m1^j)` of vertex `i`
//!   in each adjacent edge's frame `j` (Bergou 2008) and the rest polyline's curvature as
//!   natural shape; twisting `GJ/(2 l_i) (m_i - m0_i)^2` with reference twist. (Curvatures in the
//!   averaged frame would let bending pull on twist at sharp bends, an indefinite Hessian.)
//! * Unknowns: 3 per vertex and 1 twist angle per edge; material frames follow the edges by
//!   parallel transport in time, the energy's gradient includes the holonomy of that chart.
//! * Time stepping: backward Euler, solved by Newton's method on the banded Hessian (our own
//!   banded LDL^T, [`BandedMatrix`]) with an Armijo line search on the incremental potential.
//!   Where the exact Hessian is indefinite (a crumpling, released rod) a Gauss-Newton one is
//!   used; small steps reuse the last factorisation. A step that does not converge is retried
//!   as two half steps and reported ([`StepReport`]); the state never becomes NaN.
//! * Boundary conditions per vertex ([`Boundary`]): a clamp holds a vertex's position and frame,
//!   acting at the vertex itself (each adjacent edge bends and twists against the clamp frame
//!   over half its length), so a cantilever or a twisted rod matches beam theory to O(h^2).
//! * Grab: a hard constraint that puts the vertex exactly on the target. A spring would have to
//!   be far stiffer than `EA / h` to follow the cursor, which would dominate the Hessian; the
//!   constraint needs no stiffness and removes three unknowns instead.
//! * Contact (docs/contact.md): a stiff penalty against a signed distance field of
//!   the scene ([`DistanceField`], [`World::set_field`]) and against the capsules of other rods
//!   and of a rod's own far edges; the grab gives way to the scene ([`ContactSettings`]).
//! * Gravity that keeps the captured shape: [`ElasticRod::hold_under_gravity`] solves the rest
//!   shape whose equilibrium under gravity is the rod's current shape.
//! * SI parameters ([`RodParams`]); several rods per [`World`], stepped together.
//!
//! ```
//! use sketchrodgs_rod::{ElasticRod, RodParams, World};
//!
//! // A 1 m rubber rod of 21 vertices, clamped at both ends.
//! let polyline: Vec<[f64; 3]> = (0..21).map(|i| [i as f64 * 0.05, 0.0, 0.0]).collect();
//! let mut rod = ElasticRod::new(&polyline, RodParams::default())?;
//! rod.clamp(0)?;
//! rod.clamp(20)?;
//!
//! let mut world = World::new();
//! let id = world.add(rod);
//!
//! // Pull the middle vertex 0.3 m sideways over half a second, then let go.
//! for frame in 1..=30 {
//!     let y = 0.3 * frame as f64 / 30.0;
//!     world.rod_mut(id)?.grab(10, [0.5, y, 0.0])?;
//!     world.step(1.0 / 60.0)?;
//! }
//! let pulled = world.rod(id)?.positions()[10];
//! assert!((pulled.y - 0.3).abs() < 1e-9);
//!
//! world.rod_mut(id)?.release();
//! for _ in 0..600 {
//!     let report = world.step(1.0 / 60.0)?;
//!     assert!(report[0].converged);
//! }
//! let back = world.rod(id)?.positions()[10];
//! assert!(back.y.abs() < 1e-3);
//! # Ok::<(), sketchrodgs_rod::RodError>(())
//! ```

// Index loops over stencil and band entries read clearer than iterator chains here.
#![allow(clippy::needless_range_loop)]

mod banded;
mod contact;
mod dual;
mod energy;
mod error;
mod frames;
mod params;
mod rod;
#[cfg(test)]
mod test_rng;
mod world;

pub use banded::{BandedMatrix, NotPositiveDefinite};
pub use contact::{CONTACT_STIFFNESS, Capsule, DistanceField};
pub use error::RodError;
pub use params::{RodParams, SolverSettings};
pub use rod::{Boundary, ElasticRod, Energy, HoldReport, StaticReport, StepReport};
pub use world::{ContactSettings, World};

pub use glam::{DMat3, DQuat, DVec3};
