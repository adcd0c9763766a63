//! Boundary conditions and driving: pins, clamps, the grab, rigid moves, and the targets a step
//! moves them to.

use super::assembly::half_stencil;
use super::*;

impl ElasticRod {
    pub(super) fn check_vertex(&self, vertex: usize) -> Result<(), RodError> {
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

    pub(super) fn add_clamp(&mut self, vertex: usize) {
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
            // (an edge whose square overflows made the next step NaN)
            if l == f64::INFINITY {
                return Err(RodError::EdgeTooLong { edge: j });
            }
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

    /// Prescribed positions and clamp frames at the end of the next step.
    pub(super) fn targets(&self) -> Targets {
        let mut t = Targets { x: self.pins.clone(), frames: Vec::with_capacity(self.clamps.len()) };
        for c in &self.clamps {
            t.x[c.vertex] = Some(c.anchor_x + c.translation);
            t.frames.push(c.rotation * c.anchor_frame);
        }
        if let Some((i, p)) = self.grab {
            // contact first: a target inside the scene holds the vertex on its surface
            t.x[i] = Some(self.reachable(i, p));
        }
        t
    }

    /// Targets halfway between the current state and `end`.
    pub(super) fn midpoint(&self, end: &Targets) -> Targets {
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
}

pub(super) fn apply_targets(t: &Targets, x: &mut [DVec3]) {
    for (xi, p) in x.iter_mut().zip(&t.x) {
        if let Some(p) = p {
            *xi = *p;
        }
    }
}

pub(super) fn finite_point(what: &'static str, p: [f64; 3]) -> Result<DVec3, RodError> {
    if p.iter().all(|c| c.is_finite()) {
        Ok(DVec3::from_array(p))
    } else {
        Err(RodError::NonFiniteInput { what, value: p.to_vec() })
    }
}

/// Row-major 3x3 rotation, checked orthonormal and re-orthonormalised.
pub(super) fn finite_rotation(r: [[f64; 3]; 3]) -> Result<DMat3, RodError> {
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
