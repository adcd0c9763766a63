//! Stroke clean-up (DESIGN.md, path search step 1).

use crate::{IndexImage, PathError};

/// The stroke after clean-up: vertices inside the image, minus those that jumped onto an occluder.
#[derive(Debug, Clone)]
pub(crate) struct CleanStroke {
    pub points: Vec<[f32; 2]>,
    /// `Z` under each vertex; `None` over background (such vertices anchor no depth).
    pub depth: Vec<Option<f32>>,
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
}

/// Keep the stroke vertices inside the image; drop a vertex whose `Z` differs from the last kept
/// depth-carrying vertex's by more than `depth_gap` (the stroke slipped onto an occluder).
pub(crate) fn clean_stroke(image: &IndexImage, stroke: &[[f32; 2]], depth_gap: f32) -> Result<CleanStroke, PathError> {
    if let Some(vertex) = stroke.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(PathError::NonFiniteStroke { vertex });
    }
    let mut points = Vec::with_capacity(stroke.len());
    let mut depth = Vec::with_capacity(stroke.len());
    let mut last_depth: Option<f32> = None;
    for p in stroke {
        let Some(pixel) = image.pixel_at(p[0], p[1]) else { continue };
        if points.last() == Some(p) {
            continue; // a repeated point adds a zero-length segment and nothing else
        }
        let z = image.gaussian(pixel).map(|_| image.depth[pixel]);
        if let (Some(z), Some(previous)) = (z, last_depth)
            && (z - previous).abs() > depth_gap
        {
            continue;
        }
        last_depth = z.or(last_depth);
        points.push(*p);
        depth.push(z);
    }
    if points.len() < 2 {
        return Err(PathError::StrokeTooShort { inside: points.len(), width: image.width, height: image.height });
    }
    if depth.iter().all(Option::is_none) && !crosses_object(image, &points) {
        return Err(PathError::StrokeOnBackground);
    }
    Ok(CleanStroke { points, depth })
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
