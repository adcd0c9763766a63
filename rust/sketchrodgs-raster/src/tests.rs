//! Whole-pipeline tests; the per-module ones sit beside their code.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use glam::Vec3;

use crate::bin::{TileBins, sort_by_depth};
use crate::project::project;
use crate::*;

fn camera(width: u32, height: u32) -> Camera {
    Camera {
        width,
        height,
        fx: 100.0,
        fy: 100.0,
        cx: f64::from(width) / 2.0 + 0.5,
        cy: f64::from(height) / 2.0 + 0.5,
        world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
        near: crate::NEAR_PLANE,
    }
}

/// Owned arrays behind a [`Splats`].
struct Scene {
    means: Vec<Vec3>,
    scales: Vec<Vec3>,
    quats: Vec<[f32; 4]>,
    opacities: Vec<f32>,
    sh: Vec<f32>,
    k: usize,
}

impl Scene {
    fn splats(&self) -> Splats<'_> {
        Splats {
            means: &self.means,
            scales: &self.scales,
            quats: &self.quats,
            opacities: &self.opacities,
            sh: &self.sh,
            sh_coeffs: self.k,
            sh_rows: None,
            sort_offsets: None,
        }
    }

    /// `n` pseudo-random Gaussians in front of the camera (a fixed LCG, no dependency).
    fn random(n: usize, k: usize, seed: u64) -> Self {
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / ((1u64 << 24) as f32)
        };
        let mut scene = Scene { means: vec![], scales: vec![], quats: vec![], opacities: vec![], sh: vec![], k };
        for _ in 0..n {
            scene.means.push(Vec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, 1.0 + 3.0 * next()));
            scene.scales.push(Vec3::new(0.002 + 0.05 * next(), 0.002 + 0.05 * next(), 0.002 + 0.05 * next()));
            scene.quats.push([next() - 0.5, next() - 0.5, next() - 0.5, next() - 0.5]);
            scene.opacities.push(next());
            scene.sh.extend((0..k * 3).map(|_| next() - 0.5));
        }
        scene
    }
}

fn render(scene: &Scene, camera: &Camera) -> RenderOutput {
    rasterize(&scene.splats(), camera, &RenderOptions::default()).unwrap()
}

#[test]
fn output_is_identical_for_any_thread_count() {
    let scene = Scene::random(20_000, 16, 1);
    let cam = camera(200, 150);
    let runs: Vec<RenderOutput> = [1, 2, 3, 8]
        .iter()
        .map(|&threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| render(&scene, &cam))
        })
        .collect();
    assert!(runs[0].n_visible > 10_000);
    for run in &runs[1..] {
        assert_eq!(run.rgb, runs[0].rgb);
        assert_eq!(run.alpha, runs[0].alpha);
        assert_eq!(run.depth, runs[0].depth);
        assert_eq!(run.index, runs[0].index);
        assert_eq!(run.index_depth, runs[0].index_depth);
    }
}

#[test]
fn every_lane_width_blends_the_same_bits() {
    use crate::composite::{Binned, blank, composite_with};
    use crate::simd::Simd;
    let widths = Simd::available();
    if widths.len() < 2 {
        return; // nothing to compare against on this CPU
    }
    // Gaussians of all sizes, and an image whose width is not a multiple of the tile
    let mut scene = Scene::random(20_000, 16, 5);
    scene.scales.iter_mut().step_by(37).for_each(|s| *s *= 15.0);
    let cam = camera(203, 117);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for mode in [RenderMode::Full, RenderMode::IndexOnly, RenderMode::IndexSolid, RenderMode::Color] {
        let options = RenderOptions { background: [0.2, 0.1, 0.4], mode };
        let projected = project(&scene.splats(), &cam, mode.has_color(), None);
        let order = sort_by_depth(&projected);
        let bins = TileBins::new(&cam, &projected.rects, &order, None).unwrap();
        let source = Binned { projected: &projected, bins: &bins };
        let outs: Vec<RenderOutput> = widths
            .iter()
            .map(|&simd| {
                let mut out = blank(&cam, &options).unwrap();
                composite_with(simd, &mut out, &cam, &source, &options, None, None);
                out
            })
            .collect();
        let four = &outs[0];
        assert!(four.alpha.iter().filter(|&&a| a > 0.1).count() > 10_000);
        for (wide, simd) in outs.iter().zip(&widths).skip(1) {
            assert_eq!(four.index, wide.index, "{simd:?}");
            for (a, b) in [(&four.alpha, &wide.alpha), (&four.rgb, &wide.rgb), (&four.depth, &wide.depth)] {
                assert_eq!(bits(a), bits(b), "{simd:?}");
            }
            assert_eq!(four.index_depth, wide.index_depth, "{simd:?}");
        }
    }
}

#[test]
fn color_mode_gives_the_full_renders_rgb_and_alpha_bits_without_index_or_depth() {
    let mut scene = Scene::random(5_000, 16, 3);
    scene.scales.iter_mut().step_by(29).for_each(|s| *s *= 10.0);
    let cam = camera(110, 70);
    let background = [0.2, 0.3, 0.1];
    let render = |mode| rasterize(&scene.splats(), &cam, &RenderOptions { background, mode }).unwrap();
    let (full, color) = (render(RenderMode::Full), render(RenderMode::Color));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&color.rgb), bits(&full.rgb));
    assert_eq!(bits(&color.alpha), bits(&full.alpha));
    assert!(full.alpha.iter().filter(|&&a| a > 0.5).count() > 1_000);
    assert!(color.index.is_empty() && color.index_depth.is_empty() && color.depth.is_empty());
    assert_eq!((color.n_visible, color.n_tile_pairs), (full.n_visible, full.n_tile_pairs));
}

#[test]
fn index_only_mode_skips_colour_but_keeps_the_index_and_alpha() {
    let scene = Scene::random(5_000, 4, 2);
    let cam = camera(96, 80);
    let full = render(&scene, &cam);
    let options = RenderOptions { mode: RenderMode::IndexOnly, ..RenderOptions::default() };
    let fast = rasterize(&scene.splats(), &cam, &options).unwrap();
    assert!(fast.rgb.is_empty() && fast.depth.is_empty());
    assert_eq!(fast.index, full.index);
    assert_eq!(fast.alpha, full.alpha);
    assert_eq!(fast.index_depth, full.index_depth);
}

#[test]
fn index_solid_mode_keeps_the_index_and_whether_alpha_reaches_half() {
    let mut scene = Scene::random(20_000, 4, 7);
    scene.opacities.iter_mut().step_by(2).for_each(|o| *o = 0.95); // opaque patches, where pixels stop early
    let cam = camera(203, 117);
    let exact =
        rasterize(&scene.splats(), &cam, &RenderOptions { mode: RenderMode::IndexOnly, ..RenderOptions::default() })
            .unwrap();
    let runs: Vec<RenderOutput> = [1, 2, 3]
        .iter()
        .map(|&threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let options = RenderOptions { mode: RenderMode::IndexSolid, ..RenderOptions::default() };
            pool.install(|| rasterize(&scene.splats(), &cam, &options).unwrap())
        })
        .collect();
    for solid in &runs {
        assert!(solid.rgb.is_empty() && solid.depth.is_empty());
        assert_eq!(solid.index, exact.index);
        assert_eq!(solid.index_depth, exact.index_depth);
        assert_eq!(solid.alpha, runs[0].alpha);
        for (&a, &full) in solid.alpha.iter().zip(&exact.alpha) {
            assert_eq!(a >= 0.5, full >= 0.5);
            assert!(a <= full);
            if full < 0.5 {
                assert_eq!(a, full);
            }
        }
    }
    // the early stop did happen, on most of the covered pixels
    let covered = exact.alpha.iter().filter(|&&a| a >= 0.5).count();
    let stopped = runs[0].alpha.iter().zip(&exact.alpha).filter(|(a, full)| a < full).count();
    assert!(covered > 10_000 && stopped > covered / 2, "{stopped} of {covered}");
}

#[test]
fn equal_depths_blend_in_ascending_index_order() {
    // Two identical Gaussians at the same depth: the lower row is blended first, so it weighs
    // alpha against the other's alpha (1 - alpha), and it is the one the index names.
    let mut scene = Scene::random(2, 1, 3);
    scene.means = vec![Vec3::new(0.0, 0.0, 2.0); 2];
    scene.scales = vec![Vec3::splat(0.05); 2];
    scene.quats = vec![[1.0, 0.0, 0.0, 0.0]; 2];
    scene.opacities = vec![0.5; 2];
    scene.sh = vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let cam = camera(32, 32);
    let out = render(&scene, &cam);
    let centre = 16 * 32 + 16;
    assert_eq!(out.index[centre], 0);
    // Colours: row 0 (0.5 + C0, 0.5, 0.5), row 1 (0.5, 0.5 + C0, 0.5); weights 0.5 and 0.25.
    let c0 = 0.5 + project::SH_C0;
    assert!((out.rgb[centre * 3] - (c0 * 0.5 + 0.5 * 0.25)).abs() < 1e-6);
    assert!((out.rgb[centre * 3 + 1] - (0.5 * 0.5 + c0 * 0.25)).abs() < 1e-6);
}

#[test]
fn a_sort_offset_moves_where_a_gaussian_sorts_and_only_that() {
    // Two overlapping opaque Gaussians, row 0 at z = 2 in front of row 1 at z = 3. Row 1 sorting
    // half a unit in front of row 0 is blended first: its offset, +x in its own axes, points
    // along world -z after its quarter turn about y.
    let mut scene = Scene::random(2, 1, 3);
    scene.means = vec![Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.0, 0.0, 3.0)];
    scene.scales = vec![Vec3::splat(0.05), Vec3::splat(0.08)];
    let quarter = glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
    scene.quats = vec![[1.0, 0.0, 0.0, 0.0], [quarter.w, quarter.x, quarter.y, quarter.z]];
    scene.opacities = vec![0.95; 2];
    let cam = camera(32, 32);
    let centre = 16 * 32 + 16;
    let plain = render(&scene, &cam);
    assert_eq!(plain.index[centre], 0);
    let offsets = [Vec3::ZERO, Vec3::new(1.5, 0.0, 0.0)]; // world -1.5 z: sorts at z = 1.5
    assert!(((quarter * offsets[1]).z + 1.5).abs() < 1e-6);
    let splats = Splats { sort_offsets: Some(&offsets), ..scene.splats() };
    let moved = rasterize(&splats, &cam, &RenderOptions::default()).unwrap();
    assert_eq!(moved.index[centre], 1);
    assert_eq!(moved.index_depth[centre], 3.0); // its depth is still its mean's
    // zero offsets are no offsets, to the bit
    let zeros = [Vec3::ZERO; 2];
    let same = rasterize(&Splats { sort_offsets: Some(&zeros), ..scene.splats() }, &cam, &RenderOptions::default());
    let same = same.unwrap();
    assert_eq!((same.rgb, same.index, same.alpha), (plain.rgb, plain.index, plain.alpha));
    // a wrong length is an error naming the field
    let short = [Vec3::ZERO; 1];
    assert!(matches!(
        rasterize(&Splats { sort_offsets: Some(&short), ..scene.splats() }, &cam, &RenderOptions::default()),
        Err(RasterError::LengthMismatch { name: "sort_offsets", .. })
    ));
}

#[test]
fn sh_rows_render_as_the_rows_they_pick() {
    // a table of 40 rows, 200 Gaussians picking from it: the same bits as each Gaussian given its
    // own copy of its row
    let scene = Scene::random(200, 9, 11);
    let (k, table_rows) = (9, 40);
    let rows: Vec<u32> = (0..200).map(|i| (i * 7 % table_rows) as u32).collect();
    let table = &scene.sh[..table_rows * k * 3];
    let copied: Vec<f32> =
        rows.iter().flat_map(|&r| &table[r as usize * k * 3..(r as usize + 1) * k * 3]).copied().collect();
    let cam = camera(64, 48);
    let shared = Splats { sh: table, sh_rows: Some(&rows), ..scene.splats() };
    let got = rasterize(&shared, &cam, &RenderOptions::default()).unwrap();
    let want = rasterize(&Splats { sh: &copied, ..scene.splats() }, &cam, &RenderOptions::default()).unwrap();
    assert_eq!((got.rgb, got.index), (want.rgb, want.index));
    let mut bad = rows.clone();
    bad[17] = table_rows as u32;
    assert!(matches!(
        rasterize(&Splats { sh_rows: Some(&bad), ..shared }, &cam, &RenderOptions::default()),
        Err(RasterError::ShRowOutOfRange { index: 17, .. })
    ));
}

#[test]
fn tile_lists_hold_each_gaussian_in_its_rectangle_front_to_back() {
    let scene = Scene::random(3_000, 1, 4);
    let cam = camera(100, 70);
    let projected = project(&scene.splats(), &cam, true, None);
    let order = sort_by_depth(&projected);
    let (projected, rects) = (projected.splats, projected.rects);
    assert_eq!(order.len(), rects.iter().filter(|r| !r.is_empty()).count());
    let bins = TileBins::new(&cam, &rects, &order, None).unwrap();
    assert_eq!(bins.len(), rects.iter().map(|r| r.area()).sum::<usize>());
    let mut seen = vec![0usize; rects.len()];
    for ty in 0..bins.grid_y as u16 {
        for tx in 0..bins.grid_x as u16 {
            let list: Vec<u32> =
                bins.tile_lists(usize::from(ty) * bins.grid_x as usize + usize::from(tx)).flatten().copied().collect();
            for pair in list.windows(2) {
                let (a, b) = (projected[pair[0] as usize].depth, projected[pair[1] as usize].depth);
                assert!(a < b || (a == b && pair[0] < pair[1]), "tile list out of order");
            }
            for &i in &list {
                let r = rects[i as usize];
                assert!(r.x0 <= tx && tx < r.x1 && r.y0 <= ty && ty < r.y1);
                seen[i as usize] += 1;
            }
        }
    }
    for (i, r) in rects.iter().enumerate() {
        assert_eq!(seen[i], r.area());
    }
}

#[test]
fn empty_and_unseen_scenes_render_the_background() {
    let cam = camera(40, 30);
    let options = RenderOptions { background: [0.25, 0.5, 1.0], mode: RenderMode::Full };
    let empty = Scene::random(0, 1, 5);
    let mut behind = Scene::random(100, 1, 6);
    behind.means.iter_mut().for_each(|m| m.z = -m.z);
    for scene in [&empty, &behind] {
        let out = rasterize(&scene.splats(), &cam, &options).unwrap();
        assert_eq!(out.n_visible, 0);
        assert!(out.index.iter().all(|&i| i == -1));
        assert!(out.alpha.iter().all(|&a| a == 0.0));
        assert!(out.rgb.chunks_exact(3).all(|c| c == [0.25, 0.5, 1.0]));
    }
}

#[test]
fn inconsistent_inputs_are_errors() {
    let scene = Scene::random(10, 4, 7);
    let cam = camera(40, 30);
    let mut splats = scene.splats();
    splats.opacities = &scene.opacities[..9];
    assert!(matches!(
        rasterize(&splats, &cam, &RenderOptions::default()),
        Err(RasterError::LengthMismatch { name: "opacities", .. })
    ));
    let mut splats = scene.splats();
    splats.sh_coeffs = 5;
    assert!(matches!(rasterize(&splats, &cam, &RenderOptions::default()), Err(RasterError::UnsupportedShDegree(5))));
    let flat: Vec<f32> = vec![0.0; 10];
    assert!(matches!(
        Splats::from_flat(&flat, &flat, &flat, &flat, &flat, 1, None),
        Err(RasterError::LengthMismatch { name: "means", .. })
    ));
    let mut bad = cam;
    bad.fx = 0.0;
    assert!(matches!(
        rasterize(&scene.splats(), &bad, &RenderOptions::default()),
        Err(RasterError::InvalidCamera { field: "fx", .. })
    ));
}

#[test]
fn huge_gaussians_covering_everything_are_fine() {
    let mut scene = Scene::random(50, 1, 8);
    scene.scales.iter_mut().for_each(|s| *s = Vec3::splat(1e3));
    let out = render(&scene, &camera(64, 64));
    assert_eq!(out.n_visible, 50);
    assert!(out.index.iter().all(|&i| i >= 0));
    assert!(out.rgb.iter().all(|c| c.is_finite()));
}

#[test]
fn rendering_some_tiles_gives_exactly_the_full_render_there() {
    // Gaussians of all sizes, some far off-screen, and masks from a single tile to all of them.
    let mut scene = Scene::random(4_000, 4, 9);
    scene.scales.iter_mut().step_by(97).for_each(|s| *s *= 20.0);
    scene.means.iter_mut().step_by(13).for_each(|m| m.x *= 3.0);
    let cam = camera(200, 150); // 13 x 10 tiles
    let options = RenderOptions { background: [0.1, 0.2, 0.3], mode: RenderMode::Full };
    let full = rasterize(&scene.splats(), &cam, &options).unwrap();
    let (grid_x, grid_y) = cam.tile_grid();
    let n_tiles = (grid_x * grid_y) as usize;
    let masks: Vec<Vec<bool>> = vec![
        (0..n_tiles).map(|t| t == 57).collect(),
        (0..n_tiles).map(|t| (t / grid_x as usize + t % grid_x as usize).is_multiple_of(5)).collect(),
        (0..n_tiles).map(|t| t % grid_x as usize >= 11).collect(),
        vec![true; n_tiles],
    ];
    for on in masks {
        let mask = TileMask::new(&cam, on.clone()).unwrap();
        for mode in [RenderMode::Full, RenderMode::IndexOnly] {
            let part = rasterize_tiles(&scene.splats(), &cam, &RenderOptions { mode, ..options }, &mask).unwrap();
            for p in 0..(cam.width * cam.height) as usize {
                let (x, y) = (p % cam.width as usize, p / cam.width as usize);
                let tile = y / 16 * grid_x as usize + x / 16;
                if on[tile] {
                    assert_eq!(part.index[p], full.index[p], "index at {x},{y}");
                    assert_eq!(part.index_depth[p].to_bits(), full.index_depth[p].to_bits());
                    assert_eq!(part.alpha[p].to_bits(), full.alpha[p].to_bits());
                    if mode == RenderMode::Full {
                        assert_eq!(part.rgb[p * 3..p * 3 + 3], full.rgb[p * 3..p * 3 + 3]);
                        assert_eq!(part.depth[p].to_bits(), full.depth[p].to_bits());
                    }
                } else {
                    assert_eq!((part.index[p], part.alpha[p]), (-1, 0.0));
                    if mode == RenderMode::Full {
                        assert_eq!(part.rgb[p * 3..p * 3 + 3], [0.1, 0.2, 0.3]);
                    }
                }
            }
            // the cheap bound dropped none that the exact footprint keeps
            let reaching = project(&scene.splats(), &cam, false, None).rects.iter().filter(|r| mask.touches(r)).count();
            assert_eq!(part.n_visible, reaching);
        }
    }
    let wrong = TileMask::new(&camera(100, 70), vec![true; 35]).unwrap();
    assert!(matches!(
        rasterize_tiles(&scene.splats(), &cam, &options, &wrong),
        Err(RasterError::LengthMismatch { name: "tiles", .. })
    ));
}

#[test]
fn renders_after_a_larger_one_reuse_its_buffers_and_match_a_fresh_render() {
    // A render keeps its projection and sort buffers for the next (`kept`). What the larger
    // render left there must not show through: the later scene is smaller, and most of it is
    // behind the camera (culled rows where the first scene's were visible).
    let cam = camera(64, 48);
    let big = Scene::random(30_000, 4, 21);
    let mut small = Scene::random(9_000, 4, 22);
    for mean in small.means.iter_mut().step_by(3).skip(1) {
        mean.z = -mean.z;
    }
    let fresh = {
        release_kept_buffers();
        render(&small, &cam)
    };
    for _ in 0..2 {
        let _ = render(&big, &cam);
        let again = render(&small, &cam);
        assert_eq!((&again.rgb, &again.index, &again.alpha), (&fresh.rgb, &fresh.index, &fresh.alpha));
        assert_eq!(again.n_visible, fresh.n_visible);
    }
}

/// The Gaussians of `scene` whose camera z (the identity camera: their mean's z) exceeds `near`,
/// and their rows in `scene`.
fn deeper_than(scene: &Scene, near: f32) -> (Scene, Vec<i32>) {
    let rows: Vec<usize> = (0..scene.means.len()).filter(|&i| scene.means[i].z > near).collect();
    let k3 = scene.k * 3;
    let subset = Scene {
        means: rows.iter().map(|&i| scene.means[i]).collect(),
        scales: rows.iter().map(|&i| scene.scales[i]).collect(),
        quats: rows.iter().map(|&i| scene.quats[i]).collect(),
        opacities: rows.iter().map(|&i| scene.opacities[i]).collect(),
        sh: rows.iter().flat_map(|&i| scene.sh[i * k3..(i + 1) * k3].iter().copied()).collect(),
        k: scene.k,
    };
    (subset, rows.iter().map(|&i| i as i32).collect())
}

#[test]
fn a_layer_behind_a_depth_is_the_render_of_what_lies_deeper() {
    let scene = Scene::random(20_000, 1, 7);
    let cam = camera(160, 120);
    let solid = RenderOptions { mode: RenderMode::IndexSolid, ..RenderOptions::default() };
    // left half behind z = 2, right half behind z = 3
    let (width, height) = (160, 120);
    let near: Vec<f32> = (0..width * height).map(|p| if p % width < width / 2 { 2.0 } else { 3.0 }).collect();
    let layers = rasterize_behind(&scene.splats(), &cam, None, &near, 1, 8.0).unwrap();
    for (cut, left) in [(2.0, true), (3.0, false)] {
        let (deeper, rows) = deeper_than(&scene, cut);
        let expected = rasterize(&deeper.splats(), &cam, &solid).unwrap();
        let mut compared = 0;
        for p in (0..width * height).filter(|p| (p % width < width / 2) == left) {
            let k = expected.index[p];
            assert_eq!(layers[0].index[p], if k >= 0 { rows[k as usize] } else { -1 }, "pixel {p}");
            assert_eq!(layers[0].index_depth[p], expected.index_depth[p]);
            assert_eq!(layers[0].alpha[p] >= 0.5, expected.alpha[p] >= 0.5);
            compared += usize::from(k >= 0);
        }
        assert!(compared > 1000);
    }
    // nothing in front of every Gaussian: the plain index-solid render
    let everything = rasterize_behind(&scene.splats(), &cam, None, &vec![f32::NEG_INFINITY; width * height], 1, 8.0);
    let plain = rasterize(&scene.splats(), &cam, &solid).unwrap();
    assert_eq!(everything.unwrap()[0].index, plain.index);
}

#[test]
fn each_layer_lies_a_gap_behind_the_one_before() {
    // three opaque sheets at z = 2, 2.05 and 4 over the whole image; a gap of 8 px at 100 px focal
    // length is 8 % of the depth, so the sheet at 2.05 is peeled with the one at 2
    let sheet = |z: f32| Scene {
        means: vec![Vec3::new(0.0, 0.0, z)],
        scales: vec![Vec3::new(5.0, 5.0, 0.001)],
        quats: vec![[1.0, 0.0, 0.0, 0.0]],
        opacities: vec![1.0],
        sh: vec![0.0; 3],
        k: 1,
    };
    let mut scene = sheet(2.0);
    for z in [2.05, 4.0] {
        let s = sheet(z);
        scene.means.extend(s.means);
        scene.scales.extend(s.scales);
        scene.quats.extend(s.quats);
        scene.opacities.extend(s.opacities);
        scene.sh.extend(s.sh);
    }
    let cam = camera(32, 32);
    let near = vec![f32::NEG_INFINITY; 32 * 32];
    let layers = rasterize_behind(&scene.splats(), &cam, None, &near, 3, 8.0).unwrap();
    let centre = 16 * 32 + 16;
    assert_eq!(layers.iter().map(|l| l.index[centre]).collect::<Vec<_>>(), [0, 2, -1]);
    // only the tiles asked for are rendered
    let mut on = vec![false; 4];
    on[0] = true;
    let mask = TileMask::new(&cam, on).unwrap();
    let some = rasterize_behind(&scene.splats(), &cam, Some(&mask), &near, 2, 8.0).unwrap();
    assert_eq!((some[1].index[0], some[1].index[centre]), (2, -1));
    assert!(rasterize_behind(&scene.splats(), &cam, None, &near[1..], 1, 8.0).is_err());
}

#[test]
fn the_near_plane_is_the_cameras() {
    // one Gaussian 0.1 in front of the camera: culled at the reference's 0.2, drawn at 0.05
    let scene = Scene {
        means: vec![Vec3::new(0.0, 0.0, 0.1)],
        scales: vec![Vec3::splat(0.01)],
        quats: vec![[1.0, 0.0, 0.0, 0.0]],
        opacities: vec![0.9],
        sh: vec![1.0, 1.0, 1.0],
        k: 1,
    };
    let reference = camera(32, 32);
    assert_eq!(render(&scene, &reference).n_visible, 0);
    let close = Camera { near: 0.05, ..reference };
    let out = render(&scene, &close);
    assert_eq!(out.n_visible, 1);
    assert_eq!(out.index[16 * 32 + 16], 0);
    for near in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let bad = Camera { near, ..reference };
        assert!(
            matches!(
                rasterize(&scene.splats(), &bad, &RenderOptions::default()),
                Err(RasterError::InvalidCamera { field: "near", .. })
            ),
            "near {near}"
        );
    }
}
