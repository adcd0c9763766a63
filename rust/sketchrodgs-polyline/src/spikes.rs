//! Depth spikes in an extracted axis (docs/extraction.md, "Polyline", **Depth spikes**): stretches
//! that run out of the axis's line in depth and back while staying on it on screen. The path
//! followed the part on screen but climbed onto something in front of it (a leaf it passes
//! behind) or dropped behind it; a part seldom leaves its line and comes back within a few radii,
//! and exactly along the line of sight. The caller puts each stretch's points onto its chord.

/// The limits of a spike, in radii.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpikeLimits {
    /// The longest stretch (arc length).
    pub span: f64,
    /// A stretch is a spike where a point leaves its 3D chord by more than this.
    pub depth: f64,
    /// ... while every point stays closer than this to its chord on screen (radii in pixels).
    pub screen: f64,
    /// Stretches start and end at least this far from the axis's ends (the ends are judged by
    /// `cut_hooked_ends`).
    pub end: f64,
}

/// The stretches `(i, j)` (points `i` and `j` kept, those between to go onto the chord) of the
/// axis `points`, seen on screen at `uv` with `radius_px` the radius in pixels at each point:
/// from the first point on, the deepest spike starting there, then on from its end. Points whose
/// projection is not finite are never in a spike.
pub fn depth_spikes(
    points: &[[f64; 3]],
    uv: &[[f64; 2]],
    radius_px: &[f64],
    radius: f64,
    limits: SpikeLimits,
) -> Vec<(usize, usize)> {
    let n = points.len().min(uv.len()).min(radius_px.len());
    let mut arc = vec![0.0; n];
    for k in 1..n {
        arc[k] = arc[k - 1] + distance(&points[k - 1], &points[k]) / radius;
    }
    let mut spikes = Vec::new();
    let mut i = 0;
    while i + 2 < n {
        match deepest_from(i, points, uv, radius_px, radius, &arc, limits) {
            Some(j) => {
                spikes.push((i, j));
                i = j;
            }
            None => i += 1,
        }
    }
    spikes
}

/// The end of the deepest spike starting at point `i`, if any.
fn deepest_from(
    i: usize,
    points: &[[f64; 3]],
    uv: &[[f64; 2]],
    radius_px: &[f64],
    radius: f64,
    arc: &[f64],
    limits: SpikeLimits,
) -> Option<usize> {
    let last = *arc.last()?;
    if arc[i] < limits.end {
        return None;
    }
    let mut best = (limits.depth, None);
    for j in i + 2..arc.len() {
        if arc[j] - arc[i] > limits.span || last - arc[j] < limits.end {
            break;
        }
        let aside = (i + 1..j).map(|m| chord_distance(&uv[i], &uv[j], &uv[m])).fold(0.0, max_or_nan);
        // a NaN (a point behind the camera) is never a spike
        let on_line = aside / radius_px[i] < limits.screen;
        if !on_line {
            continue;
        }
        let far = (i + 1..j).map(|m| chord_distance(&points[i], &points[j], &points[m])).fold(0.0, max_or_nan);
        if far / radius > best.0 {
            best = (far / radius, Some(j));
        }
    }
    best.1
}

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

    const LIMITS: SpikeLimits = SpikeLimits { span: 10.0, depth: 3.5, screen: 0.7, end: 3.0 };

    /// An axis along x every half radius (R = 1), `bump(x)` towards the camera (-z), seen by a
    /// pinhole at z = -100 with a focal length of 100 px.
    fn seen(bump: impl Fn(f64) -> f64) -> (Vec<[f64; 3]>, Vec<[f64; 2]>, Vec<f64>) {
        let points: Vec<[f64; 3]> = (0..61).map(|k| f64::from(k) * 0.5).map(|x| [x, 0.0, -bump(x)]).collect();
        let uv = points.iter().map(|p| [100.0 * p[0] / (p[2] + 100.0), 100.0 * p[1] / (p[2] + 100.0)]).collect();
        let radius_px = points.iter().map(|p| 100.0 / (p[2] + 100.0)).collect();
        (points, uv, radius_px)
    }

    #[test]
    fn a_stretch_out_in_depth_and_back_is_a_spike_and_a_shallow_arch_or_an_end_is_not() {
        let tent =
            |centre: f64, half: f64, height: f64| move |x: f64| height * (1.0 - (x - centre).abs() / half).max(0.0);
        // 4 R out and back over 5 R: one spike, from where it leaves the line to where it returns
        let (points, uv, radius_px) = seen(tent(13.5, 2.5, 4.0));
        let spikes = depth_spikes(&points, &uv, &radius_px, 1.0, LIMITS);
        assert_eq!(spikes.len(), 1);
        let (i, j) = spikes[0];
        assert!(points[i][0] <= 11.0 && points[j][0] >= 16.0, "{:?} {:?}", points[i], points[j]);
        // 2 R out over 12 R: the part's own curve
        let (points, uv, radius_px) = seen(|x| 2.0 * (std::f64::consts::PI * ((x - 9.0) / 12.0).clamp(0.0, 1.0)).sin());
        assert!(depth_spikes(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
        // within 3 R of an end: left to the hooked ends
        let (points, uv, radius_px) = seen(tent(3.0, 2.5, 4.0));
        assert!(depth_spikes(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
    }

    #[test]
    fn a_stretch_leaving_the_line_on_screen_or_behind_the_camera_is_not_a_spike() {
        // the same excursion sideways (y): on screen it is a bend
        let (mut points, mut uv, mut radius_px) = seen(|_| 0.0);
        for (p, q) in points.iter_mut().zip(&mut uv) {
            p[1] = 4.0 * (1.0 - (p[0] - 13.5).abs() / 2.5).max(0.0);
            q[1] = p[1];
        }
        assert!(depth_spikes(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
        // the excursion in depth with a projection that is not finite there
        let (points, mut uv, _) = seen(|x| 4.0 * (1.0 - (x - 13.5).abs() / 2.5).max(0.0));
        uv[27] = [f64::NAN, f64::NAN];
        radius_px.fill(1.0);
        assert!(depth_spikes(&points, &uv, &radius_px, 1.0, LIMITS).is_empty());
        // no points, one point, points in one place
        assert!(depth_spikes(&[], &[], &[], 1.0, LIMITS).is_empty());
        assert!(depth_spikes(&[[0.0; 3]; 30], &[[0.0; 2]; 30], &[1.0; 30], 1.0, LIMITS).is_empty());
    }
}
