//! The pinhole camera the rasteriser renders for (OpenCV axes: x right, y down, z forward).

use glam::{Mat3, Vec3};

use crate::RasterError;

/// Largest image side rendered, in pixels; bigger images are refused rather than allocated.
pub const MAX_IMAGE_SIDE: u32 = 16384;
/// Allowed deviation of the world-to-camera rotation from orthonormal (|R Rᵀ - I|, |det R - 1|).
pub const RIGID_TOLERANCE: f64 = 1e-4;

/// A pinhole camera: `u = fx * x / z + cx`, `v = fy * y / z + cy` in continuous pixel
/// coordinates (pixel `(col, row)` covers `[col, col+1) x [row, row+1)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Image width in pixels (1..=16384).
    pub width: u32,
    /// Image height in pixels (1..=16384).
    pub height: u32,
    /// Focal length along x, pixels (> 0).
    pub fx: f64,
    /// Focal length along y, pixels (> 0).
    pub fy: f64,
    /// Principal point x, continuous pixel coordinates.
    pub cx: f64,
    /// Principal point y, continuous pixel coordinates.
    pub cy: f64,
    /// Row-major rigid world-to-camera transform `[[R | t], [0 0 0 1]]`.
    pub world_to_camera: [[f64; 4]; 4],
    /// Gaussians whose centre has camera z at or below this are culled (> 0; the reference's
    /// `in_frustum` uses [`crate::NEAR_PLANE`], 0.2, whatever the scene's units).
    pub near: f64,
}

impl Camera {
    /// Whether this camera can be rendered (see [`Camera::validate`]).
    pub fn is_valid(&self) -> bool {
        self.validate().is_ok()
    }

    /// Checks the image size, the intrinsics and that `world_to_camera` is rigid.
    pub fn validate(&self) -> Result<(), RasterError> {
        let bad = |field: &'static str, reason: String| Err(RasterError::InvalidCamera { field, reason });
        for (field, side) in [("width", self.width), ("height", self.height)] {
            if side == 0 || side > MAX_IMAGE_SIDE {
                return bad(field, format!("must be in 1..={MAX_IMAGE_SIDE} pixels, got {side}"));
            }
        }
        for (field, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f.is_finite() && f > 0.0) {
                return bad(field, format!("focal length must be finite and > 0, got {f}"));
            }
        }
        for (field, c) in [("cx", self.cx), ("cy", self.cy)] {
            if !c.is_finite() {
                return bad(field, format!("must be finite, got {c}"));
            }
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return bad("near", format!("must be finite and > 0, got {}", self.near));
        }
        let m = &self.world_to_camera;
        if m.iter().flatten().any(|v| !v.is_finite()) {
            return bad("world_to_camera", "contains NaN or infinite values".into());
        }
        if m[3] != [0.0, 0.0, 0.0, 1.0] {
            return bad("world_to_camera", format!("last row must be [0, 0, 0, 1], got {:?}", m[3]));
        }
        let mut worst = 0.0f64;
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| m[i][k] * m[j][k]).sum();
                let expected = if i == j { 1.0 } else { 0.0 };
                worst = worst.max((dot - expected).abs());
            }
        }
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        if worst > RIGID_TOLERANCE || (det - 1.0).abs() > RIGID_TOLERANCE {
            return bad(
                "world_to_camera",
                format!("not a rigid transform (|R R^T - I| = {worst:.3e}, det R = {det:.6})"),
            );
        }
        Ok(())
    }

    /// The camera centre in world coordinates, `-Rᵀ t`.
    pub fn center(&self) -> [f64; 3] {
        let m = &self.world_to_camera;
        let mut c = [0.0; 3];
        for (j, cj) in c.iter_mut().enumerate() {
            *cj = -(0..3).map(|i| m[i][j] * m[i][3]).sum::<f64>();
        }
        c
    }

    /// Number of 16x16 tiles across and down.
    pub fn tile_grid(&self) -> (u32, u32) {
        (self.width.div_ceil(crate::TILE_SIZE), self.height.div_ceil(crate::TILE_SIZE))
    }
}

/// The camera in the f32 form the per-Gaussian work uses.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CameraF32 {
    pub rotation: Mat3,
    pub translation: Vec3,
    pub center: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub near: f32,
    /// Bounds of x/z (and y/z) used only for the EWA Jacobian: gsplat's general form of INRIA's
    /// 1.3 x tan(fov/2) clamp, identical to it when the principal point is the image centre.
    pub lim_x_neg: f32,
    pub lim_x_pos: f32,
    pub lim_y_neg: f32,
    pub lim_y_pos: f32,
}

impl CameraF32 {
    pub fn new(camera: &Camera) -> Self {
        let m = &camera.world_to_camera;
        // glam matrices are column-major: column j holds R[.][j].
        let col = |j: usize| Vec3::new(m[0][j] as f32, m[1][j] as f32, m[2][j] as f32);
        let rotation = Mat3::from_cols(col(0), col(1), col(2));
        let translation = col(3);
        let [c0, c1, c2] = camera.center();
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        let tan_fovx = 0.5 * w / camera.fx;
        let tan_fovy = 0.5 * h / camera.fy;
        Self {
            rotation,
            translation,
            center: Vec3::new(c0 as f32, c1 as f32, c2 as f32),
            fx: camera.fx as f32,
            fy: camera.fy as f32,
            cx: camera.cx as f32,
            cy: camera.cy as f32,
            near: camera.near as f32,
            lim_x_neg: (camera.cx / camera.fx + 0.3 * tan_fovx) as f32,
            lim_x_pos: ((w - camera.cx) / camera.fx + 0.3 * tan_fovx) as f32,
            lim_y_neg: (camera.cy / camera.fy + 0.3 * tan_fovy) as f32,
            lim_y_pos: ((h - camera.cy) / camera.fy + 0.3 * tan_fovy) as f32,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    fn identity_camera() -> Camera {
        Camera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
            near: crate::NEAR_PLANE,
        }
    }

    #[test]
    fn valid_camera_passes_and_center_is_minus_rt_t() {
        let mut cam = identity_camera();
        cam.world_to_camera[0][3] = 1.0;
        cam.world_to_camera[2][3] = -2.0;
        assert!(cam.is_valid());
        assert_eq!(cam.center(), [-1.0, 0.0, 2.0]);
    }

    #[test]
    fn degenerate_cameras_are_refused_with_the_field_named() {
        type Mutation = fn(&mut Camera);
        let cases: Vec<(&str, Mutation)> = vec![
            ("width", |c| c.width = 0),
            ("height", |c| c.height = MAX_IMAGE_SIDE + 1),
            ("fx", |c| c.fx = 0.0),
            ("fy", |c| c.fy = -3.0),
            ("fx", |c| c.fx = f64::NAN),
            ("cx", |c| c.cx = f64::INFINITY),
            ("world_to_camera", |c| c.world_to_camera[0][0] = 2.0),
            ("world_to_camera", |c| c.world_to_camera[2][2] = -1.0),
            ("world_to_camera", |c| c.world_to_camera[3][0] = 0.5),
            ("world_to_camera", |c| c.world_to_camera[1][3] = f64::NAN),
        ];
        for (field, mutate) in cases {
            let mut cam = identity_camera();
            mutate(&mut cam);
            match cam.validate() {
                Err(RasterError::InvalidCamera { field: f, .. }) => assert_eq!(f, field),
                other => panic!("expected an error on {field}, got {other:?}"),
            }
        }
        let mut big = identity_camera();
        big.width = MAX_IMAGE_SIDE;
        assert!(big.is_valid());
    }
}
