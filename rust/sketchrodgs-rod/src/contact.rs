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

    /// The signed distance at `p` (trilinear) and its gradient, or None outside the grid (no
    /// contact there).
    pub fn sample(&self, p: DVec3) -> Option<(f64, DVec3)> {
        let g = (p - self.origin) / self.spacing;
        let [nx, ny, nz] = self.dims;
        let inside = |v: f64, n: usize| v >= 0.0 && v <= (n - 1) as f64;
        if !(inside(g.x, nx) && inside(g.y, ny) && inside(g.z, nz)) {
            return None;
        }
        let cell = |v: f64, n: usize| (v.floor() as usize).min(n - 2);
        let (i, j, k) = (cell(g.x, nx), cell(g.y, ny), cell(g.z, nz));
        let (fx, fy, fz) = (g.x - i as f64, g.y - j as f64, g.z - k as f64);
        let at = |di: usize, dj: usize, dk: usize| f64::from(self.values[(i + di) + nx * ((j + dj) + ny * (k + dk))]);
        let corner = [
            [[at(0, 0, 0), at(0, 0, 1)], [at(0, 1, 0), at(0, 1, 1)]],
            [[at(1, 0, 0), at(1, 0, 1)], [at(1, 1, 0), at(1, 1, 1)]],
        ];
        let lerp = |a: f64, b: f64, t: f64| a + t * (b - a);
        // along z, then y, then x; the gradient from the same corners
        let c = |a: usize, b: usize| lerp(corner[a][b][0], corner[a][b][1], fz);
        let dz = |a: usize, b: usize| corner[a][b][1] - corner[a][b][0];
        let (c00, c01, c10, c11) = (c(0, 0), c(0, 1), c(1, 0), c(1, 1));
        let (c0, c1) = (lerp(c00, c01, fy), lerp(c10, c11, fy));
        let value = lerp(c0, c1, fx);
        let gx = c1 - c0;
        let gy = lerp(c01 - c00, c11 - c10, fx);
        let gz = lerp(lerp(dz(0, 0), dz(0, 1), fy), lerp(dz(1, 0), dz(1, 1), fy), fx);
        Some((value, DVec3::new(gx, gy, gz) / self.spacing))
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

/// Projection steps of [`DistanceField::push_out`]: a trilinear field is exact after one step
/// inside a cell; more reach across cells.
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

/// One penetration: its depth (> 0) and the direction that reduces it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Push {
    pub depth: f64,
    pub normal: DVec3,
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
        {
            let len = grad.length();
            if d < radius && len > 1e-12 {
                visit(Push { depth: radius - d, normal: grad / len });
            }
        }
        let own = self.own.iter().enumerate().filter(|(j, _)| j.abs_diff(edge) > self.own_skip).map(|(_, c)| c);
        for capsule in self.others.iter().chain(own) {
            let away = p - capsule.nearest(p);
            let dist = away.length();
            let reach = radius + capsule.radius;
            if dist < reach && dist > 1e-12 {
                visit(Push { depth: reach - dist, normal: away / dist });
            }
        }
    }
}
