//! Dijkstra over the band with the paper's weight, and the resume-after-occlusion loop
//! (docs/extraction.md, "Search").

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashSet};

use rayon::prelude::*;

use crate::band::{Band, label_band};
use crate::stroke::{CleanStroke, clean_stroke};
use crate::width::{WIDE_CAP, Walks, chroma, colour_distance, median_colour};
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
    /// Where the part lies on a surface of another colour at its depth: the two colours, which the
    /// path's cost told apart (`surface_colours`).
    pub colours: Option<SurfaceColours>,
}

/// The colours of a part lying on a surface at its own depth and of that surface, RGB.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceColours {
    pub part: [f32; 3],
    pub surround: [f32; 3],
}

impl SurfaceColours {
    /// Whether `colour` is nearer the surround's than the part's.
    pub fn is_surround(&self, colour: [f32; 3]) -> bool {
        colour_distance(colour, self.surround) < colour_distance(colour, self.part)
    }
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
    let params = params.validated(image.width, image.height, radius_px)?;
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
    // The clean stroke starts and ends on the object, so its ends nearly always have band pixels
    // near them. Where the chain's end members are the part seen only at the edge of the band (a
    // nearer branch hides it under the stroke's end), an end has none: it moves inwards to the
    // first sample that has, rather than refusing a stroke that lies on the part.
    let last = clean.points.len() - 1;
    let snapped = |j: usize| snap(image, &band, clean.points[j], clean.arc[j], params.band_px).map(|node| (j, node));
    let ((first, mut start), (_, goal)) = (0..=last)
        .find_map(snapped)
        .zip((0..=last).rev().find_map(snapped))
        .ok_or(PathError::StrokeBarelyOnObject { samples: 1 })?;

    let colours = surface_colours(image, &band, &clean, &params, gap);
    let mut search = Search::new(image, centres, &band, &clean, &params, gap, colours.as_ref());
    let mut covered = CoverMask::new(image.width, image.height, params.cover_px);
    let mut pieces = Vec::new();
    let mut start_sample = first; // the chain sample each piece starts from: it moves on every time
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
    Ok(Trace { pieces, clean_stroke: on_chain, coverage, wants_behind: clean.wants_behind, colours })
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

const NONE: u32 = u32::MAX;
/// The path may step back along the stroke by this many pixels of arc.
const BACK_SLACK_PX: f32 = 4.0;
/// Extra cost per pixel step, in units of a pixel's world size, for each radius by which the
/// surface under a pixel is wider than the part (`width::excess_width`): it keeps the path off
/// leaves and bodies that touch the part at its depth, where big Gaussians make steps free.
const WIDE_WEIGHT: f64 = 2.0;
const NEIGHBOURS: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// What a step onto a node reads, in one place: the search reads it for each of a node's eight
/// neighbours. With the heap's entries as (cost bits, node) pairs, one cache line per neighbour
/// instead of six took the bench rope's search from 3.5 to 3.2 ms (docs/extraction.md, "Speed").
#[derive(Clone, Copy)]
struct Node {
    /// Centre of the Gaussian under the node, in f64 for the cost sums.
    centre: [f64; 3],
    /// Extra cost per pixel step onto the node for a surface much wider than the part, or of the
    /// colour of the surface the part lies on.
    wide: f64,
    /// The stroke term of Eq. 1 for a step onto the node (`stroke_term`).
    stroke: f64,
    /// The camera z of the node's pixel (read once: the image's reads go through its layers).
    depth: f32,
    /// The band's arc length at the node.
    arc: f32,
}

/// Dijkstra state over the band's nodes, reused across the pieces of one trace.
struct Search<'a> {
    band: &'a Band,
    nodes: Vec<Node>,
    /// No step between pixels whose depths differ by more (`crate::depth_gap`).
    gap: f32,
    /// Per node, its neighbours' nodes in `NEIGHBOURS` order (`NONE` off the band or the image),
    /// found in parallel once: the Dijkstra read them from the image-sized `node_of_pixel`.
    neighbours: Vec<[u32; 8]>,
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
        params: &TraceParams,
        gap: f32,
        colours: Option<&SurfaceColours>,
    ) -> Self {
        let depth: Vec<f32> = band.pixel.iter().map(|&p| image.depth(p as usize)).collect();
        let n = band.len();
        let mut wide = wide_penalty(image, band, stroke, params, &depth);
        // the surface a part lies on measures as wide as the part itself: its colour tells
        if let Some(colours) = colours {
            for ((w, &p), &z) in wide.iter_mut().zip(&band.pixel).zip(&depth) {
                if image.colour(p as usize).is_some_and(|c| colours.is_surround(c)) {
                    *w = w.max(SURROUND_COST * f64::from(z / params.focal_px));
                }
            }
        }
        let stroke = stroke_term(image, band, params, &depth);
        let nodes = (0..n)
            .map(|k| Node {
                centre: centres[image.id_at(band.pixel[k] as usize) as usize].map(f64::from),
                wide: wide[k],
                stroke: stroke[k],
                depth: depth[k],
                arc: band.arc[k],
            })
            .collect();
        let (width, height) = (image.width as i64, image.height as i64);
        let neighbours = band
            .pixel
            .par_iter()
            .map(|&pixel| {
                let (col, row) = ((pixel as usize % image.width) as i64, (pixel as usize / image.width) as i64);
                NEIGHBOURS.map(|(dx, dy)| {
                    let (x, y) = (col + dx, row + dy);
                    if x < 0 || y < 0 || x >= width || y >= height {
                        return NONE;
                    }
                    band.node((y * width + x) as usize).map_or(NONE, |b| b as u32)
                })
            })
            .collect();
        let (cost, previous) = (vec![f64::INFINITY; n], vec![NONE; n]);
        Self { band, nodes, gap, neighbours, cost, previous, touched: Vec::new() }
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
        // (cost, node) ordered as the pair: costs are finite and never negative, so their bits
        // order as they do
        let mut heap: BinaryHeap<Reverse<(u64, u32)>> = BinaryHeap::new();
        self.cost[start] = 0.0;
        self.touched.push(start);
        heap.push(Reverse((0.0_f64.to_bits(), start as u32)));
        let mut furthest = (start, self.nodes[start].arc);
        while let Some(Reverse((bits, a))) = heap.pop() {
            let (cost, a) = (f64::from_bits(bits), a as usize);
            if cost > self.cost[a] {
                continue; // stale entry
            }
            if a == goal {
                return (goal, true);
            }
            let node_a = self.nodes[a];
            if node_a.arc > furthest.1 {
                furthest = (a, node_a.arc);
            }
            for (&(dx, dy), &b) in NEIGHBOURS.iter().zip(&self.neighbours[a]) {
                if b == NONE {
                    continue;
                }
                let b = b as usize;
                // forward along the stroke (a little slack for its wiggles), which keeps the path on
                // its branch at crossings
                let node_b = &self.nodes[b];
                if node_b.arc < node_a.arc - BACK_SLACK_PX {
                    continue;
                }
                // a depth gap: never step onto another surface. Depth, not centre distance: on real
                // captures neighbouring pixels' Gaussians can be big and far apart sideways.
                if (node_a.depth - node_b.depth).abs() > self.gap {
                    continue;
                }
                let (ca, cb) = (node_a.centre, node_b.centre);
                let length2 = (ca[0] - cb[0]).powi(2) + (ca[1] - cb[1]).powi(2) + (ca[2] - cb[2]).powi(2);
                let step = if dx != 0 && dy != 0 { std::f64::consts::SQRT_2 } else { 1.0 };
                let next = cost + length2.sqrt() + node_b.wide * step + node_b.stroke;
                if next < self.cost[b] {
                    if self.cost[b].is_infinite() {
                        self.touched.push(b);
                    }
                    self.cost[b] = next;
                    self.previous[b] = a as u32;
                    heap.push(Reverse((next.to_bits(), b as u32)));
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

/// The stroke term of Eq. 1, `alpha (D / (W/2))^2` for a node `D` pixels from the stroke in an image
/// `W` wide, is added to world distances between centres. As it is, the path's balance between the
/// stroke and the Gaussians depended on the scene's units: the real cases' scenes (a pixel's world
/// size 0.05-5 thousandths) weighed it 100 times apart, and in units 4 times larger 7 of the 14
/// cases met every target, with 9 misses, instead of 8 with 6. So where the focal length is known it is in
/// units of this many pixels' world size at the node's depth (docs/extraction.md, "Search").
pub(crate) const STROKE_TERM_PX: f64 = 3_000.0;

/// Per node: the stroke term of a step onto it (`STROKE_TERM_PX`), in world units where the focal
/// length is known, else as the paper has it.
fn stroke_term(image: &IndexImage, band: &Band, params: &TraceParams, depth: &[f32]) -> Vec<f64> {
    let half_width = image.width as f64 / 2.0;
    let focal = f64::from(params.focal_px);
    (0..band.len())
        .map(|node| {
            let deviation = f64::from(band.distance[node]) / half_width;
            let unit = if focal > 0.0 { STROKE_TERM_PX * f64::from(depth[node]) / focal } else { 1.0 };
            params.stroke_weight * unit * deviation * deviation
        })
        .collect()
}

/// Width walks from a band pixel reach this many radii (`WIDE_FROM + WIDE_CAP` and a little): what
/// lies in front of the object is seen through that far from the stroke.
pub(crate) const WALK_RADII: f32 = 8.0;

/// Nodes per chunk of the width walks, run in parallel: a run shares its width with the nodes of
/// its own chunk only, so a node next to a chunk's end may be walked itself. The chunks do not
/// depend on the number of threads, nor the result. On the bench rope (20,277 nodes) the walks
/// took 2.7 ms on one core and 1.7 on two; of the 112 case views' rods 9 moved, and none of
/// the cases' targets (docs/extraction.md, "Speed").
const WIDE_CHUNK: usize = 4096;

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
    let mut excess = vec![f32::NAN; band.len()];
    excess.par_chunks_mut(WIDE_CHUNK).enumerate().for_each_init(
        || (Walks::default(), Vec::new()),
        |(walks, run), (chunk, excess)| {
            let nodes = chunk * WIDE_CHUNK..chunk * WIDE_CHUNK + excess.len();
            for node in nodes.clone() {
                if !excess[node - nodes.start].is_nan() {
                    continue;
                }
                run.clear();
                let p = band.pixel[node] as usize;
                let normal = stroke.normal[band.segment[node] as usize];
                let e = walks.excess_width_run(image, p, normal, focal, params.radius, Some(run));
                excess[node - nodes.start] = e;
                for other in run.iter().filter_map(|&q| band.node(q)).filter(|other| nodes.contains(other)) {
                    if excess[other - nodes.start].is_nan() {
                        excess[other - nodes.start] = e;
                    }
                }
            }
        },
    );
    (0..band.len()).map(|node| WIDE_WEIGHT * f64::from(excess[node]) * f64::from(depth[node] / focal)).collect()
}

/// A part lying on a surface at its own depth (a sprinkle on icing, a rope on a floor) has no depth
/// edge beside it, and the surface measures as wide as the part there: only colour tells them
/// apart (docs/extraction.md, "A part lying on a surface"). The surface is what lies
/// `SURROUND_FROM_R` to `SURROUND_TO_R` radii across the stroke on both sides, where
/// `ON_SURFACE_SHARE` of those pixels lie at the part's depth: within the depth gap and
/// `SURFACE_SLOPE` times the lateral distance (a surface seen obliquely slopes away; at 1, a
/// sprinkle on the donut's side in sprinkle_13's az000, its surface 8 R in front and 10 R behind at
/// 3-5 R, had none). Or where `ONE_SIDE_SHARE` of one side's pixels do: a part lying at the edge
/// of what it lies on, seen against the background beyond it (sprinkle c's az000, on the icing's
/// silhouette: 94 % on one side, none on the other).
const SURROUND_FROM_R: f32 = 3.0;
const SURROUND_TO_R: f32 = 5.0;
const ON_SURFACE_SHARE: f32 = 0.5;
const ONE_SIDE_SHARE: f32 = 0.7;
const SURFACE_SLOPE: f32 = 2.0;
/// The two colours (`two_colours`) must lie this far apart (RGB, Euclidean).
const PART_APART: f32 = 0.25;
const CHROMA_APART: f32 = 0.1;
const TWO_COLOUR_ROUNDS: usize = 4;
/// The colours over `PART_APART` off the median of all must make up this share of them for
/// `two_colours` to start again from them: along a sprinkle's edge 28 %, a stand leg's highlights
/// against its dark paint 6 % (taken for a part, they sent a jittered rod 2.2 `R` off).
const FAR_SHARE: f32 = 0.15;
/// Power-iteration steps for the colours' principal axis (`principal_halves`).
const PRINCIPAL_ROUNDS: usize = 16;
/// Extra cost per pixel step onto a pixel nearer the surround's colour than the part's, in units of
/// a pixel's world size: four times a surface `WIDE_CAP` radii too wide. From a quarter to twice
/// that the sprinkles' numbers are the same (7 misses); without it, 10.
const SURROUND_COST: f64 = 4.0 * WIDE_WEIGHT * WIDE_CAP as f64;

/// The part's colour and the surround's (`two_colours`) where the part lies on a surface at its own
/// depth: half the pixels `SURROUND_FROM_R` to `SURROUND_TO_R` radii across the clean stroke, or
/// `ONE_SIDE_SHARE` of those on one side, show a surface within the depth gap and `SURFACE_SLOPE`
/// times the lateral distance of the part's depth. None where colours or the focal length are
/// unknown, the part is outlined against the background or what lies well behind it, or the two
/// colours are alike.
fn surface_colours(
    image: &IndexImage,
    band: &Band,
    stroke: &CleanStroke,
    params: &TraceParams,
    gap: f32,
) -> Option<SurfaceColours> {
    let focal = params.focal_px;
    if focal <= 0.0 || !image.has_colours() {
        return None;
    }
    // the pixels tried on each side, and those at the part's depth on each side; the colours of
    // those at the part's depth (`ring`) and of all shown there (`across`)
    let (mut ring, mut across, mut tried, mut at_depth) = (Vec::new(), Vec::new(), 0_usize, [0_usize; 2]);
    for ((p, n), &z) in stroke.points.iter().zip(&stroke.normal).zip(&stroke.depth) {
        let radius_px = params.radius * focal / z;
        let (from, to) = ((SURROUND_FROM_R * radius_px).ceil() as usize, (SURROUND_TO_R * radius_px) as usize);
        for step in from..=to {
            tried += 1;
            for (side, sign) in [1.0_f32, -1.0].into_iter().enumerate() {
                let t = sign * step as f32;
                let Some(q) = image.pixel_at(p[0] + t * n[0], p[1] + t * n[1]) else { continue };
                let within = gap + SURFACE_SLOPE * step as f32 * z / focal;
                let Some(colour) = image.colour(q).filter(|_| image.covered(q)) else { continue };
                across.push(colour);
                if (image.depth(q) - z).abs() <= within {
                    ring.push(colour);
                    at_depth[side] += 1;
                }
            }
        }
    }
    let both_sides = (at_depth[0] + at_depth[1]) as f32 >= ON_SURFACE_SHARE * (2 * tried) as f32;
    let one_side = at_depth.iter().any(|&count| count as f32 >= ONE_SIDE_SHARE * tried as f32);
    if ring.is_empty() || !(both_sides || one_side) {
        return None;
    }
    let near: Vec<[f32; 3]> = band.pixel.iter().filter_map(|&p| image.colour(p as usize)).collect();
    two_colours(&near, &ring, &across)
}

/// The part's colour and the surround's, from the colours near the stroke (`near`) and those
/// 3-5 `R` across it at the part's depth (`ring`): two clusters of both together (2-means from the
/// median of all and that of those well off it), the part's the one that makes up more of `near`
/// than of `across`, the colours 3-5 `R` across it at any depth. Not of `ring`: a surface's pixels
/// show the depth of the Gaussian that owns them, and a big icing Gaussian's centre can lie several
/// depth gaps behind where its surface is seen, while the sprinkles around keep small Gaussians at
/// their depth. A stroke moved a pixel over sprinkle_02, among others, had 46.1 % blue in its band
/// and 46.3 % in its ring, and took the icing for the part; 35 % of all shown across is blue
/// (docs/extraction.md, "A part lying on a surface", The part's colour is told across).
/// Neighbours of the part's colour beside it (other sprinkles) fall in the part's cluster but do not
/// decide which one it is; a stroke drawn mostly over the surround still has more of the part near
/// it than 3-5 `R` away. None where the clusters lie within `PART_APART` of each other.
/// Where the two colours are about as many, the median of all lies between them, every colour is
/// well off it, and so is their median: the 2-means from there leaves one cluster empty. It starts
/// again from the two sides of the median along the colours' principal axis (a jittered stroke over
/// a sprinkle found no colours so, and its rod ran over the icing, 4.9 `R` off). Where the clusters
/// found lie too near, they may be the surround's two shades, the part too few near the stroke to
/// pull one (a stroke along a sprinkle's edge): it starts once more from the median of the colours
/// over `PART_APART` off the median of all, where they are `FAR_SHARE` of them.
fn two_colours(near: &[[f32; 3]], ring: &[[f32; 3]], across: &[[f32; 3]]) -> Option<SurfaceColours> {
    let all: Vec<[f32; 3]> = near.iter().chain(ring).copied().collect();
    if near.is_empty() || ring.is_empty() {
        return None;
    }
    // from the median of all and that of the colours well off it
    let first = median_colour(&all);
    let off: Vec<[f32; 3]> = all.iter().copied().filter(|&c| colour_distance(c, first) > PART_APART / 2.0).collect();
    if off.is_empty() {
        return None;
    }
    let apart = |c: &[[f32; 3]; 2]| {
        colour_distance(c[0], c[1]) >= PART_APART && colour_distance(chroma(c[0]), chroma(c[1])) >= CHROMA_APART
    };
    let centres = two_means(&all, [first, median_colour(&off)])
        .or_else(|| principal_halves(&all, first).and_then(|start| two_means(&all, start)))
        .filter(apart)
        .or_else(|| {
            // the surround's two shades can split first where the part is few near the stroke (a
            // stroke along a sprinkle's edge): start again from the colours a part's apart, where
            // they are not a few highlights
            let far: Vec<[f32; 3]> = all.iter().copied().filter(|&c| colour_distance(c, first) > PART_APART).collect();
            let enough = !far.is_empty() && far.len() as f32 >= FAR_SHARE * all.len() as f32;
            enough.then(|| two_means(&all, [first, median_colour(&far)])).flatten().filter(apart)
        })?;
    let share = |colours: &[[f32; 3]]| {
        colours.iter().filter(|&&c| nearer(c, &centres) == 0).count() as f32 / colours.len().max(1) as f32
    };
    let (part, surround) = if share(near) > share(across) { (0, 1) } else { (1, 0) };
    Some(SurfaceColours { part: centres[part], surround: centres[surround] })
}

/// Which of the two `centres` colour `c` is nearer (0 on a tie).
fn nearer(c: [f32; 3], centres: &[[f32; 3]; 2]) -> usize {
    usize::from(colour_distance(c, centres[1]) < colour_distance(c, centres[0]))
}

/// The two clusters' centres after `TWO_COLOUR_ROUNDS` rounds of 2-means (with medians) over
/// `colours` from `centres`; None where a cluster empties.
fn two_means(colours: &[[f32; 3]], mut centres: [[f32; 3]; 2]) -> Option<[[f32; 3]; 2]> {
    for _ in 0..TWO_COLOUR_ROUNDS {
        let mut members: [Vec<[f32; 3]>; 2] = [Vec::new(), Vec::new()];
        for &c in colours {
            members[nearer(c, &centres)].push(c);
        }
        if members.iter().any(Vec::is_empty) {
            return None;
        }
        centres = [median_colour(&members[0]), median_colour(&members[1])];
    }
    Some(centres)
}

/// The medians of `colours` on either side of `centre` along their principal axis (their greatest
/// spread about `centre`, by power iteration); None where a side is empty or they do not spread.
fn principal_halves(colours: &[[f32; 3]], centre: [f32; 3]) -> Option<[[f32; 3]; 2]> {
    let offset = |c: &[f32; 3]| [c[0] - centre[0], c[1] - centre[1], c[2] - centre[2]];
    let mut spread = [[0.0_f32; 3]; 3];
    for d in colours.iter().map(offset) {
        for (row, &di) in spread.iter_mut().zip(&d) {
            for (cell, &dj) in row.iter_mut().zip(&d) {
                *cell += di * dj;
            }
        }
    }
    // from the channel that spreads most, so that the start is not square to the axis
    let widest = (0..3).max_by(|&a, &b| spread[a][a].total_cmp(&spread[b][b]))?;
    let mut axis = [0.0_f32; 3];
    axis[widest] = 1.0;
    for _ in 0..PRINCIPAL_ROUNDS {
        let next = spread.map(|row| row.iter().zip(&axis).map(|(a, b)| a * b).sum::<f32>());
        let norm = next.iter().map(|v| v * v).sum::<f32>().sqrt();
        if !(norm.is_finite() && norm > 0.0) {
            return None;
        }
        axis = next.map(|v| v / norm);
    }
    let (ahead, behind): (Vec<[f32; 3]>, Vec<[f32; 3]>) =
        colours.iter().partition(|c| offset(c).iter().zip(&axis).map(|(a, b)| a * b).sum::<f32>() > 0.0);
    (!ahead.is_empty() && !behind.is_empty()).then(|| [median_colour(&behind), median_colour(&ahead)])
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
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_parts_colour_is_the_one_nearer_the_stroke_than_3_to_5_radii_away() {
        let (orange, grey) = ([0.85, 0.55, 0.2], [0.5, 0.45, 0.4]);
        let mix = |orange_share: usize, of: usize| -> Vec<[f32; 3]> {
            (0..of).map(|k| if k < orange_share { orange } else { grey }.map(|c| c + 0.01 * (k % 3) as f32)).collect()
        };
        // the stroke on the part, a neighbour of its colour over most of the ring on one side
        let colours = two_colours(&mix(70, 100), &mix(55, 100), &mix(55, 100)).unwrap();
        assert!(colour_distance(colours.part, orange) < 0.05 && colour_distance(colours.surround, grey) < 0.05);
        // a stroke drawn mostly over the surface beside the part
        let colours = two_colours(&mix(40, 100), &mix(10, 100), &mix(10, 100)).unwrap();
        assert!(colour_distance(colours.part, orange) < 0.05, "{colours:?}");
        assert!(colours.is_surround([0.55, 0.45, 0.4]) && !colours.is_surround([0.8, 0.5, 0.25]));
        // colours alike: none
        let alike: Vec<[f32; 3]> = mix(50, 100).iter().map(|c| c.map(|v| 0.5 + 0.2 * (v - 0.5))).collect();
        assert_eq!(two_colours(&alike, &alike, &alike), None);
        // a lit side and a shaded side of one bark (the same hue, 0.4 apart in RGB): none
        let (lit, shaded) = ([0.95, 0.73, 0.29], [0.62, 0.5, 0.21]);
        let bark = |lit_share: usize| -> Vec<[f32; 3]> {
            (0..100).map(|k| if k < lit_share { lit } else { shaded }).collect()
        };
        assert_eq!(two_colours(&bark(70), &bark(30), &bark(30)), None);
    }

    #[test]
    fn two_colours_as_many_as_each_other_are_found() {
        // a blue sprinkle on pink icing, 80 colours of each: the median of all lies between them
        // (red 0.5), every colour is as far off it, and so is their median; the 2-means from those
        // two emptied a cluster and found no colours
        let (blue, pink) = ([0.2, 0.49, 0.78], [0.8, 0.57, 0.76]);
        let mix = |blue_share: usize| -> Vec<[f32; 3]> {
            (0..80).map(|k| if k < blue_share { blue } else { pink }).collect()
        };
        let colours = two_colours(&mix(50), &mix(30), &mix(30)).unwrap();
        assert!(
            colour_distance(colours.part, blue) < 0.01 && colour_distance(colours.surround, pink) < 0.01,
            "{colours:?}"
        );
        // and a highlight far off both does not take a cluster of its own
        let mut ring = mix(30);
        ring[79] = [1.0, 1.0, 1.0];
        let colours = two_colours(&mix(50), &ring, &ring).unwrap();
        assert!(
            colour_distance(colours.part, blue) < 0.01 && colour_distance(colours.surround, pink) < 0.01,
            "{colours:?}"
        );
    }

    #[test]
    fn the_parts_colour_is_told_by_all_shown_across_not_only_what_lies_at_its_depth() {
        // a blue sprinkle among others on pink icing whose big Gaussians' centres lie behind: near
        // the stroke 52 % blue; at the part's depth 3-5 R across, the other sprinkles' small
        // Gaussians and little icing, 54 % blue; shown there at any depth, 35 % blue
        let (blue, pink) = ([0.2, 0.48, 0.77], [0.8, 0.55, 0.75]);
        let mix = |blue_share: usize| -> Vec<[f32; 3]> {
            (0..100).map(|k| if k < blue_share { blue } else { pink }).collect()
        };
        let colours = two_colours(&mix(52), &mix(54), &mix(35)).unwrap();
        assert!(
            colour_distance(colours.part, blue) < 0.01 && colour_distance(colours.surround, pink) < 0.01,
            "{colours:?}"
        );
    }

    #[test]
    fn a_part_few_near_the_stroke_is_told_from_a_surround_of_two_shades() {
        // a stroke along a blue sprinkle's edge: 40 % of the colours near it are the sprinkle's,
        // the rest the icing's two shades (0.22 apart, less than two colours must be); the 2-means
        // from the median and that of those off it split the shades, and found no colours
        let mix = |palette: [[f32; 3]; 3], shares: [usize; 3]| -> Vec<[f32; 3]> {
            palette.iter().zip(shares).flat_map(|(&c, n)| std::iter::repeat_n(c, n)).collect()
        };
        let (blue, pink, light) = ([0.2, 0.49, 0.78], [0.79, 0.55, 0.75], [0.84, 0.76, 0.81]);
        let icing = [blue, pink, light];
        let colours =
            two_colours(&mix(icing, [40, 30, 30]), &mix(icing, [0, 55, 45]), &mix(icing, [0, 55, 45])).unwrap();
        assert!(
            colour_distance(colours.part, blue) < 0.01 && colours.is_surround(pink) && colours.is_surround(light),
            "{colours:?}"
        );
        // but a few highlights on a part of two dark shades are no part of their own
        let paint = [[0.13, 0.08, 0.06], [0.25, 0.2, 0.15], [0.45, 0.51, 0.38]];
        assert_eq!(two_colours(&mix(paint, [50, 40, 10]), &mix(paint, [60, 38, 2]), &mix(paint, [60, 38, 2])), None);
    }

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
