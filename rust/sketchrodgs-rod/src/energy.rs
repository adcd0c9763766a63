//! Elastic energy of one stencil with its gradient and Hessian (Bergou et al. 2008/2010).
//!
//! Stretching lives on an edge; bending and twisting on an interior vertex `i` and its two
//! edges `e = x_i - x_{i-1}`, `f = x_{i+1} - x_i`. Derivatives are taken in the frame chart
//! where each material frame follows its edge by parallel transport (minimal rotation) plus its
//! twist angle, which is what the closed-form DER gradients assume. The Hessian is the
//! symmetric part of the Jacobian of those gradients, evaluated with dual numbers; in that chart
//! it is the exact Hessian of the energy (the antisymmetric part is the holonomy of transport).

use crate::dual::{D, NV, V};
use glam::DVec3;

/// Stretching of one edge: `E = EA/2 * (|e|/l0 - 1)^2 * l0`. Returns the energy, the gradient
/// with respect to `e` and the 3x3 Hessian (row-major). The exact Hessian is indefinite under
/// compression (its transverse part `EA s / |e|` turns negative); `project` drops that negative
/// part, which keeps Newton directions well scaled when a released rod crumples.
pub fn stretch(e: DVec3, rest_len: f64, ea: f64, project: bool) -> (f64, DVec3, [[f64; 3]; 3]) {
    let len = e.length();
    let t = e / len;
    let s = len / rest_len - 1.0;
    let energy = 0.5 * ea * s * s * rest_len;
    let grad = ea * s * t;
    let a = ea / rest_len;
    let b = if project { ea * s.max(0.0) / len } else { ea * s / len };
    let mut h = [[0.0; 3]; 3];
    let tv = t.to_array();
    for (r, row) in h.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            let tt = tv[r] * tv[c];
            let id = if r == c { 1.0 } else { 0.0 };
            *v = a * tt + b * (id - tt);
        }
    }
    (energy, grad, h)
}

/// Inputs of the bending/twisting stencil at an interior vertex.
#[derive(Debug, Clone, Copy)]
pub struct BendTwistInput {
    /// Edge vector `e = x_i - x_{i-1}`.
    pub e: DVec3,
    /// Edge vector `f = x_{i+1} - x_i`.
    pub f: DVec3,
    /// Material frame `(m1, m2)` of edge `e`.
    pub me: (DVec3, DVec3),
    /// Material frame `(m1, m2)` of edge `f`.
    pub mf: (DVec3, DVec3),
    /// Twist `m_i = theta_i - theta_{i-1} + m_ref` (rad).
    pub twist: f64,
    /// Rest material curvatures in the frame of `e` then of `f`, see [`material_curvature`].
    pub rest_kappa: [f64; 4],
    /// Rest twist.
    pub rest_twist: f64,
    /// `EI / l_i` with `l_i` the rest Voronoi length.
    pub bend_k: f64,
    /// `GJ / l_i`.
    pub twist_k: f64,
}

/// Material curvatures of vertex `i` in each adjacent edge's frame (Bergou 2008, Sec. 4.2):
/// `omega^j = (kb . m2^j, -kb . m1^j)` for `j = e, f`, returned as `[omega^e, omega^f]`.
/// For a round rod with straight rest shape the bending energy then depends on `|kb|` only,
/// not on the frames; curvatures in the averaged frame would make bending pull on twist
/// (energy ~ cos^2 of half the relative twist), an indefinite Hessian at sharp bends.
pub fn material_curvature(e: DVec3, f: DVec3, me: (DVec3, DVec3), mf: (DVec3, DVec3)) -> [f64; 4] {
    let te = e.normalize();
    let tf = f.normalize();
    let kb = 2.0 * te.cross(tf) / (1.0 + te.dot(tf));
    [kb.dot(me.1), -kb.dot(me.0), kb.dot(mf.1), -kb.dot(mf.0)]
}

/// Bending and twisting energy of the stencil, no derivatives (for line searches):
/// `EI/(4 l) sum_j |omega^j - omega0^j|^2` and `GJ/(2 l) (m - m0)^2`.
pub fn bend_twist_parts(inp: &BendTwistInput) -> (f64, f64) {
    let w = material_curvature(inp.e, inp.f, inp.me, inp.mf);
    let mut sq = 0.0;
    for k in 0..4 {
        let d = w[k] - inp.rest_kappa[k];
        sq += d * d;
    }
    let dm = inp.twist - inp.rest_twist;
    (0.25 * inp.bend_k * sq, 0.5 * inp.twist_k * dm * dm)
}

/// Energy, gradient and Hessian of the bending/twisting stencil in the local variables
/// `y = (e, f, theta_e, theta_f)` (8 of them). The Hessian is symmetric.
pub fn bend_twist(inp: &BendTwistInput) -> (f64, [f64; NV], [[f64; NV]; NV]) {
    let e = V::seed(inp.e, 0);
    let f = V::seed(inp.f, 3);
    let ne = e.length();
    let nf = f.length();
    let te = e.scale(ne.recip());
    let tf = f.scale(nf.recip());
    // Material frames move with their edge by minimal rotation, and turn with their angle:
    // dm1 = -(m1 . dt) t + m2 dtheta, dm2 = -(m2 . dt) t - m1 dtheta.
    let frame = |t: &V, m: (DVec3, DVec3), k_theta: usize| -> (V, V) {
        let tv = t.value();
        let mut d1 = [DVec3::ZERO; NV];
        let mut d2 = [DVec3::ZERO; NV];
        for k in 0..NV {
            let dt = t.deriv(k);
            d1[k] = -(m.0.dot(dt)) * tv;
            d2[k] = -(m.1.dot(dt)) * tv;
        }
        d1[k_theta] += m.1;
        d2[k_theta] -= m.0;
        (V::from_parts(m.0, &d1), V::from_parts(m.1, &d2))
    };
    let frames = [(frame(&te, inp.me, 6), 6), (frame(&tf, inp.mf, 7), 7)];

    let chi = te.dot(tf) + 1.0;
    let inv_chi = chi.recip();
    let kb = te.cross(tf).scale(inv_chi.scale(2.0));
    let tt = (te + tf).scale(inv_chi);
    let inv_ne = ne.recip();
    let inv_nf = nf.recip();
    let two_inv_chi = inv_chi.scale(2.0);

    let mut g = [D::cst(0.0); NV];
    let mut energy = 0.0;
    // Closed-form gradients of the material curvatures (Bergou 2008, Sec. 7.1) in each
    // edge's frame, evaluated in duals: their derivatives are the Hessian.
    for (j, ((m1, m2), k_theta)) in frames.iter().enumerate() {
        let w1 = kb.dot(*m2);
        let w2 = -kb.dot(*m1);
        let d1t = m1.scale(two_inv_chi);
        let d2t = m2.scale(two_inv_chi);
        let dw1_de = (tf.cross(d2t) - tt.scale(w1)).scale(inv_ne);
        let dw1_df = (-(te.cross(d2t)) - tt.scale(w1)).scale(inv_nf);
        let dw2_de = (-(tf.cross(d1t)) - tt.scale(w2)).scale(inv_ne);
        let dw2_df = (te.cross(d1t) - tt.scale(w2)).scale(inv_nf);
        let dw1_dth = -kb.dot(*m1);
        let dw2_dth = -kb.dot(*m2);
        let c1 = w1.v - inp.rest_kappa[2 * j];
        let c2 = w2.v - inp.rest_kappa[2 * j + 1];
        energy += 0.25 * inp.bend_k * (c1 * c1 + c2 * c2);
        let r1 = (w1 - inp.rest_kappa[2 * j]).scale(0.5 * inp.bend_k);
        let r2 = (w2 - inp.rest_kappa[2 * j + 1]).scale(0.5 * inp.bend_k);
        for k in 0..3 {
            g[k] = g[k] + r1 * comp(&dw1_de, k) + r2 * comp(&dw2_de, k);
            g[k + 3] = g[k + 3] + r1 * comp(&dw1_df, k) + r2 * comp(&dw2_df, k);
        }
        g[*k_theta] = g[*k_theta] + r1 * dw1_dth + r2 * dw2_dth;
    }

    // Reference twist gradient: d m / d e = kb / (2|e|), d m / d f = kb / (2|f|) (Bergou 2010).
    let dm_de = kb.scale(inv_ne.scale(0.5));
    let dm_df = kb.scale(inv_nf.scale(0.5));
    let mut twist = D::cst(inp.twist);
    for k in 0..3 {
        twist.d[k] = comp(&dm_de, k).v;
        twist.d[k + 3] = comp(&dm_df, k).v;
    }
    twist.d[6] = -1.0;
    twist.d[7] = 1.0;
    let rm = (twist - inp.rest_twist).scale(inp.twist_k);
    for k in 0..3 {
        g[k] = g[k] + rm * comp(&dm_de, k);
        g[k + 3] = g[k + 3] + rm * comp(&dm_df, k);
    }
    g[6] = g[6] - rm;
    g[7] = g[7] + rm;
    let dm = inp.twist - inp.rest_twist;
    energy += 0.5 * inp.twist_k * dm * dm;

    let mut grad = [0.0; NV];
    let mut hess = [[0.0; NV]; NV];
    for a in 0..NV {
        grad[a] = g[a].v;
        for b in 0..NV {
            hess[a][b] = 0.5 * (g[a].d[b] + g[b].d[a]);
        }
    }
    (energy, grad, hess)
}

/// The four material curvatures `[omega^e, omega^f]` and the twist of a stencil with their
/// gradients in `y = (e, f, theta_e, theta_f)`: the closed-form DER gradients (Bergou 2008,
/// Sec. 7.1; reference twist, Bergou 2010) in plain arithmetic.
fn curvature_gradients(inp: &BendTwistInput) -> ([f64; 4], [[f64; NV]; 4], [f64; NV]) {
    let ne = inp.e.length();
    let nf = inp.f.length();
    let te = inp.e / ne;
    let tf = inp.f / nf;
    let chi = 1.0 + te.dot(tf);
    let kb = 2.0 * te.cross(tf) / chi;
    let tt = (te + tf) / chi;
    let mut w = [0.0; 4];
    let mut dw = [[0.0; NV]; 4];
    for (j, (m1, m2)) in [inp.me, inp.mf].into_iter().enumerate() {
        let d1t = 2.0 * m1 / chi;
        let d2t = 2.0 * m2 / chi;
        let w1 = kb.dot(m2);
        let w2 = -kb.dot(m1);
        let rows = [
            ((tf.cross(d2t) - w1 * tt) / ne, (-te.cross(d2t) - w1 * tt) / nf, -kb.dot(m1)),
            ((-tf.cross(d1t) - w2 * tt) / ne, (te.cross(d1t) - w2 * tt) / nf, -kb.dot(m2)),
        ];
        for (a, (de, df, dth)) in rows.into_iter().enumerate() {
            let k = 2 * j + a;
            w[k] = if a == 0 { w1 } else { w2 };
            dw[k][..3].copy_from_slice(&de.to_array());
            dw[k][3..6].copy_from_slice(&df.to_array());
            dw[k][6 + j] = dth;
        }
    }
    let de = kb / (2.0 * ne);
    let df = kb / (2.0 * nf);
    let dm = [de.x, de.y, de.z, df.x, df.y, df.z, -1.0, 1.0];
    (w, dw, dm)
}

/// Energy and gradient of the bending/twisting stencil (as [`bend_twist`], without the
/// Hessian).
pub fn bend_twist_gradient(inp: &BendTwistInput) -> (f64, [f64; NV]) {
    let (e, g, _) = bend_twist_gauss_newton(inp, false);
    (e, g)
}

/// Energy, gradient and, when asked, the Gauss-Newton Hessian of the stencil:
/// `EI/(2 l) sum_a grad omega_a grad omega_a^T + GJ/l grad m grad m^T`, positive semidefinite.
/// The solver falls back to it where the exact Hessian is indefinite (sharp folds).
pub fn bend_twist_gauss_newton(inp: &BendTwistInput, with_hessian: bool) -> (f64, [f64; NV], [[f64; NV]; NV]) {
    let (w, dw, dm) = curvature_gradients(inp);
    let kb2 = 0.5 * inp.bend_k;
    let mut energy = 0.0;
    let mut grad = [0.0; NV];
    let mut hess = [[0.0; NV]; NV];
    for a in 0..4 {
        let r = w[a] - inp.rest_kappa[a];
        energy += 0.5 * kb2 * r * r;
        for k in 0..NV {
            grad[k] += kb2 * r * dw[a][k];
        }
    }
    let rm = inp.twist - inp.rest_twist;
    energy += 0.5 * inp.twist_k * rm * rm;
    for k in 0..NV {
        grad[k] += inp.twist_k * rm * dm[k];
    }
    if with_hessian {
        for r in 0..NV {
            for c in 0..NV {
                let mut v = inp.twist_k * dm[r] * dm[c];
                for d in &dw {
                    v += kb2 * d[r] * d[c];
                }
                hess[r][c] = v;
            }
        }
    }
    (energy, grad, hess)
}

fn comp(v: &V, k: usize) -> D {
    match k {
        0 => v.x,
        1 => v.y,
        _ => v.z,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;
    use crate::frames::{material_frame, perpendicular};

    /// Frames of edges e and f after a local perturbation `y` (the chart of `bend_twist`):
    /// parallel transport from the base tangent plus the twist change.
    fn moved(base: &BendTwistInput, dy: &[f64; NV]) -> BendTwistInput {
        let e = base.e + DVec3::new(dy[0], dy[1], dy[2]);
        let f = base.f + DVec3::new(dy[3], dy[4], dy[5]);
        let te0 = base.e.normalize();
        let tf0 = base.f.normalize();
        let te = e.normalize();
        let tf = f.normalize();
        let be = crate::frames::transport(base.me.0, te0, te);
        let bf = crate::frames::transport(base.mf.0, tf0, tf);
        // Reference twist change of the chart: angle between the transported frames.
        let ref0 = {
            let p = crate::frames::transport(base.me.0, te0, tf0);
            crate::frames::signed_angle(p, base.mf.0, tf0)
        };
        let ref1 = {
            let p = crate::frames::transport(be, te, tf);
            crate::frames::signed_angle(p, bf, tf)
        };
        BendTwistInput {
            e,
            f,
            me: material_frame(be, te, dy[6]),
            mf: material_frame(bf, tf, dy[7]),
            twist: base.twist + (ref1 - ref0) + dy[7] - dy[6],
            ..*base
        }
    }

    fn sample() -> BendTwistInput {
        let e = DVec3::new(0.9, 0.2, -0.1);
        let f = DVec3::new(0.7, 0.5, 0.3);
        let te = e.normalize();
        let tf = f.normalize();
        let a = perpendicular(te);
        let b = crate::frames::transport(a, te, tf);
        BendTwistInput {
            e,
            f,
            me: material_frame(a, te, 0.3),
            mf: material_frame(b, tf, -0.2),
            twist: -0.5,
            rest_kappa: [0.1, -0.2, 0.15, -0.1],
            rest_twist: 0.05,
            bend_k: 2.0,
            twist_k: 1.5,
        }
    }

    fn bend_twist_sum(inp: &BendTwistInput) -> f64 {
        let (b, t) = bend_twist_parts(inp);
        b + t
    }

    #[test]
    fn bend_twist_gradient_matches_finite_differences() {
        let base = sample();
        let (e0, g, _) = bend_twist(&base);
        assert!((e0 - bend_twist_sum(&base)).abs() < 1e-12);
        let (e1, g1) = bend_twist_gradient(&base);
        assert!((e1 - e0).abs() < 1e-12);
        for k in 0..NV {
            assert!((g1[k] - g[k]).abs() < 1e-12 * (1.0 + g[k].abs()), "plain vs dual gradient {k}");
        }
        let h = 1e-6;
        for k in 0..NV {
            let mut dy = [0.0; NV];
            dy[k] = h;
            let ep = bend_twist_sum(&moved(&base, &dy));
            dy[k] = -h;
            let em = bend_twist_sum(&moved(&base, &dy));
            let fd = (ep - em) / (2.0 * h);
            assert!((fd - g[k]).abs() < 1e-6 * (1.0 + g[k].abs()), "k={k} fd={fd} an={}", g[k]);
        }
    }

    #[test]
    fn bend_twist_hessian_matches_second_differences() {
        let base = sample();
        let (e0, _, hs) = bend_twist(&base);
        let h = 1e-4;
        for a in 0..NV {
            for b in 0..NV {
                // Polarised second difference of the energy along y_a and y_b.
                let mut pp = [0.0; NV];
                let mut pm = [0.0; NV];
                let mut mp = [0.0; NV];
                let mut mm = [0.0; NV];
                pp[a] += h;
                pp[b] += h;
                pm[a] += h;
                pm[b] -= h;
                mp[a] -= h;
                mp[b] += h;
                mm[a] -= h;
                mm[b] -= h;
                let f = |dy: &[f64; NV]| bend_twist_sum(&moved(&base, dy));
                let fd = (f(&pp) - f(&pm) - f(&mp) + f(&mm)) / (4.0 * h * h);
                let _ = e0;
                assert!((fd - hs[a][b]).abs() < 2e-5 * (1.0 + hs[a][b].abs()), "a={a} b={b} fd={fd} an={}", hs[a][b]);
            }
        }
    }

    #[test]
    fn gauss_newton_hessian_is_positive_semidefinite_with_the_exact_gradient() {
        let base = sample();
        let (e0, g, _) = bend_twist(&base);
        let (e1, g1, h) = bend_twist_gauss_newton(&base, true);
        assert!((e0 - e1).abs() < 1e-12);
        let mut seed = 5u64;
        for k in 0..NV {
            assert!((g[k] - g1[k]).abs() < 1e-12 * (1.0 + g[k].abs()));
        }
        for _ in 0..100 {
            let v: Vec<f64> = (0..NV)
                .map(|_| {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                    (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                })
                .collect();
            let q: f64 = (0..NV).map(|r| (0..NV).map(|c| v[r] * h[r][c] * v[c]).sum::<f64>()).sum();
            assert!(q >= -1e-12);
        }
    }

    #[test]
    fn stretch_derivatives_match_finite_differences() {
        let e = DVec3::new(0.3, -1.2, 0.4);
        let (l0, ea) = (1.1, 3.0);
        let (_, g, hm) = stretch(e, l0, ea, false);
        let h = 1e-6;
        for k in 0..3 {
            let mut d = DVec3::ZERO;
            d[k] = h;
            let (ep, gp, _) = stretch(e + d, l0, ea, false);
            let (em, gm, _) = stretch(e - d, l0, ea, false);
            assert!(((ep - em) / (2.0 * h) - g[k]).abs() < 1e-7);
            for r in 0..3 {
                assert!(((gp[r] - gm[r]) / (2.0 * h) - hm[r][k]).abs() < 1e-6);
            }
        }
    }
}
