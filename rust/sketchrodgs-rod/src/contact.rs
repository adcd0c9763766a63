//! Contact (docs/contact.md): what a rod touches enters its implicit solve as a penalty energy
//! `k/2 (r - d)^2` for each contact point closer than its radius `r` to an obstacle at distance
//! `d`. The contact points are the rod's vertices and the midpoints of its edges. Obstacles:
//!
//! * the static scene, a signed distance field on a regular grid ([`DistanceField`], negative
//!   inside), which the caller builds (sketchrodgs builds it from the scene's Gaussians);
//! * other rods, and the rod's own edges further along it: capsules ([`Capsule`]) where they are
//!   at the start of the step, set by [`crate::World::step`].
//!
//! The penalty is stiff (`CONTACT_STIFFNESS` times the stretching stiffness per unit length), so a
//! contact's penetration is a tiny fraction of the radius under any load the rod itself can carry,
//! and it is part of the potential that the Newton line search decreases, so the step stays stable.
//! The grab target is moved out of the scene before a step: contact takes precedence over the grab,
//! and a vertex dragged into a table slides on it.

use std::sync::Arc;

use glam::DVec3;

use crate::RodError;

/// The penalty stiffness of a contact, in units of the rod's stretching stiffness `EA` divided by
/// its mean rest edge length.
pub const CONTACT_STIFFNESS: f64 = 1.0e3;

/// A signed distance field on a regular grid: negative inside the scene's solid parts.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceField {
    origin: DVec3,
    spacing: f64,
    dims: [usize; 3],
    /// Signed distance at each grid node, `x` fastest, then `y`, then `z`.
    values: Vec<f32>,
}

impl DistanceField {
    /// A field with node `(i, j, k)` at `origin + spacing * (i, j, k)`; `values` holds
    /// `dims[0] * dims[1] * dims[2]` signed distances, `x` fastest.
    pub fn new(origin: [f64; 3], spacing: f64, dims: [usize; 3], values: Vec<f32>) -> Result<Self, RodError> {
        if origin.iter().any(|c| !c.is_finite()) {
            return Err(RodError::NonFiniteInput { what: "distance field origin", value: origin.to_vec() });
        }
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(RodError::InvalidField(format!("spacing must be finite and > 0, got {spacing}")));
        }
        if dims.iter().any(|&d| d < 2) {
            return Err(RodError::InvalidField(format!("needs at least 2 nodes along each axis, got {dims:?}")));
        }
        let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if count != Some(values.len()) {
            return Err(RodError::InvalidField(format!(
                "{dims:?} nodes need {} values, got {}",
                count.map_or("too many".into(), |c| c.to_string()),
                values.len()
            )));
        }
        if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
            return Err(RodError::InvalidField(format!("value {bad} is not finite")));
        }
        Ok(Self { origin: DVec3::from_array(origin), spacing, dims, values })
    }

    /// The signed distance at `p` and its gradient, or None outside the grid (no contact there).
    ///
    /// The field between nodes is the uniform cubic B-spline with the node values as coefficients
    /// (the nodes beyond the border repeat the border's): twice continuously differentiable, so the
    /// penalty's gradient has no kinks at cell faces for Newton to stall on, and exact on planes.
    pub fn sample(&self, p: DVec3) -> Option<(f64, DVec3)> {
        let g = (p - self.origin) / self.spacing;
        let [nx, ny, nz] = self.dims;
        let inside = |v: f64, n: usize| v >= 0.0 && v <= (n - 1) as f64;
        if !(inside(g.x, nx) && inside(g.y, ny) && inside(g.z, nz)) {
            return None;
        }
        let (wx, ix) = spline_weights(g.x, nx);
        let (wy, iy) = spline_weights(g.y, ny);
        let (wz, iz) = spline_weights(g.z, nz);
        let (mut value, mut grad) = (0.0, DVec3::ZERO);
        for (c, &k) in iz.iter().enumerate() {
            for (b, &j) in iy.iter().enumerate() {
                let row = nx * (j + ny * k);
                for (a, &i) in ix.iter().enumerate() {
                    let v = f64::from(self.values[row + i]);
                    let (fx, fy, fz) = (wx[0][a], wy[0][b], wz[0][c]);
                    value += v * fx * fy * fz;
                    grad += v * DVec3::new(wx[1][a] * fy * fz, fx * wy[1][b] * fz, fx * fy * wz[1][c]);
                }
            }
        }
        Some((value, grad / self.spacing))
    }

    /// `p` moved out along the field's gradient until it is at least `radius` from the surface
    /// (a few steps; where the gradient vanishes it stays).
    pub fn push_out(&self, mut p: DVec3, radius: f64) -> DVec3 {
        for _ in 0..PUSH_OUT_STEPS {
            let Some((d, grad)) = self.sample(p) else { break };
            let len = grad.length();
            if d >= radius || len < 1e-12 {
                break;
            }
            p += (radius - d) / len * (grad / len);
        }
        p
    }
}

impl DistanceField {
    /// Moving a point of radius `radius` from `from` towards `to`: where it first comes within its
    /// radius of the surface, and the surface's normal there; None when the way is clear. Marched
    /// by the clearance, at least a quarter of a grid spacing a step, then refined by bisection.
    pub fn first_contact(&self, from: DVec3, to: DVec3, radius: f64) -> Option<(DVec3, DVec3)> {
        let length = (to - from).length();
        if length <= 0.0 {
            return None;
        }
        let dir = (to - from) / length;
        let clearance = |s: f64| self.sample(from + s * dir).map_or(f64::INFINITY, |(d, _)| d - radius);
        let (mut free, mut s) = (0.0, 0.0);
        let hit = loop {
            let c = clearance(s);
            if c < 0.0 {
                break s;
            }
            if s >= length {
                return None;
            }
            free = s;
            s = (s + c.max(0.25 * self.spacing)).min(length);
        };
        let (mut lo, mut hi) = (free, hit);
        for _ in 0..BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if clearance(mid) < 0.0 { hi = mid } else { lo = mid }
        }
        let point = from + lo * dir;
        let (_, grad) = self.sample(from + hi * dir)?;
        let len = grad.length();
        (len > 1e-12).then(|| (point, grad / len))
    }
}

/// The cubic B-spline weights (values, then derivatives) of the four nodes around grid coordinate
/// `g` along an axis of `n` nodes, and those nodes (clamped to the grid).
fn spline_weights(g: f64, n: usize) -> ([[f64; 4]; 2], [usize; 4]) {
    let cell = (g.floor() as usize).min(n - 2);
    let t = g - cell as f64;
    let u = 1.0 - t;
    let (t2, t3) = (t * t, t * t * t);
    let values =
        [u * u * u / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0];
    let slopes = [-0.5 * u * u, 0.5 * (3.0 * t2 - 4.0 * t), 0.5 * (-3.0 * t2 + 2.0 * t + 1.0), 0.5 * t2];
    let node = |o: isize| (cell as isize + o).clamp(0, n as isize - 1) as usize;
    ([values, slopes], [node(-1), node(0), node(1), node(2)])
}

/// Bisection steps that place a contact along a way (to 2^-20 of a step).
const BISECTIONS: usize = 20;

/// Projection steps of [`DistanceField::push_out`] (each is exact on a plane; more follow curved
/// surfaces).
const PUSH_OUT_STEPS: usize = 8;

/// A segment with a radius: an edge of a rod.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    pub a: DVec3,
    pub b: DVec3,
    pub radius: f64,
}

impl Capsule {
    /// The point of the segment nearest `p`.
    pub(crate) fn nearest(&self, p: DVec3) -> DVec3 {
        let ab = self.b - self.a;
        let len2 = ab.length_squared();
        let t = if len2 > 0.0 { ((p - self.a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
        self.a + t * ab
    }
}

/// The parameters `(s, t)` of the closest points of segments `p0 p1` and `q0 q1` (clamped to
/// the segments; Ericson, *Real-Time Collision Detection*, 5.1.9).
pub(crate) fn closest_parameters(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> (f64, f64) {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    if a <= 1e-300 && e <= 1e-300 {
        return (0.0, 0.0);
    }
    if a <= 1e-300 {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(r);
    if e <= 1e-300 {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(d2);
    let denom = a * e - b * b;
    let mut s = if denom > 1e-300 { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (s, t)
}

/// What one rod touches during a step.
#[derive(Debug, Clone, Default)]
pub(crate) struct Obstacles {
    pub field: Option<Arc<DistanceField>>,
    /// Other rods' edges.
    pub others: Vec<Capsule>,
    /// The rod's own edges (edge `j` at index `j`), where self-contact is on.
    pub own: Vec<Capsule>,
    /// Own edges within this many edges of a contact point's edge are its neighbours, not obstacles.
    pub own_skip: usize,
}

/// One penetration: its depth (> 0) and the gradient of the distance it is measured by (the
/// direction that reduces the depth; unit length for a capsule, about so for the field). The
/// penalty's gradient and Hessian use this gradient as it is, so that they are those of the energy
/// the line search measures.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Push {
    pub depth: f64,
    pub gradient: DVec3,
}

impl Obstacles {
    pub fn is_empty(&self) -> bool {
        self.field.is_none() && self.others.is_empty() && self.own.is_empty()
    }

    /// The penetrations of a contact point at `p` of radius `radius`, on edge `edge` of its rod
    /// (for self-contact), handed to `visit`.
    pub fn each_push(&self, p: DVec3, radius: f64, edge: usize, mut visit: impl FnMut(Push)) {
        if let Some(field) = &self.field
            && let Some((d, grad)) = field.sample(p)
            && d < radius
            && grad.length_squared() > 1e-24
        {
            visit(Push { depth: radius - d, gradient: grad });
        }
        let own = self.own.iter().enumerate().filter(|(j, _)| j.abs_diff(edge) > self.own_skip).map(|(_, c)| c);
        for capsule in self.others.iter().chain(own) {
            let away = p - capsule.nearest(p);
            let dist = away.length();
            let reach = radius + capsule.radius;
            if dist < reach && dist > 1e-12 {
                visit(Push { depth: reach - dist, gradient: away / dist });
            }
        }
    }
}
