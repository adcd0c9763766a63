//! Stroke clean-up (DESIGN.md, path search step 1).

use crate::{IndexImage, PathError};

/// The stroke after clean-up: vertices inside the image, minus those that jumped onto an occluder.
#[derive(Debug, Clone)]
pub(crate) struct CleanStroke {
    pub points: Vec<[f32; 2]>,
    /// `Z` under each vertex; `None` over background (such vertices anchor no depth).
    pub depth: Vec<Option<f32>>,
    /// Screen arc length from the first vertex to each vertex, in pixels.
    pub arc: Vec<f32>,
}

impl CleanStroke {
    pub fn segment_count(&self) -> usize {
        self.points.len().saturating_sub(1)
    }

    /// Depth of segment `i`: the smaller `Z` of its two ends (`None` if both are over background).
    pub fn segment_depth(&self, i: usize) -> Option<f32> {
        match (self.depth[i], self.depth[i + 1]) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Screen arc length at `progress` (segment index + parameter).
    pub fn arc_at(&self, progress: f32) -> f32 {
        let i = (progress.floor().max(0.0) as usize).min(self.segment_count().saturating_sub(1));
        let t = (progress - i as f32).clamp(0.0, 1.0);
        self.arc[i] + t * (self.arc[i + 1] - self.arc[i])
    }

    /// How fast the object's depth changes per pixel of stroke just before `arc`, from the
    /// vertices with depth (see [`depth_slope`]).
    pub fn slope_before(&self, arc: f32) -> f32 {
        let history: Vec<(f32, f32)> =
            (0..self.points.len()).filter(|&j| self.arc[j] <= arc).filter_map(|j| self.depth[j].map(|z| (self.arc[j], z))).collect();
        depth_slope(&history)
    }
}

/// Stroke vertices this far back (pixels of stroke) inform the depth trend.
const TREND_WINDOW_PX: f32 = 120.0;
/// A trend needs at least this much stroke behind it; shorter ones are noise.
const TREND_MIN_SPAN_PX: f32 = 30.0;

/// Least-squares slope dZ/ds of the last `TREND_WINDOW_PX` of `(arc, depth)` history; 0 when the
/// history is too short to tell a trend from the surface's own depth noise.
pub(crate) fn depth_slope(history: &[(f32, f32)]) -> f32 {
    let Some(&(last, _)) = history.last() else { return 0.0 };
    let recent: Vec<(f64, f64)> = history
        .iter()
        .filter(|(s, _)| last - s <= TREND_WINDOW_PX)
        .map(|&(s, z)| (f64::from(s), f64::from(z)))
        .collect();
    let span = recent.first().map_or(0.0, |f| last - f.0 as f32);
    if recent.len() < 3 || span < TREND_MIN_SPAN_PX {
        return 0.0;
    }
    let n = recent.len() as f64;
    let (ms, mz) = (recent.iter().map(|r| r.0).sum::<f64>() / n, recent.iter().map(|r| r.1).sum::<f64>() / n);
    let sxx: f64 = recent.iter().map(|r| (r.0 - ms).powi(2)).sum();
    let sxz: f64 = recent.iter().map(|r| (r.0 - ms) * (r.1 - mz)).sum();
    if sxx > 0.0 { (sxz / sxx) as f32 } else { 0.0 }
}

/// Keep the stroke vertices inside the image; drop a vertex whose `Z` differs by more than
/// `depth_gap` from the depth the object is expected to have there: the last kept vertex's depth,
/// carried along the stroke by the recent depth trend (so a receding object is not mistaken for
/// an occluder after a gap).
pub(crate) fn clean_stroke(image: &IndexImage, stroke: &[[f32; 2]], depth_gap: f32) -> Result<CleanStroke, PathError> {
    if let Some(vertex) = stroke.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(PathError::NonFiniteStroke { vertex });
    }
    let mut points: Vec<[f32; 2]> = Vec::with_capacity(stroke.len());
    let mut depth = Vec::with_capacity(stroke.len());
    let mut arc = Vec::with_capacity(stroke.len());
    let mut history: Vec<(f32, f32)> = Vec::new(); // (arc, depth) of kept vertices with depth
    for p in stroke {
        let Some(pixel) = image.pixel_at(p[0], p[1]) else { continue };
        let s = match points.last() {
            Some(q) if q == p => continue, // a repeated point adds a zero-length segment and nothing else
            Some(q) => arc.last().copied().unwrap_or(0.0) + (p[0] - q[0]).hypot(p[1] - q[1]),
            None => 0.0,
        };
        let z = image.gaussian(pixel).map(|_| image.depth[pixel]);
        if let (Some(z), Some(&(s_last, z_last))) = (z, history.last()) {
            let expected = z_last + depth_slope(&history) * (s - s_last);
            if (z - expected).abs() > depth_gap {
                continue;
            }
        }
        if let Some(z) = z {
            history.push((s, z));
        }
        points.push(*p);
        depth.push(z);
        arc.push(s);
    }
    if points.len() < 2 {
        return Err(PathError::StrokeTooShort { inside: points.len(), width: image.width, height: image.height });
    }
    if depth.iter().all(Option::is_none) && !crosses_object(image, &points) {
        return Err(PathError::StrokeOnBackground);
    }
    Ok(CleanStroke { points, depth, arc })
}

/// Whether any point along the stroke (sampled every half pixel) lies over a Gaussian.
fn crosses_object(image: &IndexImage, points: &[[f32; 2]]) -> bool {
    points.windows(2).any(|w| {
        let (a, b) = (w[0], w[1]);
        let steps = ((b[0] - a[0]).hypot(b[1] - a[1]) * 2.0).ceil().max(1.0) as usize;
        (0..=steps).any(|s| {
            let t = s as f32 / steps as f32;
            image.pixel_at(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])).is_some_and(|p| image.index[p] >= 0)
        })
    })
}
