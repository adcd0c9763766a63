//! Dijkstra over the band with the paper's weight, and the resume-after-occlusion loop
//! (docs/extraction.md, "Search").

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, HashSet};

use crate::band::{Band, label_band};
use crate::stroke::{CleanStroke, clean_stroke};
use crate::width::Walks;
use crate::{IndexImage, PathError, TraceParams};

/// How a piece of the path ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PieceEnd {
    /// It reached the stroke's last point.
    Goal,
    /// No forward step was possible without crossing a depth gap over `3R` or leaving the band;
    /// `pixel` is where the connection was lost and `progress` how far along the clean stroke it
    /// was (pixels of its arc length).
    Lost { pixel: [u32; 2], progress: f32 },
}

/// One connected piece of the path.
#[derive(Debug, Clone, PartialEq)]
pub struct Piece {
    /// Pixels `(col, row)` from start to end, 8-connected.
    pub pixels: Vec<[u32; 2]>,
    /// The Gaussian the search saw at each pixel: the front image's, or where something lay in
    /// front of the object, the one behind it (docs/extraction.md, "What lies behind").
    pub pixel_ids: Vec<u32>,
    /// Distinct Gaussians under those pixels, in path order (first occurrence kept).
    pub gaussian_ids: Vec<u32>,
    pub end: PieceEnd,
}

/// The result of [`trace_stroke`].
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    pub pieces: Vec<Piece>,
    /// The stroke samples (every few pixels, smoothed) on the depth chain the path follows: inside
    /// the image, past overshooting ends, not over occluders.
    pub clean_stroke: Vec<[f32; 2]>,
    /// Fraction of the input stroke's length (inside the image) within `cover_px` of the path.
    pub coverage: f32,
    /// The image came without the layers behind it, and with them the trace might run elsewhere
    /// (behind what lies in front of the object): give them and trace again.
    pub wants_behind: bool,
}

/// Find the path under `stroke` (continuous pixel coordinates) over `image`.
///
/// `centres[k]` is the centre of Gaussian `k` (the ids stored in the index image).
pub fn trace_stroke(
    image: &IndexImage,
    centres: &[[f32; 3]],
    stroke: &[[f32; 2]],
    params: &TraceParams,
) -> Result<Trace, PathError> {
    let radius_px = match crate::depth_under(image, stroke) {
        Some(z) if z > 0.0 && params.focal_px > 0.0 => params.radius * params.focal_px / z,
        _ => 0.0,
    };
    let params = params.validated(image.width, radius_px)?;
    let id = image.max_id();
    if id >= 0 && id as usize >= centres.len() {
        return Err(PathError::IndexOutOfRange { id, count: centres.len() });
    }
    let gap = crate::depth_gap(image, stroke, params.radius, params.focal_px);
    let clean = clean_stroke(image, stroke, params.band_px, gap, params.focal_px, Some(params.radius))?;
    // from here on, what lies more than the gap in front of the object is seen through
    let floors = clean.floors(image, gap, params.band_px + WALK_RADII * radius_px);
    let image = &image.seen_from_cells(&floors);
    let band = label_band(image, &clean, params.band_px, gap);
    // the clean stroke starts and ends on the object, so both ends have band pixels near them
    let last = clean.points.len() - 1;
    let endpoint = |j: usize| {
        snap(image, &band, clean.points[j], clean.arc[j], params.band_px)
            .ok_or(PathError::StrokeBarelyOnObject { samples: 1 })
    };
    let mut start = endpoint(0)?;
    let goal = endpoint(last)?;

    let mut search = Search::new(image, centres, &band, &clean, &params, gap);
    let mut covered = CoverMask::new(image.width, image.height, params.cover_px);
    let mut pieces = Vec::new();
    let mut start_sample = 0; // the chain sample each piece starts from: it moves on every time
    loop {
        let (end_node, reached) = search.run(start, goal);
        let pixels = search.path_to(end_node);
        covered.stamp(&pixels);
        let end = if reached {
            PieceEnd::Goal
        } else {
            PieceEnd::Lost { pixel: pixel_xy(image, band.pixel[end_node] as usize), progress: band.arc[end_node] }
        };
        pieces.push(Piece {
            pixel_ids: pixels.iter().map(|&p| image.gaussian(p).unwrap_or(u32::MAX)).collect(),
            gaussian_ids: distinct_ids(image, &pixels),
            pixels: pixels.iter().map(|&p| pixel_xy(image, p)).collect(),
            end,
        });
        if reached {
            break;
        }
        match resume_point(image, &band, &clean, &covered, start, start_sample, params.band_px) {
            Some((sample, node)) => (start_sample, start) = (sample, node),
            None => break,
        }
    }
    let coverage = covered.coverage(image, stroke);
    let on_chain = clean.points.iter().zip(&clean.anchor).filter(|(_, a)| a.is_some()).map(|(p, _)| *p).collect();
    Ok(Trace { pieces, clean_stroke: on_chain, coverage, wants_behind: clean.wants_behind })
}

/// The node of the nearest band pixel within `radius` of `point` that belongs to the stroke near
/// arc length `arc` (where the stroke crosses itself, pixels nearby can belong to the other pass).
fn snap(image: &IndexImage, band: &Band, point: [f32; 2], arc: f32, radius: f32) -> Option<usize> {
    let reach = radius.ceil() as i64 + 1;
    let (cx, cy) = (point[0].floor() as i64, point[1].floor() as i64);
    let mut best: Option<(f32, usize)> = None;
    for row in (cy - reach).max(0)..=(cy + reach).min(image.height as i64 - 1) {
        for col in (cx - reach).max(0)..=(cx + reach).min(image.width as i64 - 1) {
            let p = row as usize * image.width + col as usize;
            let (dx, dy) = (col as f32 + 0.5 - point[0], row as f32 + 0.5 - point[1]);
            let d = (dx * dx + dy * dy).sqrt();
            if let Some(node) = band.node(p)
                && d <= radius.max(0.75)
                && (band.arc[node] - arc).abs() <= 2.0 * radius + 2.0
                && best.is_none_or(|(bd, _)| d < bd)
            {
                best = Some((d, node));
            }
        }
    }
    best.map(|(_, p)| p)
}

/// After a piece that started at node `start` (from chain sample `start_sample`) is lost: the first
/// sample on the stroke's depth chain past that start that no path covers yet, and its node (paper,
/// "Occlusion"; the chain already skips samples over occluders). Counting from the start, not from
/// the furthest pixel reached, matters where the stroke crosses itself: a pixel at the crossing can
/// belong to the later pass. The sample is always a later one than `start_sample`, so the loop ends
/// even where a piece does not cover its own sample (a band wider than `cover_px`).
fn resume_point(
    image: &IndexImage,
    band: &Band,
    stroke: &CleanStroke,
    covered: &CoverMask,
    start: usize,
    start_sample: usize,
    band_px: f32,
) -> Option<(usize, usize)> {
    let arc = band.arc[start];
    (start_sample + 1..stroke.points.len())
        .filter(|&j| stroke.arc[j] > arc && stroke.anchor[j].is_some())
        .filter(|&j| !covered.contains(stroke.points[j]))
        .find_map(|j| snap(image, band, stroke.points[j], stroke.arc[j], band_px).map(|node| (j, node)))
}

fn pixel_xy(image: &IndexImage, p: usize) -> [u32; 2] {
    [(p % image.width) as u32, (p / image.width) as u32]
}

fn distinct_ids(image: &IndexImage, pixels: &[usize]) -> Vec<u32> {
    let mut seen = HashSet::new();
    pixels.iter().filter_map(|&p| image.gaussian(p)).filter(|&k| seen.insert(k)).collect()
}

/// A cost for the heap: f64 ordered totally (costs are never NaN).
#[derive(Clone, Copy, PartialEq)]
struct Cost(f64);
impl Eq for Cost {}
impl PartialOrd for Cost {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Cost {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0)
    }
}

const NONE: u32 = u32::MAX;
/// The path may step back along the stroke by this many pixels of arc.
const BACK_SLACK_PX: f32 = 4.0;
/// Extra cost per pixel step, in units of a pixel's world size, for each radius by which the
/// surface under a pixel is wider than the part (`width::excess_width`): it keeps the path off
/// leaves and bodies that touch the part at its depth, where big Gaussians make steps free.
const WIDE_WEIGHT: f64 = 2.0;
const NEIGHBOURS: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Dijkstra state over the band's nodes, reused across the pieces of one trace.
struct Search<'a> {
    image: &'a IndexImage<'a>,
    band: &'a Band,
    params: &'a TraceParams,
    /// Centre of the Gaussian under each node, in f64 for the cost sums.
    centre: Vec<[f64; 3]>,
    /// The camera z of each node's pixel (read once: the image's reads go through its layers).
    depth: Vec<f32>,
    /// Extra cost per pixel step onto each node for a surface much wider than the part.
    wide: Vec<f64>,
    /// No step between pixels whose depths differ by more (`crate::depth_gap`).
    gap: f32,
    cost: Vec<f64>,
    previous: Vec<u32>,
    touched: Vec<usize>,
}

impl<'a> Search<'a> {
    fn new(
        image: &'a IndexImage<'a>,
        centres: &[[f32; 3]],
        band: &'a Band,
        stroke: &CleanStroke,
        params: &'a TraceParams,
        gap: f32,
    ) -> Self {
        let centre = band.pixel.iter().map(|&p| centres[image.id_at(p as usize) as usize].map(f64::from)).collect();
        let depth: Vec<f32> = band.pixel.iter().map(|&p| image.depth(p as usize)).collect();
        let n = band.len();
        let wide = wide_penalty(image, band, stroke, params, &depth);
        Self {
            image,
            band,
            params,
            centre,
            depth,
            wide,
            gap,
            cost: vec![f64::INFINITY; n],
            previous: vec![NONE; n],
            touched: Vec::new(),
        }
    }

    /// Shortest paths from node `start`. Returns the goal if reached, else the settled node of
    /// furthest progress along the stroke (the cheapest one among equals), and whether the goal was
    /// reached.
    fn run(&mut self, start: usize, goal: usize) -> (usize, bool) {
        for &node in &self.touched {
            self.cost[node] = f64::INFINITY;
            self.previous[node] = NONE;
        }
        self.touched.clear();
        let (width, height) = (self.image.width as i64, self.image.height as i64);
        let half_width = self.image.width as f64 / 2.0;
        let mut heap = BinaryHeap::new();
        self.cost[start] = 0.0;
        self.touched.push(start);
        heap.push(Reverse((Cost(0.0), start)));
        let mut furthest = (start, self.band.arc[start]);
        while let Some(Reverse((Cost(cost), a))) = heap.pop() {
            if cost > self.cost[a] {
                continue; // stale entry
            }
            if a == goal {
                return (goal, true);
            }
            let progress = self.band.arc[a];
            if progress > furthest.1 {
                furthest = (a, progress);
            }
            let pixel = self.band.pixel[a] as usize;
            let (col, row) = ((pixel % self.image.width) as i64, (pixel / self.image.width) as i64);
            let (ca, arc_a) = (self.centre[a], self.band.arc[a]);
            for (dx, dy) in NEIGHBOURS {
                let (x, y) = (col + dx, row + dy);
                if x < 0 || y < 0 || x >= width || y >= height {
                    continue;
                }
                let Some(b) = self.band.node((y * width + x) as usize) else { continue };
                // forward along the stroke (a little slack for its wiggles), which keeps the path on
                // its branch at crossings
                if self.band.arc[b] < arc_a - BACK_SLACK_PX {
                    continue;
                }
                let cb = self.centre[b];
                let length2 = (ca[0] - cb[0]).powi(2) + (ca[1] - cb[1]).powi(2) + (ca[2] - cb[2]).powi(2);
                // a depth gap: never step onto another surface. Depth, not centre distance: on real
                // captures neighbouring pixels' Gaussians can be big and far apart sideways.
                let (za, zb) = (self.depth[a], self.depth[b]);
                if (za - zb).abs() > self.gap {
                    continue;
                }
                let deviation = f64::from(self.band.distance[b]) / half_width;
                let step = if dx != 0 && dy != 0 { std::f64::consts::SQRT_2 } else { 1.0 };
                let next =
                    cost + length2.sqrt() + self.wide[b] * step + self.params.stroke_weight * deviation * deviation;
                if next < self.cost[b] {
                    if self.cost[b].is_infinite() {
                        self.touched.push(b);
                    }
                    self.cost[b] = next;
                    self.previous[b] = a as u32;
                    heap.push(Reverse((Cost(next), b)));
                }
            }
        }
        (furthest.0, false)
    }

    /// Pixels from the last run's start to node `end`.
    fn path_to(&self, end: usize) -> Vec<usize> {
        let mut path = vec![self.band.pixel[end] as usize];
        let mut node = end;
        while self.previous[node] != NONE {
            node = self.previous[node] as usize;
            path.push(self.band.pixel[node] as usize);
        }
        path.reverse();
        path
    }
}

/// Width walks from a band pixel reach this many radii (`WIDE_FROM + WIDE_CAP` and a little): what
/// lies in front of the object is seen through that far from the stroke.
pub(crate) const WALK_RADII: f32 = 8.0;

/// Per node: `WIDE_WEIGHT` times the excess width (in radii, capped) times a pixel's world size;
/// all zero when the focal length is unknown. One walk across the stroke measures the surface's
/// run, and every band pixel of that run takes its width: a part 20 pixels wide is walked once
/// per line, not twenty times.
fn wide_penalty(
    image: &IndexImage,
    band: &Band,
    stroke: &CleanStroke,
    params: &TraceParams,
    depth: &[f32],
) -> Vec<f64> {
    let focal = params.focal_px;
    if focal <= 0.0 {
        return vec![0.0; band.len()];
    }
    let (mut walks, mut run) = (Walks::default(), Vec::new());
    let mut excess = vec![f32::NAN; band.len()];
    for node in 0..band.len() {
        if !excess[node].is_nan() {
            continue;
        }
        run.clear();
        let p = band.pixel[node] as usize;
        let normal = stroke.normal[band.segment[node] as usize];
        let e = walks.excess_width_run(image, p, normal, focal, params.radius, Some(&mut run));
        excess[node] = e;
        for other in run.iter().filter_map(|&q| band.node(q)) {
            if excess[other].is_nan() {
                excess[other] = e;
            }
        }
    }
    (0..band.len()).map(|node| WIDE_WEIGHT * f64::from(excess[node]) * f64::from(depth[node] / focal)).collect()
}

/// Pixels within `cover_px` of any path pixel found so far.
struct CoverMask {
    width: usize,
    height: usize,
    radius: f32,
    mask: Vec<bool>,
}

impl CoverMask {
    fn new(width: usize, height: usize, radius: f32) -> Self {
        Self { width, height, radius, mask: vec![false; width * height] }
    }

    fn stamp(&mut self, pixels: &[usize]) {
        let r = self.radius.floor() as i64;
        let r2 = self.radius * self.radius;
        for &p in pixels {
            let (col, row) = ((p % self.width) as i64, (p / self.width) as i64);
            for y in (row - r).max(0)..=(row + r).min(self.height as i64 - 1) {
                // the disc's half-width on this row: the largest dx with dx² + dy² within r²
                let dy2 = (y - row).pow(2);
                let Some(half) = (0..=r).rev().find(|dx| (dx * dx + dy2) as f32 <= r2) else { continue };
                let (low, high) = ((col - half).max(0) as usize, (col + half).min(self.width as i64 - 1) as usize);
                let start = y as usize * self.width;
                self.mask[start + low..=start + high].fill(true);
            }
        }
    }

    fn contains(&self, point: [f32; 2]) -> bool {
        let (x, y) = (point[0].floor(), point[1].floor());
        x >= 0.0
            && y >= 0.0
            && (x as usize) < self.width
            && (y as usize) < self.height
            && self.mask[y as usize * self.width + x as usize]
    }

    /// Fraction of the stroke's length inside the image that lies on covered pixels (sampled every
    /// half pixel).
    fn coverage(&self, image: &IndexImage, stroke: &[[f32; 2]]) -> f32 {
        let (mut total, mut hit) = (0.0_f64, 0.0_f64);
        for w in stroke.windows(2) {
            let (a, b) = (w[0], w[1]);
            let length = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            if !length.is_finite() || length == 0.0 {
                continue;
            }
            let steps = (length * 2.0).ceil() as usize;
            let step = f64::from(length) / steps as f64;
            for s in 0..steps {
                let t = (s as f32 + 0.5) / steps as f32;
                let point = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                if image.pixel_at(point[0], point[1]).is_some() {
                    total += step;
                    if self.contains(point) {
                        hit += step;
                    }
                }
            }
        }
        if total > 0.0 { (hit / total) as f32 } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cover_mask_stamps_the_pixels_within_its_radius() {
        // radii whole and not, path pixels in the middle and at the image's edges
        for radius in [0.5_f32, 3.0, 4.7, 10.0] {
            let (width, height) = (23, 17);
            let path = [0, 5 * width + 7, 8 * width + 22, 16 * width + 3];
            let mut mask = CoverMask::new(width, height, radius);
            mask.stamp(&path);
            for y in 0..height as i64 {
                for x in 0..width as i64 {
                    let expected = path.iter().any(|&p| {
                        let (col, row) = ((p % width) as i64, (p / width) as i64);
                        ((x - col).pow(2) + (y - row).pow(2)) as f32 <= radius * radius
                    });
                    assert_eq!(mask.mask[y as usize * width + x as usize], expected, "radius {radius} at ({x}, {y})");
                }
            }
        }
    }
}
