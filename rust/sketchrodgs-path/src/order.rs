//! The path's Gaussians in order along the stroke (docs/extraction.md, "Polyline, segmentation,
//! binding"). The search may double back (around a node, at a junction), and its Gaussians taken
//! in visiting order would then fold the rod onto itself; those that go back are left out.

/// Segments of the stroke per bounding box.
const RUN: usize = 16;

/// Which of the points (the path's Gaussian centres on screen, in visiting order) to keep: each
/// is placed at the arc length of its nearest point on `stroke`; among the stroke's stretches
/// within its `radius_px` of the nearest, the first not more than two radii behind the farthest
/// placed point is taken, so that a stroke crossing itself is followed through the crossing. A
/// point placed more than its radius behind the farthest kept one is left out. The same is done
/// from the far end (points and stroke reversed), and the choice that keeps more points is taken:
/// from the start, the first point visited is always kept, so where a big Gaussian owns the path's
/// first pixels with its centre far along (a sprinkle of a few Gaussians), all those between were
/// left out.
///
/// `points` and `radius_px` have one entry per point; non-finite points are left out. Fewer than
/// two kept (or a stroke of fewer than two points): all are kept.
pub fn forward_along_stroke(points: &[[f32; 2]], radius_px: &[f32], stroke: &[[f32; 2]]) -> Vec<bool> {
    if stroke.len() < 2 {
        return vec![true; points.len()];
    }
    let forward = in_order(points, radius_px, stroke);
    let reversed = |v: &[[f32; 2]]| v.iter().rev().copied().collect::<Vec<_>>();
    let radius_back: Vec<f32> = radius_px.iter().rev().copied().collect();
    let mut backward = in_order(&reversed(points), &radius_back, &reversed(stroke));
    backward.reverse();
    let count = |keep: &[bool]| keep.iter().filter(|&&k| k).count();
    let keep = if count(&backward) > count(&forward) { backward } else { forward };
    if count(&keep) < 2 {
        return vec![true; points.len()];
    }
    keep
}

/// `forward_along_stroke` from the first point on; `stroke` has at least two points.
fn in_order(points: &[[f32; 2]], radius_px: &[f32], stroke: &[[f32; 2]]) -> Vec<bool> {
    let mut keep = vec![false; points.len()];
    // per segment: start, direction, squared length, length, arc length at its start
    let mut segments = Vec::with_capacity(stroke.len() - 1);
    let mut s = 0.0_f32;
    for w in stroke.windows(2) {
        let ab = [w[1][0] - w[0][0], w[1][1] - w[0][1]];
        let length2 = ab[0] * ab[0] + ab[1] * ab[1];
        segments.push((w[0], ab, length2, length2.sqrt(), s));
        s += segments[segments.len() - 1].3;
    }
    // runs of segments with their bounding boxes: a point is measured against the segments of the
    // runs that can hold one within its radius of the nearest, not against the whole stroke
    let boxes: Vec<[f32; 4]> = (0..segments.len())
        .step_by(RUN)
        .map(|k| {
            let corners = [f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY];
            stroke[k..=(k + RUN).min(stroke.len() - 1)]
                .iter()
                .fold(corners, |b, q| [b[0].min(q[0]), b[1].min(q[1]), b[2].max(q[0]), b[3].max(q[1])])
        })
        .collect();
    // (distance, arc length) of the nearest point of each segment measured
    let mut feet: Vec<(f32, f32)> = Vec::with_capacity(segments.len());
    let mut below = Vec::with_capacity(boxes.len()); // each run's least distance from the point
    let mut farthest = f32::NEG_INFINITY;
    for ((p, &r), kept) in points.iter().zip(radius_px).zip(keep.iter_mut()) {
        if !(p[0].is_finite() && p[1].is_finite() && r.is_finite()) {
            continue;
        }
        // the nearest segment is no further than the nearest run's first vertex
        below.clear();
        let mut above = f32::INFINITY;
        for (k, b) in boxes.iter().enumerate() {
            let dx = (b[0] - p[0]).max(p[0] - b[2]).max(0.0);
            let dy = (b[1] - p[1]).max(p[1] - b[3]).max(0.0);
            below.push((dx * dx + dy * dy).sqrt());
            let q = stroke[k * RUN];
            above = above.min(((q[0] - p[0]) * (q[0] - p[0]) + (q[1] - p[1]) * (q[1] - p[1])).sqrt());
        }
        feet.clear();
        let runs = below.iter().enumerate().filter(|&(_, &d)| d <= above + r);
        let measured = runs.flat_map(|(k, _)| &segments[k * RUN..((k + 1) * RUN).min(segments.len())]);
        feet.extend(measured.map(|&(a, ab, length2, length, s0)| {
            let t = if length2 > 0.0 {
                (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / length2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = [p[0] - a[0] - t * ab[0], p[1] - a[1] - t * ab[1]];
            ((d[0] * d[0] + d[1] * d[1]).sqrt(), s0 + t * length) // not hypot: a libm call
        }));
        let nearest = feet.iter().map(|f| f.0).fold(f32::INFINITY, f32::min);
        let near = || feet.iter().filter(|f| f.0 <= nearest + r).map(|f| f.1);
        let ahead = near().filter(|&s| s >= farthest - 2.0 * r).fold(f32::INFINITY, f32::min);
        let placed = if ahead.is_finite() { ahead } else { near().fold(f32::INFINITY, f32::min) };
        if placed >= farthest - r {
            *kept = true;
            farthest = farthest.max(placed);
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_that_go_back_are_left_out() {
        let stroke = [[0.0, 0.0], [100.0, 0.0]];
        // along, back by 10 (more than the radius 2), then on past where it was
        let xs = [0.0, 5.0, 10.0, 15.0, 20.0, 10.0, 12.0, 21.0, 25.0, 30.0];
        let points: Vec<[f32; 2]> = xs.iter().map(|&x| [x, 1.0]).collect();
        let keep = forward_along_stroke(&points, &[2.0; 10], &stroke);
        assert_eq!(keep, [true, true, true, true, true, false, false, true, true, true]);
        // a step back within the radius is the path's zigzag, and stays
        let points: Vec<[f32; 2]> = [0.0, 5.0, 4.0, 8.0].iter().map(|&x| [x, 0.0]).collect();
        assert_eq!(forward_along_stroke(&points, &[2.0; 4], &stroke), [true; 4]);
    }

    #[test]
    fn a_first_point_far_along_does_not_cut_out_those_between() {
        // a big Gaussian owns the path's first pixels with its centre far along (a sprinkle):
        // from the start only it and those past it would be kept
        let stroke = [[0.0, 0.0], [100.0, 0.0]];
        let xs = [60.0, 10.0, 20.0, 30.0, 40.0, 50.0, 70.0];
        let points: Vec<[f32; 2]> = xs.iter().map(|&x| [x, 1.0]).collect();
        let keep = forward_along_stroke(&points, &[2.0; 7], &stroke);
        assert_eq!(keep, [false, true, true, true, true, true, true]);
        // and a last point far back is left out, as before
        let xs = [10.0, 20.0, 30.0, 40.0, 50.0, 5.0];
        let points: Vec<[f32; 2]> = xs.iter().map(|&x| [x, 1.0]).collect();
        assert_eq!(forward_along_stroke(&points, &[2.0; 6], &stroke), [true, true, true, true, true, false]);
    }

    #[test]
    fn a_stroke_that_crosses_itself_is_followed_through_the_crossing() {
        // a loop: right along y = 0, up, back left along y = 10 and down across the first stretch
        let stroke = [[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [20.0, 10.0], [20.0, -20.0]];
        let mut points: Vec<[f32; 2]> = (0..=40).step_by(4).map(|x| [x as f32, 0.0]).collect();
        points.extend((0..=10).step_by(2).map(|y| [40.0, y as f32]));
        points.extend((20..=40).rev().step_by(4).map(|x| [x as f32, 10.0]));
        points.extend((-20..=10).rev().step_by(4).map(|y| [20.0, y as f32])); // crosses (20, 0)
        let radius = vec![2.0; points.len()];
        assert!(forward_along_stroke(&points, &radius, &stroke).iter().all(|&k| k));
    }

    #[test]
    fn runs_of_segments_find_what_every_segment_finds() {
        // a wandering stroke of 300 points and a path that zigzags along it and doubles back
        let mut state = 7_u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let stroke: Vec<[f32; 2]> =
            (0..300).map(|i| [i as f32 * 3.0, 80.0 * (i as f32 * 0.05).sin() + 10.0 * next()]).collect();
        let mut points = Vec::new();
        for i in 0..900 {
            let k = (i as f32 / 3.0 + 8.0 * (i as f32 * 0.07).sin()).clamp(0.0, 298.0) as usize;
            let q = stroke[k];
            points.push([q[0] + 6.0 * next() - 3.0, q[1] + 6.0 * next() - 3.0]);
        }
        let radius: Vec<f32> = (0..points.len()).map(|_| 1.0 + 3.0 * next()).collect();
        let keep = in_order(&points, &radius, &stroke);
        assert_eq!(keep, forward_by_every_segment(&points, &radius, &stroke));
        assert!(keep.iter().any(|&k| !k) && keep.iter().filter(|&&k| k).count() > 300);
    }

    /// The same choice, every point measured against every segment.
    fn forward_by_every_segment(points: &[[f32; 2]], radius_px: &[f32], stroke: &[[f32; 2]]) -> Vec<bool> {
        let mut farthest = f32::NEG_INFINITY;
        let mut start = 0.0;
        let segments: Vec<([f32; 2], [f32; 2], f32)> = stroke
            .windows(2)
            .map(|w| {
                let s = start;
                start += ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt();
                (w[0], w[1], s)
            })
            .collect();
        points
            .iter()
            .zip(radius_px)
            .map(|(p, &r)| {
                let feet: Vec<(f32, f32)> = segments
                    .iter()
                    .map(|&(a, b, s0)| {
                        let ab = [b[0] - a[0], b[1] - a[1]];
                        let length2 = ab[0] * ab[0] + ab[1] * ab[1];
                        let t = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / length2).clamp(0.0, 1.0);
                        let d = [p[0] - a[0] - t * ab[0], p[1] - a[1] - t * ab[1]];
                        ((d[0] * d[0] + d[1] * d[1]).sqrt(), s0 + t * length2.sqrt())
                    })
                    .collect();
                let nearest = feet.iter().map(|f| f.0).fold(f32::INFINITY, f32::min);
                let near: Vec<f32> = feet.iter().filter(|f| f.0 <= nearest + r).map(|f| f.1).collect();
                let ahead = near.iter().copied().filter(|&s| s >= farthest - 2.0 * r).fold(f32::INFINITY, f32::min);
                let placed = if ahead.is_finite() { ahead } else { near.iter().copied().fold(f32::INFINITY, f32::min) };
                let kept = placed >= farthest - r;
                if kept {
                    farthest = farthest.max(placed);
                }
                kept
            })
            .collect()
    }

    #[test]
    fn odd_input_keeps_what_it_can() {
        let stroke = [[0.0, 0.0], [10.0, 0.0]];
        assert_eq!(forward_along_stroke(&[[1.0, 0.0]], &[1.0], &stroke), [true]);
        assert_eq!(forward_along_stroke(&[[1.0, 0.0]; 3], &[1.0; 3], &stroke[..1]), [true; 3]);
        let keep = forward_along_stroke(&[[1.0, 0.0], [f32::NAN, 0.0], [5.0, 0.0]], &[1.0; 3], &stroke);
        assert_eq!(keep, [true, false, true]);
    }
}
