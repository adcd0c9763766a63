//! Per-Gaussian projection (INRIA `preprocessCUDA`): view transform, near-plane cull, EWA 2D
//! covariance with the low-pass, conic, 3-sigma radius and tile rectangle, and SH colour.

use glam::{Mat3, Quat, Vec3};
use rayon::prelude::*;

use crate::camera::{Camera, CameraF32};
use crate::kept;
use crate::simd::Simd;
use crate::tiles::{TileMask, TileRect};
use crate::{ALPHA_MIN, LOW_PASS, SIGMA_EXTENT, Splats, TILE_SIZE};

/// Gaussians per rayon task in the per-Gaussian passes.
pub(crate) const MIN_GAUSSIANS_PER_TASK: usize = 4096;
/// `ln(ALPHA_MIN)`, `ln(1/255)`.
const LN_ALPHA_MIN: f32 = -5.541_263_5;

/// What compositing needs of one projected Gaussian.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Zeroable)]
pub struct Splat2D {
    /// Mean in INRIA pixel coordinates: `u - 0.5`, `v - 0.5` (pixel (i, j) is sampled at (i, j)).
    pub mean: [f32; 2],
    /// Inverse 2D covariance `(A, B, C)`: `power = -0.5 (A dx² + C dy²) - B dx dy`.
    pub conic: [f32; 3],
    /// `log2(opacity)`: compositing takes `alpha = min(0.99, 2^(log2(opacity) + power log2(e)))`,
    /// the opacity folded into the exponent (docs/rendering.md, step 9).
    pub log2_opacity: f32,
    /// View-dependent colour (zero in index-only mode).
    pub color: [f32; 3],
    /// Camera z of the centre.
    pub depth: f32,
    /// Inclusive pixel box `[x0, y0, x1, y1]`, clipped to the image, outside which alpha < 1/255
    /// (pixels outside it would be skipped anyway, so compositing never visits them).
    pub pixel_box: [u16; 4],
}

/// The projected Gaussians: `splats[k]` and `rects[k]` are Gaussian `ids[k]`, or Gaussian k when
/// `ids` is None (then a culled Gaussian has an empty [`TileRect`], and its [`Splat2D`] and sort
/// depth are left over from an earlier render: sorting and compositing never read them).
#[derive(Debug, Default)]
pub struct Projected {
    pub ids: Option<Vec<u32>>,
    pub splats: Vec<Splat2D>,
    pub rects: Vec<TileRect>,
    /// Per entry, the camera z it sorts by: its own depth, or where the splats have sort offsets
    /// its sort point's (see [`sort_depth`]); None: each sorts by its own depth. Kept apart from
    /// [`Splat2D`], which compositing reads, so that the sort reads 4 bytes an entry, not 48.
    pub sort_depths: Option<Vec<f32>>,
}

impl Projected {
    /// From (row, projection, tiles) triples in row order.
    pub fn from_found(found: Vec<(u32, Splat2D, TileRect)>) -> Self {
        let mut ids = Vec::with_capacity(found.len());
        let (mut splats, mut rects) = (Vec::with_capacity(found.len()), Vec::with_capacity(found.len()));
        for (i, splat, rect) in found {
            ids.push(i);
            splats.push(splat);
            rects.push(rect);
        }
        Self { ids: Some(ids), splats, rects, sort_depths: None }
    }

    /// Gives its buffers back to be kept for the next render (see `kept`).
    pub(crate) fn give_back(self) {
        crate::kept::SPLATS.give_back(self.splats);
        crate::kept::RECTS.give_back(self.rects);
        if let Some(depths) = self.sort_depths {
            crate::kept::DEPTHS.give_back(depths);
        }
    }

    /// The scene row of entry `k`.
    #[inline]
    pub fn id(&self, k: usize) -> u32 {
        self.ids.as_ref().map_or(k as u32, |ids| ids[k])
    }

    /// The bits entry `k` sorts by (a positive float's bits order like its value).
    #[inline]
    pub fn sort_key(&self, k: usize) -> u32 {
        self.sort_depths.as_ref().map_or(self.splats[k].depth, |d| d[k]).to_bits()
    }

    /// Sets the entries' sort depths from the Gaussians' `means` and `quats` (rows of the scene)
    /// and `offset(row)`, their sort offsets.
    pub(crate) fn sort_at(
        &mut self,
        means: &[Vec3],
        quats: &[[f32; 4]],
        offset: impl Fn(usize) -> Vec3 + Sync,
        cam: &CameraF32,
    ) {
        let depths = (0..self.splats.len())
            .into_par_iter()
            .with_min_len(MIN_GAUSSIANS_PER_TASK)
            .map(|k| {
                let row = self.id(k) as usize;
                sort_depth(means[row], quats[row], offset(row), cam)
            })
            .collect();
        if let Some(own) = self.sort_depths.replace(depths) {
            crate::kept::DEPTHS.give_back(own);
        }
    }
}

/// The camera z a Gaussian sorts by: of its sort point `mean + R(quat) offset` (docs/rendering.md,
/// "Sort points"). A zero offset gives its mean's z, the very bits [`project_each`] computes; a sort
/// point behind the camera sorts first.
#[inline]
pub(crate) fn sort_depth(mean: Vec3, quat: [f32; 4], offset: Vec3, cam: &CameraF32) -> f32 {
    let point = if offset == Vec3::ZERO { mean } else { mean + rotation(quat) * offset };
    let z = (cam.rotation * point + cam.translation).z;
    if z > 0.0 { z } else { 0.0 }
}

/// Projects every Gaussian, or with `tiles` only those whose footprint reaches a tile of it (the
/// others are dropped by a cheap bound on the footprint before the EWA projection).
pub fn project(splats: &Splats, camera: &Camera, with_color: bool, tiles: Option<&TileMask>) -> Projected {
    let cam = CameraF32::new(camera);
    let mut projected = match tiles {
        None => project_all(splats, &cam, camera, with_color),
        Some(mask) => project_reaching(splats, &cam, camera, with_color, mask),
    };
    if let Some(offsets) = splats.sort_offsets {
        projected.sort_at(splats.means, splats.quats, |row| offsets[row], &cam);
    }
    projected
}

/// Row `i` of `splats` as input to [`project_each`].
#[inline(always)]
fn input<'a>(splats: &Splats<'a>, i: usize, with_color: bool) -> Input<'a> {
    let sh = if with_color { splats.sh_of(i) } else { None };
    Input { mean: splats.means[i], scale: splats.scales[i], quat: splats.quats[i], opacity: splats.opacities[i], sh }
}

/// Every row, entry i row i (a culled one an empty rectangle).
fn project_all(splats: &Splats, cam: &CameraF32, camera: &Camera, with_color: bool) -> Projected {
    let n = splats.len();
    // the last render's buffers, or zeroed pages from the system that the writers touch first
    let mut projected = kept::with_len(kept::SPLATS.take(), n);
    let mut rects = kept::with_len(kept::RECTS.take(), n);
    let mut depths = kept::with_len(kept::DEPTHS.take(), n);
    projected
        .par_chunks_mut(MIN_GAUSSIANS_PER_TASK)
        .zip(rects.par_chunks_mut(MIN_GAUSSIANS_PER_TASK))
        .zip(depths.par_chunks_mut(MIN_GAUSSIANS_PER_TASK))
        .enumerate()
        .for_each(|(chunk, ((projected, rects), depths))| {
            // A culled Gaussian gets an empty rectangle, so nothing reads its splat or depth:
            // those keep whatever a last render left (writing defaults there cost a pass over
            // 60 bytes a Gaussian).
            rects.fill(TileRect::default());
            let start = chunk * MIN_GAUSSIANS_PER_TASK;
            let row = |k: usize| input(splats, start + k, with_color);
            project_each(projected.len(), row, cam, camera, |k, splat, rect| {
                projected[k] = splat;
                rects[k] = rect;
                depths[k] = splat.depth;
            });
        });
    Projected { ids: None, splats: projected, rects, sort_depths: Some(depths) }
}

/// The rows whose footprint reaches a tile of `mask`.
fn project_reaching(splats: &Splats, cam: &CameraF32, camera: &Camera, with_color: bool, mask: &TileMask) -> Projected {
    let reach = Reach::new(mask, cam);
    let found: Vec<(u32, Splat2D, TileRect)> = (0..splats.len())
        .into_par_iter()
        .step_by(MIN_GAUSSIANS_PER_TASK)
        .flat_map_iter(|start| {
            let end = (start + MIN_GAUSSIANS_PER_TASK).min(splats.len());
            let mut candidates = Vec::new();
            let mut may = [false; REACH_BLOCK];
            for block in (start..end).step_by(REACH_BLOCK) {
                let rows = block..(block + REACH_BLOCK).min(end);
                reach.block(
                    &splats.means[rows.clone()],
                    &splats.scales[rows.clone()],
                    &splats.opacities[rows.clone()],
                    &mut may,
                );
                candidates.extend(rows.zip(may).filter(|(_, m)| *m).map(|(i, _)| i));
            }
            let mut found = Vec::new();
            let row = |k: usize| input(splats, candidates[k], with_color);
            project_each(candidates.len(), row, cam, camera, |k, splat, rect| {
                if mask.touches(&rect) {
                    found.push((candidates[k] as u32, splat, rect));
                }
            });
            found
        })
        .collect();
    Projected::from_found(found)
}

/// Projects every Gaussian (entry i is row i) and culls those whose `excluded` flag is set (the
/// moving part of an animated scene): the static part, without a compacting copy.
pub fn project_static(splats: &Splats, camera: &Camera, with_color: bool, excluded: &[bool]) -> Projected {
    let mut projected = project(splats, camera, with_color, None);
    for (rect, _) in projected.rects.iter_mut().zip(excluded).filter(|(_, e)| **e) {
        *rect = TileRect::default();
    }
    projected
}

/// Gaussians tested together by [`Reach::block`] (straight-line code the compiler vectorises).
const REACH_BLOCK: usize = 8;

/// Whether a Gaussian can reach the rendered tiles, from its centre and largest scale only: a
/// bound on the footprint [`project_each`] gives. The EWA covariance is `T R S² Rᵀ Tᵀ + 0.3 I`
/// (T the Jacobian rows), so its largest eigenvalue is at most `max(S)² |J|²_F + 0.3`, the
/// radius's `max(., 0.1)` adds at most `sqrt(0.1)`, and `|J|²_F <= K / z²` with K from the
/// Jacobian's clamp limits. A relative margin and two pixels cover rounding.
struct Reach<'a> {
    mask: &'a TileMask,
    cam: CameraF32,
    /// sqrt(K) * 3 sigma
    scale_to_px: f32,
    /// 3 sigma * sqrt(0.62) + rounding
    floor_px: f32,
    /// The rendered tiles' pixel box (INRIA coordinates) grown by a tile: a footprint wholly
    /// outside it reaches none of them.
    pixel_box: [f32; 4],
}

impl<'a> Reach<'a> {
    fn new(mask: &'a TileMask, cam: &CameraF32) -> Self {
        let lim_x = cam.lim_x_neg.max(cam.lim_x_pos);
        let lim_y = cam.lim_y_neg.max(cam.lim_y_pos);
        let k = cam.fx * cam.fx * (1.0 + lim_x * lim_x) + cam.fy * cam.fy * (1.0 + lim_y * lim_y);
        let tile = TILE_SIZE as f32;
        let [x0, y0, x1, y1] = mask.tile_box().map(|t| t as f32 * tile);
        Self {
            mask,
            cam: *cam,
            scale_to_px: SIGMA_EXTENT * k.sqrt() * 1.001,
            floor_px: SIGMA_EXTENT * (LOW_PASS + 0.32_f32).sqrt() * 1.001 + 2.0,
            pixel_box: [x0 - tile, y0 - tile, x1 + tile, y1 + tile],
        }
    }

    /// `may[k]`: whether Gaussian k of the block may reach a rendered tile (false: it cannot).
    #[inline]
    fn block(&self, means: &[Vec3], scales: &[Vec3], opacities: &[f32], may: &mut [bool; REACH_BLOCK]) {
        let c = &self.cam;
        let [bx0, by0, bx1, by1] = self.pixel_box;
        let mut near = [false; REACH_BLOCK];
        let (mut u, mut v, mut r) = ([0.0f32; REACH_BLOCK], [0.0f32; REACH_BLOCK], [0.0f32; REACH_BLOCK]);
        for k in 0..means.len().min(REACH_BLOCK) {
            let p = c.rotation * means[k] + c.translation;
            let inv_z = 1.0 / p.z;
            let s = scales[k].abs().max_element();
            u[k] = c.fx * p.x * inv_z + c.cx - 0.5;
            v[k] = c.fy * p.y * inv_z + c.cy - 0.5;
            r[k] = self.scale_to_px * s * inv_z + self.floor_px;
            // NaN anywhere fails a comparison, and the exact projection culls it too
            near[k] = p.z > c.near && opacities[k] >= ALPHA_MIN;
        }
        for k in 0..REACH_BLOCK {
            let inside = u[k] + r[k] >= bx0 && u[k] - r[k] <= bx1 && v[k] + r[k] >= by0 && v[k] - r[k] <= by1;
            may[k] =
                k < means.len() && near[k] && (inside || !(u[k].is_finite() && v[k].is_finite() && r[k].is_finite()));
            if may[k] && inside {
                may[k] = self.mask.touches(&tile_rect_of(u[k], v[k], r[k], self.mask.grid()));
            }
        }
    }
}

/// INRIA getRect: the tiles a footprint of `radius` px about (u, v) (INRIA pixel coordinates)
/// overlaps; C truncation toward zero, then clamped to the grid.
#[inline]
fn tile_rect_of(u: f32, v: f32, radius: f32, grid: (usize, usize)) -> TileRect {
    let [x0, y0, x1, y1] = tile_span(u, v, radius, grid).map(whole);
    TileRect { x0, y0, x1, y1 }
}

/// [`tile_rect_of`] as whole numbers in f32 (a NaN gives 0), so that a loop over lanes of it
/// vectorises: `[x0, y0, x1, y1]`.
#[inline(always)]
fn tile_span(u: f32, v: f32, radius: f32, (grid_x, grid_y): (usize, usize)) -> [f32; 4] {
    let tile_scale = 1.0 / TILE_SIZE as f32; // exact: a power of two
    let last = (TILE_SIZE - 1) as f32;
    // for t >= 0 truncation is `floor`; `max` turns a NaN into 0, as C's cast to int did
    let grid = |t: f32, max: usize| floor(t.max(0.0).min(max as f32));
    [
        grid((u - radius) * tile_scale, grid_x),
        grid((v - radius) * tile_scale, grid_y),
        grid((u + radius + last) * tile_scale, grid_x),
        grid((v + radius + last) * tile_scale, grid_y),
    ]
}

/// One Gaussian's inputs to [`project_each`]; `sh` (K*3 values) is None when no colour is wanted.
#[derive(Clone, Copy)]
pub(crate) struct Input<'a> {
    pub mean: Vec3,
    pub scale: Vec3,
    pub quat: [f32; 4],
    pub opacity: f32,
    pub sh: Option<&'a [f32]>,
}

/// Gaussians projected together: the geometry runs as straight-line code over arrays of this many
/// lanes, which the compiler turns into SIMD (eight f32 lanes with AVX2). Every lane does the same
/// IEEE operations in the same order whatever the width, so the bits never depend on it.
const LANES: usize = 8;
type Lanes = [f32; LANES];

/// Projects the Gaussians `input(0..count)` and calls `emit(k, splat, rect)`, in order, for each
/// one that reaches the image; compiled for AVX2 where the CPU has it.
#[inline]
pub(crate) fn project_each<'a>(
    count: usize,
    input: impl Fn(usize) -> Input<'a>,
    cam: &CameraF32,
    camera: &Camera,
    emit: impl FnMut(usize, Splat2D, TileRect),
) {
    project_each_with(Simd::detect(), count, input, cam, camera, emit);
}

/// [`project_each`] compiled for `simd` (which the CPU must have: from `Simd::detect`).
#[inline]
fn project_each_with<'a>(
    simd: Simd,
    count: usize,
    input: impl Fn(usize) -> Input<'a>,
    cam: &CameraF32,
    camera: &Camera,
    emit: impl FnMut(usize, Splat2D, TileRect),
) {
    #[cfg(target_arch = "x86_64")]
    if matches!(simd, Simd::Eight | Simd::Sixteen) {
        #[target_feature(enable = "avx2")]
        fn run<'a>(
            count: usize,
            input: impl Fn(usize) -> Input<'a>,
            cam: &CameraF32,
            camera: &Camera,
            emit: impl FnMut(usize, Splat2D, TileRect),
        ) {
            project_blocks(count, input, cam, camera, emit);
        }
        // SAFETY: `Simd::Eight` and `Simd::Sixteen` come only from `Simd::detect`, which found AVX2
        // on this CPU for either.
        unsafe { run(count, input, cam, camera, emit) };
        return;
    }
    project_blocks(count, input, cam, camera, emit);
}

#[inline(always)] // into `project_each`'s AVX2 copy too
fn project_blocks<'a>(
    count: usize,
    input: impl Fn(usize) -> Input<'a>,
    cam: &CameraF32,
    camera: &Camera,
    mut emit: impl FnMut(usize, Splat2D, TileRect),
) {
    for start in (0..count).step_by(LANES) {
        let len = LANES.min(count - start);
        // lanes past the end repeat the last Gaussian; their results are not emitted
        let inputs: [Input; LANES] = std::array::from_fn(|l| input(start + l.min(len - 1)));
        let found = project_block(&inputs, cam, camera);
        for (l, (found, input)) in found.into_iter().zip(inputs).take(len).enumerate() {
            if let Some((mut splat, rect)) = found {
                if let Some(sh) = input.sh {
                    splat.color = sh_to_color(sh, (input.mean - cam.center).normalize_or_zero());
                }
                emit(start + l, splat, rect);
            }
        }
    }
}

/// The projection of `LANES` Gaussians without colour (INRIA `preprocessCUDA`); None for one
/// that is culled or reaches no pixel. Every test is a lane mask, so the code has no branch.
#[inline(always)]
fn project_block(inputs: &[Input; LANES], cam: &CameraF32, camera: &Camera) -> [Option<(Splat2D, TileRect)>; LANES] {
    let field = |f: fn(&Input) -> f32| -> Lanes { std::array::from_fn(|l| f(&inputs[l])) };
    let (mx, my, mz) = (field(|g| g.mean.x), field(|g| g.mean.y), field(|g| g.mean.z));
    let (sx, sy, sz) = (field(|g| g.scale.x), field(|g| g.scale.y), field(|g| g.scale.z));
    let (qw, qx, qy, qz) = (field(|g| g.quat[0]), field(|g| g.quat[1]), field(|g| g.quat[2]), field(|g| g.quat[3]));
    let opacity = field(|g| g.opacity);
    let (w, t) = (cam.rotation, cam.translation);
    let (grid_x, grid_y) = camera.tile_grid();
    let (width, height) = (camera.width, camera.height);

    let mut valid = [false; LANES];
    let (mut mean_u, mut mean_v, mut depth) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
    let mut conic = [[0.0f32; LANES]; 3];
    let mut log2_opacity = [0.0f32; LANES];
    let mut pixel_box = [[0u16; LANES]; 4];
    let mut rect = [[0u16; LANES]; 4];
    for l in 0..LANES {
        // View transform, in glam's order (so `sort_depth` of a zero offset gives the same z).
        let x = w.x_axis.x * mx[l] + w.y_axis.x * my[l] + w.z_axis.x * mz[l] + t.x;
        let y = w.x_axis.y * mx[l] + w.y_axis.y * my[l] + w.z_axis.y * mz[l] + t.y;
        let z = w.x_axis.z * mx[l] + w.y_axis.z * my[l] + w.z_axis.z * mz[l] + t.z;
        // alpha = min(0.99, opacity * exp(power)) <= opacity: below 1/255 it is skipped everywhere
        let mut ok = opacity[l] >= ALPHA_MIN && z > cam.near;
        let inv_z = 1.0 / z;

        // EWA Jacobian at the mean, with x/z and y/z clamped (for J only) as the reference does.
        let tx = z * (x * inv_z).max(-cam.lim_x_neg).min(cam.lim_x_pos);
        let ty = z * (y * inv_z).max(-cam.lim_y_neg).min(cam.lim_y_pos);
        let (j0x, j0z) = (cam.fx * inv_z, -cam.fx * tx * inv_z * inv_z);
        let (j1y, j1z) = (cam.fy * inv_z, -cam.fy * ty * inv_z * inv_z);
        // Rows of T = J W in world axes: W^T j (W's rows are its matrix's columns' components).
        let e0 = [
            w.x_axis.x * j0x + w.x_axis.z * j0z,
            w.y_axis.x * j0x + w.y_axis.z * j0z,
            w.z_axis.x * j0x + w.z_axis.z * j0z,
        ];
        let e1 = [
            w.x_axis.y * j1y + w.x_axis.z * j1z,
            w.y_axis.y * j1y + w.y_axis.z * j1z,
            w.z_axis.y * j1y + w.z_axis.z * j1z,
        ];
        let r = rotation([qw[l], qx[l], qy[l], qz[l]]);
        // Σ2D = T R S Sᵀ Rᵀ Tᵀ = M Mᵀ with the rows of M = (T R) S.
        let scale = [sx[l], sy[l], sz[l]];
        let row = |e: [f32; 3]| -> [f32; 3] { std::array::from_fn(|j| r.col(j).dot(Vec3::from(e)) * scale[j]) };
        let (m0, m1) = (row(e0), row(e1));
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let a = dot(m0, m0) + LOW_PASS;
        let b = dot(m0, m1);
        let c = dot(m1, m1) + LOW_PASS;
        // det(G + εI) = |m0 × m1|² + ε tr(G) + ε², free of the cancellation in a·c - b².
        let cross = [m0[1] * m1[2] - m0[2] * m1[1], m0[2] * m1[0] - m0[0] * m1[2], m0[0] * m1[1] - m0[1] * m1[0]];
        let det = dot(cross, cross) + LOW_PASS * (a + c - 2.0 * LOW_PASS) + LOW_PASS * LOW_PASS;
        ok &= det > 0.0 && det <= f32::MAX;
        let inv_det = 1.0 / det;
        conic[0][l] = c * inv_det;
        conic[1][l] = -b * inv_det;
        conic[2][l] = a * inv_det;

        let mid = 0.5 * (a + c);
        let half_diff = 0.5 * (a - c);
        let lambda1 = mid + (half_diff * half_diff + b * b).max(0.1).sqrt(); // mid² - det, exactly
        let radius = ceil(SIGMA_EXTENT * lambda1.sqrt());
        let u = cam.fx * x * inv_z + cam.cx - 0.5;
        let v = cam.fy * y * inv_z + cam.cy - 0.5;
        ok &= u.abs() <= f32::MAX && v.abs() <= f32::MAX && radius <= f32::MAX;

        // Pixels where opacity * exp(-q/2) >= 1/255 satisfy q <= tau; on that ellipse |dx| reaches
        // sqrt(tau Σxx). The margin keeps rounding from dropping a boundary pixel.
        let tau = 2.0 * ln_at_least_one(opacity[l] / ALPHA_MIN);
        let reach = |var: f32| (tau * var).sqrt() * (1.0 + 1e-3) + 0.05;
        // Inclusive pixel range [ceil(m - r), floor(m + r)] clipped to [0, side - 1]. Everything
        // from here on stays in f32 (whole numbers, exact): a conversion to an integer per lane
        // kept the compiler from vectorising the loop.
        let span = |m: f32, r: f32, side: u32| (ceil(m - r).max(0.0), floor(m + r).min((side - 1) as f32));
        let (bx0, bx1) = span(u, reach(a), width);
        let (by0, by1) = span(v, reach(c), height);
        ok &= bx0 <= bx1 && by0 <= by1;
        let pixels = [bx0, by0, bx1.max(0.0), by1.max(0.0)];
        // The tiles of the footprint (`tile_rect_of`), less those holding no pixel of the box,
        // which would only skip this Gaussian.
        let tiles = tile_span(u, v, radius, (grid_x as usize, grid_y as usize));
        let first_tile = |p: f32| floor(p * (1.0 / TILE_SIZE as f32));
        let clipped = [
            tiles[0].max(first_tile(pixels[0])),
            tiles[1].max(first_tile(pixels[1])),
            tiles[2].min(first_tile(pixels[2]) + 1.0),
            tiles[3].min(first_tile(pixels[3]) + 1.0),
        ];
        ok &= clipped[0] < clipped[2] && clipped[1] < clipped[3];

        valid[l] = ok;
        (mean_u[l], mean_v[l], depth[l]) = (u, v, z);
        // ln(opacity) = tau / 2 + ln(1/255), from the ln just taken
        log2_opacity[l] = (0.5 * tau + LN_ALPHA_MIN) * std::f32::consts::LOG2_E;
        for k in 0..4 {
            pixel_box[k][l] = whole(pixels[k]);
            rect[k][l] = whole(clipped[k]);
        }
    }
    std::array::from_fn(|l| {
        valid[l].then(|| {
            let splat = Splat2D {
                mean: [mean_u[l], mean_v[l]],
                conic: [conic[0][l], conic[1][l], conic[2][l]],
                log2_opacity: log2_opacity[l],
                color: [0.0; 3],
                depth: depth[l],
                pixel_box: [pixel_box[0][l], pixel_box[1][l], pixel_box[2][l], pixel_box[3][l]],
            };
            let [x0, y0, x1, y1] = [rect[0][l], rect[1][l], rect[2][l], rect[3][l]];
            (splat, TileRect { x0, y0, x1, y1 })
        })
    })
}

/// `ln(x)` for `1 <= x <= 255` (what `tau` needs), in lane-friendly arithmetic: `x = 2^e m` with
/// `m` in [0.75, 1.5), and `ln m = 2 atanh(f)`, `f = (m - 1) / (m + 1)`, by its odd series to f¹¹
/// (|f| <= 0.2, so the error is below 1e-9 relative to ln 2). Other inputs give a finite value.
#[inline(always)]
fn ln_at_least_one(x: f32) -> f32 {
    let bits = x.to_bits();
    // the exponent of x / 0.75, so that m = x / 2^e lands in [0.75, 1.5)
    let e = ((bits.wrapping_add(0x0040_0000) >> 23) & 0xff) as i32 - 127;
    let m = f32::from_bits(bits.wrapping_sub((e as u32) << 23));
    let f = (m - 1.0) / (m + 1.0);
    let f2 = f * f;
    let series = 1.0 + f2 * (1.0 / 3.0 + f2 * (1.0 / 5.0 + f2 * (1.0 / 7.0 + f2 * (1.0 / 9.0 + f2 * (1.0 / 11.0)))));
    e as f32 * std::f32::consts::LN_2 + 2.0 * f * series
}

/// Pixel coordinates are clamped to ±this before rounding: far beyond any image, and small
/// enough for rounding by adding `ROUND` below.
const FAR: f32 = 4_194_304.0; // 2^22
/// Adding 1.5 * 2^23 to a number of magnitude at most 2^22 rounds it to a whole number.
const ROUND: f32 = 12_582_912.0;

/// `ceil` without a libm call (SSE2 has no rounding instruction) or a conversion to an integer;
/// exact for |x| <= FAR, and only ever used where the result is then clipped to the image. A NaN
/// gives -FAR (`max` drops it), so the result is always finite.
#[inline(always)]
#[allow(clippy::manual_clamp)] // `clamp` keeps a NaN, and `whole` must never see one
fn ceil(x: f32) -> f32 {
    let x = x.max(-FAR).min(FAR);
    let r = (x + ROUND) - ROUND;
    if r < x { r + 1.0 } else { r }
}

/// `floor` without a libm call or a conversion; exact for |x| <= FAR.
#[inline(always)]
#[allow(clippy::manual_clamp)] // as in `ceil`
fn floor(x: f32) -> f32 {
    let x = x.max(-FAR).min(FAR);
    let r = (x + ROUND) - ROUND;
    if r > x { r - 1.0 } else { r }
}

/// A whole number in [0, 2^16) as u16 (outside it, of a culled Gaussian, any value).
#[inline(always)]
fn whole(x: f32) -> u16 {
    // SAFETY: `x` comes from `ceil`/`floor` (so it is finite, with |x| <= FAR < 2^31), after
    // which i32 -> u16 only drops bits.
    unsafe { x.to_int_unchecked::<i32>() as u16 }
}

/// Rotation matrix of `[w, x, y, z]`, normalised by `max(|q|, 1e-12)` as the reference does.
pub fn rotation(q: [f32; 4]) -> Mat3 {
    let [w, x, y, z] = q;
    let inv_norm = 1.0 / (w * w + x * x + y * y + z * z).sqrt().max(1e-12);
    Mat3::from_quat(Quat::from_xyzw(x * inv_norm, y * inv_norm, z * inv_norm, w * inv_norm))
}

pub const SH_C0: f32 = 0.282_094_8;
pub const SH_C1: f32 = 0.488_602_5;
pub const SH_C2: [f32; 5] = [1.092_548_5, -1.092_548_5, 0.315_391_57, -1.092_548_5, 0.546_274_24];
pub const SH_C3: [f32; 7] =
    [-0.590_043_6, 2.890_611_4, -0.457_045_8, 0.373_176_33, -0.457_045_8, 1.445_305_7, -0.590_043_6];

/// Colour of SH coefficients `sh` (K RGB triples, K in 1, 4, 9, 16) seen along the unit world
/// direction `dir` from the camera to the Gaussian (`computeColorFromSH`); clamped at 0 only.
pub fn sh_to_color(sh: &[f32], dir: Vec3) -> [f32; 3] {
    let k = sh.len() / 3;
    let (x, y, z) = (dir.x, dir.y, dir.z);
    let mut basis = [0.0f32; 16];
    basis[0] = SH_C0;
    if k >= 4 {
        basis[1] = -SH_C1 * y;
        basis[2] = SH_C1 * z;
        basis[3] = -SH_C1 * x;
    }
    if k >= 9 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        basis[4] = SH_C2[0] * x * y;
        basis[5] = SH_C2[1] * y * z;
        basis[6] = SH_C2[2] * (2.0 * zz - xx - yy);
        basis[7] = SH_C2[3] * x * z;
        basis[8] = SH_C2[4] * (xx - yy);
        if k >= 16 {
            basis[9] = SH_C3[0] * y * (3.0 * xx - yy);
            basis[10] = SH_C3[1] * x * y * z;
            basis[11] = SH_C3[2] * y * (4.0 * zz - xx - yy);
            basis[12] = SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
            basis[13] = SH_C3[4] * x * (4.0 * zz - xx - yy);
            basis[14] = SH_C3[5] * z * (xx - yy);
            basis[15] = SH_C3[6] * x * (xx - 3.0 * yy);
        }
    }
    let mut rgb = [0.5f32; 3];
    for (coeff, b) in sh.chunks_exact(3).zip(basis) {
        for (out, c) in rgb.iter_mut().zip(coeff) {
            *out += b * c;
        }
    }
    rgb.map(|c| c.max(0.0))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn rotation_matches_the_reference_matrix() {
        // docs/rendering.md step 2: R[1][0] = 2(xy + wz) for a unit (w, x, y, z).
        let (w, x, y, z) = (0.5f32, 0.5f32, -0.5f32, 0.5f32);
        let r = rotation([w, x, y, z]);
        let expected = [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ];
        for (i, row) in expected.iter().enumerate() {
            for (j, e) in row.iter().enumerate() {
                assert!((r.col(j)[i] - e).abs() < 1e-6, "R[{i}][{j}]");
            }
        }
        // Unnormalised input is normalised; a zero quaternion is the identity.
        assert!((rotation([2.0, 0.0, 0.0, 0.0]) - Mat3::IDENTITY).abs_diff_eq(Mat3::ZERO, 1e-6));
        assert!((rotation([0.0; 4]) - Mat3::IDENTITY).abs_diff_eq(Mat3::ZERO, 1e-6));
    }

    #[test]
    fn ln_matches_the_library_over_the_opacity_range() {
        for i in 0..=100_000 {
            let x = 1.0 + 254.0 * i as f32 / 100_000.0;
            let (ours, libm) = (ln_at_least_one(x), x.ln());
            assert!((ours - libm).abs() <= 2e-7 * libm.max(1.0), "ln({x}): {ours} vs {libm}");
        }
    }

    #[test]
    fn lanes_give_the_same_bits_at_every_width_and_cull_what_the_reference_culls() {
        let mut state = 99u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let camera = Camera {
            width: 96,
            height: 64,
            fx: 80.0,
            fy: 80.0,
            cx: 48.0,
            cy: 32.0,
            world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
            near: crate::NEAR_PLANE,
        };
        // some behind the camera, off the image, nearly transparent, or NaN
        let inputs: Vec<Input> = (0..1001)
            .map(|i| Input {
                mean: Vec3::new(next() * 4.0 - 2.0, next() * 3.0 - 1.5, next() * 6.0 - 1.0),
                scale: Vec3::new(next(), next(), next()) * 0.1,
                quat: [next() - 0.5, next() - 0.5, next() - 0.5, next() - 0.5],
                opacity: if i % 97 == 0 { f32::NAN } else { next() * 0.5 },
                sh: None,
            })
            .collect();
        // and some with a NaN or infinite field: culled, like the reference's checks cull them
        let mut inputs = inputs;
        let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        for (i, value) in bad.iter().enumerate() {
            inputs[10 * i + 1].mean.x = *value;
            inputs[10 * i + 2].scale.y = *value;
            inputs[10 * i + 3].quat[2] = *value;
            inputs[10 * i + 4].mean.z = *value;
        }
        let cam = CameraF32::new(&camera);
        let run = |simd: Simd| {
            let mut found = Vec::new();
            project_each_with(simd, inputs.len(), |k| inputs[k], &cam, &camera, |k, s, r| found.push((k, s, r)));
            found
        };
        let four = run(Simd::Four);
        for simd in Simd::available() {
            assert_eq!(four, run(simd), "{simd:?}");
        }
        let kept: Vec<usize> = four.iter().map(|f| f.0).collect();
        for (k, g) in inputs.iter().enumerate() {
            let z = g.mean.z; // the identity camera
            let expected = g.opacity >= ALPHA_MIN && z > camera.near as f32;
            if !expected {
                assert!(!kept.contains(&k), "Gaussian {k} should be culled");
            }
        }
        assert!(kept.len() > 300, "{} kept", kept.len());
        for (_, splat, rect) in &four {
            assert!(!rect.is_empty() && splat.conic.iter().all(|c| c.is_finite()));
        }
        for i in 0..bad.len() {
            for k in 1..=4 {
                assert!(!kept.contains(&(10 * i + k)), "Gaussian {} with a non-finite field kept", 10 * i + k);
            }
        }
    }

    #[test]
    fn sh_bands_use_the_reference_signs() {
        // One channel per band term: put 1 in coefficient j of the red channel only.
        let dir = Vec3::new(0.36, -0.48, 0.8); // unit
        let (x, y, z) = (dir.x, dir.y, dir.z);
        let expected_basis = [
            SH_C0,
            -SH_C1 * y,
            SH_C1 * z,
            -SH_C1 * x,
            SH_C2[0] * x * y,
            SH_C2[1] * y * z,
            SH_C2[2] * (2.0 * z * z - x * x - y * y),
            SH_C2[3] * x * z,
            SH_C2[4] * (x * x - y * y),
            SH_C3[0] * y * (3.0 * x * x - y * y),
            SH_C3[1] * x * y * z,
            SH_C3[2] * y * (4.0 * z * z - x * x - y * y),
            SH_C3[3] * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y),
            SH_C3[4] * x * (4.0 * z * z - x * x - y * y),
            SH_C3[5] * z * (x * x - y * y),
            SH_C3[6] * x * (x * x - 3.0 * y * y),
        ];
        for (j, b) in expected_basis.iter().enumerate() {
            let mut sh = [0.0f32; 48];
            sh[3 * j] = 1.0;
            sh[3 * j + 1] = -1.0;
            let rgb = sh_to_color(&sh, dir);
            assert!((rgb[0] - (0.5 + b).max(0.0)).abs() < 1e-6, "basis {j}");
            assert!((rgb[1] - (0.5 - b).max(0.0)).abs() < 1e-6, "basis {j}");
            assert_eq!(rgb[2], 0.5);
        }
    }
}
