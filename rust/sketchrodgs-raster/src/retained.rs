//! Frames of an animation where only some Gaussians move (docs/rendering.md, "Frames of an
//! animation"): the static Gaussians are projected, sorted and binned once; each frame projects
//! the moving ones, and re-blends only the tiles they touch now or touched in the last frame,
//! from the static list and the moving list merged by (depth, row). That is the order a full
//! render sorts them in, so every frame equals a full render of the same scene exactly.

use glam::Vec3;
use rayon::prelude::*;

use crate::bin::{TileBins, sort_by_depth};
use crate::camera::{Camera, CameraF32};
use crate::composite::{Source, blank, composite_into};
use crate::project::{Input, Projected, Splat2D, project_each, project_static};
use crate::tiles::TileMask;
use crate::tiles::TileRect;
use crate::{MAX_TILE_PAIRS, RasterError, RenderOptions, RenderOutput, Splats};

/// A render kept from frame to frame.
pub struct Retained {
    camera: Camera,
    options: RenderOptions,
    /// Scene rows that may move, ascending; with their opacities and SH (which do not change).
    moving: Vec<u32>,
    opacities: Vec<f32>,
    /// Their sort offsets (`Splats::sort_offsets`), which turn with them.
    sort_offsets: Option<Vec<Vec3>>,
    sh: Vec<f32>,
    sh_coeffs: usize,
    n: usize,
    statics: Projected,
    n_static: usize,
    static_bins: TileBins,
    image: RenderOutput,
    /// Tiles the moving Gaussians touched in the last frame.
    touched: Vec<bool>,
}

/// The moving Gaussians of one frame, binned, and the merged lists of the tiles to re-blend.
struct Merged<'a> {
    statics: &'a Projected,
    moving: &'a Projected,
    lists: Vec<Vec<u32>>,
}

/// Entries below this are static (index into `statics`); from it on, moving (`- MOVING`).
const MOVING: u32 = 1 << 31;

impl Merged<'_> {
    /// The projection entry `k` is in, and its index there.
    #[inline]
    fn entry(&self, k: u32) -> (&Projected, u32) {
        if k >= MOVING { (self.moving, k - MOVING) } else { (self.statics, k) }
    }
}

impl Source for Merged<'_> {
    fn lists(&self, tile: usize) -> impl Iterator<Item = &[u32]> {
        self.lists.get(tile).map(|l| &l[..]).into_iter()
    }

    #[inline]
    fn splat(&self, k: u32) -> Splat2D {
        let (p, i) = self.entry(k);
        p.splats.get(i as usize).copied().unwrap_or_default()
    }

    #[inline]
    fn row(&self, k: u32) -> u32 {
        let (p, i) = self.entry(k);
        p.id(i as usize)
    }

    #[inline]
    fn prefetch(&self, k: u32) {
        let (p, i) = self.entry(k);
        crate::composite::prefetch_splat(&p.splats, i);
    }
}

/// Moving Gaussians projected per rayon task each frame.
const MOVING_PER_TASK: usize = 1024;

impl Retained {
    /// Renders `splats` once, keeping the projection and tile lists of every Gaussian not in
    /// `moving` (scene rows).
    pub fn new(splats: &Splats, camera: &Camera, options: &RenderOptions, moving: &[u32]) -> Result<Self, RasterError> {
        camera.validate()?;
        splats.validate()?;
        if moving.len() as u64 >= u64::from(MOVING) {
            return Err(RasterError::TooManyGaussians(moving.len()));
        }
        let n = splats.len();
        let mut moving = moving.to_vec();
        moving.sort_unstable();
        moving.dedup();
        if let Some(&bad) = moving.iter().find(|&&r| r as usize >= n) {
            return Err(RasterError::LengthMismatch { name: "moving", expected: n, got: bad as usize + 1 });
        }
        let mut is_moving = vec![false; n];
        moving.iter().for_each(|&r| is_moving[r as usize] = true);
        let statics = project_static(splats, camera, options.mode.has_color(), &is_moving);
        let order = sort_by_depth(&statics);
        let pairs: usize = order.iter().map(|&i| statics.rects[i as usize].area()).sum();
        if pairs > MAX_TILE_PAIRS {
            return Err(RasterError::TooManyTilePairs(pairs));
        }
        let static_bins = TileBins::new(camera, &statics.rects, &order, None)?;
        let n_static = order.len();
        drop(order);
        let mut statics = statics;
        statics.rects = Vec::new(); // binned: only the splats are read from here on
        let k = splats.sh_coeffs;
        let sh = moving.iter().flat_map(|&r| splats.sh_of(r as usize).unwrap_or_default()).copied().collect();
        let opacities = moving.iter().map(|&r| splats.opacities[r as usize]).collect();
        let sort_offsets = splats.sort_offsets.map(|o| moving.iter().map(|&r| o[r as usize]).collect());
        let image = blank(camera, options)?;
        let (grid_x, grid_y) = camera.tile_grid();
        let touched = vec![true; (grid_x * grid_y) as usize]; // the first frame blends every tile
        let mut retained = Self {
            camera: *camera,
            options: *options,
            moving,
            opacities,
            sort_offsets,
            sh,
            sh_coeffs: k,
            n,
            statics,
            n_static,
            static_bins,
            image,
            touched,
        };
        retained.frame(splats.means, splats.scales, splats.quats)?;
        Ok(retained)
    }

    /// [`Retained::frame`] from flat row-major arrays (means and scales N*3, quats N*4).
    pub fn frame_flat(&mut self, means: &[f32], scales: &[f32], quats: &[f32]) -> Result<&RenderOutput, RasterError> {
        let rows = |name: &'static str, width: usize, len: usize| RasterError::LengthMismatch {
            name,
            expected: self.n * width,
            got: len,
        };
        let m: &[Vec3] = bytemuck::try_cast_slice(means).map_err(|_| rows("means", 3, means.len()))?;
        let s: &[Vec3] = bytemuck::try_cast_slice(scales).map_err(|_| rows("scales", 3, scales.len()))?;
        let q: &[[f32; 4]] = bytemuck::try_cast_slice(quats).map_err(|_| rows("quats", 4, quats.len()))?;
        self.frame(m, s, q)
    }

    /// The frame with the moving rows of `means`, `scales` and `quats` (whole-scene arrays; the
    /// other rows are not read). Timings and counts of the output are this frame's.
    pub fn frame(&mut self, means: &[Vec3], scales: &[Vec3], quats: &[[f32; 4]]) -> Result<&RenderOutput, RasterError> {
        for (name, len) in [("means", means.len()), ("scales", scales.len()), ("quats", quats.len())] {
            if len != self.n {
                return Err(RasterError::LengthMismatch { name, expected: self.n, got: len });
            }
        }
        let start = std::time::Instant::now();
        let cam = CameraF32::new(&self.camera);
        let k_sh = self.sh_coeffs;
        let with_color = self.options.mode.has_color();
        let found: Vec<(u32, Splat2D, TileRect)> = self
            .moving
            .par_chunks(MOVING_PER_TASK)
            .enumerate()
            .flat_map_iter(|(chunk, rows)| {
                let input = |k: usize| {
                    let (j, r) = (chunk * MOVING_PER_TASK + k, rows[k] as usize);
                    let sh = if with_color { self.sh.get(j * k_sh * 3..(j + 1) * k_sh * 3) } else { None };
                    Input { mean: means[r], scale: scales[r], quat: quats[r], opacity: self.opacities[j], sh }
                };
                let mut found = Vec::with_capacity(rows.len());
                project_each(rows.len(), input, &cam, &self.camera, |k, splat, rect| {
                    found.push((rows[k], splat, rect))
                });
                found
            })
            .collect();
        let mut moving = Projected::from_found(found);
        if let Some(offsets) = &self.sort_offsets {
            // self.moving is ascending: a row's position there is its offset's
            let of_row = |row: usize| self.moving.binary_search(&(row as u32)).map_or(Vec3::ZERO, |j| offsets[j]);
            moving.sort_at(means, quats, of_row, &cam);
        }
        let projected_at = std::time::Instant::now();
        // the moving Gaussians front to back, ties by row (as a full render's sort)
        let mut order: Vec<u32> = (0..moving.splats.len() as u32).collect();
        order.sort_by_key(|&i| (moving.sort_key(i as usize), moving.id(i as usize)));
        let (grid_x, grid_y) = self.camera.tile_grid();
        let n_tiles = (grid_x * grid_y) as usize;
        let mut per_tile: Vec<Vec<u32>> = vec![Vec::new(); n_tiles];
        let mut touched = vec![false; n_tiles];
        for &i in &order {
            let r = moving.rects[i as usize];
            for ty in r.y0..r.y1 {
                for tx in r.x0..r.x1 {
                    let t = usize::from(ty) * grid_x as usize + usize::from(tx);
                    per_tile[t].push(i);
                    touched[t] = true;
                }
            }
        }
        let dirty: Vec<bool> = touched.iter().zip(&self.touched).map(|(a, b)| *a || *b).collect();
        let statics = &self.statics;
        let static_bins = &self.static_bins;
        let lists: Vec<Vec<u32>> =
            (0..n_tiles)
                .into_par_iter()
                .map(|t| {
                    if dirty[t] { merge(statics, static_bins.tile_lists(t), &moving, &per_tile[t]) } else { Vec::new() }
                })
                .collect();
        let sorted_at = std::time::Instant::now();
        let mask = TileMask::new(&self.camera, dirty)?;
        let source = Merged { statics, moving: &moving, lists };
        composite_into(&mut self.image, &self.camera, &source, &self.options, Some(&mask));
        let end = std::time::Instant::now();
        self.touched = touched;
        self.image.n_visible = self.n_static + moving.splats.len();
        self.image.n_tile_pairs = source.lists.iter().map(Vec::len).sum();
        self.image.timings = crate::StageTimings {
            project_s: (projected_at - start).as_secs_f64(),
            sort_s: (sorted_at - projected_at).as_secs_f64(),
            composite_s: (end - sorted_at).as_secs_f64(),
        };
        Ok(&self.image)
    }
}

/// One tile's static list (entries of `statics`, front to back) and moving list (entries of
/// `moving`) merged front to back, ties by scene row; moving entries offset by `MOVING`.
fn merge<'a>(
    statics: &Projected,
    lists: impl Iterator<Item = &'a [u32]>,
    moving: &Projected,
    tile: &[u32],
) -> Vec<u32> {
    let key = |p: &Projected, i: u32| (p.sort_key(i as usize), p.id(i as usize));
    let mut out = Vec::with_capacity(tile.len());
    let mut m = tile.iter().peekable();
    for list in lists {
        for &s in list {
            let ks = key(statics, s);
            while let Some(&&j) = m.peek() {
                if key(moving, j) < ks {
                    out.push(j + MOVING);
                    m.next();
                } else {
                    break;
                }
            }
            out.push(s);
        }
    }
    out.extend(m.map(|&j| j + MOVING));
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::{RenderMode, rasterize};

    #[test]
    fn every_frame_equals_a_full_render() {
        // a random cloud; a tenth of it moves each frame, some of it behind the camera or off-screen
        let mut state = 11u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / ((1u64 << 24) as f32)
        };
        let n = 3000;
        let k = 4;
        let mut means: Vec<Vec3> =
            (0..n).map(|_| Vec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, 1.0 + 3.0 * next())).collect();
        let scales: Vec<Vec3> = (0..n).map(|_| Vec3::new(0.002 + 0.05 * next(), 0.01, 0.002 + 0.05 * next())).collect();
        let quats: Vec<[f32; 4]> = (0..n).map(|_| [next() - 0.5, next() - 0.5, next() - 0.5, next() - 0.5]).collect();
        let opacities: Vec<f32> = (0..n).map(|_| next()).collect();
        // half as many SH rows as Gaussians, each row shared by two (as a split needle's pieces)
        let sh: Vec<f32> = (0..n / 2 * k * 3).map(|_| next() - 0.5).collect();
        let sh_rows: Vec<u32> = (0..n).map(|i| (i % (n / 2)) as u32).collect();
        // equal depths between a static and a moving Gaussian: the lower row goes first
        means[7] = means[8];
        // every third Gaussian sorts off its mean (as a split needle's pieces do), static and moving
        let sort_offsets: Vec<Vec3> =
            (0..n).map(|i| if i % 3 == 0 { Vec3::new(0.3, -0.2, 0.5 * (next() - 0.5)) } else { Vec3::ZERO }).collect();
        let moving: Vec<u32> = (0..n as u32).filter(|r| r % 10 == 8).collect();
        let camera = Camera {
            width: 150,
            height: 100,
            fx: 120.0,
            fy: 120.0,
            cx: 75.0,
            cy: 50.0,
            world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
            near: crate::NEAR_PLANE,
        };
        for mode in [RenderMode::Full, RenderMode::IndexOnly, RenderMode::IndexSolid, RenderMode::Color] {
            let options = RenderOptions { background: [0.3, 0.2, 0.1], mode };
            let splats = |means: &[Vec3], quats: &[[f32; 4]]| {
                let splats = Splats {
                    means,
                    scales: &scales,
                    quats,
                    opacities: &opacities,
                    sh: &sh,
                    sh_coeffs: k,
                    sh_rows: Some(&sh_rows),
                    sort_offsets: Some(&sort_offsets),
                };
                rasterize(&splats, &camera, &options).unwrap()
            };
            let first = Splats {
                means: &means,
                scales: &scales,
                quats: &quats,
                opacities: &opacities,
                sh: &sh,
                sh_coeffs: k,
                sh_rows: Some(&sh_rows),
                sort_offsets: Some(&sort_offsets),
            };
            let mut retained = Retained::new(&first, &camera, &options, &moving).unwrap();
            let (mut means, mut quats) = (means.clone(), quats.clone());
            for frame in 0..4 {
                for &r in &moving {
                    let r = r as usize;
                    means[r] += Vec3::new(0.15 * (frame as f32 + next() - 0.5), 0.1 * next(), -0.4 * next());
                    quats[r][0] += next();
                }
                let got = retained.frame(&means, &scales, &quats).unwrap().clone();
                let want = splats(&means, &quats);
                assert_eq!(got.index, want.index, "frame {frame}");
                assert_eq!(got.index_depth, want.index_depth);
                assert_eq!(got.alpha, want.alpha);
                assert_eq!(got.rgb, want.rgb);
                assert_eq!(got.depth, want.depth);
            }
        }
    }
}
