//! Skinning (docs/deformation.md, "Skinning"): each Gaussian bound to a rod at `(segment, t)` with
//! rest offset `o` and weight `w` follows the transform of its binding point. Where `w = 1` its
//! centre becomes the deformed point at `(segment, t)` plus `Q(t) o`, where `Q(t)` blends the
//! rotations that carry the rest vertex frames at the segment's two ends to their deformed frames;
//! where `w < 1` (the blend band at the boundary with the static scene) it moves that fraction of
//! the way, and turns by that fraction of `Q(t)`.
//!
//! The covariance follows the deformation's Jacobian `F = Q(t) (I + (s - 1) τ τᵀ)`: the rotation,
//! and the segment's stretch `s` (length now over length at rest) along its rest direction `τ`, so
//! a stretched rod opens no gaps. `F Σ Fᵀ` is re-diagonalised into a rotation and scales.
//!
//! Blending rotations (not positions) along each segment is what keeps a bent rod's skin from
//! tearing at a joint: a Gaussian at the end of one segment and one at the start of the next get
//! the same rotation, that of the shared vertex.
//!
//! Arrays are plain `[f32; N]` rows as they come from numpy; quaternions are `w, x, y, z`.
//!
//! ```
//! use glam::{Quat, Vec3};
//! use sketchrodgs_skin::{Binding, Pose, skin, wxyz};
//! // A two-vertex rod along x, moved up by 1 and turned a quarter turn about z.
//! let turn = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
//! let rest = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
//! let deformed = [[0.0, 1.0, 0.0], (Vec3::Y + turn * Vec3::X).to_array()];
//! let pose = Pose { rest: &rest, deformed: &deformed, rotation: &[wxyz(turn), wxyz(turn)] };
//! let binding = Binding {
//!     segment: &[0], t: &[0.5], offset: &[[0.0, 0.0, 0.1]], rotation: &[[1.0, 0.0, 0.0, 0.0]],
//!     scale: &[[0.1, 0.01, 0.01]], weight: &[1.0],
//! };
//! let skinned = skin(&pose, &binding).unwrap();
//! assert!((Vec3::from(skinned.means[0]) - Vec3::new(0.0, 1.5, 0.1)).length() < 1e-6);
//! assert!((skinned.quats[0][0] - wxyz(turn)[0]).abs() < 1e-6);
//! assert!((skinned.scales[0][0] - 0.1).abs() < 1e-6); // no stretch: the scales stay
//! ```

use glam::{DMat3, DQuat, Quat, Vec3};
use rayon::prelude::*;

/// What makes skinning impossible. Each names the offending input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkinError {
    #[error("rod needs at least 2 vertices, got {0}")]
    TooFewVertices(usize),
    #[error("{vertices} deformed vertices but {rotations} vertex rotations and {rest} rest vertices")]
    RotationCount { vertices: usize, rotations: usize, rest: usize },
    #[error(
        "binding arrays disagree in length: segment {segment}, t {t}, offset {offset}, rotation {rotation}, scale {scale}, weight {weight}"
    )]
    BindingLengths { segment: usize, t: usize, offset: usize, rotation: usize, scale: usize, weight: usize },
    #[error("output arrays hold {got} rows but the binding has {want}")]
    OutputLength { got: usize, want: usize },
    #[error("binding {index} refers to segment {segment} but the rod has {segments} segments")]
    SegmentOutOfRange { index: usize, segment: u32, segments: usize },
    #[error("{which} vertex {index} is not finite")]
    NonFiniteVertex { which: &'static str, index: usize },
    #[error("rest segment {0} has zero length")]
    ZeroLengthSegment(usize),
}

/// The rod: its vertices at rest and now, and each vertex frame's rotation from rest to now
/// (`R_now * R_rest^T`, `w, x, y, z`; the identity at rest).
#[derive(Debug, Clone, Copy)]
pub struct Pose<'a> {
    pub rest: &'a [[f32; 3]],
    pub deformed: &'a [[f32; 3]],
    pub rotation: &'a [[f32; 4]],
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
    /// The Gaussian's scales at rest.
    pub scale: &'a [[f32; 3]],
    /// How much of the motion it takes, in `[0, 1]`.
    pub weight: &'a [f32],
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

/// Per vertex, the rotation (`w, x, y, z`) that carries its rest frame to its frame now, from the
/// rod's vertex frames as unit quaternions `w, x, y, z` (`ElasticRod::vertex_quats`).
pub fn frame_rotations(rest: &[[f64; 4]], now: &[[f64; 4]]) -> Vec<[f32; 4]> {
    let dquat = |q: &[f64; 4]| glam::DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
    rest.iter()
        .zip(now)
        .map(|(r, n)| {
            let q = (dquat(n) * dquat(r).conjugate()).normalize();
            [q.w as f32, q.x as f32, q.y as f32, q.z as f32]
        })
        .collect()
}

/// Blend of two unit rotations at `t` (normalised lerp on the shorter arc).
#[inline]
fn blend(a: Quat, b: Quat, t: f32) -> Quat {
    let b = if a.dot(b) < 0.0 { -b } else { b };
    (a * (1.0 - t) + b * t).normalize()
}

/// New centres, rotations (`w, x, y, z`) and scales of the bound Gaussians.
#[derive(Debug, Clone, PartialEq)]
pub struct Skinned {
    pub means: Vec<[f32; 3]>,
    pub quats: Vec<[f32; 4]>,
    pub scales: Vec<[f32; 3]>,
}

/// Skin the bound Gaussians: their new centres, rotations and scales.
pub fn skin(pose: &Pose, binding: &Binding) -> Result<Skinned, SkinError> {
    let n = binding.len();
    let mut out = Skinned { means: vec![[0.0; 3]; n], quats: vec![[1.0, 0.0, 0.0, 0.0]; n], scales: vec![[0.0; 3]; n] };
    skin_in_place(pose, binding, &mut out.means, &mut out.quats, &mut out.scales)?;
    Ok(out)
}

/// [`skin`] writing into caller-owned buffers (the interactive path reuses them every frame).
pub fn skin_in_place(
    pose: &Pose,
    binding: &Binding,
    means: &mut [[f32; 3]],
    quats: &mut [[f32; 4]],
    scales: &mut [[f32; 3]],
) -> Result<(), SkinError> {
    let segments = check(pose, binding)?;
    for got in [means.len(), quats.len(), scales.len()] {
        if got != binding.len() {
            return Err(SkinError::OutputLength { got, want: binding.len() });
        }
    }
    skin_into(pose, &segments, binding, means, quats, scales);
    Ok(())
}

/// Per rest segment: its unit direction at rest and its stretch now.
struct Segment {
    direction: Vec3,
    stretch: f32,
}

fn check(pose: &Pose, binding: &Binding) -> Result<Vec<Segment>, SkinError> {
    let m = pose.deformed.len();
    if m < 2 {
        return Err(SkinError::TooFewVertices(m));
    }
    if pose.rotation.len() != m || pose.rest.len() != m {
        return Err(SkinError::RotationCount { vertices: m, rotations: pose.rotation.len(), rest: pose.rest.len() });
    }
    let n = binding.len();
    let lengths =
        [binding.t.len(), binding.offset.len(), binding.rotation.len(), binding.scale.len(), binding.weight.len()];
    if lengths.iter().any(|&l| l != n) {
        let [t, offset, rotation, scale, weight] = lengths;
        return Err(SkinError::BindingLengths { segment: n, t, offset, rotation, scale, weight });
    }
    for (which, vertices) in [("deformed", pose.deformed), ("rest", pose.rest)] {
        if let Some(index) = vertices.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(SkinError::NonFiniteVertex { which, index });
        }
    }
    let segments = m - 1;
    if let Some(index) = binding.segment.iter().position(|&s| s as usize >= segments) {
        return Err(SkinError::SegmentOutOfRange { index, segment: binding.segment[index], segments });
    }
    (0..segments)
        .map(|i| {
            let rest = Vec3::from(pose.rest[i + 1]) - Vec3::from(pose.rest[i]);
            let now = Vec3::from(pose.deformed[i + 1]) - Vec3::from(pose.deformed[i]);
            let length = rest.length();
            if length <= 0.0 {
                return Err(SkinError::ZeroLengthSegment(i));
            }
            Ok(Segment { direction: rest / length, stretch: now.length() / length })
        })
        .collect()
}

const CHUNK: usize = 4096;
// Below this relative stretch the covariance only turns.
const STRETCH_EPSILON: f32 = 1e-4;
// Below this one, each of the Gaussian's own axes is stretched by its share of the rod's
// direction, keeping the axes: exact when an axis lies along the rod, and within 2 % of the exact
// covariance otherwise, where 2 % of stretch opens no visible gap. Above it the stretched
// covariance is re-diagonalised exactly (and costs several times as much).
const EXACT_FROM: f32 = 0.02;

fn skin_into(
    pose: &Pose,
    segments: &[Segment],
    binding: &Binding,
    means: &mut [[f32; 3]],
    quats: &mut [[f32; 4]],
    scales: &mut [[f32; 3]],
) {
    means
        .par_chunks_mut(CHUNK)
        .zip(quats.par_chunks_mut(CHUNK))
        .zip(scales.par_chunks_mut(CHUNK))
        .enumerate()
        // per thread, the rows of a chunk whose stretched covariance is re-diagonalised (LANES at
        // a time, below)
        .for_each_init(Vec::new, |exact: &mut Vec<Stretch>, (chunk, ((means, quats), scales))| {
            let start = chunk * CHUNK;
            exact.clear();
            for (k, ((mean, rotated), scaled)) in
                means.iter_mut().zip(quats.iter_mut()).zip(scales.iter_mut()).enumerate()
            {
                let g = start + k;
                let i = binding.segment[g] as usize;
                let t = binding.t[g].clamp(0.0, 1.0);
                let w = binding.weight[g].clamp(0.0, 1.0);
                let offset = Vec3::from(binding.offset[g]);
                let mut rotation = blend(quat(pose.rotation[i]), quat(pose.rotation[i + 1]), t);
                let point = Vec3::from(pose.deformed[i]).lerp(Vec3::from(pose.deformed[i + 1]), t);
                let mut centre = point + rotation * offset;
                if w < 1.0 {
                    let rest = Vec3::from(pose.rest[i]).lerp(Vec3::from(pose.rest[i + 1]), t) + offset;
                    centre = rest.lerp(centre, w);
                    rotation = blend(Quat::IDENTITY, rotation, w);
                }
                *mean = centre.to_array();
                let own = quat(binding.rotation[g]);
                let stretch = 1.0 + w * (segments[i].stretch - 1.0);
                if (stretch - 1.0).abs() < STRETCH_EPSILON {
                    *rotated = wxyz((rotation * own).normalize());
                    *scaled = binding.scale[g];
                } else if (stretch - 1.0).abs() < EXACT_FROM {
                    *rotated = wxyz((rotation * own).normalize());
                    *scaled = stretched_axes(own, binding.scale[g], segments[i].direction, stretch);
                } else {
                    *rotated = wxyz(rotation * own); // turned further below
                    exact.push(Stretch {
                        row: k,
                        own,
                        scale: binding.scale[g],
                        direction: segments[i].direction,
                        stretch,
                    });
                }
            }
            stretch_rows(exact, quats, scales);
        });
}

/// Re-diagonalise the stretched Gaussians `exact`, LANES at a time: turn their rows of `quats`
/// (which hold `rotation * own`) and set their `scales`. Compiled for AVX2 where the CPU has it,
/// whose square roots and divisions take four f64 lanes per instruction at the rate of two (75 to
/// 62 ns a Gaussian on one thread); nothing is fused, so both give the same bits.
fn stretch_rows(exact: &[Stretch], quats: &mut [[f32; 4]], scales: &mut [[f32; 3]]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        #[target_feature(enable = "avx2")]
        fn wide(exact: &[Stretch], quats: &mut [[f32; 4]], scales: &mut [[f32; 3]]) {
            stretch_groups(exact, quats, scales);
        }
        // SAFETY: the CPU has AVX2, checked just above.
        unsafe { wide(exact, quats, scales) };
        return;
    }
    stretch_groups(exact, quats, scales);
}

#[inline(always)]
fn stretch_groups(exact: &[Stretch], quats: &mut [[f32; 4]], scales: &mut [[f32; 3]]) {
    for group in exact.chunks(LANES) {
        // a short last group repeats its last row in the spare lanes
        let lanes: [&Stretch; LANES] = std::array::from_fn(|l| &group[l.min(group.len() - 1)]);
        for (stretch, (turn, new_scale)) in group.iter().zip(stretched(lanes)) {
            quats[stretch.row] = wxyz((quat(quats[stretch.row]) * turn).normalize());
            scales[stretch.row] = new_scale;
        }
    }
}

/// The scales of a Gaussian stretched by `stretch` along `direction`, each own axis `e_k`
/// lengthened to `|(I + ε d dᵀ) e_k|` (`d` the direction in the Gaussian's axes).
fn stretched_axes(own: Quat, scale: [f32; 3], direction: Vec3, stretch: f32) -> [f32; 3] {
    let d = own.inverse() * direction;
    let grow = stretch * stretch - 1.0; // |(I + ε d dᵀ) e_k|² = 1 + (2ε + ε²) d_k²
    [
        scale[0] * (1.0 + grow * d.x * d.x).sqrt(),
        scale[1] * (1.0 + grow * d.y * d.y).sqrt(),
        scale[2] * (1.0 + grow * d.z * d.z).sqrt(),
    ]
}

/// One Gaussian to stretch exactly: its row in the chunk, its rotation and scales at rest, and the
/// stretch of its segment along the segment's rest direction.
struct Stretch {
    row: usize,
    own: Quat,
    scale: [f32; 3],
    direction: Vec3,
    stretch: f32,
}

/// Gaussians re-diagonalised together. One alone is a chain of dependent square roots and
/// divisions, each waiting for the last; independent lanes overlap them and vectorise
/// (docs/deformation.md, "Speed": on one thread 108 ns a Gaussian one at a time, 75 ns eight at a
/// time).
const LANES: usize = 8;
type Lanes = [f64; LANES];

/// Per lane, a Gaussian (rotation `own`, scales `scale`) stretched by `stretch` along the world
/// direction `direction`: the rotation to apply after `own` and the new scales. In the Gaussian's
/// own axes the stretched covariance is `M Mᵀ` with `M = (I + ε d dᵀ) S`, nearly diagonal for a
/// modest stretch, so two Jacobi sweeps diagonalise it (to 3e-4 of the covariance, measured in its
/// own metric, for stretches up to 30 %, thin Gaussians included). In f64: squaring the scales of a
/// thin Gaussian (1e-3 of its length) would lose its thickness in f32.
#[inline(always)]
fn stretched(lanes: [&Stretch; LANES]) -> [(Quat, [f32; 3]); LANES] {
    // in the Gaussian's own axes, per lane: the direction d, the scales s and ε
    let mut d = [[0.0; LANES]; 3];
    let mut s = [[0.0; LANES]; 3];
    let mut e = [0.0; LANES];
    for (l, g) in lanes.iter().enumerate() {
        let direction = g.own.inverse() * g.direction;
        for k in 0..3 {
            d[k][l] = f64::from(direction[k]);
            s[k][l] = f64::from(g.scale[k]);
        }
        e[l] = f64::from(g.stretch) - 1.0;
    }
    // M = S + ε d uᵀ with u = S d, so A = M Mᵀ = S² + ε (w dᵀ + d wᵀ) + ε² |u|² d dᵀ with w = S u
    let mut a = [[[0.0; LANES]; 3]; 3];
    for l in 0..LANES {
        let u = [s[0][l] * d[0][l], s[1][l] * d[1][l], s[2][l] * d[2][l]];
        let w = [s[0][l] * u[0], s[1][l] * u[1], s[2][l] * u[2]];
        let uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
        for i in 0..3 {
            for j in 0..3 {
                let diagonal = if i == j { s[i][l] * s[i][l] } else { 0.0 };
                a[i][j][l] = diagonal + e[l] * (w[i] * d[j][l] + d[i][l] * w[j]) + e[l] * e[l] * uu * d[i][l] * d[j][l];
            }
        }
    }
    let (vectors, values) = jacobi_eigen(a);
    // the singular values of M are at least min(1, stretch) * min(S), which also keeps them > 0
    let floor: Lanes = std::array::from_fn(|l| (1.0 + e[l]).min(1.0) * s[0][l].min(s[1][l]).min(s[2][l]));
    let scales = values.map(|v| -> Lanes { std::array::from_fn(|l| v[l].max(0.0).sqrt().max(floor[l])) });
    let turns = rotation_quats(&vectors);
    std::array::from_fn(|l| (turns[l], scales.map(|v| v[l] as f32)))
}

/// Per lane, the unit quaternion (to rounding; the caller normalises what it is multiplied into) of
/// the rotation whose columns are `v[column][row]`. Jacobi turns a nearly diagonal matrix by less
/// than a right angle, so `w` is large (`4 w² = 1 + trace >= 1`) and one formula serves every lane;
/// a lane turned further takes glam's, which picks the largest component.
#[inline(always)]
fn rotation_quats(v: &[[Lanes; 3]; 3]) -> [Quat; LANES] {
    let four_wsq: Lanes = std::array::from_fn(|l| 1.0 + v[0][0][l] + v[1][1][l] + v[2][2][l]);
    if four_wsq.iter().all(|&f| f >= 1.0) {
        let inv: Lanes = std::array::from_fn(|l| 0.5 / four_wsq[l].sqrt());
        let x: Lanes = std::array::from_fn(|l| (v[1][2][l] - v[2][1][l]) * inv[l]);
        let y: Lanes = std::array::from_fn(|l| (v[2][0][l] - v[0][2][l]) * inv[l]);
        let z: Lanes = std::array::from_fn(|l| (v[0][1][l] - v[1][0][l]) * inv[l]);
        let w: Lanes = std::array::from_fn(|l| four_wsq[l] * inv[l]);
        return std::array::from_fn(|l| DQuat::from_xyzw(x[l], y[l], z[l], w[l]).as_quat());
    }
    std::array::from_fn(|l| {
        let column = |k: usize| glam::DVec3::new(v[k][0][l], v[k][1][l], v[k][2][l]);
        DQuat::from_mat3(&DMat3::from_cols(column(0), column(1), column(2))).as_quat()
    })
}

const JACOBI_SWEEPS: usize = 2;

/// Per lane, the eigenvectors (columns of a proper rotation, `v[column][row]`) and eigenvalues of a
/// symmetric 3x3 matrix (`a[i][j]`) that is nearly diagonal, by two sweeps of cyclic Jacobi
/// rotations. Each rotation zeroes `a_pq` and touches only what it changes (the symmetric update:
/// two diagonal entries, the pair in the third row, and two columns of the eigenvectors), a third
/// of the work of rotating whole rows and columns.
#[inline(always)]
fn jacobi_eigen(mut a: [[Lanes; 3]; 3]) -> ([[Lanes; 3]; 3], [Lanes; 3]) {
    let mut v = [[[0.0; LANES]; 3]; 3];
    for (k, column) in v.iter_mut().enumerate() {
        column[k] = [1.0; LANES];
    }
    for _sweep in 0..JACOBI_SWEEPS {
        for (p, q, r) in [(0, 1, 2), (0, 2, 1), (1, 2, 0)] {
            // each step a plain loop over the lanes, so that it vectorises
            let apq = a[p][q];
            let mut t = [0.0; LANES];
            for l in 0..LANES {
                // t = sign(θ) / (|θ| + sqrt(θ² + 1)) with θ = δ / 2a_pq, multiplied through by 2|a_pq|
                let delta = a[q][q][l] - a[p][p][l];
                let hypot = (delta * delta + 4.0 * apq[l] * apq[l]).sqrt();
                let root = 2.0 * apq[l] * 1.0_f64.copysign(delta) / (delta.abs() + hypot);
                t[l] = if apq[l] == 0.0 { 0.0 } else { root }; // a_pq already 0: no rotation
            }
            let c: Lanes = std::array::from_fn(|l| 1.0 / (t[l] * t[l] + 1.0).sqrt());
            let s: Lanes = std::array::from_fn(|l| t[l] * c[l]);
            // A <- Jᵀ A J, J the rotation by (c, s) in the (p, q) plane
            for l in 0..LANES {
                a[p][p][l] -= t[l] * apq[l];
                a[q][q][l] += t[l] * apq[l];
            }
            (a[p][q], a[q][p]) = ([0.0; LANES], [0.0; LANES]);
            let (arp, arq) = (a[r][p], a[r][q]);
            let new_rp: Lanes = std::array::from_fn(|l| c[l] * arp[l] - s[l] * arq[l]);
            let new_rq: Lanes = std::array::from_fn(|l| s[l] * arp[l] + c[l] * arq[l]);
            (a[r][p], a[p][r], a[r][q], a[q][r]) = (new_rp, new_rp, new_rq, new_rq);
            let (column_p, column_q) = (v[p], v[q]);
            v[p] = std::array::from_fn(|k| std::array::from_fn(|l| c[l] * column_p[k][l] - s[l] * column_q[k][l]));
            v[q] = std::array::from_fn(|k| std::array::from_fn(|l| s[l] * column_p[k][l] + c[l] * column_q[k][l]));
        }
    }
    (v, [a[0][0], a[1][1], a[2][2]])
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use glam::Mat3;

    fn straight_rod(n: usize) -> Vec<[f32; 3]> {
        (0..n).map(|i| [i as f32 * 0.1, 0.0, 0.0]).collect()
    }

    const ID: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

    /// A binding whose scale and weight arrays are `n` copies of `scale` and 1.
    struct Rows {
        scale: Vec<[f32; 3]>,
        weight: Vec<f32>,
    }

    fn rows(n: usize) -> Rows {
        Rows { scale: vec![[0.02, 0.01, 0.005]; n], weight: vec![1.0; n] }
    }

    fn covariance(q: [f32; 4], s: [f32; 3]) -> Mat3 {
        let r = Mat3::from_quat(quat(q));
        r * Mat3::from_diagonal(Vec3::from(s) * Vec3::from(s)) * r.transpose()
    }

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
        let r = rows(100);
        let binding = Binding {
            segment: &segment,
            t: &t,
            offset: &offset,
            rotation: &rotation,
            scale: &r.scale,
            weight: &r.weight,
        };
        let pose = Pose { rest: &rest, deformed: &deformed, rotation: &rotations };
        let out = skin(&pose, &binding).unwrap();
        for g in 0..100 {
            let i = segment[g] as usize;
            let rest_centre = Vec3::from(rest[i]).lerp(Vec3::from(rest[i + 1]), t[g]) + Vec3::from(offset[g]);
            assert!((Vec3::from(out.means[g]) - (motion * rest_centre + shift)).length() < 1e-5);
            assert!(quat(out.quats[g]).angle_between(motion * quat(rotation[g])) < 1e-3);
            assert_eq!(out.scales[g], r.scale[g]);
        }
    }

    #[test]
    fn at_rest_nothing_moves() {
        let rest = straight_rod(4);
        let r = rows(2);
        let binding = Binding {
            segment: &[0, 2],
            t: &[0.0, 1.0],
            offset: &[[0.0, 0.01, 0.0], [0.0, 0.0, 0.02]],
            rotation: &[ID; 2],
            scale: &r.scale,
            weight: &r.weight,
        };
        let out = skin(&Pose { rest: &rest, deformed: &rest, rotation: &[ID; 4] }, &binding).unwrap();
        assert_eq!(out.means[0], [0.0, 0.01, 0.0]);
        assert!((Vec3::from(out.means[1]) - Vec3::new(0.3, 0.0, 0.02)).length() < 1e-7);
    }

    #[test]
    fn a_shared_vertex_gives_both_segments_the_same_transform() {
        // bend at vertex 1: the end of segment 0 and the start of segment 1 must coincide
        let rest = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        let deformed = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let rotations = [ID, wxyz(Quat::from_rotation_z(0.785)), wxyz(Quat::from_rotation_z(1.571))];
        let offset = [[0.0, 0.0, 0.1], [0.0, 0.0, 0.1]];
        let r = rows(2);
        let binding = Binding {
            segment: &[0, 1],
            t: &[1.0, 0.0],
            offset: &offset,
            rotation: &[ID; 2],
            scale: &r.scale,
            weight: &r.weight,
        };
        let out = skin(&Pose { rest: &rest, deformed: &deformed, rotation: &rotations }, &binding).unwrap();
        assert!((Vec3::from(out.means[0]) - Vec3::from(out.means[1])).length() < 1e-6);
        assert!(quat(out.quats[0]).angle_between(quat(out.quats[1])) < 1e-6);
    }

    #[test]
    fn weight_moves_that_fraction_of_the_way() {
        let rest = straight_rod(3);
        let deformed: Vec<[f32; 3]> = rest.iter().map(|p| [p[0], p[1] + 1.0, p[2]]).collect();
        let turn = wxyz(Quat::from_rotation_x(0.8));
        let binding = Binding {
            segment: &[1, 1, 1],
            t: &[0.5; 3],
            offset: &[[0.0, 0.0, 0.0]; 3],
            rotation: &[ID; 3],
            scale: &[[0.01; 3]; 3],
            weight: &[0.0, 0.25, 1.0],
        };
        let out = skin(&Pose { rest: &rest, deformed: &deformed, rotation: &[turn; 3] }, &binding).unwrap();
        assert_eq!(out.means[0], [0.15, 0.0, 0.0]);
        assert!((out.means[1][1] - 0.25).abs() < 1e-6 && (out.means[2][1] - 1.0).abs() < 1e-6);
        assert!(quat(out.quats[0]).angle_between(Quat::IDENTITY) < 1e-6);
        assert!((quat(out.quats[1]).angle_between(Quat::IDENTITY) - 0.2).abs() < 0.02);
    }

    #[test]
    fn stretch_scales_the_covariance_along_the_rest_direction() {
        // Segment 0 stretched by 1.5 along x; a tilted, anisotropic Gaussian bound to it.
        let rest = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let deformed = [[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]];
        let own = wxyz(Quat::from_euler(glam::EulerRot::XYZ, 0.4, 0.9, -0.3));
        let scale = [0.03, 0.01, 0.004];
        let binding = Binding {
            segment: &[0],
            t: &[0.5],
            offset: &[[0.0; 3]],
            rotation: &[own],
            scale: &[scale],
            weight: &[1.0],
        };
        let out = skin(&Pose { rest: &rest, deformed: &deformed, rotation: &[ID; 2] }, &binding).unwrap();
        let f = Mat3::from_diagonal(Vec3::new(1.5, 1.0, 1.0));
        let want = f * covariance(own, scale) * f.transpose();
        let got = covariance(out.quats[0], out.scales[0]);
        let error = (0..3).map(|c| (got.col(c) - want.col(c)).abs().max_element()).fold(0.0, f32::max);
        assert!(error < 1e-6 * 1e2 * want.col(0).x, "{got:?} vs {want:?}");
        assert!((Vec3::from(out.means[0]) - Vec3::new(0.75, 0.0, 0.0)).length() < 1e-6);
    }

    #[test]
    fn jacobi_diagonalises_symmetric_matrices_lane_by_lane() {
        // a strongly stretched, tilted Gaussian in its own axes (far from diagonal), a diagonal
        // matrix (every rotation the identity), and two with equal eigenvalues
        let d = Vec3::new(0.6, -0.5, 0.62).normalize();
        let s = Mat3::from_diagonal(Vec3::new(1.0, 0.3, 0.001));
        let m = s + 0.3 * Mat3::from_cols(d * d.x, d * (d.y * 0.3), d * (d.z * 0.001));
        let turn = Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.2, 0.9));
        let matrices = [
            (m * m.transpose()).as_dmat3(),
            DMat3::from_diagonal(glam::DVec3::new(2.0, 0.5, 1e-6)),
            (turn * Mat3::from_diagonal(Vec3::new(1.0, 1.0, 0.01)) * turn.transpose()).as_dmat3(),
            DMat3::IDENTITY,
        ];
        let mut lanes = [[[0.0; LANES]; 3]; 3];
        for (l, matrix) in matrices.iter().enumerate() {
            for (i, row) in lanes.iter_mut().enumerate() {
                for (j, entry) in row.iter_mut().enumerate() {
                    entry[l] = matrix.col(j)[i];
                }
            }
        }
        let (vectors, values) = jacobi_eigen(lanes);
        for (l, matrix) in matrices.iter().enumerate() {
            let column = |k: usize| glam::DVec3::new(vectors[k][0][l], vectors[k][1][l], vectors[k][2][l]);
            let v = DMat3::from_cols(column(0), column(1), column(2));
            let back =
                v * DMat3::from_diagonal(glam::DVec3::new(values[0][l], values[1][l], values[2][l])) * v.transpose();
            for c in 0..3 {
                assert!((back.col(c) - matrix.col(c)).abs().max_element() < 1e-5, "lane {l}: {back:?} vs {matrix:?}");
            }
            assert!((v.determinant() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn rotation_quats_match_glam_for_small_and_large_turns() {
        // all lanes turned by less than a right angle (the shared formula), then one lane turned
        // by 170 degrees (glam's formula for every lane)
        let turns: Vec<Quat> = (0..LANES)
            .map(|l| Quat::from_axis_angle(Vec3::new(1.0, l as f32, 2.0 - l as f32).normalize(), 0.2 * l as f32))
            .collect();
        for large in [false, true] {
            let mut turns = turns.clone();
            if large {
                turns[3] = Quat::from_axis_angle(Vec3::new(0.3, -0.8, 0.5).normalize(), 170f32.to_radians());
            }
            let mut v = [[[0.0; LANES]; 3]; 3];
            for (l, turn) in turns.iter().enumerate() {
                let m = DMat3::from_quat(turn.as_dquat());
                for (k, column) in v.iter_mut().enumerate() {
                    for (row, entry) in column.iter_mut().enumerate() {
                        entry[l] = m.col(k)[row];
                    }
                }
            }
            for (got, want) in rotation_quats(&v).iter().zip(&turns) {
                assert!(got.dot(*want).abs() > 1.0 - 1e-6, "{got:?} vs {want:?}");
                assert!((got.length() - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn the_avx2_build_of_the_stretch_gives_the_same_bits() {
        // 37 Gaussians: four full groups of lanes and a short one
        let exact: Vec<Stretch> = (0..37)
            .map(|k| {
                let f = k as f32;
                Stretch {
                    row: k,
                    own: Quat::from_euler(glam::EulerRot::XYZ, 0.3 * f, -0.7 * f, 0.11 * f),
                    scale: [0.01 + 0.001 * f, 0.002 * (1.0 + (f * 0.7).sin().abs()), 1e-4 * (1.0 + f)],
                    direction: Vec3::new(1.0, 0.2 * f.cos(), 0.1 * f).normalize(),
                    stretch: 1.05 + 0.01 * f,
                }
            })
            .collect();
        let start: Vec<[f32; 4]> = (0..37).map(|k| wxyz(Quat::from_rotation_z(0.1 * k as f32))).collect();
        let (mut quats, mut scales) = (start.clone(), vec![[0.0; 3]; 37]);
        stretch_rows(&exact, &mut quats, &mut scales); // AVX2 where the CPU has it
        let (mut plain_quats, mut plain_scales) = (start, vec![[0.0; 3]; 37]);
        stretch_groups(&exact, &mut plain_quats, &mut plain_scales);
        assert_eq!(quats, plain_quats);
        assert_eq!(scales, plain_scales);
        assert!(scales.iter().flatten().all(|s| s.is_finite() && *s > 0.0));
    }

    #[test]
    fn frame_rotations_carry_the_rest_frames_to_the_frames_now() {
        let rest = [[0.9_f64, 0.1, -0.3, 0.2], [1.0, 0.0, 0.0, 0.0]];
        let now = [[0.2_f64, 0.7, 0.1, -0.5], [0.0, 0.0, 1.0, 0.0]];
        for ((r, n), q) in rest.iter().zip(&now).zip(frame_rotations(&rest, &now)) {
            let to = |q: &[f64; 4]| glam::DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
            let turn = glam::DQuat::from_xyzw(f64::from(q[1]), f64::from(q[2]), f64::from(q[3]), f64::from(q[0]));
            let carried = turn * to(r);
            assert!(carried.dot(to(n)).abs() > 1.0 - 1e-6, "{carried:?} vs {:?}", to(n));
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let r = rows(1);
        let pose3 = |rest: &'static [[f32; 3]]| rest;
        let rod = straight_rod(3);
        let b = Binding {
            segment: &[3],
            t: &[0.5],
            offset: &[[0.0; 3]],
            rotation: &[ID],
            scale: &r.scale,
            weight: &r.weight,
        };
        let pose = Pose { rest: &rod, deformed: &rod, rotation: &[ID; 3] };
        assert_eq!(skin(&pose, &b).unwrap_err(), SkinError::SegmentOutOfRange { index: 0, segment: 3, segments: 2 });
        assert!(matches!(skin(&Pose { rotation: &[ID; 2], ..pose }, &b), Err(SkinError::RotationCount { .. })));
        let one = pose3(&[[0.0; 3]]);
        assert!(matches!(
            skin(&Pose { rest: one, deformed: one, rotation: &[ID] }, &b),
            Err(SkinError::TooFewVertices(1))
        ));
        let mut bad = straight_rod(3);
        bad[1][0] = f32::NAN;
        let ok = Binding {
            segment: &[0],
            t: &[0.5],
            offset: &[[0.0; 3]],
            rotation: &[ID],
            scale: &r.scale,
            weight: &r.weight,
        };
        assert_eq!(
            skin(&Pose { deformed: &bad, ..pose }, &ok).unwrap_err(),
            SkinError::NonFiniteVertex { which: "deformed", index: 1 }
        );
        let flat = [[0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]];
        assert_eq!(skin(&Pose { rest: &flat, ..pose }, &ok).unwrap_err(), SkinError::ZeroLengthSegment(0));
        let short = Binding { weight: &[], ..ok };
        assert!(matches!(skin(&pose, &short), Err(SkinError::BindingLengths { .. })));
    }
}
