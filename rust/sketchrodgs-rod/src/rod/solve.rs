//! The implicit solve: backward-Euler steps (halved where Newton does not converge), the
//! quasi-static solve, and the damped Newton iteration with its line search.

use super::assembly::Hessian;
use super::constraints::apply_targets;
use super::*;

impl ElasticRod {
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

    pub(super) fn advance(&mut self, h: f64, end: &Targets, depth: u32, settings: &SolverSettings) -> StepReport {
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

    pub(super) fn start_is_finite(&mut self, t: &Targets) -> bool {
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
    pub(super) fn commit(&mut self, dynamic: Option<(f64, &State)>) {
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
    pub(super) fn rebase(&mut self) {
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
    pub(super) fn solve(&mut self, h: Option<f64>, end: &Targets, max_iter: usize, tol: f64) -> Solve {
        let fixed = self.fixed_unknowns(end);
        self.state.clamp_frame.clone_from(&end.frames);
        let inertia = h.map(|h| self.inertia(h));
        let mut trial = std::mem::take(&mut self.trial);
        let Some((mut phi, mut x, mut th)) = self.best_start(end, inertia.as_ref(), &mut trial) else {
            self.trial = trial;
            return Solve { iterations: 0, converged: false, finite: false };
        };

        let mut iterations = 0;
        let mut converged = false;
        let mut geo = std::mem::take(&mut self.geo);
        let mut dir = vec![0.0; fixed.len()];
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
            if !self.direction(&x, &th, &geo, inertia.as_ref(), &fixed, fresh, &mut dir) {
                break;
            }
            let size = self.step_size(&dir);
            if size <= tol {
                // Below tolerance: take it as is, no line search needed.
                add_step(&mut x, &mut th, &dir, 1.0);
                converged = true;
                break;
            }
            let slope: f64 = dir.iter().zip(&self.grad).map(|(d, g)| d * g).sum();
            let ray = Ray { x: &x, th: &th, dir: &dir, phi, slope };
            let Some((alpha, p)) = self.line_search(ray, inertia.as_ref(), &mut trial, &mut x_try, &mut th_try) else {
                if fresh {
                    break;
                }
                // A chord step that does not descend: retry with a fresh Hessian.
                reuse = false;
                continue;
            };
            phi = p;
            std::mem::swap(&mut x, &mut x_try);
            std::mem::swap(&mut th, &mut th_try);
            reuse = alpha == 1.0 && if fresh { size < CHORD_AFTER } else { size < CHORD_CONTRACTION * last_size };
            last_size = size;
        }
        self.geo = geo;
        self.trial = trial;
        self.state.x = x;
        self.state.theta = th;
        Solve { iterations, converged, finite: true }
    }

    /// Which unknowns the targets fix (the positions of pinned, clamped and grabbed vertices).
    fn fixed_unknowns(&self, end: &Targets) -> Vec<bool> {
        let n = self.num_vertices();
        let mut fixed = vec![false; 4 * n - 1];
        for (i, p) in end.x.iter().enumerate() {
            if p.is_some() {
                fixed[dof_x(i)..dof_x(i) + 3].iter_mut().for_each(|f| *f = true);
            }
        }
        fixed
    }

    /// The inertial term of a backward-Euler step of length `h` from the current state.
    fn inertia(&self, h: f64) -> Inertia {
        let s = &self.state;
        Inertia {
            h,
            alpha: self.params.damping,
            x_hat: s.x.iter().zip(&s.v).map(|(x, v)| *x + h * *v).collect(),
            th_hat: s.theta.iter().zip(&s.omega).map(|(t, w)| t + h * w).collect(),
            x_n: s.x.clone(),
            th_n: s.theta.clone(),
        }
    }

    /// The start of Newton with the lowest potential, targets applied, among: the inertial
    /// prediction, the current state, and (when a constraint moves) the current state with the
    /// constraint displacements spread along the rod. The last keeps a far-moved grab from
    /// crushing its neighbouring edges. None when every start has an infinite potential.
    fn best_start(
        &self,
        end: &Targets,
        inertia: Option<&Inertia>,
        trial: &mut Geometry,
    ) -> Option<(f64, Vec<DVec3>, Vec<f64>)> {
        let moved = end.x.iter().zip(&self.state.x).any(|(p, x)| p.is_some_and(|p| p != *x));
        let mut starts = Vec::with_capacity(3);
        if let Some(inr) = inertia {
            starts.push((inr.x_hat.clone(), inr.th_hat.clone()));
        }
        starts.push((self.state.x.clone(), self.state.theta.clone()));
        if moved {
            starts.push(self.spread_guess(end));
        }
        let mut best: Option<(f64, Vec<DVec3>, Vec<f64>)> = None;
        for (mut x, th) in starts {
            apply_targets(end, &mut x);
            let phi = self.potential(&x, &th, inertia, trial);
            if phi.is_finite() && best.as_ref().is_none_or(|b| phi < b.0) {
                best = Some((phi, x, th));
            }
        }
        best
    }

    /// The Newton direction at `(x, th)` into `dir`: with a fresh Hessian (the exact one; where
    /// it is indefinite, at sharp folds, the positive semidefinite Gauss-Newton one, then growing
    /// diagonal shifts), or a chord step with the last factorisation. False if none is found.
    #[allow(clippy::too_many_arguments)]
    fn direction(
        &mut self,
        x: &[DVec3],
        th: &[f64],
        geo: &Geometry,
        inertia: Option<&Inertia>,
        fixed: &[bool],
        fresh: bool,
        dir: &mut [f64],
    ) -> bool {
        if !fresh {
            self.assemble_system(x, th, geo, inertia, fixed, Hessian::None);
            for (d, g) in dir.iter_mut().zip(&self.grad) {
                *d = -g;
            }
            self.factor.solve_in_place(dir);
            return true;
        }
        self.assemble_system(x, th, geo, inertia, fixed, Hessian::Exact);
        if self.newton_direction(dir, false) {
            return true;
        }
        self.assemble_system(x, th, geo, inertia, fixed, Hessian::GaussNewton);
        self.newton_direction(dir, true)
    }

    /// A step's size: its largest position change relative to the rod length, or its largest
    /// twist change in radians.
    fn step_size(&self, dir: &[f64]) -> f64 {
        let n = self.num_vertices();
        let max_dx = (0..n).flat_map(|i| (0..3).map(move |r| dof_x(i) + r)).fold(0.0_f64, |m, k| m.max(dir[k].abs()));
        let max_dth = (0..n - 1).fold(0.0_f64, |m, j| m.max(dir[dof_theta(j)].abs()));
        (max_dx / self.length).max(max_dth)
    }

    /// Backtracking (Armijo) line search along `dir` from `(x, th)` of potential `phi` and slope
    /// `slope`: the accepted step length and potential, the state in `(x_try, th_try)`; None when
    /// no step length descends.
    fn line_search(
        &self,
        Ray { x, th, dir, phi, slope }: Ray<'_>,
        inertia: Option<&Inertia>,
        trial: &mut Geometry,
        x_try: &mut [DVec3],
        th_try: &mut [f64],
    ) -> Option<(f64, f64)> {
        let mut alpha = self.step_limit(x, dir);
        for _ in 0..MAX_BACKTRACKS {
            x_try.copy_from_slice(x);
            th_try.copy_from_slice(th);
            add_step(x_try, th_try, dir, alpha);
            let p = self.potential(x_try, th_try, inertia, trial);
            if p <= phi + ARMIJO * alpha * slope.min(0.0) {
                return Some((alpha, p));
            }
            alpha *= 0.5;
        }
        None
    }

    /// Gradient (and Hessian as asked) of the potential at `(x, th)` into the workspace, with
    /// the fixed unknowns' rows and columns replaced by the identity's.
    pub(super) fn assemble_system(
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
        self.assemble_contact(x, with_hessian);
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
    pub(super) fn newton_direction(&mut self, dir: &mut [f64], shift: bool) -> bool {
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
    pub(super) fn spread_guess(&self, end: &Targets) -> (Vec<DVec3>, Vec<f64>) {
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

/// Where a line search starts: the state, the direction, the potential there and its slope
/// along the direction.
struct Ray<'a> {
    x: &'a [DVec3],
    th: &'a [f64],
    dir: &'a [f64],
    phi: f64,
    slope: f64,
}

/// `(x, th) += alpha * dir` over the rod's unknowns.
fn add_step(x: &mut [DVec3], th: &mut [f64], dir: &[f64], alpha: f64) {
    for (i, xi) in x.iter_mut().enumerate() {
        *xi += alpha * DVec3::new(dir[dof_x(i)], dir[dof_x(i) + 1], dir[dof_x(i) + 2]);
    }
    for (j, t) in th.iter_mut().enumerate() {
        *t += alpha * dir[dof_theta(j)];
    }
}
