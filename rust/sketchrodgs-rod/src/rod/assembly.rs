//! Assembly: the geometry of a state (edges, frames, curvatures), the elastic energy and its
//! gradient and Hessian scattered into the banded system.

use super::*;

impl ElasticRod {
    /// Edge lengths, tangents, material frames and twists of `(x, theta)` with frames
    /// transported from the chart. Returns `false` for a degenerate configuration (a vanishing
    /// edge, a fold, a non-finite value): its energy is infinite.
    pub(super) fn geometry(&self, x: &[DVec3], theta: &[f64], geo: &mut Geometry) -> bool {
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

    pub(super) fn bend_input(&self, x: &[DVec3], geo: &Geometry, i: usize) -> BendTwistInput {
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
    pub(super) fn half_input(&self, x: &[DVec3], geo: &Geometry, k: usize, h: usize, half: &Half) -> BendTwistInput {
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

    pub(super) fn is_clamped(&self, vertex: usize) -> bool {
        self.boundary[vertex] == Boundary::Clamped
    }

    /// Stretch, bend and twist energies of a configuration whose geometry is `geo`.
    pub(super) fn elastic_parts(&self, x: &[DVec3], geo: &Geometry) -> (f64, f64, f64) {
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
    pub(super) fn potential(&self, x: &[DVec3], theta: &[f64], inertia: Option<&Inertia>, geo: &mut Geometry) -> f64 {
        if !self.geometry(x, theta, geo) {
            return f64::INFINITY;
        }
        let (s, b, t) = self.elastic_parts(x, geo);
        let mut phi = s + b + t + self.contact_energy(x);
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
    pub(super) fn assemble_elastic(&mut self, x: &[DVec3], geo: &Geometry, hessian: Hessian) {
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
    pub(super) fn scatter_stencil(&mut self, base: usize, gy: &[f64; NV], hy: &[[f64; NV]; NV], with_hessian: bool) {
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
    pub(super) fn scatter<const L: usize>(
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
}

/// What `assemble_elastic` computes besides the gradient.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Hessian {
    None,
    /// The exact Hessian (stretching projected, see [`ElasticRod::project_stretch`]).
    Exact,
    /// Positive semidefinite: Gauss-Newton bending/twisting, projected stretching.
    GaussNewton,
}

/// Gradient, and Hessian as asked (zero otherwise), of a bending/twisting stencil.
pub(super) fn stencil_derivatives(inp: &BendTwistInput, hessian: Hessian) -> ([f64; NV], [[f64; NV]; NV]) {
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
pub(super) const HALF_MAP_E: [[Option<(usize, f64)>; 2]; 7] = [
    [Some((0, -1.0)), None],
    [Some((1, -1.0)), None],
    [Some((2, -1.0)), None],
    [Some((6, 1.0)), None],
    [Some((0, 1.0)), None],
    [Some((1, 1.0)), None],
    [Some((2, 1.0)), None],
];

/// As [`HALF_MAP_E`] with the real edge playing `f` (the clamp frame plays `e`).
pub(super) const HALF_MAP_F: [[Option<(usize, f64)>; 2]; 7] = [
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
pub(super) fn half_stencil(half: &Half, ev: DVec3, edge: DMat3, clamp: DMat3, near: f64) -> BendTwistInput {
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
