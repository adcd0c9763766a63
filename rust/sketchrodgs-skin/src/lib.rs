//! Skinning (DESIGN.md, "Skinning"): each Gaussian bound to a rod at `(segment, t)` with rest
//! offset `o` follows the rigid transform of its binding point. Its centre becomes the deformed
//! point at `(segment, t)` plus `Q(t) o`, and its rotation `Q(t) q`, where `Q(t)` blends the
//! rotations that carry the rest vertex frames at the segment's two ends to their deformed frames.
//!
//! Blending rotations (not positions) along each segment is what keeps a bent rod's skin from
//! tearing at a joint: a Gaussian at the end of one segment and one at the start of the next get
//! the same rotation, that of the shared vertex.
//!
//! Arrays are plain `[f32; N]` rows as they come from numpy; quaternions are `w, x, y, z`.
//!
//! ```
//! use glam::{Quat, Vec3};
//! use sketchrodgs_skin::{Binding, skin, wxyz};
//! // A two-vertex rod along x, moved up by 1 and turned a quarter turn about z.
//! let turn = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
//! let deformed = [[0.0, 1.0, 0.0], (Vec3::Y + turn * Vec3::X).to_array()];
//! let rotations = [wxyz(turn), wxyz(turn)];
//! let binding = Binding { segment: &[0], t: &[0.5], offset: &[[0.0, 0.0, 0.1]], rotation: &[[1.0, 0.0, 0.0, 0.0]] };
//! let (means, quats) = skin(&deformed, &rotations, &binding).unwrap();
//! assert!((Vec3::from(means[0]) - Vec3::new(0.0, 1.5, 0.1)).length() < 1e-6);
//! assert!((quats[0][0] - wxyz(turn)[0]).abs() < 1e-6);
//! ```

use glam::{Quat, Vec3};
use rayon::prelude::*;

/// What makes skinning impossible. Each names the offending input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkinError {
    #[error("rod needs at least 2 vertices, got {0}")]
    TooFewVertices(usize),
    #[error("{vertices} deformed vertices but {rotations} vertex rotations")]
    RotationCount { vertices: usize, rotations: usize },
    #[error("binding arrays disagree in length: segment {segment}, t {t}, offset {offset}, rotation {rotation}")]
    BindingLengths { segment: usize, t: usize, offset: usize, rotation: usize },
    #[error("binding {index} refers to segment {segment} but the rod has {segments} segments")]
    SegmentOutOfRange { index: usize, segment: u32, segments: usize },
    #[error("deformed vertex {0} is not finite")]
    NonFiniteVertex(usize),
}

/// Where each Gaussian sits on the rest rod (all slices the same length).
#[derive(Debug, Clone, Copy)]
pub struct Binding<'a> {
    /// Segment index `i` (between vertices `i` and `i + 1`).
    pub segment: &'a [u32],
    /// Parameter along the segment in `[0, 1]`.
    pub t: &'a [f32],
    /// Centre minus the rest point at `(segment, t)`, in world axes at rest.
    pub offset: &'a [[f32; 3]],
    /// The Gaussian's rotation at rest, `w, x, y, z`.
    pub rotation: &'a [[f32; 4]],
}

impl Binding<'_> {
    fn len(&self) -> usize {
        self.segment.len()
    }
}

/// A glam quaternion as `w, x, y, z`.
pub fn wxyz(q: Quat) -> [f32; 4] {
    [q.w, q.x, q.y, q.z]
}

fn quat(q: [f32; 4]) -> Quat {
    Quat::from_xyzw(q[1], q[2], q[3], q[0])
}

/// Blend of two unit rotations at `t` (normalised lerp on the shorter arc).
#[inline]
fn blend(a: Quat, b: Quat, t: f32) -> Quat {
    let b = if a.dot(b) < 0.0 { -b } else { b };
    (a * (1.0 - t) + b * t).normalize()
}

/// New centres and rotations (`w, x, y, z`) of the bound Gaussians.
pub type Skinned = (Vec<[f32; 3]>, Vec<[f32; 4]>);

/// Skin the bound Gaussians: their new centres and rotations.
///
/// `deformed[i]` is rod vertex `i` now and `vertex_rotation[i]` the rotation (`w, x, y, z`) from
/// its rest frame to its current frame (`R_now * R_rest^T`; the identity at rest).
pub fn skin(deformed: &[[f32; 3]], vertex_rotation: &[[f32; 4]], binding: &Binding) -> Result<Skinned, SkinError> {
    check(deformed, vertex_rotation, binding)?;
    let mut means = vec![[0.0; 3]; binding.len()];
    let mut quats = vec![[1.0, 0.0, 0.0, 0.0]; binding.len()];
    skin_into(deformed, vertex_rotation, binding, &mut means, &mut quats);
    Ok((means, quats))
}

/// [`skin`] writing into caller-owned buffers (the interactive path reuses them every frame).
pub fn skin_in_place(
    deformed: &[[f32; 3]],
    vertex_rotation: &[[f32; 4]],
    binding: &Binding,
    means: &mut [[f32; 3]],
    quats: &mut [[f32; 4]],
) -> Result<(), SkinError> {
    check(deformed, vertex_rotation, binding)?;
    if means.len() != binding.len() || quats.len() != binding.len() {
        return Err(SkinError::BindingLengths { segment: binding.len(), t: binding.len(), offset: means.len(), rotation: quats.len() });
    }
    skin_into(deformed, vertex_rotation, binding, means, quats);
    Ok(())
}

fn check(deformed: &[[f32; 3]], vertex_rotation: &[[f32; 4]], binding: &Binding) -> Result<(), SkinError> {
    if deformed.len() < 2 {
        return Err(SkinError::TooFewVertices(deformed.len()));
    }
    if vertex_rotation.len() != deformed.len() {
        return Err(SkinError::RotationCount { vertices: deformed.len(), rotations: vertex_rotation.len() });
    }
    let n = binding.len();
    if binding.t.len() != n || binding.offset.len() != n || binding.rotation.len() != n {
        return Err(SkinError::BindingLengths {
            segment: n,
            t: binding.t.len(),
            offset: binding.offset.len(),
            rotation: binding.rotation.len(),
        });
    }
    if let Some(i) = deformed.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        return Err(SkinError::NonFiniteVertex(i));
    }
    let segments = deformed.len() - 1;
    if let Some(index) = binding.segment.iter().position(|&s| s as usize >= segments) {
        return Err(SkinError::SegmentOutOfRange { index, segment: binding.segment[index], segments });
    }
    Ok(())
}

const CHUNK: usize = 4096;

fn skin_into(
    deformed: &[[f32; 3]],
    vertex_rotation: &[[f32; 4]],
    binding: &Binding,
    means: &mut [[f32; 3]],
    quats: &mut [[f32; 4]],
) {
    means.par_chunks_mut(CHUNK).zip(quats.par_chunks_mut(CHUNK)).enumerate().for_each(|(chunk, (means, quats))| {
        let start = chunk * CHUNK;
        for (k, (mean, rotated)) in means.iter_mut().zip(quats.iter_mut()).enumerate() {
            let g = start + k;
            let i = binding.segment[g] as usize;
            let t = binding.t[g].clamp(0.0, 1.0);
            let rotation = blend(quat(vertex_rotation[i]), quat(vertex_rotation[i + 1]), t);
            let point = Vec3::from(deformed[i]).lerp(Vec3::from(deformed[i + 1]), t);
            *mean = (point + rotation * Vec3::from(binding.offset[g])).to_array();
            *rotated = wxyz((rotation * quat(binding.rotation[g])).normalize());
        }
    });
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn straight_rod(n: usize) -> Vec<[f32; 3]> {
        (0..n).map(|i| [i as f32 * 0.1, 0.0, 0.0]).collect()
    }

    const ID: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

    #[test]
    fn rigid_motion_of_the_rod_moves_bound_gaussians_rigidly() {
        let rest = straight_rod(11);
        let motion = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
        let shift = Vec3::new(0.5, -2.0, 3.0);
        let deformed: Vec<[f32; 3]> = rest.iter().map(|&p| (motion * Vec3::from(p) + shift).to_array()).collect();
        let rotations = vec![wxyz(motion); rest.len()];
        let segment: Vec<u32> = (0..100).map(|g| (g % 10) as u32).collect();
        let t: Vec<f32> = (0..100).map(|g| (g as f32 * 0.37).fract()).collect();
        let offset: Vec<[f32; 3]> = (0..100).map(|g| [0.0, (g as f32).sin() * 0.02, (g as f32).cos() * 0.02]).collect();
        let rotation: Vec<[f32; 4]> = (0..100).map(|g| wxyz(Quat::from_rotation_y(g as f32 * 0.1))).collect();
        let binding = Binding { segment: &segment, t: &t, offset: &offset, rotation: &rotation };
        let (means, quats) = skin(&deformed, &rotations, &binding).unwrap();
        for g in 0..100 {
            let i = segment[g] as usize;
            let rest_centre = Vec3::from(rest[i]).lerp(Vec3::from(rest[i + 1]), t[g]) + Vec3::from(offset[g]);
            assert!((Vec3::from(means[g]) - (motion * rest_centre + shift)).length() < 1e-5);
            assert!(quat(quats[g]).angle_between(motion * quat(rotation[g])) < 1e-3);
        }
    }

    #[test]
    fn at_rest_nothing_moves() {
        let rest = straight_rod(4);
        let binding = Binding { segment: &[0, 2], t: &[0.0, 1.0], offset: &[[0.0, 0.01, 0.0], [0.0, 0.0, 0.02]], rotation: &[ID; 2] };
        let (means, _) = skin(&rest, &[ID; 4], &binding).unwrap();
        assert_eq!(means[0], [0.0, 0.01, 0.0]);
        assert!((Vec3::from(means[1]) - Vec3::new(0.3, 0.0, 0.02)).length() < 1e-7);
    }

    #[test]
    fn a_shared_vertex_gives_both_segments_the_same_transform() {
        // bend at vertex 1: the end of segment 0 and the start of segment 1 must coincide
        let deformed = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let rotations = [ID, wxyz(Quat::from_rotation_z(0.785)), wxyz(Quat::from_rotation_z(1.571))];
        let offset = [[0.0, 0.0, 0.1], [0.0, 0.0, 0.1]];
        let binding = Binding { segment: &[0, 1], t: &[1.0, 0.0], offset: &offset, rotation: &[ID; 2] };
        let (means, quats) = skin(&deformed, &rotations, &binding).unwrap();
        assert!((Vec3::from(means[0]) - Vec3::from(means[1])).length() < 1e-6);
        assert!(quat(quats[0]).angle_between(quat(quats[1])) < 1e-6);
    }

    #[test]
    fn bad_input_is_an_error() {
        let b = Binding { segment: &[3], t: &[0.5], offset: &[[0.0; 3]], rotation: &[ID] };
        assert_eq!(skin(&straight_rod(3), &[ID; 3], &b).unwrap_err(), SkinError::SegmentOutOfRange { index: 0, segment: 3, segments: 2 });
        assert!(matches!(skin(&straight_rod(3), &[ID; 2], &b), Err(SkinError::RotationCount { .. })));
        assert!(matches!(skin(&straight_rod(1), &[ID; 1], &b), Err(SkinError::TooFewVertices(1))));
        let mut bad = straight_rod(3);
        bad[1][0] = f32::NAN;
        let ok = Binding { segment: &[0], t: &[0.5], offset: &[[0.0; 3]], rotation: &[ID] };
        assert_eq!(skin(&bad, &[ID; 3], &ok).unwrap_err(), SkinError::NonFiniteVertex(1));
    }
}
