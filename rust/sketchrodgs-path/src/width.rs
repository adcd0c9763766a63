//! The object's width across the stroke (docs/extraction.md, "Widths"): from a pixel, walk both
//! ways along the stroke's normal over covered pixels (alpha >= 0.5 where alpha is known; one
//! failing pixel is stepped over), then keep the depth cluster of the start: the walked depths
//! split wherever consecutive values are more than `GAP_FLOOR_PX` pixels' world size apart. The
//! width is the run of pixels around the start that lie in that cluster. A round part's surface
//! and a flat bar seen obliquely (whose depth rises steadily across it, with the scatter of real
//! Gaussian centres) stay in one cluster; the scene behind the silhouette is a cluster of its own.
//! A leaf or body facing the camera at the part's depth continues, so it measures wide.

use crate::{GAP_FLOOR_PX, IndexImage};

/// This many failing pixels in a row end a walk.
const MAX_MISSES: usize = 1;
/// A pixel more than this many depth gaps from every depth its walk has seen fails: the walk ends
/// at the scene behind a silhouette instead of crossing it. Centres on one surface scatter by less.
const FAR_GAPS: f32 = 3.0;

/// A pixel is off the part's colour (`Walks::cross_width` with a colour) only where its hue differs
/// too, by this much in chroma (each colour over the sum of its channels): a capture's baked shading
/// changes a colour's brightness, not its hue. A tree branch's lit and shaded sides, (0.95, 0.73,
/// 0.29) and (0.62, 0.50, 0.21), lie 0.02 apart: by RGB alone a stroke over the middle half of the
/// centre branch in az060 measured its lit side, 0.30 of its radius (docs/extraction.md, "A part
/// lying on a surface", Shading is not a surface).
const CHROMA_OFF: f32 = 0.05;

/// Reusable buffers for measuring widths (one per thread): a trace measures thousands, and these
/// keep them from allocating. Each way holds the depth of every pixel walked, NaN where it failed,
/// and the pixel itself.
#[derive(Debug, Default)]
pub(crate) struct Walks {
    ways: [Vec<f32>; 2],
    pixels: [Vec<usize>; 2],
    /// Per way, how far behind the depths walked the walk first failed, where the part's silhouette
    /// bounds its width there: infinite where nothing is shown (or at the image's edge), the depth
    /// difference on a surface more than `FAR_GAPS` behind, and negative infinity where it failed
    /// otherwise (on a surface in front, or off the part's colour).
    silhouette_behind: [f32; 2],
}

impl Walks {
    /// Width in pixels of the surface at pixel `p` across the unit direction `normal`, walking at
    /// most `max_px` each way (then the width is `2 * max_px + 1`). With `colour` (the part's colour
    /// and how far off it may be, RGB Euclidean), pixels whose Gaussian's colour is farther off, and
    /// of another hue (`CHROMA_OFF`), fail as uncovered ones do: a part lying on a surface at its own
    /// depth (a rope on a floor, a sprinkle on icing) has no depth edge beside it.
    pub fn cross_width(
        &mut self,
        image: &IndexImage,
        p: usize,
        normal: [f32; 2],
        focal_px: f32,
        max_px: usize,
        colour: Option<([f32; 3], f32)>,
    ) -> usize {
        let gap = self.walk(image, p, normal, focal_px, max_px, colour);
        self.width(image.depth(p), gap, None)
    }

    /// Walks both ways from pixel `p` (see the module docs); returns the depth gap at its depth.
    fn walk(
        &mut self,
        image: &IndexImage,
        p: usize,
        normal: [f32; 2],
        focal_px: f32,
        max_px: usize,
        colour: Option<([f32; 3], f32)>,
    ) -> f32 {
        let off_colour = |q: usize| {
            colour.zip(image.colour(q)).is_some_and(|((a, off), b)| {
                colour_distance(a, b) > off && colour_distance(chroma(a), chroma(b)) > CHROMA_OFF
            })
        };
        let (col, row) = ((p % image.width) as f32 + 0.5, (p / image.width) as f32 + 0.5);
        let z0 = image.depth(p);
        let gap = GAP_FLOOR_PX * z0 / focal_px;
        let far = FAR_GAPS * gap;
        for (((walk, pixels), silhouette), sign) in
            self.ways.iter_mut().zip(&mut self.pixels).zip(&mut self.silhouette_behind).zip([1.0_f32, -1.0])
        {
            walk.clear();
            pixels.clear();
            *silhouette = f32::NEG_INFINITY;
            let (mut low, mut high, mut misses) = (z0, z0, 0);
            // no walk leaves the image later than this; where the stroke has no direction (a
            // zero normal) a walk stays on its pixel, and only its length in radii bounds it
            for k in 1..=max_px.min(image.width + image.height) {
                let (x, y) = (col + sign * k as f32 * normal[0], row + sign * k as f32 * normal[1]);
                let Some(q) = image.pixel_at(x, y) else {
                    if misses == 0 {
                        *silhouette = f32::INFINITY;
                    }
                    break;
                };
                pixels.push(q);
                if !image.known(q) {
                    // not rendered (a render of the band only): walk on, so that one more render
                    // holds all this walk can read; this result is discarded
                    walk.push(f32::NAN);
                    continue;
                }
                let z = image.depth(q);
                let in_reach = z >= low - far && z <= high + far;
                if image.covered(q) && in_reach && !off_colour(q) {
                    walk.push(z);
                    (low, high, misses, *silhouette) = (low.min(z), high.max(z), 0, f32::NEG_INFINITY);
                } else {
                    if misses == 0 {
                        // nothing shown, or a surface far behind: the part's silhouette either way
                        *silhouette = if !image.covered(q) {
                            f32::INFINITY
                        } else if z > high + far {
                            z - high
                        } else {
                            f32::NEG_INFINITY
                        };
                    }
                    walk.push(f32::NAN);
                    misses += 1;
                    if misses > MAX_MISSES {
                        break;
                    }
                }
            }
        }
        gap
    }

    /// How far behind the part the last walk's silhouette lies on its nearer side: infinite where
    /// nothing is shown on both sides (the part outlined against the background), negative
    /// infinity where either side is not a silhouette (`silhouette_behind`).
    pub fn outlined_behind(&self) -> f32 {
        self.silhouette_behind[0].min(self.silhouette_behind[1])
    }

    /// The last walk's width from silhouette to silhouette, where it has one on both sides (nothing
    /// shown, or a surface far behind) and every pixel it crossed before them shows a Gaussian of
    /// `colour` (the part's, and how far off it may be): then all it crossed is the part, whatever
    /// its depths (docs/extraction.md, "Radius", A flat bar's faces). None otherwise.
    pub fn outline_width(&self, image: &IndexImage, colour: ([f32; 3], f32)) -> Option<usize> {
        if !self.silhouette_behind.iter().all(|&behind| behind > 0.0) {
            return None;
        }
        let mut width = 1;
        for (walk, pixels) in self.ways.iter().zip(&self.pixels) {
            // up to the last pixel that passed: the failing ones after it are the silhouette
            let run = walk.iter().rposition(|z| !z.is_nan()).map_or(0, |k| k + 1);
            let of_the_part = |(z, &q): (&f32, &usize)| {
                z.is_nan() || image.colour(q).is_some_and(|c| colour_distance(c, colour.0) <= colour.1)
            };
            if !walk[..run].iter().zip(&pixels[..run]).all(of_the_part) {
                return None;
            }
            width += run;
        }
        Some(width)
    }

    /// The width of the last walk from a pixel at depth `z0`: the run around it in its depth
    /// cluster. The run's pixels in the cluster (the start left out) go into `run_pixels`, if given.
    fn width(&self, z0: f32, gap: f32, mut run_pixels: Option<&mut Vec<usize>>) -> usize {
        let ways = &self.ways;
        let (low, high) = depth_cluster(z0, || ways.iter().flatten().copied().filter(|z| !z.is_nan()), gap);
        let mut width = 1;
        for (walk, pixels) in ways.iter().zip(&self.pixels) {
            let (mut run, mut misses) = (0, 0);
            for (k, &z) in walk.iter().enumerate() {
                if (low..=high).contains(&z) {
                    (run, misses) = (k + 1, 0);
                } else {
                    misses += 1;
                    if misses > MAX_MISSES {
                        break;
                    }
                }
            }
            width += run;
            if let Some(out) = run_pixels.as_deref_mut() {
                out.extend((0..run).filter(|&k| (low..=high).contains(&walk[k])).map(|k| pixels[k]));
            }
        }
        width
    }

    /// By how many radii the surface at pixel `p` is wider across `normal` than `WIDE_FROM` radii
    /// (0 to `WIDE_CAP`), for a part of radius `radius` seen at focal length `focal_px`.
    pub fn excess_width(&mut self, image: &IndexImage, p: usize, normal: [f32; 2], focal_px: f32, radius: f32) -> f32 {
        self.excess_width_run(image, p, normal, focal_px, radius, None)
    }

    /// As `excess_width`, with the pixels of the surface's run across `normal` (other than `p`)
    /// added to `run`: the width measured from any of them along this line is about the same.
    pub fn excess_width_run(
        &mut self,
        image: &IndexImage,
        p: usize,
        normal: [f32; 2],
        focal_px: f32,
        radius: f32,
        run: Option<&mut Vec<usize>>,
    ) -> f32 {
        let radius_px = radius * focal_px / image.depth(p);
        let reach = ((WIDE_FROM + WIDE_CAP) * radius_px).ceil() as usize + 2;
        let gap = self.walk(image, p, normal, focal_px, reach, None);
        let width = self.width(image.depth(p), gap, run) as f32;
        (width / radius_px - WIDE_FROM).clamp(0.0, WIDE_CAP)
    }
}

/// The range of the cluster of `depths` that holds `start`: the values reachable from it in steps
/// of at most `gap` (as if sorted and split where neighbours are more than `gap` apart). Grown by
/// passes over the values, which are few and mostly in walking order, instead of a sort.
fn depth_cluster<I: Iterator<Item = f32>>(start: f32, depths: impl Fn() -> I, gap: f32) -> (f32, f32) {
    let (mut low, mut high) = (start, start);
    loop {
        let mut grew = false;
        for z in depths() {
            if z < low && low - z <= gap {
                (low, grew) = (z, true);
            } else if z > high && z - high <= gap {
                (high, grew) = (z, true);
            }
        }
        if !grew {
            return (low, high);
        }
    }
}

/// A round part is 2 radii wide; a surface wider than this many radii is not the part alone.
pub(crate) const WIDE_FROM: f32 = 3.5;
/// Widths past `WIDE_FROM` count up to this many radii.
pub(crate) const WIDE_CAP: f32 = 4.0;

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

/// The per-channel median of `colours` (which must be non-empty).
pub(crate) fn median_colour(colours: &[[f32; 3]]) -> [f32; 3] {
    let channel = |k: usize| median(&mut colours.iter().map(|c| c[k]).collect::<Vec<f32>>());
    [channel(0), channel(1), channel(2)]
}

/// The RGB Euclidean distance between two colours.
pub(crate) fn colour_distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>().sqrt()
}

/// `colour` over the sum of its channels (0.1 at least): its hue and saturation without its
/// brightness, which shading changes.
pub(crate) fn chroma(colour: [f32; 3]) -> [f32; 3] {
    let sum = colour.iter().sum::<f32>().max(0.1);
    colour.map(|c| c / sum)
}
