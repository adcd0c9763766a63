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
        Some(self.spline(g))
    }

    /// [`Self::sample`] where the distance at `p` may be under `within`; None where it is surely
    /// not (or `p` is outside the grid). One node read decides for most points: the spline mixes
    /// nodes at most 2 cells from the nearest one, and node values, distances, differ by at most
    /// their distance apart.
    pub fn sample_within(&self, p: DVec3, within: f64) -> Option<(f64, DVec3)> {
        self.near_surface(p, within).map(|g| self.spline(g))
    }

    /// The distance alone where it may be under `within` (as [`Self::sample_within`]): the line
    /// search's energies need no gradient.
    pub fn value_within(&self, p: DVec3, within: f64) -> Option<f64> {
        self.near_surface(p, within).map(|g| self.spline_value(g))
    }

    /// The grid coordinates of `p` where the distance there may be under `within`.
    fn near_surface(&self, p: DVec3, within: f64) -> Option<DVec3> {
        let g = (p - self.origin) / self.spacing;
        let [nx, ny, nz] = self.dims;
        let inside = |v: f64, n: usize| v >= 0.0 && v <= (n - 1) as f64;
        if !(inside(g.x, nx) && inside(g.y, ny) && inside(g.z, nz)) {
            return None;
        }
        let node = |v: f64| (v + 0.5) as usize; // rounded: v >= 0
        let nearest = f64::from(self.values[node(g.x) + nx * (node(g.y) + ny * node(g.z))]);
        (nearest - SPLINE_REACH * self.spacing < within).then_some(g)
    }

    /// The spline's value alone at grid coordinates `g` (inside the grid).
    fn spline_value(&self, g: DVec3) -> f64 {
        let [nx, ny, nz] = self.dims;
        let (wx, ix) = spline_weights(g.x, nx);
        let (wy, iy) = spline_weights(g.y, ny);
        let (wz, iz) = spline_weights(g.z, nz);
        let mut value = 0.0;
        for (c, &k) in iz.iter().enumerate() {
            let mut plane = 0.0;
            for (b, &j) in iy.iter().enumerate() {
                let row = &self.values[nx * (j + ny * k)..];
                let line: f64 = ix.iter().zip(&wx[0]).map(|(&i, w)| f64::from(row[i]) * w).sum();
                plane += line * wy[0][b];
            }
            value += plane * wz[0][c];
        }
        value
    }

    /// The spline's value and gradient at grid coordinates `g` (inside the grid).
    fn spline(&self, g: DVec3) -> (f64, DVec3) {
        let [nx, ny, nz] = self.dims;
        let (wx, ix) = spline_weights(g.x, nx);
        let (wy, iy) = spline_weights(g.y, ny);
        let (wz, iz) = spline_weights(g.z, nz);
        // separably: along x (value and slope) for each of the 4x4 rows, then y, then z
        let (mut value, mut grad) = (0.0, DVec3::ZERO);
        for (c, &k) in iz.iter().enumerate() {
            let (mut v0, mut vx, mut vy) = (0.0, 0.0, 0.0);
            for (b, &j) in iy.iter().enumerate() {
                let row = &self.values[nx * (j + ny * k)..];
                let (mut s0, mut s1) = (0.0, 0.0);
                for (a, &i) in ix.iter().enumerate() {
                    let v = f64::from(row[i]);
                    s0 += v * wx[0][a];
                    s1 += v * wx[1][a];
                }
                v0 += s0 * wy[0][b];
                vx += s1 * wy[0][b];
                vy += s0 * wy[1][b];
            }
            value += v0 * wz[0][c];
            grad += DVec3::new(vx * wz[0][c], vy * wz[0][c], v0 * wz[1][c]);
        }
        (value, grad / self.spacing)
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
        // the length taken on the step scaled to its largest coordinate: a step of 1e300 (a grab
        // target that far) squares to infinity, and the march along a zero direction never ended
        let scale = (to - from).abs().max_element();
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let unit = (to - from) / scale;
        let unit_length = unit.length();
        let (length, dir) = (scale * unit_length, unit / unit_length);
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
    let cell = (g as usize).min(n - 2); // floor: g >= 0
    let t = g - cell as f64;
    let u = 1.0 - t;
    let (t2, t3) = (t * t, t * t * t);
    let values =
        [u * u * u / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0];
    let slopes = [-0.5 * u * u, 0.5 * (3.0 * t2 - 4.0 * t), 0.5 * (-3.0 * t2 + 2.0 * t + 1.0), 0.5 * t2];
    let node = |o: isize| (cell as isize + o).clamp(0, n as isize - 1) as usize;
    ([values, slopes], [node(-1), node(0), node(1), node(2)])
}

/// How far (in cells) the nodes a spline value mixes lie from the nearest node: up to 2 cells along
/// each axis, so at most 2√3 < 3.5.
const SPLINE_REACH: f64 = 3.5;

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

/// Capsules with a bounding-box hierarchy over their order (a rod's consecutive edges lie close
/// together, so halving the sequence halves space well): finding what lies near a point visits
/// O(log n) boxes instead of every capsule, which makes rod–rod contact affordable at n = 1000.
#[derive(Debug, Clone, Default)]
pub(crate) struct CapsuleTree {
    capsules: Vec<Capsule>,
    /// Node `k`: the box around capsules `start..end`, and its children (none for a leaf).
    nodes: Vec<TreeNode>,
}

#[derive(Debug, Clone, Copy)]
struct TreeNode {
    low: DVec3,
    high: DVec3,
    start: usize,
    end: usize,
    children: Option<(usize, usize)>,
}

/// Capsules per leaf of a [`CapsuleTree`].
const LEAF: usize = 8;

impl CapsuleTree {
    pub fn new(capsules: Vec<Capsule>) -> Self {
        let mut tree = Self { capsules, nodes: Vec::new() };
        if !tree.capsules.is_empty() {
            tree.build(0, tree.capsules.len());
        }
        tree
    }

    pub fn is_empty(&self) -> bool {
        self.capsules.is_empty()
    }

    /// Adds the node over `start..end` and its subtree; returns its index.
    fn build(&mut self, start: usize, end: usize) -> usize {
        let (mut low, mut high) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for c in &self.capsules[start..end] {
            low = low.min(c.a.min(c.b) - DVec3::splat(c.radius));
            high = high.max(c.a.max(c.b) + DVec3::splat(c.radius));
        }
        let index = self.nodes.len();
        self.nodes.push(TreeNode { low, high, start, end, children: None });
        if end - start > LEAF {
            let mid = start + (end - start) / 2;
            let left = self.build(start, mid);
            let right = self.build(mid, end);
            self.nodes[index].children = Some((left, right));
        }
        index
    }

    /// Visits `(index, capsule)` for every capsule whose box comes within `reach` of the box
    /// `low..high` (a superset of the capsules within `reach` of anything in it), except those
    /// with an index in `skip` (a contact point's own neighbours along its rod).
    pub fn each_near(
        &self,
        low: DVec3,
        high: DVec3,
        reach: f64,
        skip: std::ops::Range<usize>,
        mut visit: impl FnMut(usize, &Capsule),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        // depth-first with a fixed stack: the tree is balanced, at most log2(n) levels deep
        let mut stack = [0usize; 2 * usize::BITS as usize];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top]];
            if skip.start <= node.start && node.end <= skip.end {
                continue;
            }
            let gap = (node.low - high).max(low - node.high).max(DVec3::ZERO);
            if gap.length_squared() > reach * reach {
                continue;
            }
            match node.children {
                Some((left, right)) => {
                    stack[top] = left;
                    stack[top + 1] = right;
                    top += 2;
                }
                None => (node.start..node.end).filter(|j| !skip.contains(j)).for_each(|j| visit(j, &self.capsules[j])),
            }
        }
    }
}

impl CapsuleTree {
    /// How much further apart than touching the capsules `j` and `k` with `k > j + skip` are,
    /// up to `cap` (0 where two touch): a tree that is one rod's edges, with `skip` neighbours.
    pub fn clearance(&self, skip: usize, cap: f64) -> f64 {
        let mut clearance = cap;
        for (j, c) in self.capsules.iter().enumerate() {
            let later = 0..j + skip + 1;
            self.each_near(c.a.min(c.b), c.a.max(c.b), c.radius + cap, later, |_, d| {
                let (s, t) = closest_parameters(c.a, c.b, d.a, d.b);
                let gap = c.a.lerp(c.b, s).distance(d.a.lerp(d.b, t)) - c.radius - d.radius;
                clearance = clearance.min(gap.max(0.0));
            });
        }
        clearance
    }
}

/// The largest distance of the vectors `v` from the centre of their bounding box: each pair of them
/// differs by at most twice this.
pub(crate) fn spread(v: impl Iterator<Item = DVec3> + Clone) -> f64 {
    let (low, high) = v.clone().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), d| (l.min(d), h.max(d)));
    let centre = 0.5 * (low + high);
    v.map(|d| d.distance(centre)).fold(0.0, f64::max)
}

/// What one rod touches during a step.
#[derive(Debug, Clone, Default)]
pub(crate) struct Obstacles {
    pub field: Option<Arc<DistanceField>>,
    /// Other rods' edges.
    pub others: CapsuleTree,
    /// The rod's own edges (edge `j` at index `j`), where self-contact is on.
    pub own: CapsuleTree,
    /// Own edges within this many edges of a contact point's edge are its neighbours, not obstacles.
    pub own_skip: usize,
    /// Where the rod's vertices were at the start of the step, and how much further apart than
    /// touching its non-neighbouring edges were then (capped): while its vertices have not moved
    /// apart by that much ([`Self::moved`]), the rod cannot touch itself and its own edges need
    /// not be searched.
    pub own_start: Vec<DVec3>,
    pub own_clearance: f64,
    /// The radius the clearance was measured with.
    pub own_radius: f64,
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

    /// Whether the rod may touch itself once its vertices have moved up to `moved` from where they
    /// were at the start of the step.
    pub fn may_touch_itself(&self, moved: f64) -> bool {
        !self.own.is_empty() && 2.0 * moved >= self.own_clearance
    }

    /// How far the vertices `x` moved from where they were at the start of the step, apart from a
    /// shift they share (infinite when that is not known): two of them came closer by at most
    /// twice this.
    pub fn moved(&self, x: &[DVec3]) -> f64 {
        if self.own_start.len() != x.len() {
            return f64::INFINITY;
        }
        spread(x.iter().zip(&self.own_start).map(|(p, q)| *p - *q))
    }

    /// The penetration depths alone of a contact point (as [`Self::each_push`]), for energies.
    pub fn each_depth(&self, p: DVec3, radius: f64, edge: usize, scene: bool, own: bool, mut visit: impl FnMut(f64)) {
        if scene
            && let Some(field) = &self.field
            && let Some(d) = field.value_within(p, radius)
            && d < radius
        {
            visit(radius - d);
        }
        self.each_capsule_push(p, radius, edge, own, |push| visit(push.depth));
    }

    /// The penetrations of a contact point at `p` of radius `radius`, on edge `edge` of its rod,
    /// handed to `visit`: into the scene where `scene`, into other rods, and into its own rod's
    /// edges where `own` (`may_touch_itself`).
    pub fn each_push(&self, p: DVec3, radius: f64, edge: usize, scene: bool, own: bool, mut visit: impl FnMut(Push)) {
        if scene
            && let Some(field) = &self.field
            && let Some((d, grad)) = field.sample_within(p, radius)
            && d < radius
            && grad.length_squared() > 1e-24
        {
            visit(Push { depth: radius - d, gradient: grad });
        }
        self.each_capsule_push(p, radius, edge, own, visit);
    }

    /// The penetrations of a contact point into other rods' capsules and its own far ones.
    fn each_capsule_push(&self, p: DVec3, radius: f64, edge: usize, own: bool, mut visit: impl FnMut(Push)) {
        let mut touch = |capsule: &Capsule| {
            let away = p - capsule.nearest(p);
            let dist = away.length();
            let reach = radius + capsule.radius;
            if dist < reach && dist > 1e-12 {
                visit(Push { depth: reach - dist, gradient: away / dist });
            }
        };
        self.others.each_near(p, p, radius, 0..0, |_, c| touch(c));
        if own {
            let neighbours = edge.saturating_sub(self.own_skip)..edge + self.own_skip + 1;
            self.own.each_near(p, p, radius, neighbours, |_, c| touch(c));
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    fn capsules(points: &[DVec3], radius: f64) -> CapsuleTree {
        CapsuleTree::new(points.windows(2).map(|w| Capsule { a: w[0], b: w[1], radius }).collect())
    }

    /// A hairpin: out along x, a half turn, back 3 r above itself (a gap of r between the arms).
    fn hairpin(r: f64) -> Vec<DVec3> {
        let out = (0..20).map(|i| DVec3::new(0.01 * i as f64, 0.0, 0.0));
        let turn = (1..8).map(|i| {
            let a = std::f64::consts::PI * i as f64 / 8.0;
            DVec3::new(0.19 + 1.5 * r * a.sin(), 1.5 * r * (1.0 - a.cos()), 0.0)
        });
        let back = (0..20).map(|i| DVec3::new(0.19 - 0.01 * i as f64, 3.0 * r, 0.0));
        out.chain(turn).chain(back).collect()
    }

    #[test]
    fn a_move_too_long_to_square_still_meets_the_surface() {
        // a floor at z = 0.35 in a field of 8^3 nodes 0.1 apart; moving down from above it by 1e300
        // (whose square overflows) meets it, moving up by as much is clear
        let values = (0..512).map(|i| (0.1 * (i / 64) as f64 - 0.35) as f32).collect();
        let field = DistanceField::new([0.0; 3], 0.1, [8, 8, 8], values).unwrap();
        let from = DVec3::new(0.35, 0.35, 0.6);
        let (point, normal) = field.first_contact(from, DVec3::new(0.35, 0.35, -1e300), 0.05).unwrap();
        assert!((point.z - 0.4).abs() < 0.01 && normal.z > 0.99, "{point} {normal}");
        assert!(field.first_contact(from, DVec3::new(0.35, 0.35, 1e300), 0.05).is_none());
        assert!(field.first_contact(from, DVec3::new(0.35, 0.35, f64::INFINITY), 0.05).is_none());
    }

    #[test]
    fn the_clearance_of_a_rod_is_the_gap_between_its_far_edges() {
        let r = 0.01;
        let straight: Vec<DVec3> = (0..40).map(|i| DVec3::new(0.01 * i as f64, 0.0, 0.0)).collect();
        // the nearest non-neighbours along a straight rod: 5 edges of arc apart, less two radii
        let along = capsules(&straight, r).clearance(5, 4.0 * r);
        assert!((along - (0.05 - 2.0 * r)).abs() < 1e-9, "{along}");
        assert_eq!(capsules(&straight, r).clearance(10, 4.0 * r), 4.0 * r); // nothing near: the cap
        // a hairpin: what every pair of edges more than 5 apart says
        let points = hairpin(r);
        let edges: Vec<Capsule> = points.windows(2).map(|w| Capsule { a: w[0], b: w[1], radius: r }).collect();
        let mut brute = 4.0 * r;
        for (j, c) in edges.iter().enumerate() {
            for d in edges.iter().skip(j + 6) {
                let (s, t) = closest_parameters(c.a, c.b, d.a, d.b);
                brute = brute.min((c.a.lerp(c.b, s).distance(d.a.lerp(d.b, t)) - 2.0 * r).max(0.0));
            }
        }
        let gap = capsules(&points, r).clearance(5, 4.0 * r);
        assert!(brute < r && (gap - brute).abs() < 1e-12, "{gap} {brute}");
    }

    #[test]
    fn the_spread_of_displacements_ignores_a_shared_shift() {
        let shift = DVec3::new(3.0, -2.0, 1.0);
        assert_eq!(spread([shift, shift, shift].into_iter()), 0.0); // moved together: cannot meet
        let (a, b) = (shift, shift + DVec3::new(0.4, 0.0, 0.3));
        assert!((spread([a, b, 0.5 * (a + b)].into_iter()) - 0.25).abs() < 1e-12); // half of |a - b|
    }

    #[test]
    fn a_tree_finds_every_capsule_a_brute_force_search_finds() {
        let points = hairpin(0.01);
        let tree = capsules(&points, 0.01);
        for p in [DVec3::new(0.1, 0.015, 0.0), DVec3::new(0.2, 0.02, 0.0), DVec3::new(0.05, -0.02, 0.01)] {
            let mut found = Vec::new();
            tree.each_near(p, p, 0.012, 3..6, |j, _| found.push(j));
            found.sort_unstable();
            let brute: Vec<usize> = (0..points.len() - 1)
                .filter(|j| !(3..6).contains(j))
                .filter(|&j| {
                    let c = Capsule { a: points[j], b: points[j + 1], radius: 0.01 };
                    c.nearest(p).distance(p) < 0.012 + 0.01
                })
                .collect();
            assert!(brute.iter().all(|j| found.contains(j)), "{brute:?} not all in {found:?}");
        }
    }
}
