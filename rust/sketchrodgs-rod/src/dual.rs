//! Forward-mode dual numbers with 8 tangent directions. The bending/twisting stencil of a
//! vertex has 8 local variables (the two edge vectors and two twist angles); evaluating the
//! closed-form gradient (Bergou 2008, Sec. 7) in duals gives its Jacobian, the Hessian, without
//! hand-deriving another page of formulas.

use glam::DVec3;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Number of local variables of a bending/twisting stencil: `e` (3), `f` (3), `theta_e`, `theta_f`.
pub const NV: usize = 8;

/// A scalar with its derivatives along the [`NV`] local variables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct D {
    pub v: f64,
    pub d: [f64; NV],
}

impl D {
    pub const fn cst(v: f64) -> Self {
        Self { v, d: [0.0; NV] }
    }

    #[inline]
    pub fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let k = 0.5 / s;
        let mut d = self.d;
        d.iter_mut().for_each(|x| *x *= k);
        Self { v: s, d }
    }

    #[inline]
    pub fn recip(self) -> Self {
        let r = 1.0 / self.v;
        let k = -r * r;
        let mut d = self.d;
        d.iter_mut().for_each(|x| *x *= k);
        Self { v: r, d }
    }

    #[inline]
    pub fn scale(self, k: f64) -> Self {
        let mut d = self.d;
        d.iter_mut().for_each(|x| *x *= k);
        Self { v: self.v * k, d }
    }
}

impl Add for D {
    type Output = D;
    #[inline]
    fn add(self, o: D) -> D {
        let mut d = self.d;
        d.iter_mut().zip(o.d).for_each(|(a, b)| *a += b);
        D { v: self.v + o.v, d }
    }
}

impl Sub for D {
    type Output = D;
    #[inline]
    fn sub(self, o: D) -> D {
        let mut d = self.d;
        d.iter_mut().zip(o.d).for_each(|(a, b)| *a -= b);
        D { v: self.v - o.v, d }
    }
}

impl Mul for D {
    type Output = D;
    #[inline]
    fn mul(self, o: D) -> D {
        let mut d = [0.0; NV];
        for k in 0..NV {
            d[k] = self.d[k] * o.v + self.v * o.d[k];
        }
        D { v: self.v * o.v, d }
    }
}

impl Div for D {
    type Output = D;
    #[inline]
    #[allow(clippy::suspicious_arithmetic_impl)] // a / b = a * (1 / b)
    fn div(self, o: D) -> D {
        self * o.recip()
    }
}

impl Neg for D {
    type Output = D;
    #[inline]
    fn neg(self) -> D {
        self.scale(-1.0)
    }
}

impl Add<f64> for D {
    type Output = D;
    #[inline]
    fn add(self, o: f64) -> D {
        D { v: self.v + o, d: self.d }
    }
}

impl Sub<f64> for D {
    type Output = D;
    #[inline]
    fn sub(self, o: f64) -> D {
        D { v: self.v - o, d: self.d }
    }
}

impl Mul<f64> for D {
    type Output = D;
    #[inline]
    fn mul(self, o: f64) -> D {
        self.scale(o)
    }
}

/// A 3-vector of duals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct V {
    pub x: D,
    pub y: D,
    pub z: D,
}

impl V {
    /// A vector whose components are the local variables `k..k+3`.
    #[inline]
    pub fn seed(v: DVec3, k: usize) -> Self {
        let mut x = D::cst(v.x);
        let mut y = D::cst(v.y);
        let mut z = D::cst(v.z);
        x.d[k] = 1.0;
        y.d[k + 1] = 1.0;
        z.d[k + 2] = 1.0;
        Self { x, y, z }
    }

    /// A vector with value `v` and derivative `dv[k]` along local variable `k`.
    #[inline]
    pub fn from_parts(v: DVec3, dv: &[DVec3; NV]) -> Self {
        let mut out = Self { x: D::cst(v.x), y: D::cst(v.y), z: D::cst(v.z) };
        for (k, g) in dv.iter().enumerate() {
            out.x.d[k] = g.x;
            out.y.d[k] = g.y;
            out.z.d[k] = g.z;
        }
        out
    }

    #[inline]
    pub fn value(&self) -> DVec3 {
        DVec3::new(self.x.v, self.y.v, self.z.v)
    }

    /// Derivative along local variable `k`.
    #[inline]
    pub fn deriv(&self, k: usize) -> DVec3 {
        DVec3::new(self.x.d[k], self.y.d[k], self.z.d[k])
    }

    #[inline]
    pub fn dot(self, o: V) -> D {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    #[inline]
    pub fn cross(self, o: V) -> V {
        V { x: self.y * o.z - self.z * o.y, y: self.z * o.x - self.x * o.z, z: self.x * o.y - self.y * o.x }
    }

    #[inline]
    pub fn scale(self, k: D) -> V {
        V { x: self.x * k, y: self.y * k, z: self.z * k }
    }

    #[inline]
    pub fn length(self) -> D {
        self.dot(self).sqrt()
    }
}

impl Add for V {
    type Output = V;
    #[inline]
    fn add(self, o: V) -> V {
        V { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }
}

impl Sub for V {
    type Output = V;
    #[inline]
    fn sub(self, o: V) -> V {
        V { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }
}

impl Neg for V {
    type Output = V;
    #[inline]
    fn neg(self) -> V {
        V { x: -self.x, y: -self.y, z: -self.z }
    }
}
