//! Errors of the rod crate. Bad input is reported with its context; a simulation step that
//! cannot converge is not an error (see [`crate::StepReport`]), it is retried and reported.

use thiserror::Error;

/// Everything that can go wrong when building or driving a rod.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RodError {
    /// The polyline has fewer than 2 vertices.
    #[error("a rod needs at least 2 vertices, got {0}")]
    TooFewVertices(usize),
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {value:?}")]
    NonFiniteVertex { vertex: usize, value: [f64; 3] },
    /// Two consecutive vertices coincide (or nearly): the edge has no direction.
    #[error(
        "edge {edge} (vertices {edge} and {next}) has length {length:.3e}, below {min_length:.3e}; merge coincident vertices first",
        next = edge + 1
    )]
    DegenerateEdge { edge: usize, length: f64, min_length: f64 },
    /// An edge longer than a float can hold (coordinates near the float range).
    #[error("edge {edge} has an infinite length: the coordinates are too large")]
    EdgeTooLong { edge: usize },
    /// A rotation given as a matrix that is not one.
    #[error(
        "rotation: not a rotation matrix (largest entry of R Rᵀ - I is {deviation:.3e}, det {determinant:.6}); give an orthonormal matrix with det 1"
    )]
    NotARotation { deviation: f64, determinant: f64 },
    /// A grab on a pinned or clamped vertex.
    #[error("vertex {vertex} is {}: set it free before grabbing it", if matches!(boundary, crate::Boundary::Pinned) { "pinned" } else { "clamped" })]
    HeldVertex { vertex: usize, boundary: crate::Boundary },
    /// Two consecutive edges of the rest polyline point in opposite directions.
    #[error("vertex {vertex} folds the polyline back on itself (turning angle ~180 degrees)")]
    FoldedVertex { vertex: usize },
    /// A material or solver parameter is out of range.
    #[error("parameter `{name}` = {value:?} is invalid: {reason}")]
    InvalidParameter { name: &'static str, value: f64, reason: &'static str },
    /// A vertex index past the end of the rod.
    #[error("vertex {vertex} is out of range for a rod of {len} vertices")]
    VertexOutOfRange { vertex: usize, len: usize },
    /// A rod index past the end of the world.
    #[error("rod {rod} is out of range for a world of {len} rods")]
    RodOutOfRange { rod: usize, len: usize },
    /// A target point or transform with NaN or infinite entries.
    #[error("{what} is not finite: {value:?}")]
    NonFiniteInput { what: &'static str, value: Vec<f64> },
    /// `move_grab` or similar without an active grab.
    #[error("no vertex is grabbed")]
    NotGrabbed,
    /// `move_clamp` on a vertex that is not clamped.
    #[error("vertex {0} is not clamped")]
    NotClamped(usize),
    /// The time step is not a positive finite number.
    #[error("time step {0} must be positive and finite")]
    InvalidTimeStep(f64),
    /// No rest shape holds the rod's shape under gravity with its boundary conditions.
    #[error(
        "no rest shape holds this rod's shape under gravity: its equilibrium stays {:.2} radii away; its pins and clamps cannot carry its weight (clamp an end, or turn gravity off)",
        deviation / radius
    )]
    CannotHold { deviation: f64, radius: f64 },
    /// A distance field that cannot be used.
    #[error("distance field: {0}")]
    InvalidField(String),
    /// A state array of the wrong length.
    #[error("{what} has {got} entries, expected {expected}")]
    LengthMismatch { what: &'static str, got: usize, expected: usize },
}
