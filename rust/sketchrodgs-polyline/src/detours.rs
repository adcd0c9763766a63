//! Detours in an extracted axis (docs/extraction.md, "Polyline", **Detours**): short stretches
//! that leave the axis's line and come back. Either in depth, staying on the line on screen (the
//! path followed the part on screen but climbed onto a leaf in front of it, or dropped behind
//! it), or doubling back, their arc several times their chord (the path ran out onto a side
//! branch or a leaf at a node and back). A part seldom does either within a few radii. The caller
//! puts each stretch's points onto its chord.
//!
//! Bumps are a third kind, judged apart (`bumps`), after the detours are bridged: a short stretch
//! that leaves its chord by more than a radius or so where the axis runs along that chord on both
//! sides (the path ran onto the stalks of a leaf pair at a node and back). A bend changes the
//! axis's direction, and a wave's sides are not in line, so neither is a bump.

/// The limits of a detour, in radii.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetourLimits {
    /// The longest stretch (arc length).
    pub span: f64,
    /// A stretch is a detour in depth where a point leaves its 3D chord by more than this...
    pub depth: f64,
    /// ... while every point stays closer than this to its chord on screen (radii in pixels).
    pub screen: f64,
    /// A stretch whose arc is at least this many times its chord doubles back...
    pub back_ratio: f64,
    /// ... and is a detour where a point leaves its chord by more than this.
    pub back: f64,
    /// Stretches start and end at least this far from the axis's ends (the ends are judged by
    /// `cut_hooked_ends`).
    pub end: f64,
}

/// The stretches `(i, j)` (points `i` and `j` kept, those between to go onto the chord) of the
/// axis `points`, seen on screen at `uv` with `radius_px` the radius in pixels at each point, in
/// order: of overlapping detours the one that saves the most arc over its chord. Points whose
/// projection is not finite are never in a detour in depth.
pub fn detours(
    points: &[[f64; 3]],
    uv: &[[f64; 2]],
    radius_px: &[f64],
    radius: f64,
    limits: DetourLimits,
) -> Vec<(usize, usize)> {
    detours_read(points, uv, radius_px, radius, limits, Reading::SkipStraight)
}

/// Which stretches `detours_from` reads point by point.
#[derive(Clone, Copy, PartialEq)]
enum Reading {
    /// Those whose arc leaves room for a point as far from the chord as a detour goes.
    SkipStraight,
    /// Every one (the tests' reference).
    #[cfg(test)]
    Every,
}

fn detours_read(
    points: &[[f64; 3]],
    uv: &[[f64; 2]],
    radius_px: &[f64],
    radius: f64,
    limits: DetourLimits,
    reading: Reading,
) -> Vec<(usize, usize)> {
    let n = points.len().min(uv.len()).min(radius_px.len());
    let axis = SeenAxis { points, uv, radius_px, radius, arc: arc_in_radii(&points[..n], radius) };
    // every detour, the one saving the most arc first (the whole excursion, not part of it with a
    // stub left) and, of those saving as much, the shortest (no stretch of the line either side)
    let mut all: Vec<(f64, usize, usize)> = Vec::new();
    for i in 0..n.saturating_sub(2) {
        all.extend(detours_from(i, &axis, limits, reading));
    }
    all.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.1, a.2).cmp(&(b.1, b.2))));
    // then each that overlaps none taken before (sharing an end is not overlapping)
    let (mut inside, mut end) = (vec![false; n], vec![false; n]);
    let mut found = Vec::new();
    for (_, i, j) in all {
        if (i..=j).any(|k| inside[k]) || (i + 1..j).any(|k| end[k]) {
            continue;
        }
        inside[i + 1..j].fill(true);
        (end[i], end[j]) = (true, true);
        found.push((i, j));
    }
    found.sort_unstable();
    found
}

/// An axis as `detours` reads it, with its arc length at each point in radii.
struct SeenAxis<'a> {
    points: &'a [[f64; 3]],
    uv: &'a [[f64; 2]],
    radius_px: &'a [f64],
    radius: f64,
    arc: Vec<f64>,
}

/// Each detour starting at point `i`: (the arc it saves over its chord, less `ARC_WEIGHT` times
/// its arc, in radii; `i`; its last point).
fn detours_from(i: usize, axis: &SeenAxis, limits: DetourLimits, reading: Reading) -> Vec<(f64, usize, usize)> {
    let SeenAxis { points, uv, radius_px, radius, ref arc } = *axis;
    let mut found = Vec::new();
    let last = arc.last().copied().unwrap_or(0.0);
    if arc[i] < limits.end {
        return found;
    }
    let least_of_all = limits.depth.min(limits.back);
    for j in i + 2..arc.len() {
        if arc[j] - arc[i] > limits.span || last - arc[j] < limits.end {
            break;
        }
        let (along, chord) = (arc[j] - arc[i], distance(&points[i], &points[j]) / radius);
        // The stretch's points lie within the ellipse whose foci are its ends and whose focal
        // distances sum to its arc: none is farther from the chord than its semi-minor axis. Where
        // that is too short for any detour, the stretch is not read (most of an axis is nearly
        // straight, and a stretch 20 R long was read point by point for every end).
        if reading == Reading::SkipStraight
            && (along * along - chord * chord) / 4.0 < least_of_all * least_of_all * (1.0 - 1e-9)
        {
            continue;
        }
        let aside = (i + 1..j).map(|m| chord_distance(&uv[i], &uv[j], &uv[m])).fold(0.0, max_or_nan);
        // a NaN (a point behind the camera) is never on the line
        let on_line = aside / radius_px[i] < limits.screen;
        let doubles_back = along >= limits.back_ratio * chord;
        let least = match (on_line, doubles_back) {
            (true, true) => limits.depth.min(limits.back),
            (true, false) => limits.depth,
            (false, true) => limits.back,
            (false, false) => continue,
        };
        let far = (i + 1..j).map(|m| chord_distance(&points[i], &points[j], &points[m])).fold(0.0, max_or_nan) / radius;
        if far > least {
            found.push(((1.0 - ARC_WEIGHT) * along - chord, i, j));
        }
    }
    found
}

/// The limits of a bump, in radii and degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BumpLimits {
    /// The longest stretch (arc length).
    pub span: f64,
    /// A stretch is a bump where a point leaves its chord by more than this...
    pub off: f64,
    /// ... and the axis over `lead` before it and after it runs within this angle of the chord.
    pub angle_deg: f64,
    pub lead: f64,
    /// Stretches start and end at least this far from the axis's ends.
    pub end: f64,
}

/// The bumps `(i, j)` (points `i` and `j` kept, those between to go onto the chord) of the axis
/// `points` (about R apart), in order: the one saving the most arc over its chord first, then each
/// that shares no point with one taken.
pub fn bumps(points: &[[f64; 3]], radius: f64, limits: BumpLimits) -> Vec<(usize, usize)> {
    let n = points.len();
    let arc = arc_in_radii(points, radius);
    let last = arc.last().copied().unwrap_or(0.0);
    let cos = limits.angle_deg.to_radians().cos();
    let direction = |a: usize, b: usize| {
        let d: [f64; 3] = std::array::from_fn(|k| points[b][k] - points[a][k]);
        let length = distance(&points[a], &points[b]);
        d.map(|x| if length > 0.0 { x / length } else { 0.0 })
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let mut all: Vec<(f64, usize, usize)> = Vec::new();
    for i in 0..n {
        if arc[i] < limits.end {
            continue;
        }
        // the first point within `lead` before i
        let before = arc.partition_point(|&a| a < arc[i] - limits.lead);
        if before >= i {
            continue;
        }
        for j in i + 2..n {
            if arc[j] - arc[i] > limits.span || arc[j] > last - limits.end {
                break;
            }
            let off = (i + 1..j).map(|m| chord_distance(&points[i], &points[j], &points[m])).fold(0.0, f64::max);
            let after = arc.partition_point(|&a| a < arc[j] + limits.lead).min(n - 1);
            if off / radius <= limits.off || after <= j {
                continue;
            }
            let chord = direction(i, j);
            if dot(direction(before, i), chord) >= cos && dot(direction(j, after), chord) >= cos {
                all.push((arc[j] - arc[i] - distance(&points[i], &points[j]) / radius, i, j));
            }
        }
    }
    // stable: of bumps saving as much, the first found
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut used = vec![false; n];
    let mut found = Vec::new();
    for (_, i, j) in all {
        if used[i..=j].iter().any(|&u| u) {
            continue;
        }
        used[i..=j].fill(true);
        found.push((i, j));
    }
    found.sort_unstable();
    found
}

/// The arc length at each point, in radii (0 at the first).
pub(crate) fn arc_in_radii(points: &[[f64; 3]], radius: f64) -> Vec<f64> {
    let mut arc = vec![0.0; points.len()];
    for k in 1..points.len() {
        arc[k] = arc[k - 1] + distance(&points[k - 1], &points[k]) / radius;
    }
    arc
}

/// Of two detours saving as much arc, the shorter is taken: each radius of arc costs this much of
/// the saving.
const ARC_WEIGHT: f64 = 0.01;

/// The larger of the two, NaN if either is (`f64::max` drops a NaN).
fn max_or_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) }
}

/// Distance of `p` from the segment `a`-`b` (2 or 3 dimensions).
fn chord_distance<const D: usize>(a: &[f64; D], b: &[f64; D], p: &[f64; D]) -> f64 {
    let ab: [f64; D] = std::array::from_fn(|k| b[k] - a[k]);
    let length2: f64 = ab.iter().map(|d| d * d).sum();
    let along: f64 = (0..D).map(|k| (p[k] - a[k]) * ab[k]).sum();
    let t = if length2 > 0.0 { (along / length2).clamp(0.0, 1.0) } else { 0.0 };
    let foot: [f64; D] = std::array::from_fn(|k| a[k] + t * ab[k]);
    distance(&foot, p)
}

/// `|a - b|`.
fn distance<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    (0..D).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const LIMITS: DetourLimits =
        DetourLimits { span: 10.0, depth: 3.5, screen: 0.7, back_ratio: 2.5, back: 3.0, end: 3.0 };

    /// An axis along x every half radius (R = 1), `bump(x)` towards the camera (-z), seen by a
    /// pinhole at z = -100 with a focal length of 100 px.
    fn seen(bump: impl Fn(f64) -> f64) -> (Vec<[f64; 3]>, Vec<[f64; 2]>, Vec<f64>) {
        let points: Vec<[f64; 3]> = (0..61).map(|k| f64::from(k) * 0.5).map(|x| [x, 0.0, -bump(x)]).collect();
        let uv = points.iter().map(|p| [100.0 * p[0] / (p[2] + 100.0), 100.0 * p[1] / (p[2] + 100.0)]).collect();
        let radius_px = points.iter().map(|p| 100.0 / (p[2] + 100.0)).collect();
        (points, uv, radius_px)
    }

    #[test]
    fn a_stretch_out_in_depth_and_back_is_a_detour_and_a_shallow_arch_or_an_end_is_not() {
        let tent =
            |centre: f64, half: f64, height: f64| move |x: f64| height * (1.0 - (x - centre).abs() / half).max(0.0);
        // 4 R out and back over 5 R: one detour, from where it leaves the line to where it returns
        let (points, uv, radius_px) = seen(tent(13.5, 2.5, 4.0));
        let found = detours(&points, &uv, &radius_px, 1.0, LIMITS);
        assert_eq!(found.len(), 1);
        let (i, j) = found[0];
        assert!(points[i][0] <= 11.0 && points[j][0] >= 16.0, "{:?} {:?}", points[i], points[j]);
        // 2 R out over 12 R: the part's own curve
        let (points, uv, radius_px) = seen(|x| 2.0 * (std::f64::consts::PI * ((x - 9.0) / 12.0).clamp(0.0, 1.0)).sin());
        assert!(detours(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
        // within 3 R of an end: left to the hooked ends
        let (points, uv, radius_px) = seen(tent(3.0, 2.5, 4.0));
        assert!(detours(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
    }

    #[test]
    fn skipping_the_straight_stretches_finds_what_reading_every_stretch_finds() {
        // wiggly axes in 3D, every half radius, seen from several distances, with the limits of
        // both passes (docs/extraction.md, "Polyline", Behind a leaf)
        let behind = DetourLimits { span: 20.0, screen: 1.5, back_ratio: 1e9, back: 1e9, ..LIMITS };
        let mut state = 12345_u64;
        let mut random = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut found = 0;
        for trial in 0..40 {
            let (amplitude, wavelength) = (0.5 + 6.0 * random(), 2.0 + 20.0 * random());
            let (phase, eye) = (10.0 * random(), 20.0 + 200.0 * random());
            let points: Vec<[f64; 3]> = (0..121)
                .map(|k| f64::from(k) * 0.5)
                .map(|x| {
                    let wave = (x / wavelength + phase).sin();
                    [x, amplitude * wave * (x / 7.0).cos() * random(), -amplitude * wave.powi(3)]
                })
                .collect();
            let uv: Vec<[f64; 2]> =
                points.iter().map(|p| [100.0 * p[0] / (p[2] + eye), 100.0 * p[1] / (p[2] + eye)]).collect();
            let radius_px: Vec<f64> = points.iter().map(|p| 100.0 / (p[2] + eye)).collect();
            for limits in [LIMITS, behind] {
                let skipping = detours_read(&points, &uv, &radius_px, 1.0, limits, Reading::SkipStraight);
                let every = detours_read(&points, &uv, &radius_px, 1.0, limits, Reading::Every);
                assert_eq!(skipping, every, "trial {trial}");
                found += every.len();
            }
        }
        assert!(found > 20, "{found}");
    }

    #[test]
    fn a_stretch_leaving_the_line_on_screen_or_behind_the_camera_is_not_a_detour_in_depth() {
        // the same excursion sideways (y): on screen it is a bend (its arc is 1.9 times its chord)
        let (mut points, mut uv, mut radius_px) = seen(|_| 0.0);
        for (p, q) in points.iter_mut().zip(&mut uv) {
            p[1] = 4.0 * (1.0 - (p[0] - 13.5).abs() / 2.5).max(0.0);
            q[1] = p[1];
        }
        assert!(detours(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
        // the excursion in depth with a projection that is not finite there
        let (points, mut uv, _) = seen(|x| 4.0 * (1.0 - (x - 13.5).abs() / 2.5).max(0.0));
        uv[27] = [f64::NAN, f64::NAN];
        radius_px.fill(1.0);
        assert!(detours(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
        // no points, one point, points in one place
        assert!(detours(&[], &[], &[], 1.0, LIMITS).is_empty());
        assert!(detours(&[[0.0; 3]; 30], &[[0.0; 2]; 30], &[1.0; 30], 1.0, LIMITS).is_empty());
    }

    #[test]
    fn a_stretch_doubling_back_is_a_detour_and_a_u_turn_is_not() {
        // along x to 12 R, a finger 4 R out along y and back half a radius on, then on along x
        let mut points: Vec<[f64; 3]> = (0..=24).map(|k| [f64::from(k) * 0.5, 0.0, 0.0]).collect();
        points.extend((1..=8).map(|k| [12.0, f64::from(k) * 0.5, 0.0]));
        points.extend((0..8).rev().map(|k| [12.5, f64::from(k) * 0.5, 0.0]));
        points.extend((26..=60).map(|k| [f64::from(k) * 0.5, 0.0, 0.0]));
        let flat = |points: &[[f64; 3]]| -> (Vec<[f64; 2]>, Vec<f64>) {
            (points.iter().map(|p| [p[0], p[1]]).collect(), vec![1.0; points.len()])
        };
        let (uv, radius_px) = flat(&points);
        let found = detours(&points, &uv, &radius_px, 1.0, LIMITS);
        assert_eq!(found.len(), 1);
        let (i, j) = found[0];
        assert!(points[i] == [12.0, 0.0, 0.0] && points[j] == [12.5, 0.0, 0.0], "{:?} {:?}", points[i], points[j]);
        // a rope's U-turn of radius 3 R (its arc 1.6 times its chord) is the rope's
        let mut points: Vec<[f64; 3]> = (0..=20).map(|k| [f64::from(k) * 0.5, 0.0, 0.0]).collect();
        points.extend((1..19).map(|k| {
            let a = f64::from(k) * std::f64::consts::PI / 19.0;
            [10.0 + 3.0 * a.sin(), 3.0 - 3.0 * a.cos(), 0.0]
        }));
        points.extend((0..=20).rev().map(|k| [f64::from(k) * 0.5, 6.0, 0.0]));
        let (uv, radius_px) = flat(&points);
        assert!(detours(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
    }

    const BUMP: BumpLimits = BumpLimits { span: 8.0, off: 1.5, angle_deg: 15.0, lead: 3.0, end: 3.0 };

    /// An axis along x every radius (R = 1), `side(x)` along y.
    fn along_x(side: impl Fn(f64) -> f64) -> Vec<[f64; 3]> {
        (0..41).map(f64::from).map(|x| [x, side(x), 0.0]).collect()
    }

    #[test]
    fn a_stretch_out_and_back_into_line_is_a_bump_and_a_bend_a_wave_or_an_end_is_not() {
        let tent =
            |centre: f64, half: f64, height: f64| move |x: f64| height * (1.0 - (x - centre).abs() / half).max(0.0);
        // 2.5 R out over 6 R, the axis straight either side: one bump, from where it leaves the line
        // to where it returns
        let points = along_x(tent(20.0, 3.0, 2.5));
        assert_eq!(bumps(&points, 1.0, BUMP), vec![(17, 23)]);
        // a bend of 40 degrees at x = 20: the axis before and after are not in line
        let points = along_x(|x| (x - 20.0).max(0.0) * 40f64.to_radians().tan());
        assert!(bumps(&points, 1.0, BUMP).is_empty());
        // a wave 2 R high every 16 R: each crest leaves its chord, but its sides are not in line
        let points = along_x(|x| 2.0 * (x * std::f64::consts::TAU / 16.0).sin());
        assert!(bumps(&points, 1.0, BUMP).is_empty());
        // 1.2 R out: the part's own wobble
        let points = along_x(tent(20.0, 3.0, 1.2));
        assert!(bumps(&points, 1.0, BUMP).is_empty());
        // within 3 R of an end (left to the hooked ends), or wider than the span
        assert!(bumps(&along_x(tent(2.0, 2.0, 2.5)), 1.0, BUMP).is_empty());
        assert!(bumps(&along_x(tent(20.0, 5.0, 2.5)), 1.0, BUMP).is_empty());
        // no points, one, all in one place
        assert!(bumps(&[], 1.0, BUMP).is_empty());
        assert!(bumps(&[[0.0; 3]], 1.0, BUMP).is_empty());
        assert!(bumps(&[[0.0; 3]; 30], 1.0, BUMP).is_empty());
    }
}
