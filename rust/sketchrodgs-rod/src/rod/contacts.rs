//! The contact penalty of a rod's points (docs/contact.md, [`crate::contact`]): its energy for the
//! line search, its gradient and (Gauss-Newton) Hessian for the Newton direction, the grab target
//! kept out of the scene, and friction after a step.

use super::*;
use crate::contact::{Obstacles, Push};

/// Times the grab's way slides along the scene's surface after meeting it.
const SLIDES: usize = 4;

/// A Newton step may take a contact point this many radii into an obstacle it approaches (the
/// penalty then pushes it back), no further.
const STEP_SLACK: f64 = 0.5;

/// The penalty of a penetration `depth` of a point of radius `r` (docs/contact.md): its energy,
/// force and stiffness. Quadratic (`k/2 depth^2`) past `SMOOTHING * r`, cubic below, so that the
/// stiffness grows from zero instead of jumping to `k` where a point starts to touch: Newton's
/// steps then do not chatter as points at the edge of a contact flip in and out.
fn penalty(k: f64, r: f64, depth: f64) -> (f64, f64, f64) {
    let eps = SMOOTHING * r;
    if depth < eps {
        (k * depth.powi(3) / (6.0 * eps), k * depth * depth / (2.0 * eps), k * depth / eps)
    } else {
        (k * (depth * depth / 2.0 - eps * depth / 2.0 + eps * eps / 6.0), k * (depth - eps / 2.0), k)
    }
}

/// Edges longer than this many radii have their midpoint meet the scene too: two spheres of radius
/// `r` 0.6 r apart cover their capsule to within 0.046 r, under the 0.05 r a contact may sink.
const SCENE_MIDPOINT_EDGE: f64 = 0.6;

/// Share of the radius over which the penalty's stiffness ramps up.
const SMOOTHING: f64 = 0.01;

impl ElasticRod {
    /// Sets what the rod touches from now on (the World does before each step).
    pub(crate) fn set_obstacles(&mut self, obstacles: Obstacles) {
        self.obstacles = obstacles;
    }

    /// Whether the rod, where it is now, may touch itself: its far edges were further apart at the
    /// start of the step than it has moved since (`Obstacles::may_touch_itself`).
    pub(crate) fn may_touch_itself(&self) -> bool {
        self.obstacles.may_touch_itself(self.obstacles.moved(&self.state.x))
    }

    /// A lower bound on the clearance of the rod's far edges now (`CapsuleTree::clearance`): the
    /// one measured at the start of the last step, less twice how far it has moved since; None
    /// when there was none (or it counted other neighbours, or another radius).
    pub(crate) fn clearance_since_last_step(&self, skip: usize) -> Option<f64> {
        let o = &self.obstacles;
        let same = o.own_skip == skip && o.own_radius == self.params.radius;
        (same && !o.own.is_empty() && o.own_start.len() == self.state.x.len())
            .then(|| (o.own_clearance - 2.0 * o.moved(&self.state.x)).max(0.0))
    }

    /// The rod's edges as capsules of its radius, where they are now.
    pub(crate) fn capsules(&self) -> Vec<crate::Capsule> {
        let r = self.params.radius;
        self.state.x.windows(2).map(|w| crate::Capsule { a: w[0], b: w[1], radius: r }).collect()
    }

    /// Own edges within this many edges of a contact point are its neighbours along the rod, not
    /// obstacles: those within two diameters of arc, and the adjacent ones.
    pub(crate) fn own_skip(&self) -> usize {
        let shortest = self.rest_len.iter().copied().fold(f64::INFINITY, f64::min);
        (4.0 * self.params.radius / shortest).ceil() as usize + 1
    }

    /// Visits the contact points of configuration `x`: each vertex, and each edge's midpoint, as
    /// (point, its edge, the vertices it moves with and their weights, whether it meets the scene).
    /// A midpoint meets the scene only on an edge longer than `SCENE_MIDPOINT_EDGE` radii: the
    /// vertices' spheres of a shorter edge already cover its capsule to within 0.046 R.
    fn each_contact_point(&self, x: &[DVec3], mut visit: impl FnMut(DVec3, usize, [(usize, f64); 2], bool)) {
        let n = x.len();
        for i in 0..n {
            visit(x[i], i.min(n - 2), [(i, 1.0), (i, 0.0)], true);
        }
        let long = SCENE_MIDPOINT_EDGE * self.params.radius;
        for j in 0..n - 1 {
            visit(0.5 * (x[j] + x[j + 1]), j, [(j, 0.5), (j + 1, 0.5)], self.rest_len[j] > long);
        }
    }

    /// The contact energy of configuration `x`.
    pub(super) fn contact_energy(&self, x: &[DVec3]) -> f64 {
        if self.obstacles.is_empty() {
            return 0.0;
        }
        let (k, r) = (self.contact_stiffness, self.params.radius);
        let own = self.obstacles.may_touch_itself(self.obstacles.moved(x));
        let mut energy = 0.0;
        self.each_contact_point(x, |p, edge, _, scene| {
            self.obstacles.each_depth(p, r, edge, scene, own, |depth| energy += penalty(k, r, depth).0);
        });
        energy
    }

    /// Adds the contact gradient (and Gauss-Newton Hessian `k n nᵀ` per penetration) of `x`.
    pub(super) fn assemble_contact(&mut self, x: &[DVec3], with_hessian: bool) {
        if self.obstacles.is_empty() {
            return;
        }
        let (k, r) = (self.contact_stiffness, self.params.radius);
        let own = self.obstacles.may_touch_itself(self.obstacles.moved(x));
        let mut pushes: Vec<([(usize, f64); 2], Push)> = Vec::new();
        self.each_contact_point(x, |p, edge, weights, scene| {
            self.obstacles.each_push(p, r, edge, scene, own, |push| pushes.push((weights, push)));
        });
        for (weights, Push { depth, gradient }) in pushes {
            let (_, force, stiffness) = penalty(k, r, depth);
            // E = k/2 depth², d(depth)/dp = -gradient
            for &(i, w) in weights.iter().filter(|(_, w)| *w != 0.0) {
                for c in 0..3 {
                    self.grad[dof_x(i) + c] -= w * force * gradient[c];
                }
            }
            if !with_hessian {
                continue;
            }
            for &(a, wa) in weights.iter().filter(|(_, w)| *w != 0.0) {
                for &(b, wb) in weights.iter().filter(|(_, w)| *w != 0.0) {
                    if b > a {
                        continue; // the lower triangle: (a, b) with a >= b
                    }
                    for ra in 0..3 {
                        for rb in 0..3 {
                            let (row, col) = (dof_x(a) + ra, dof_x(b) + rb);
                            if row >= col {
                                self.hess.add_lower(row, col, wa * wb * stiffness * gradient[ra] * gradient[rb]);
                            }
                        }
                    }
                }
            }
        }
    }

    /// The longest fraction (<= 1) of the step `dir` from `x` that takes no contact point deeper
    /// than `STEP_SLACK` radii into an obstacle it approaches: a penalty acts only where points
    /// overlap, so an unlimited Newton step could jump right through a thin obstacle (another rod)
    /// to where the energy is lower. Points already deeper are left to the penalty.
    pub(super) fn step_limit(&self, x: &[DVec3], dir: &[f64]) -> f64 {
        if self.obstacles.is_empty() {
            return 1.0;
        }
        let r = self.params.radius;
        let motion = |i: usize| DVec3::new(dir[dof_x(i)], dir[dof_x(i) + 1], dir[dof_x(i) + 2]);
        let farthest = crate::contact::spread((0..x.len()).map(motion));
        let own = self.obstacles.may_touch_itself(self.obstacles.moved(x) + farthest);
        let mut limit: f64 = 1.0;
        self.each_contact_point(x, |p, edge, weights, scene| {
            let dp = weights.iter().map(|&(i, w)| w * motion(i)).sum::<DVec3>();
            let speed = dp.length();
            if speed <= 0.0 {
                return;
            }
            // obstacles within reach of this step: pushes against the grown radius
            self.obstacles.each_push(p, r + speed, edge, scene, own, |push| {
                let depth = push.depth - speed; // below 0: a gap, within reach
                let approaching = -dp.dot(push.gradient);
                let room = STEP_SLACK * r - depth;
                if approaching > 0.0 && room > 0.0 {
                    limit = limit.min(room / approaching);
                }
            });
        });
        limit
    }

    /// Where the grab's target may put vertex `i`: the way from where it is to the target, up to
    /// where it meets the scene, then along the surface (the part of the way into the surface
    /// taken out), a few times. A vertex dragged into a table slides on it, on the side it came
    /// from (another rod in the way is pushed aside instead, by `World::separate_rods`).
    pub(super) fn reachable(&self, i: usize, target: DVec3) -> DVec3 {
        let Some(field) = &self.obstacles.field else { return target };
        let r = self.params.radius;
        let mut from = field.push_out(self.state.x[i], r);
        let mut goal = target;
        for _ in 0..SLIDES {
            let Some((contact, normal)) = field.first_contact(from, goal, r) else { return goal };
            let rest = goal - contact;
            goal = contact + rest - normal * rest.dot(normal).min(0.0);
            from = contact;
        }
        from
    }

    /// Whether vertex `i` is held (pinned, clamped or grabbed): contact cannot move it.
    pub(crate) fn is_held(&self, i: usize) -> bool {
        self.boundary[i] != Boundary::Free || self.grab.is_some_and(|(g, _)| g == i)
    }

    /// Moves vertex `i` by `delta` (a contact resolved after a step of `h`), its velocity with it.
    pub(crate) fn nudge(&mut self, i: usize, delta: DVec3, h: f64) {
        self.state.x[i] += delta;
        self.state.v[i] += delta / h;
    }

    /// Re-bases the frames after vertices were nudged.
    pub(crate) fn after_nudges(&mut self) {
        self.rebase();
    }

    /// Coulomb friction `mu` after a step of `h`: each vertex touching the scene loses tangential
    /// speed by up to `mu` times the normal impulse its contact gave it (per unit mass).
    pub(crate) fn apply_friction(&mut self, mu: f64, h: f64) {
        let Some(field) = self.obstacles.field.clone().filter(|_| mu > 0.0) else { return };
        let (k, r) = (self.contact_stiffness, self.params.radius);
        for i in 0..self.state.x.len() {
            let Some((d, grad)) = field.sample(self.state.x[i]) else { continue };
            let len = grad.length();
            if d >= r || len < 1e-12 {
                continue;
            }
            let (depth, normal) = (r - d, grad / len);
            let v = self.state.v[i];
            let tangential = v - normal * v.dot(normal);
            let speed = tangential.length();
            if speed <= 0.0 || self.mass[i] <= 0.0 {
                continue;
            }
            let loss = mu * penalty(k, r, depth).1 * h / self.mass[i];
            self.state.v[i] = v - tangential * (loss / speed).min(1.0);
        }
    }
}
