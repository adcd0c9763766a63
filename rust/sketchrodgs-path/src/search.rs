//! Dijkstra over the band with the paper's weight, and the resume-after-occlusion loop
//! (DESIGN.md, path search steps 3-5).

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, HashSet};

use crate::band::{Band, label_band};
use crate::stroke::{CleanStroke, clean_stroke};
use crate::{IndexImage, PathError, TraceParams};

/// How a piece of the path ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PieceEnd {
    /// It reached the stroke's last point.
    Goal,
    /// No forward step was possible without crossing a depth gap over `3R` or leaving the band;
    /// `pixel` is where the connection was lost and `progress` how far along the stroke it was
    /// (segment index + parameter on the cleaned stroke).
    Lost { pixel: [u32; 2], progress: f32 },
}

/// One connected piece of the path.
#[derive(Debug, Clone, PartialEq)]
pub struct Piece {
    /// Pixels `(col, row)` from start to end, 8-connected.
    pub pixels: Vec<[u32; 2]>,
    /// Distinct Gaussians under those pixels, in path order (first occurrence kept).
    pub gaussian_ids: Vec<u32>,
    pub end: PieceEnd,
}

/// The result of [`trace_stroke`].
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    pub pieces: Vec<Piece>,
    /// The stroke after clean-up (vertices inside the image that did not jump onto an occluder).
    pub clean_stroke: Vec<[f32; 2]>,
    /// Fraction of the input stroke's length (inside the image) within `cover_px` of the path.
    pub coverage: f32,
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
    let params = params.validated(image.width)?;
    if let Some(&id) = image.index.iter().find(|&&k| k >= 0 && k as usize >= centres.len()) {
        return Err(PathError::IndexOutOfRange { id, count: centres.len() });
    }
    let gap = 3.0 * params.radius;
    let clean = clean_stroke(image, stroke, gap)?;
    let band = label_band(image, &clean, params.band_px, gap);
    let endpoint = |which: &'static str, point: [f32; 2]| {
        snap(image, &band, point, params.band_px).ok_or(PathError::EndpointOffObject {
            which,
            x: point[0],
            y: point[1],
            band_px: params.band_px,
        })
    };
    let mut start = endpoint("first", clean.points[0])?;
    let goal = endpoint("last", clean.points[clean.points.len() - 1])?;

    let mut search = Search::new(image, centres, &band, &params);
    let mut covered = CoverMask::new(image.width, image.height, params.cover_px);
    let mut pieces = Vec::new();
    loop {
        let (end_node, reached) = search.run(start, goal);
        let pixels = search.path_to(end_node);
        covered.stamp(&pixels);
        let end = if reached {
            PieceEnd::Goal
        } else {
            PieceEnd::Lost { pixel: pixel_xy(image, band.pixel[end_node] as usize), progress: band.progress(end_node) }
        };
        pieces.push(Piece {
            gaussian_ids: distinct_ids(image, &pixels),
            pixels: pixels.iter().map(|&p| pixel_xy(image, p)).collect(),
            end,
        });
        if reached {
            break;
        }
        match resume_point(image, &band, &clean, &covered, end_node, gap, params.band_px) {
            Some(next) => start = next,
            None => break,
        }
    }
    let coverage = covered.coverage(image, stroke);
    Ok(Trace { pieces, clean_stroke: clean.points, coverage })
}

/// The node of the nearest band pixel within `radius` of `point`.
fn snap(image: &IndexImage, band: &Band, point: [f32; 2], radius: f32) -> Option<usize> {
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
                && best.is_none_or(|(bd, _)| d < bd)
            {
                best = Some((d, node));
            }
        }
    }
    best.map(|(_, p)| p)
}

/// After a piece is lost at `lost`: the first uncovered stroke vertex past its progress whose
/// depth is within `gap` of the depth where the connection was lost (paper, "Occlusion").
fn resume_point(
    image: &IndexImage,
    band: &Band,
    stroke: &CleanStroke,
    covered: &CoverMask,
    lost: usize,
    gap: f32,
    band_px: f32,
) -> Option<usize> {
    let progress = band.progress(lost);
    let (lost_depth, lost_arc) = (image.depth[band.pixel[lost] as usize], stroke.arc_at(progress));
    // carry the lost depth along the stroke by the object's depth trend, as clean-up does
    let slope = stroke.slope_before(lost_arc);
    (0..stroke.points.len())
        .filter(|&j| j as f32 > progress)
        .filter(|&j| !covered.contains(stroke.points[j]))
        .filter(|&j| stroke.depth[j].is_some_and(|z| (z - lost_depth - slope * (stroke.arc[j] - lost_arc)).abs() <= gap))
        .find_map(|j| snap(image, band, stroke.points[j], band_px))
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
const NEIGHBOURS: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Dijkstra state over the band's nodes, reused across the pieces of one trace.
struct Search<'a> {
    image: &'a IndexImage<'a>,
    band: &'a Band,
    params: &'a TraceParams,
    /// Centre of the Gaussian under each node, in f64 for the cost sums.
    centre: Vec<[f64; 3]>,
    cost: Vec<f64>,
    previous: Vec<u32>,
    touched: Vec<usize>,
}

impl<'a> Search<'a> {
    fn new(image: &'a IndexImage<'a>, centres: &[[f32; 3]], band: &'a Band, params: &'a TraceParams) -> Self {
        let centre = band
            .pixel
            .iter()
            .map(|&p| centres[image.index[p as usize] as usize].map(f64::from))
            .collect();
        let n = band.len();
        Self { image, band, params, centre, cost: vec![f64::INFINITY; n], previous: vec![NONE; n], touched: Vec::new() }
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
        let max_jump2 = (3.0 * f64::from(self.params.radius)).powi(2);
        let half_width = self.image.width as f64 / 2.0;
        let mut heap = BinaryHeap::new();
        self.cost[start] = 0.0;
        self.touched.push(start);
        heap.push(Reverse((Cost(0.0), start)));
        let mut furthest = (start, self.band.progress(start));
        while let Some(Reverse((Cost(cost), a))) = heap.pop() {
            if cost > self.cost[a] {
                continue; // stale entry
            }
            if a == goal {
                return (goal, true);
            }
            let progress = self.band.progress(a);
            if progress > furthest.1 {
                furthest = (a, progress);
            }
            let pixel = self.band.pixel[a] as usize;
            let (col, row) = ((pixel % self.image.width) as i64, (pixel / self.image.width) as i64);
            let (ca, segment_a) = (self.centre[a], self.band.segment[a]);
            for (dx, dy) in NEIGHBOURS {
                let (x, y) = (col + dx, row + dy);
                if x < 0 || y < 0 || x >= width || y >= height {
                    continue;
                }
                let Some(b) = self.band.node((y * width + x) as usize) else { continue };
                // forward only along the stroke, which keeps the path on its branch at crossings
                if self.band.segment[b] < segment_a {
                    continue;
                }
                let cb = self.centre[b];
                let length2 = (ca[0] - cb[0]).powi(2) + (ca[1] - cb[1]).powi(2) + (ca[2] - cb[2]).powi(2);
                if length2 > max_jump2 {
                    continue; // a depth gap: never jump onto another surface
                }
                let deviation = f64::from(self.band.distance[b]) / half_width;
                let next = cost + length2.sqrt() + self.params.stroke_weight * deviation * deviation;
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
                for x in (col - r).max(0)..=(col + r).min(self.width as i64 - 1) {
                    if ((x - col).pow(2) + (y - row).pow(2)) as f32 <= r2 {
                        self.mask[y as usize * self.width + x as usize] = true;
                    }
                }
            }
        }
    }

    fn contains(&self, point: [f32; 2]) -> bool {
        let (x, y) = (point[0].floor(), point[1].floor());
        x >= 0.0 && y >= 0.0 && (x as usize) < self.width && (y as usize) < self.height && self.mask[y as usize * self.width + x as usize]
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
