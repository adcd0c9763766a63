//! Frame geometry of discrete elastic rods: parallel transport, curvature binormal, signed
//! angles (Bergou et al. 2008, Sec. 4).

use glam::{DMat3, DQuat, DVec3};

/// Below this `1 + t0.t1` two unit tangents count as opposite and transport picks a fixed axis.
const ANTIPARALLEL: f64 = 1.0e-12;

/// Parallel transport of `a` (perpendicular to unit `u`) to unit `t`: the rotation about
/// `u x t` taking `u` to `t`, applied to `a`. Opposite tangents rotate by pi about `a`.
pub fn transport(a: DVec3, u: DVec3, t: DVec3) -> DVec3 {
    let c = 1.0 + u.dot(t);
    if c < ANTIPARALLEL {
        return a;
    }
    a - (t.dot(a) / c) * (u + t)
}

/// Curvature binormal `kb = 2 (t0 x t1) / (1 + t0 . t1)`, of length `2 tan(phi / 2)`.
pub fn curvature_binormal(t0: DVec3, t1: DVec3) -> DVec3 {
    let c = (1.0 + t0.dot(t1)).max(ANTIPARALLEL);
    2.0 * t0.cross(t1) / c
}

/// Angle from `a` to `b` measured about `axis` (right-handed), in (-pi, pi].
pub fn signed_angle(a: DVec3, b: DVec3, axis: DVec3) -> f64 {
    a.cross(b).dot(axis).atan2(a.dot(b))
}

/// Adds a multiple of 2 pi to `angle` to bring it nearest to `near`.
pub fn unwrap_near(angle: f64, near: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    angle + tau * ((near - angle) / tau).round()
}

/// Any unit vector perpendicular to unit `t`.
pub fn perpendicular(t: DVec3) -> DVec3 {
    let helper = if t.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    (helper - t * t.dot(helper)).normalize()
}

/// Material frame of an edge from its reference director `a1`, tangent `t` and twist angle
/// `theta`: `(m1, m2)` with `m1 = cos a1 + sin a2`, `m2 = t x m1`.
pub fn material_frame(a1: DVec3, t: DVec3, theta: f64) -> (DVec3, DVec3) {
    let a2 = t.cross(a1);
    let (s, c) = theta.sin_cos();
    let m1 = c * a1 + s * a2;
    let m2 = -s * a1 + c * a2;
    (m1, m2)
}

/// The rotation whose columns are `(m1, m2, t)`.
pub fn frame_matrix(m1: DVec3, m2: DVec3, t: DVec3) -> DMat3 {
    DMat3::from_cols(m1, m2, t)
}

/// Halfway rotation between two frames (the per-vertex frame of the paper: the average of the
/// adjacent edges' frames), as the normalised sum of sign-aligned quaternions.
pub fn average_rotation(a: DQuat, b: DQuat) -> DQuat {
    let b = if a.dot(b) < 0.0 { -b } else { b };
    let s = a + b;
    let len = s.length();
    if len > 1.0e-12 { s / len } else { a }
}

/// Rotation of vertex `i`: the average of its edges' frames (one edge at the ends).
pub(crate) fn vertex_rotation(edge_frames: &[DMat3], i: usize) -> DMat3 {
    let ne = edge_frames.len();
    let q = |j: usize| DQuat::from_mat3(&edge_frames[j]).normalize();
    let r = if i == 0 {
        q(0)
    } else if i >= ne {
        q(ne - 1)
    } else {
        average_rotation(q(i - 1), q(i))
    };
    DMat3::from_quat(r)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    #[test]
    fn transport_keeps_perpendicular_unit() {
        let u = DVec3::new(0.0, 0.0, 1.0);
        let t = DVec3::new(0.3, -0.5, 0.8).normalize();
        let a = DVec3::new(1.0, 0.0, 0.0);
        let b = transport(a, u, t);
        assert!((b.length() - 1.0).abs() < 1e-14);
        assert!(b.dot(t).abs() < 1e-14);
        // Transport along the same tangent is the identity.
        assert!((transport(a, u, u) - a).length() < 1e-15);
    }

    #[test]
    fn curvature_binormal_length_is_two_tan_half_angle() {
        let phi: f64 = 0.7;
        let t0 = DVec3::X;
        let t1 = DVec3::new(phi.cos(), phi.sin(), 0.0);
        let kb = curvature_binormal(t0, t1);
        assert!((kb.length() - 2.0 * (phi / 2.0).tan()).abs() < 1e-14);
        assert!((kb.normalize() - DVec3::Z).length() < 1e-14);
    }

    #[test]
    fn unwrap_picks_nearest_branch() {
        let tau = std::f64::consts::TAU;
        assert!((unwrap_near(0.1, tau) - (0.1 + tau)).abs() < 1e-12);
        assert!((unwrap_near(3.0, -3.0) - (3.0 - tau)).abs() < 1e-12);
    }
}
