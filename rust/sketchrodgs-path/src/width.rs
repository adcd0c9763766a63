//! The object's width across the stroke (docs/extraction.md, "Radius" and "Staying on the part"):
//! from a pixel, walk both ways along the stroke's normal while the surface continues. It
//! continues while the pixel is covered (alpha >= 0.5 where alpha is known) and its depth stays
//! within 1.5 times the lateral distance walked of the start's depth (a single stray pixel is
//! skipped): a cylinder's depth rises by less than
//! the lateral offset until its silhouette, where the scene behind (or the body a sprinkle sits on)
//! jumps away. A flat leaf or body facing the camera continues, so it measures wide.

use crate::IndexImage;

/// Depth noise allowance, in pixels of lateral distance (Gaussian centres scatter about the surface).
const NOISE_PX: f32 = 2.0;
/// The depth may differ from the start's by this many times the lateral distance walked: a round
/// part's surface stays within 1 until its silhouette; Gaussian centres scatter past that.
const SLOPE: f32 = 1.5;
/// This many failing pixels in a row end the walk.
const MAX_MISSES: usize = 1;

/// Width in pixels of the surface at pixel `p` across the unit direction `normal`, walking at most
/// `max_px` each way (then the width is `2 * max_px + 1`).
pub(crate) fn cross_width(image: &IndexImage, p: usize, normal: [f32; 2], focal_px: f32, max_px: usize) -> usize {
    let (col, row) = ((p % image.width) as f32 + 0.5, (p / image.width) as f32 + 0.5);
    let z0 = image.depth(p);
    let per_px = z0 / focal_px;
    let mut width = 1;
    for sign in [1.0_f32, -1.0] {
        let (mut run, mut misses) = (0, 0);
        for k in 1..=max_px {
            let (x, y) = (col + sign * k as f32 * normal[0], row + sign * k as f32 * normal[1]);
            let Some(q) = image.pixel_at(x, y) else { break };
            if !image.known(q) {
                // not rendered (a render of the band only): walk on, so that one more render
                // holds all this walk can read; this result is discarded
                continue;
            }
            if image.covered(q) && (image.depth(q) - z0).abs() <= (SLOPE * k as f32).max(NOISE_PX) * per_px {
                (run, misses) = (k, 0);
            } else {
                // one stray Gaussian (a centre far off the surface) does not end the surface
                misses += 1;
                if misses > MAX_MISSES {
                    break;
                }
            }
        }
        width += run;
    }
    width
}

/// A round part is 2 radii wide; a surface wider than this many radii is not the part alone.
pub(crate) const WIDE_FROM: f32 = 3.5;
/// Widths past `WIDE_FROM` count up to this many radii.
pub(crate) const WIDE_CAP: f32 = 4.0;

/// By how many radii the surface at pixel `p` is wider across `normal` than `WIDE_FROM` radii
/// (0 to `WIDE_CAP`), for a part of radius `radius` seen at focal length `focal_px`.
pub(crate) fn excess_width(image: &IndexImage, p: usize, normal: [f32; 2], focal_px: f32, radius: f32) -> f32 {
    let radius_px = radius * focal_px / image.depth(p);
    let reach = ((WIDE_FROM + WIDE_CAP) * radius_px).ceil() as usize + 2;
    let width = cross_width(image, p, normal, focal_px, reach) as f32;
    (width / radius_px - WIDE_FROM).clamp(0.0, WIDE_CAP)
}

/// Unit normal of the polyline at each point (central differences; zero where it has no direction).
pub(crate) fn normals(points: &[[f32; 2]]) -> Vec<[f32; 2]> {
    (0..points.len())
        .map(|i| {
            let (a, b) = (points[i.saturating_sub(1)], points[(i + 1).min(points.len() - 1)]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let length = dx.hypot(dy);
            if length > 0.0 { [-dy / length, dx / length] } else { [0.0, 0.0] }
        })
        .collect()
}

/// Median of `values` (which must be non-empty).
pub(crate) fn median(values: &mut [f32]) -> f32 {
    values.sort_by(f32::total_cmp);
    let n = values.len();
    if n % 2 == 1 { values[n / 2] } else { 0.5 * (values[n / 2 - 1] + values[n / 2]) }
}
