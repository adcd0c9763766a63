#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use crate::*;

/// A synthetic scene: one Gaussian per covered pixel, its centre the pixel back-projected at depth
/// `z` with focal length `focal` (so neighbouring pixels on one surface are `z / focal` apart).
struct Synthetic {
    width: usize,
    height: usize,
    index: Vec<i32>,
    depth: Vec<f32>,
    centres: Vec<[f32; 3]>,
}

impl Synthetic {
    fn new(width: usize, height: usize, focal: f32, surface: impl Fn(usize, usize) -> Option<f32>) -> Self {
        let (mut index, mut depth, mut centres) = (vec![-1; width * height], vec![0.0; width * height], Vec::new());
        for row in 0..height {
            for col in 0..width {
                if let Some(z) = surface(col, row) {
                    let p = row * width + col;
                    index[p] = centres.len() as i32;
                    depth[p] = z;
                    centres.push([(col as f32 + 0.5) * z / focal, (row as f32 + 0.5) * z / focal, z]);
                }
            }
        }
        Self { width, height, index, depth, centres }
    }

    fn image(&self) -> IndexImage<'_> {
        IndexImage::new(self.width, self.height, &self.index, &self.depth).unwrap()
    }

    fn trace(&self, stroke: &[[f32; 2]], radius: f32) -> Result<Trace, PathError> {
        let params = TraceParams { radius, band_px: 6.0, focal_px: FOCAL, ..TraceParams::default() };
        trace_stroke(&self.image(), &self.centres, stroke, &params)
    }

    /// `estimate_radius` with each Gaussian coloured by its pixel's row (its centre's y is
    /// (row + 0.5) z / focal).
    fn radius_with_colours(
        &self,
        stroke: &[[f32; 2]],
        params: &TraceParams,
        colour_of: impl Fn(usize) -> [f32; 3],
    ) -> f32 {
        let colours: Vec<[f32; 3]> = self.centres.iter().map(|c| colour_of((c[1] * FOCAL / c[2]) as usize)).collect();
        let ids: Vec<u32> = (0..self.centres.len() as u32).collect();
        estimate_radius(&self.image().with_colours(&ids, &colours).unwrap(), stroke, params).unwrap().radius
    }

    fn rows_of(&self, piece: &Piece) -> Vec<u32> {
        piece.pixels.iter().map(|p| p[1]).collect()
    }
}

const FOCAL: f32 = 100.0;

/// A horizontal rope 3 px thick at rows 19..=21, depth 5.
fn rope(_col: usize, row: usize) -> Option<f32> {
    (19..=21).contains(&row).then_some(5.0)
}

#[test]
fn straight_rope_is_followed_end_to_end() {
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let trace = scene.trace(&[[2.5, 20.5], [40.0, 21.5], [77.5, 20.5]], 0.05).unwrap();
    assert_eq!(trace.pieces.len(), 1);
    let piece = &trace.pieces[0];
    assert_eq!(piece.end, PieceEnd::Goal);
    assert_eq!(piece.pixels.first(), Some(&[2, 20]));
    assert_eq!(piece.pixels.last(), Some(&[77, 20]));
    assert!(scene.rows_of(piece).iter().all(|r| (19..=21).contains(r)));
    // 8-connected and monotone in x: the shortest 3D path does not wander
    for w in piece.pixels.windows(2) {
        assert!(w[1][0] == w[0][0] + 1 && w[1][1].abs_diff(w[0][1]) <= 1, "{w:?}");
    }
    assert_eq!(piece.gaussian_ids.len(), piece.pixels.len());
    assert!(trace.coverage > 0.99, "coverage {}", trace.coverage);
}

#[test]
fn the_path_prefers_the_surface_nearest_the_stroke() {
    // Two ropes 8 px apart at the same depth; the stroke runs on the lower one.
    let scene =
        Synthetic::new(60, 40, FOCAL, |_, row| ((10..=12).contains(&row) || (20..=22).contains(&row)).then_some(5.0));
    let trace = scene.trace(&[[1.5, 21.5], [58.5, 20.5]], 0.05).unwrap();
    assert!(scene.rows_of(&trace.pieces[0]).iter().all(|r| (20..=22).contains(r)));
}

#[test]
fn an_occluding_pole_splits_the_path_and_it_resumes_behind() {
    // A rope at depth 5 passes behind a vertical pole (cols 38..=42) at depth 3.
    let scene =
        Synthetic::new(80, 40, FOCAL, |col, row| if (38..=42).contains(&col) { Some(3.0) } else { rope(col, row) });
    let trace = scene.trace(&[[2.5, 20.5], [20.5, 20.5], [40.5, 20.5], [60.5, 20.5], [77.5, 20.5]], 0.05).unwrap();
    assert_eq!(trace.pieces.len(), 2, "{:?}", trace.pieces.iter().map(|p| p.end).collect::<Vec<_>>());
    let (first, second) = (&trace.pieces[0], &trace.pieces[1]);
    assert!(matches!(first.end, PieceEnd::Lost { pixel, .. } if pixel[0] == 37), "{:?}", first.end);
    assert_eq!(second.end, PieceEnd::Goal);
    // neither piece uses a pole Gaussian
    for piece in &trace.pieces {
        assert!(piece.pixels.iter().all(|p| !(38..=42).contains(&p[0])));
    }
    // the chain the path follows runs on both sides of the pole
    assert!(trace.clean_stroke.iter().any(|p| p[0] < 38.0) && trace.clean_stroke.iter().any(|p| p[0] > 43.0));
    assert!(trace.coverage > 0.95, "coverage {}", trace.coverage);
}

#[test]
fn a_band_wider_than_the_cover_distance_still_ends() {
    // A rope broken by a gap; in the gap a small blob 13 px off the stroke is the only surface. With
    // a 16 px band the search resumes on the blob, whose piece is too far from its stroke sample to
    // cover it: the next resume must move on along the stroke, not start from the blob again.
    let scene = Synthetic::new(80, 40, FOCAL, |col, row| {
        let rope = row == 20 && (col <= 30 || col >= 60);
        let blob = row == 33 && (45..=46).contains(&col);
        (rope || blob).then_some(5.0)
    });
    let params = TraceParams { radius: 0.05, band_px: 16.0, focal_px: FOCAL, ..TraceParams::default() };
    let trace = trace_stroke(&scene.image(), &scene.centres, &[[1.5, 20.5], [78.5, 20.5]], &params).unwrap();
    assert_eq!(trace.pieces.last().unwrap().end, PieceEnd::Goal);
    assert!(trace.pieces.len() <= 4, "{} pieces", trace.pieces.len());
}

#[test]
fn the_path_does_not_jump_across_a_depth_gap_onto_an_occluder() {
    // Same pole, but a stroke whose straight line would be cheapest across it.
    let scene =
        Synthetic::new(80, 40, FOCAL, |col, row| if (38..=42).contains(&col) { Some(3.0) } else { rope(col, row) });
    let trace = scene.trace(&[[2.5, 20.5], [77.5, 20.5]], 0.05).unwrap();
    let ids: Vec<u32> = trace.pieces.iter().flat_map(|p| p.gaussian_ids.iter().copied()).collect();
    assert!(ids.iter().all(|&k| scene.centres[k as usize][2] == 5.0));
    assert_eq!(trace.pieces.last().unwrap().end, PieceEnd::Goal);
}

#[test]
fn forward_only_keeps_the_path_on_its_branch_at_a_crossing() {
    // A stroke that goes right along row 20, then comes back left along row 30 (a hairpin). Without
    // the forward-only rule the path could cut straight to the goal along the bottom strand.
    let scene = Synthetic::new(80, 50, FOCAL, |col, row| {
        (((19..=21).contains(&row) || (29..=31).contains(&row)) && col >= 5
            || (70..=74).contains(&col) && (19..=31).contains(&row))
        .then_some(5.0)
    });
    let trace = scene.trace(&[[6.5, 20.5], [72.5, 20.5], [72.5, 30.5], [6.5, 30.5]], 0.05).unwrap();
    assert_eq!(trace.pieces.len(), 1);
    let piece = &trace.pieces[0];
    assert!(piece.pixels.iter().any(|p| p[0] >= 70), "the path must go round the hairpin");
    assert_eq!(piece.end, PieceEnd::Goal);
}

#[test]
fn endpoints_a_few_pixels_off_the_object_snap_onto_it() {
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let trace = scene.trace(&[[2.5, 15.5], [77.5, 24.5]], 0.05).unwrap();
    let piece = &trace.pieces[0];
    assert_eq!(piece.end, PieceEnd::Goal);
    assert_eq!(piece.pixels.first().unwrap()[1], 19);
    assert_eq!(piece.pixels.last().unwrap()[1], 21);
}

#[test]
fn ends_that_overshoot_the_object_are_trimmed() {
    // The rope spans cols 10..70; the stroke runs 25 px past it on background at both ends.
    let scene =
        Synthetic::new(100, 40, FOCAL, |col, row| ((10..70).contains(&col) && (19..=21).contains(&row)).then_some(5.0));
    let trace = scene.trace(&[[-15.0, 20.5], [50.0, 20.5], [95.0, 20.5]], 0.05).unwrap();
    assert_eq!(trace.pieces.len(), 1);
    let piece = &trace.pieces[0];
    assert_eq!(piece.end, PieceEnd::Goal);
    assert!(
        piece.pixels.first().unwrap()[0] <= 11 && piece.pixels.last().unwrap()[0] >= 68,
        "{:?}",
        (piece.pixels.first(), piece.pixels.last())
    );
    let (first, last) = (trace.clean_stroke[0][0], trace.clean_stroke.last().unwrap()[0]);
    assert!((0.0..=12.0).contains(&first) && (68.0..=80.0).contains(&last), "trimmed to {first}..{last}");
}

#[test]
fn an_end_on_a_neighbour_at_another_depth_is_trimmed() {
    // The stroke's last 20 px lie on a wall 2 units behind the rope: they are not part of its chain.
    let scene = Synthetic::new(100, 40, FOCAL, |col, row| {
        if (19..=21).contains(&row) && col < 70 {
            Some(5.0)
        } else if col >= 75 {
            Some(7.0)
        } else {
            None
        }
    });
    let trace = scene.trace(&[[2.5, 20.5], [95.5, 20.5]], 0.05).unwrap();
    assert_eq!(
        trace.pieces.len(),
        1,
        "{:?}",
        trace.pieces.iter().map(|p| (p.pixels[0], p.pixels[p.pixels.len() - 1])).collect::<Vec<_>>()
    );
    assert!(trace.pieces[0].pixels.iter().all(|p| p[0] < 70));
    assert!(trace.clean_stroke.last().unwrap()[0] < 80.0);
}

#[test]
fn a_stroke_touching_the_object_once_is_a_clear_error() {
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let err = scene.trace(&[[40.5, 2.5], [40.5, 3.5]], 0.05).unwrap_err();
    assert_eq!(err, PathError::StrokeOnBackground { outside: 0, width: 80, height: 40 });
    assert!(err.to_string().contains("entirely on background"), "{err}");
    assert!(err.to_string().contains("draw it over the object"));
}

#[test]
fn bad_strokes_and_parameters_are_errors() {
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let nan = scene.trace(&[[2.5, 20.5], [f32::NAN, 20.5]], 0.05).unwrap_err();
    assert_eq!(nan, PathError::NonFiniteStroke { vertex: 1 });
    let short = scene.trace(&[[2.5, 20.5]], 0.05).unwrap_err();
    assert!(matches!(short, PathError::StrokeTooShort { inside: 1, outside: 0, .. }));
    let same = scene.trace(&[[2.5, 20.5]; 3], 0.05).unwrap_err();
    assert!(matches!(same, PathError::StrokeTooShort { inside: 1, outside: 0, .. }), "{same:?}");
    let outside = scene.trace(&[[-5.0, 20.5], [-9.0, 30.5]], 0.05).unwrap_err();
    assert!(matches!(outside, PathError::StrokeTooShort { inside: 0, outside: 2, .. }));
    assert!(outside.to_string().contains("2 outside the image"), "{outside}");
    // a stroke reaching in from outside the image keeps its inside part
    let across = scene.trace(&[[-5.0, 20.5], [100.0, 20.5]], 0.05).unwrap();
    assert_eq!(across.pieces[0].pixels.first().unwrap()[0], 0);
    let background = scene.trace(&[[2.5, 2.5], [77.5, 2.5]], 0.05).unwrap_err();
    assert_eq!(background, PathError::StrokeOnBackground { outside: 0, width: 80, height: 40 });
    // reaching out of the image over background: its points outside are said to be outside
    let leaving = scene.trace(&[[2.5, 2.5], [77.5, 2.5], [120.0, 2.5]], 0.05).unwrap_err();
    assert_eq!(leaving, PathError::StrokeOnBackground { outside: 1, width: 80, height: 40 });
    let text = leaving.to_string();
    assert!(text.contains("inside the 80x40 image") && text.contains("1 of its points lies outside"), "{text}");
    for radius in [0.0, -1.0, f32::NAN] {
        assert!(matches!(
            scene.trace(&[[2.5, 20.5], [77.5, 20.5]], radius),
            Err(PathError::BadParameter { name: "radius", .. })
        ));
    }
    // a radius or a band wider than the image (a radius in the wrong units) is an error, not minutes
    // of reading the whole image at every sample: R = 10 is 200 px at depth 5
    let wide = scene.trace(&[[2.5, 20.5], [77.5, 20.5]], 10.0).unwrap_err();
    assert!(matches!(wide, PathError::RadiusWiderThanImage { width: 80, height: 40, .. }), "{wide:?}");
    assert!(wide.to_string().starts_with("radius 10 is 200 pixels at the stroke's depth, wider than the 80x40 image"));
    let params = TraceParams { radius: 0.05, band_px: 81.0, focal_px: FOCAL, ..TraceParams::default() };
    let band = trace_stroke(&scene.image(), &scene.centres, &[[2.5, 20.5], [77.5, 20.5]], &params).unwrap_err();
    assert_eq!(band.to_string(), "band_px 81 is wider than the 80x40 image: give a smaller band");
    // a stroke running 1e20 pixels out samples its part on the image only (it asked for more samples
    // than memory holds); one far out altogether is outside the image
    let far = scene.trace(&[[2.5, 20.5], [77.5, 20.5], [1e20, 20.5]], 0.05).unwrap();
    assert_eq!(far.pieces[0].pixels, scene.trace(&[[2.5, 20.5], [77.5, 20.5]], 0.05).unwrap().pieces[0].pixels);
    let away = scene.trace(&[[1e20, 20.5], [2e20, 1e20]], 0.05).unwrap_err();
    assert!(matches!(away, PathError::StrokeTooShort { inside: 0, outside: 2, .. }), "{away:?}");
}

#[test]
fn a_stroke_of_points_a_tenth_of_a_pixel_apart_is_followed_as_a_sparse_one() {
    // a tablet's stroke: 751 points along the rope; the same path as three points give
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let dense: Vec<[f32; 2]> = (0..=750).map(|i| [2.5 + i as f32 * 0.1, 20.5]).collect();
    let sparse = scene.trace(&[[2.5, 20.5], [40.0, 20.5], [77.5, 20.5]], 0.05).unwrap();
    assert_eq!(scene.trace(&dense, 0.05).unwrap().pieces[0].pixels, sparse.pieces[0].pixels);
}

#[test]
fn malformed_images_are_errors() {
    assert!(matches!(IndexImage::new(4, 4, &[0; 15], &[0.0; 16]), Err(PathError::ImageSize { .. })));
    assert!(matches!(IndexImage::new(0, 4, &[], &[]), Err(PathError::ImageSize { .. })));
    let index = [0, 1, 7, 2];
    let image = IndexImage::new(4, 1, &index, &[1.0; 4]).unwrap();
    let err = trace_stroke(&image, &[[0.0; 3]; 3], &[[0.5, 0.5], [3.5, 0.5]], &TraceParams::default()).unwrap_err();
    assert_eq!(err, PathError::IndexOutOfRange { id: 7, count: 3 });
    // a shown Gaussian's depth must be finite and > 0 (background pixels may hold anything)
    for bad in [0.0, -2.0, f32::NAN, f32::INFINITY] {
        let depth = [1.0, bad, 1.0, 1.0, f32::NAN, 1.0];
        let err = IndexImage::new(3, 2, &[0, 1, 2, 0, -1, 1], &depth).unwrap_err();
        assert!(matches!(err, PathError::BadDepth { col: 1, row: 0, .. }), "{err:?}");
        assert!(err.to_string().starts_with("index image: the depth at pixel (1, 0) is "), "{err}");
    }
    let image = IndexImage::new(2, 2, &[0; 4], &[1.0; 4]).unwrap();
    let err = image.with_behind(&[-1, -1, -1, -1, -1, -1, 0, -1], &[0.0; 8], &[1.0; 8]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "layer 1 behind the index image: the depth at pixel (0, 1) is 0 where a Gaussian is shown; it must be finite and > 0"
    );
}

#[test]
fn a_stroke_wandering_off_the_object_mid_way_still_covers_the_object() {
    // The stroke bows 15 px above the rope in the middle, beyond the band: the path is lost there and
    // resumes where the stroke comes back.
    let scene = Synthetic::new(100, 50, FOCAL, |_, row| (29..=31).contains(&row).then_some(5.0));
    let stroke = [[2.5, 30.5], [30.5, 30.5], [45.5, 15.5], [55.5, 15.5], [70.5, 30.5], [97.5, 30.5]];
    let trace = scene.trace(&stroke, 0.05).unwrap();
    assert_eq!(trace.pieces.last().unwrap().end, PieceEnd::Goal);
    assert!(trace.pieces.len() >= 2);
    let cols: Vec<u32> = trace.pieces.iter().flat_map(|p| p.pixels.iter().map(|q| q[0])).collect();
    assert!(cols.iter().any(|&c| c < 30) && cols.iter().any(|&c| c > 70));
}

#[test]
fn a_receding_rope_resumes_behind_a_wide_occluder() {
    // The rope's depth grows 0.01 per pixel; across the 30 px pole it changes by 0.3 > 3R = 0.15,
    // so only the depth trend tells the rope beyond the pole from something else.
    let scene = Synthetic::new(120, 40, FOCAL, |col, row| {
        if (45..=74).contains(&col) { Some(3.0) } else { (19..=21).contains(&row).then_some(5.0 + 0.01 * col as f32) }
    });
    let stroke: Vec<[f32; 2]> = (0..=23).map(|i| [2.5 + 5.0 * i as f32, 20.5]).collect();
    let trace = scene.trace(&stroke, 0.05).unwrap();
    assert_eq!(trace.pieces.len(), 2, "{:?}", trace.pieces.iter().map(|p| p.end).collect::<Vec<_>>());
    assert_eq!(trace.pieces[1].end, PieceEnd::Goal);
    assert!(trace.pieces[1].pixels[0][0] >= 75);
    // the samples over the middle of the pole (no rope within the band) are off the chain, the
    // ones beyond it on it
    assert!(trace.clean_stroke.iter().all(|p| !(52.0..68.0).contains(&p[0])));
    assert!(trace.clean_stroke.iter().any(|p| p[0] > 75.0));
}

#[test]
fn a_first_point_on_an_occluder_does_not_decide() {
    // The stroke starts on a pole in front (cols 0..=6, depth 3); the rest runs along the rope.
    let scene = Synthetic::new(80, 40, FOCAL, |col, row| if col <= 6 { Some(3.0) } else { rope(col, row) });
    let trace = scene.trace(&[[3.5, 20.5], [20.5, 20.5], [40.5, 20.5], [77.5, 20.5]], 0.05).unwrap();
    assert_eq!(trace.pieces.len(), 1);
    let piece = &trace.pieces[0];
    assert_eq!(piece.end, PieceEnd::Goal);
    assert!(piece.pixels.iter().all(|p| p[0] > 6), "the path must not use the pole");
    assert!(piece.pixels.last().unwrap()[0] >= 76);
    assert_eq!(piece.pixels[0][0], 7, "the path starts where the rope appears from behind the pole");
}

#[test]
fn the_path_keeps_off_a_wide_surface_touching_the_part() {
    // A leaf (rows 22..=34, cols 20..=60) touches the rope from below at the same depth. The stroke
    // runs 3 px into the leaf: without the width penalty the path would follow the stroke onto it.
    let leaf = |col: usize, row: usize| ((20..=60).contains(&col) && (22..=34).contains(&row)).then_some(5.0);
    let scene = Synthetic::new(80, 40, FOCAL, move |col, row| rope(col, row).or_else(|| leaf(col, row)));
    let stroke = [[2.5, 20.5], [20.5, 24.5], [60.5, 24.5], [77.5, 20.5]];
    // The stroke term is relative to the image's half-width: 4 px off in this 80 px image weigh as
    // 48 px would at 960. Weighed as 4 px are at 960:
    let params = TraceParams {
        radius: 0.075,
        band_px: 6.0,
        focal_px: FOCAL,
        stroke_weight: (80.0_f64 / 960.0).powi(2),
        ..TraceParams::default()
    };
    let trace = trace_stroke(&scene.image(), &scene.centres, &stroke, &params).unwrap();
    let on_leaf = trace.pieces.iter().flat_map(|p| p.pixels.iter()).filter(|p| p[1] >= 23).count();
    assert_eq!(on_leaf, 0, "{} path pixels on the leaf", on_leaf);
    // the same without the focal length (no width measure) does go onto the leaf
    let params = TraceParams { focal_px: 0.0, stroke_weight: 1.0, ..params };
    let blind = trace_stroke(&scene.image(), &scene.centres, &stroke, &params).unwrap();
    assert!(blind.pieces.iter().flat_map(|p| p.pixels.iter()).any(|p| p[1] >= 23));
}

#[test]
fn a_faint_haze_beside_the_part_is_not_a_surface_to_follow() {
    // One big faint Gaussian (0.04 opaque, its centre far off, depth 6) owns the pixels below the
    // rope, where the stroke runs 3-4 px off it. Its pixels are not solid: it is a haze, and the rod
    // stays on the rope (a leaf stalk of the plant in az000, with such a Gaussian beside it).
    let mut scene = Synthetic::new(80, 40, FOCAL, rope);
    let haze = scene.centres.len() as i32;
    scene.centres.push([4.0, 3.0, 6.0]);
    let mut alpha = vec![0.0_f32; scene.width * scene.height];
    for row in 0..scene.height {
        for col in 0..scene.width {
            let p = row * scene.width + col;
            if scene.index[p] >= 0 {
                alpha[p] = 1.0;
            } else if (22..=34).contains(&row) && (4..=76).contains(&col) {
                (scene.index[p], scene.depth[p], alpha[p]) = (haze, 6.0, 0.04);
            }
        }
    }
    let image = scene.image().with_alpha(&alpha).unwrap();
    let params = TraceParams { radius: 0.05, band_px: 6.0, focal_px: FOCAL, ..TraceParams::default() };
    let trace = trace_stroke(&image, &scene.centres, &[[4.5, 24.5], [40.5, 23.5], [76.5, 24.5]], &params).unwrap();
    let pixels: Vec<&[u32; 2]> = trace.pieces.iter().flat_map(|p| p.pixels.iter()).collect();
    assert!(pixels.iter().all(|p| (19..=21).contains(&p[1])), "{pixels:?}");
    assert!(pixels.iter().any(|p| p[0] <= 12) && pixels.iter().any(|p| p[0] >= 68), "{pixels:?}");
}

#[test]
fn the_radius_is_half_the_visible_width() {
    // The rope is 3 px thick at depth 5 with a focal length of 100: R = 1.5 px * 5 / 100.
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let radius = estimate_radius(&scene.image(), &[[2.5, 20.5], [40.0, 21.5], [77.5, 20.5]], &params).unwrap().radius;
    assert!((radius - 0.075).abs() < 0.01, "R = {radius}");
    // a short stroke, two diameters long, still gives it
    let short = estimate_radius(&scene.image(), &[[30.5, 20.5], [36.5, 20.5]], &params).unwrap().radius;
    assert!((short - 0.075).abs() < 0.01, "R = {short}");
    let unknown_focal = TraceParams { focal_px: 0.0, ..params };
    assert!(matches!(
        estimate_radius(&scene.image(), &[[2.5, 20.5], [77.5, 20.5]], &unknown_focal),
        Err(PathError::BadParameter { name: "focal_px", .. })
    ));
}

#[test]
fn a_stroke_just_off_the_ropes_silhouette_measures_the_rope() {
    // drawn along the rope's edge, a pixel outside it (rows 19..=21: the stroke on row 22): no
    // sample has the rope under it, but the rope lies within the band, as the search finds it
    let scene = Synthetic::new(80, 40, FOCAL, rope);
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let radius = estimate_radius(&scene.image(), &[[2.5, 22.5], [77.5, 22.5]], &params).unwrap().radius;
    assert!((radius - 0.075).abs() < 0.01, "R = {radius}");
    // beyond the band it is on the background
    let far = estimate_radius(&scene.image(), &[[2.5, 30.5], [77.5, 30.5]], &params);
    assert_eq!(far.unwrap_err(), PathError::StrokeOnBackground { outside: 0, width: 80, height: 40 });
}

#[test]
fn the_radius_of_a_rope_mostly_behind_a_leaf_is_the_ropes() {
    // A leaf 21 px wide (rows 10..=30) one unit in front of the rope covers cols 20..=60, half the
    // stroke: the median width under the stroke is the leaf's, the slender cluster the rope's.
    let leaf = |col: usize, row: usize| ((20..=60).contains(&col) && (10..=30).contains(&row)).then_some(4.0);
    let scene = Synthetic::new(80, 40, FOCAL, move |col, row| leaf(col, row).or_else(|| rope(col, row)));
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let radius = estimate_radius(&scene.image(), &[[2.5, 20.5], [77.5, 20.5]], &params).unwrap().radius;
    assert!((radius - 0.075).abs() < 0.01, "R = {radius}");
}

#[test]
fn the_radius_of_a_rope_lying_on_a_floor_is_told_by_its_colour() {
    // A rope 5 px thick (rows 18..=22) on a floor at its own depth, all pixels covered: no depth edge
    // beside the rope. Its Gaussians are orange, the floor's grey, each scattered a little.
    let scene = Synthetic::new(80, 40, FOCAL, |_, _| Some(5.0));
    let ids: Vec<u32> = (0..scene.centres.len() as u32).collect();
    let colours: Vec<[f32; 3]> = (0..scene.centres.len())
        .map(|g| {
            let (row, wobble) = (g / 80, [0.0, 0.04, -0.03, 0.02, -0.05][g % 5]);
            let base = if (18..=22).contains(&row) { [0.85, 0.55, 0.2] } else { [0.5, 0.45, 0.4] };
            base.map(|c| c + wobble)
        })
        .collect();
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let stroke = [[2.5, 20.5], [77.5, 20.5]];
    let plain = estimate_radius(&scene.image(), &stroke, &params).unwrap().radius;
    let image = scene.image().with_colours(&ids, &colours).unwrap();
    let radius = estimate_radius(&image, &stroke, &params).unwrap().radius;
    assert!(plain > 0.4, "without colours the floor is measured too: R = {plain}");
    assert!((radius - 0.125).abs() < 0.02, "R = {radius} (the rope's half-width: 2.5 px at 5 / 100)");
}

#[test]
fn a_rope_lying_on_a_floor_of_big_gaussians_is_followed_by_its_colour_under_a_stroke_beside_it() {
    // A rope 5 px thick (rows 18..=22) on a floor at its own depth made of Gaussians 10 px square
    // (a step within one is free), the stroke drawn 4 px above the rope, over the floor: by depth and
    // width the two are alike and the path follows the stroke on the floor. The rope's Gaussians
    // are orange and the floor's grey: the path keeps to the rope.
    let mut scene = Synthetic::new(80, 40, FOCAL, |_, _| Some(5.0));
    let on_rope = |row: usize| (18..=22).contains(&row);
    let first_block = scene.centres.len();
    for row in (0..40).filter(|&row| !on_rope(row)) {
        for col in 0..80 {
            let block = (row / 10) * 8 + col / 10;
            scene.index[row * 80 + col] = (first_block + block) as i32;
        }
    }
    for block in 0..32 {
        let (x, y) = ((block % 8) as f32 * 10.0 + 5.0, (block / 8) as f32 * 10.0 + 5.0);
        scene.centres.push([x * 5.0 / FOCAL, y * 5.0 / FOCAL, 5.0]);
    }
    let colours: Vec<[f32; 3]> = (0..scene.centres.len())
        .map(|g| if g < first_block && on_rope(g / 80) { [0.85, 0.55, 0.2] } else { [0.5, 0.45, 0.4] })
        .collect();
    let plain = middle_rows(&traced_above_the_rope(&scene, None));
    assert!(plain.iter().any(|&r| !on_rope(r as usize)), "without colours the path takes the floor");
    let rows = middle_rows(&traced_above_the_rope(&scene, Some(&colours)));
    assert!(!rows.is_empty() && rows.iter().all(|&r| on_rope(r as usize)), "rows {rows:?}");
}

/// The trace of a stroke along row 15.5 of an 80 px wide scene (4 px above a rope at rows 18..=22,
/// R 2.5 px), with each Gaussian's colour where `colours` are given.
fn traced_above_the_rope(scene: &Synthetic, colours: Option<&[[f32; 3]]>) -> Trace {
    let params = TraceParams { radius: 0.125, band_px: 6.0, focal_px: FOCAL, ..TraceParams::default() };
    let stroke = [[2.5, 15.5], [77.5, 15.5]];
    let ids: Vec<u32> = (0..scene.centres.len() as u32).collect();
    let image = match colours {
        Some(colours) => scene.image().with_colours(&ids, colours).unwrap(),
        None => scene.image(),
    };
    trace_stroke(&image, &scene.centres, &stroke, &params).unwrap()
}

/// The rows of a trace's pixels over columns 10..70 (away from the stroke's ends).
fn middle_rows(trace: &Trace) -> Vec<u32> {
    trace.pieces.iter().flat_map(|p| &p.pixels).filter(|p| (10..70).contains(&p[0])).map(|p| p[1]).collect()
}

#[test]
fn a_rope_along_the_edge_of_a_shelf_is_told_from_the_shelf_by_its_colour() {
    // A rope 5 px thick (rows 18..=22) along the lower edge of a shelf at its own depth (rows
    // 4..=17, Gaussians 10 px wide and the shelf's height), with nothing below the rope: seen
    // against the background beyond the edge, as a sprinkle on the icing's silhouette. The stroke
    // is drawn 4 px above the rope, over the shelf. Of the pixels 3-5 R across the stroke, 80 %
    // show the shelf on its side and none on the other: under half of all, and the colours (orange
    // rope, grey shelf) are still told apart, which keeps the path on the rope.
    let on_rope = |row: usize| (18..=22).contains(&row);
    let on_shelf = |row: usize| (4..=17).contains(&row);
    let mut scene = Synthetic::new(80, 40, FOCAL, |_, row| on_rope(row).then_some(5.0));
    let first_block = scene.centres.len();
    for row in (0..40).filter(|&row| on_shelf(row)) {
        for col in 0..80 {
            scene.index[row * 80 + col] = (first_block + col / 10) as i32;
            scene.depth[row * 80 + col] = 5.0;
        }
    }
    for block in 0..8 {
        let (x, y) = (block as f32 * 10.0 + 5.0, 11.0);
        scene.centres.push([x * 5.0 / FOCAL, y * 5.0 / FOCAL, 5.0]);
    }
    let (orange, grey) = ([0.85, 0.55, 0.2], [0.5, 0.45, 0.4]);
    let colours: Vec<[f32; 3]> =
        (0..scene.centres.len()).map(|g| if g < first_block { orange } else { grey }).collect();
    let plain = middle_rows(&traced_above_the_rope(&scene, None));
    assert!(plain.iter().any(|&r| !on_rope(r as usize)), "without colours the path takes the shelf");
    let trace = traced_above_the_rope(&scene, Some(&colours));
    let found = trace.colours.expect("the rope lies on the shelf");
    assert_eq!((found.part, found.surround), (orange, grey));
    let rows = middle_rows(&trace);
    assert!(!rows.is_empty() && rows.iter().all(|&r| on_rope(r as usize)), "rows {rows:?}");
}

#[test]
fn the_radius_of_a_shaded_rope_against_the_background_or_a_wall_behind_is_its_silhouettes() {
    // A rope 9 px thick (rows 16..=24) against nothing, whose Gaussians' colours change across it
    // (light on top, dark below, as a capture's baked shading): by colour it would measure a few
    // pixels, but every walk ends at its outline on both sides, so the plain width stands. The same
    // rope lying on a grey floor at its own depth is told by its colour.
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let stroke = [[2.5, 20.5], [77.5, 20.5]];
    let shaded =
        |row: usize| if (16..=24).contains(&row) { [0.9 - 0.12 * (row - 16) as f32, 0.7, 0.2] } else { [0.5; 3] };
    let radius_with_colours = |scene: &Synthetic| scene.radius_with_colours(&stroke, &params, shaded);
    let alone = Synthetic::new(80, 40, FOCAL, |_, row| (16..=24).contains(&row).then_some(5.0));
    let radius = radius_with_colours(&alone);
    assert!((radius - 0.225).abs() < 0.02, "R = {radius} (the rope's half-width: 4.5 px at 5 / 100)");
    // in front of a wall 2.5 behind (11 R: a branch before its trunk), its silhouette against the
    // wall; a wall 1.3 behind (6 R less a little) ends the walks too (over 3 depth gaps of 8 px,
    // 1.2), but not as a silhouette: the colour tells
    let before_a_wall = |behind: f32| {
        Synthetic::new(80, 40, FOCAL, move |_, row| Some(if (16..=24).contains(&row) { 5.0 } else { 5.0 + behind }))
    };
    let radius = radius_with_colours(&before_a_wall(2.5));
    assert!((radius - 0.225).abs() < 0.02, "before a wall R = {radius}");
    let radius = radius_with_colours(&before_a_wall(1.3));
    assert!(radius < 0.2, "just before a wall the colour tells: R = {radius}");
    let on_floor = Synthetic::new(80, 40, FOCAL, |_, _| Some(5.0));
    let radius = radius_with_colours(&on_floor);
    assert!(radius < 0.2, "on the floor the colour tells the rope from it: R = {radius}");
}

#[test]
fn the_radius_of_a_rope_shaded_in_brightness_only_is_its_width_though_a_wall_lies_just_behind() {
    // The rope above just before a wall 1.3 behind (its walks end on the wall, not as a silhouette),
    // its colour darkening across it to 0.2 of its lit side's but keeping its hue, as a capture's
    // baked light and shade do (a tree branch's): by RGB its colour width was 3 px, a third of it.
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let stroke = [[2.5, 20.5], [77.5, 20.5]];
    let shaded = |row: usize| {
        let light = 1.0 - 0.1 * row.saturating_sub(16) as f32;
        if (16..=24).contains(&row) { [0.9 * light, 0.7 * light, 0.2 * light] } else { [0.5; 3] }
    };
    let before_a_wall = Synthetic::new(80, 40, FOCAL, |_, row| Some(if (16..=24).contains(&row) { 5.0 } else { 6.3 }));
    let radius = before_a_wall.radius_with_colours(&stroke, &params, shaded);
    assert!((radius - 0.225).abs() < 0.02, "R = {radius} (the rope's half-width: 4.5 px at 5 / 100)");
}

#[test]
fn a_flat_bar_seen_obliquely_measures_its_whole_width() {
    // A bar 15 px wide (rows 13..=27) whose depth rises by 2 px of world size per pixel across it
    // (seen at about 63 degrees), with the centres scattered in depth by up to 12 px, in front of a
    // wall 40 px behind: the width is the bar's, not a few pixels (a limit on the depth's slope from
    // the start would stop after 2-3 pixels) and not the wall's.
    let per_px = 5.0 / FOCAL;
    let scene = Synthetic::new(80, 40, FOCAL, |col, row| {
        let scatter = [0.0, 12.0, -6.0, 9.0, -12.0, 3.0][(col * 7 + row * 3) % 6];
        Some(if (13..=27).contains(&row) { 5.0 + (2.0 * (row as f32 - 13.0) + scatter) * per_px } else { 7.5 })
    });
    let image = scene.image();
    for col in [20, 40, 60] {
        let width = crate::width::Walks::default().cross_width(&image, 20 * 80 + col, [0.0, 1.0], FOCAL, 30, None);
        assert!((13..=17).contains(&width), "col {col}: width {width}");
    }
}

#[test]
fn the_radius_of_a_bar_showing_two_faces_is_the_whole_bars_where_its_colour_outlines_it() {
    // A bar 18 px wide against nothing: a face of 7 px (rows 11..=17) 12 px of world size nearer
    // than the other, of 11 px (rows 18..=28), as the centres of a real bar's big Gaussians step
    // between its faces. The depths split in two clusters at the 8 px floor; the stroke runs along
    // the wider face.
    let bar = |near: f32| {
        Synthetic::new(160, 40, FOCAL, move |_, row| match row {
            11..=17 => Some(5.0 - near * 5.0 / FOCAL),
            18..=28 => Some(5.0),
            _ => None,
        })
    };
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let stroke = [[2.5, 23.5], [157.5, 23.5]]; // (walks reach 160 / 8 px)
    let black = |_: usize| [0.1, 0.1, 0.12];
    // every walk ends at the outline on both sides over the bar's colour: 9 px at 5 / 100
    let whole = bar(12.0).radius_with_colours(&stroke, &params, black);
    assert!((whole - 0.45).abs() < 0.02, "R = {whole}");
    // without colours, or where the nearer face is of another colour (a leaf's edge beside a
    // stem), only the face under the stroke: 5.5 px
    let plain = estimate_radius(&bar(12.0).image(), &stroke, &params).unwrap().radius;
    assert!((plain - 0.275).abs() < 0.02, "R = {plain}");
    let green_face = |row: usize| if row < 18 { [0.2, 0.6, 0.2] } else { [0.1, 0.1, 0.12] };
    let two_colours = bar(12.0).radius_with_colours(&stroke, &params, green_face);
    assert!((two_colours - 0.275).abs() < 0.02, "R = {two_colours}");
    // a same-coloured surface over three times the part's width outlined with it (a leaf behind a
    // stem of its colour) is not taken for it: a 5 px stem (rows 18..=22) before a 12 px strip 20 px
    // behind, both within the walks' reach
    let stem_before_strip = Synthetic::new(160, 60, FOCAL, |_, row| match row {
        18..=22 => Some(5.0),
        23..=34 => Some(5.0 + 20.0 * 5.0 / FOCAL),
        _ => None,
    });
    let stem = stem_before_strip.radius_with_colours(&[[2.5, 20.5], [157.5, 20.5]], &params, black);
    assert!((stem - 0.125).abs() < 0.02, "R = {stem}");
}

#[test]
fn a_part_in_front_of_a_surface_close_behind_measures_alone() {
    // A 5 px rope 10 px of world size in front of a wall: they are separate surfaces.
    let scene = Synthetic::new(80, 40, FOCAL, |_, row| {
        Some(if (18..=22).contains(&row) { 5.0 } else { 5.0 + 10.0 * 5.0 / FOCAL })
    });
    let width = crate::width::Walks::default().cross_width(&scene.image(), 20 * 80 + 40, [0.0, 1.0], FOCAL, 30, None);
    assert_eq!(width, 5);
}

#[test]
fn a_stroke_wandering_off_a_thick_part_within_its_radius_stays_on_it() {
    // A thick rope (rows 25..=45, radius 10.5 px); mid-way the stroke bows to 7.5 px above its upper
    // edge for 16 px. The default band is 1.25 R in pixels here (13 px), not 1 % of the 80 px image
    // (2 px), so the band still holds the rope there and the path is one piece.
    assert_eq!(TraceParams::default_band_px(80, 10.4), 13.0);
    assert!((TraceParams::default_band_px(960, 1.0) - 9.6).abs() < 1e-5);
    let scene = Synthetic::new(80, 60, FOCAL, |_, row| (25..=45).contains(&row).then_some(5.0));
    let stroke = [[2.5, 35.5], [26.5, 35.5], [32.5, 17.5], [48.5, 17.5], [54.5, 35.5], [77.5, 35.5]];
    let params = TraceParams { radius: 10.4 * 5.0 / FOCAL, focal_px: FOCAL, ..TraceParams::default() };
    let trace = trace_stroke(&scene.image(), &scene.centres, &stroke, &params).unwrap();
    assert_eq!(trace.pieces.len(), 1);
    assert_eq!(trace.pieces[0].end, PieceEnd::Goal);
    // with a band of 2 px the path loses the rope where the stroke leaves it
    let narrow = TraceParams { band_px: 2.0, ..params };
    assert!(trace_stroke(&scene.image(), &scene.centres, &stroke, &narrow).unwrap().pieces.len() > 1);
}

#[test]
fn depth_keys_order_as_total_cmp() {
    let mut values = [3.0_f32, -0.0, 0.0, -2.5, f32::INFINITY, 1e-30, -1e30, 7.25, f32::NEG_INFINITY];
    let mut keys: Vec<u32> = values.iter().map(|&z| crate::stroke::ordered_bits(z)).collect();
    values.sort_by(f32::total_cmp);
    keys.sort_unstable();
    assert_eq!(keys, values.iter().map(|&z| crate::stroke::ordered_bits(z)).collect::<Vec<_>>());
}

/// A rope at depth 5 (rows 19..=21) behind a leaf at depth 4 over cols 20..=50 (rows 5..=35): the
/// front image, and the layer behind it holding the rope where the leaf hides it.
struct HiddenRope {
    front: Synthetic,
    behind_index: Vec<i32>,
    behind_depth: Vec<f32>,
    behind_alpha: Vec<f32>,
}

impl HiddenRope {
    fn new() -> Self {
        let leaf = |col: usize, row: usize| (20..=50).contains(&col) && (5..=35).contains(&row);
        let mut front =
            Synthetic::new(80, 40, FOCAL, |col, row| if leaf(col, row) { Some(4.0) } else { rope(col, row) });
        let pixels = front.width * front.height;
        let (mut behind_index, mut behind_depth) = (vec![-1; pixels], vec![0.0; pixels]);
        for row in 19..=21 {
            for col in 20..=50 {
                let p = row * front.width + col;
                behind_index[p] = front.centres.len() as i32;
                behind_depth[p] = 5.0;
                front.centres.push([(col as f32 + 0.5) * 5.0 / FOCAL, (row as f32 + 0.5) * 5.0 / FOCAL, 5.0]);
            }
        }
        let behind_alpha = behind_index.iter().map(|&k| if k >= 0 { 1.0 } else { 0.0 }).collect();
        Self { front, behind_index, behind_depth, behind_alpha }
    }

    fn trace(&self, with_behind: bool) -> Trace {
        let image = self.front.image();
        let image = if with_behind {
            image.with_behind(&self.behind_index, &self.behind_depth, &self.behind_alpha).unwrap()
        } else {
            image
        };
        let params = TraceParams { radius: 0.075, band_px: 6.0, focal_px: FOCAL, ..TraceParams::default() };
        trace_stroke(&image, &self.front.centres, &[[2.5, 20.5], [77.5, 20.5]], &params).unwrap()
    }
}

#[test]
fn a_rope_behind_a_leaf_is_followed_behind_it_when_the_layers_behind_are_given() {
    let scene = HiddenRope::new();
    // front only: the path stops at the leaf and resumes past it, and asks for what lies behind
    let front = scene.trace(false);
    assert!(front.wants_behind);
    assert_eq!(front.pieces.len(), 2);
    // with the layer behind: one piece on the rope, the Gaussians behind the leaf included
    let behind = scene.trace(true);
    assert!(!behind.wants_behind);
    assert_eq!(behind.pieces.len(), 1);
    let piece = &behind.pieces[0];
    assert_eq!(piece.end, PieceEnd::Goal);
    assert!(scene.front.rows_of(piece).iter().all(|r| (19..=21).contains(r)));
    for (pixel, &id) in piece.pixels.iter().zip(&piece.pixel_ids) {
        let p = pixel[1] as usize * scene.front.width + pixel[0] as usize;
        let seen = if (20..=50).contains(&pixel[0]) { scene.behind_index[p] } else { scene.front.index[p] };
        assert_eq!(id as i32, seen, "pixel {pixel:?}");
    }
}

#[test]
fn layers_behind_a_visible_part_change_nothing() {
    // the rope in front of the leaf: a layer behind it (the leaf) is not taken
    let leaf = |col: usize, row: usize| (20..=50).contains(&col) && (5..=35).contains(&row);
    let scene = Synthetic::new(80, 40, FOCAL, |col, row| rope(col, row).map(|_| 4.0).or(leaf(col, row).then_some(5.0)));
    let pixels = scene.width * scene.height;
    let behind_index: Vec<i32> =
        (0..pixels).map(|p| if scene.depth[p] == 4.0 && leaf(p % 80, p / 80) { 0 } else { -1 }).collect();
    let behind_depth = vec![5.0; pixels];
    let behind_alpha = vec![1.0; pixels];
    let params = TraceParams { radius: 0.05, band_px: 6.0, focal_px: FOCAL, ..TraceParams::default() };
    let stroke = [[2.5, 20.5], [77.5, 20.5]];
    let plain = trace_stroke(&scene.image(), &scene.centres, &stroke, &params).unwrap();
    let image = scene.image().with_behind(&behind_index, &behind_depth, &behind_alpha).unwrap();
    let layered = trace_stroke(&image, &scene.centres, &stroke, &params).unwrap();
    assert!(!plain.wants_behind);
    assert_eq!(plain, layered);
    // layers of the wrong size are an error
    assert!(matches!(
        scene.image().with_behind(&behind_index[1..], &behind_depth, &behind_alpha),
        Err(PathError::BehindSize { .. })
    ));
}

#[test]
fn the_radius_behind_a_leaf_is_the_ropes_and_asks_for_the_layers_without_them() {
    let scene = HiddenRope::new();
    let params = TraceParams { focal_px: FOCAL, band_px: 6.0, ..TraceParams::default() };
    let stroke = [[2.5, 20.5], [77.5, 20.5]];
    assert!(estimate_radius(&scene.front.image(), &stroke, &params).unwrap().wants_behind);
    let image = scene.front.image().with_behind(&scene.behind_index, &scene.behind_depth, &scene.behind_alpha).unwrap();
    let estimate = estimate_radius(&image, &stroke, &params).unwrap();
    // the rope is 3 px thick at depth 5 with a focal length of 100
    assert!(!estimate.wants_behind);
    assert!((estimate.radius - 1.5 * 5.0 / FOCAL).abs() < 0.01, "{}", estimate.radius);
}
