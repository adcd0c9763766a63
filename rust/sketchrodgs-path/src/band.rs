//! The band of pixels around the stroke, each labelled with its nearest depth-compatible stroke
//! segment (docs/extraction.md, "Search"). Band pixels become the nodes of the search graph.

use rayon::prelude::*;

use crate::IndexImage;
use crate::stroke::CleanStroke;

/// No node at this pixel.
pub(crate) const NO_NODE: u32 = u32::MAX;

/// The labelled band, stored per node (band pixel) so the search touches only band memory.
pub(crate) struct Band {
    /// Node of each pixel (`NO_NODE` outside the band); the only image-sized array.
    pub node_of_pixel: Vec<u32>,
    /// Pixel (flat index) of each node.
    pub pixel: Vec<u32>,
    /// Stroke segment of each node.
    pub segment: Vec<u32>,
    /// Distance in pixels from the pixel centre to that segment.
    pub distance: Vec<f32>,
    /// Arc length along the clean stroke at (segment, t), in pixels.
    pub arc: Vec<f32>,
}

impl Band {
    fn empty(pixels: usize) -> Self {
        Self {
            node_of_pixel: vec![NO_NODE; pixels],
            pixel: Vec::new(),
            segment: Vec::new(),
            distance: Vec::new(),
            arc: Vec::new(),
        }
    }

    pub fn node(&self, pixel: usize) -> Option<usize> {
        let node = self.node_of_pixel[pixel];
        (node != NO_NODE).then_some(node as usize)
    }

    pub fn len(&self) -> usize {
        self.pixel.len()
    }

    /// Label `pixel` with `segment` at `distance` (and `arc`) unless a segment at most as far has it:
    /// strict, so at a shared vertex the earlier segment keeps the pixel (the plain scan of the tests).
    #[cfg(test)]
    fn offer(&mut self, pixel: usize, segment: usize, distance: f32, arc: f32) {
        match self.node(pixel) {
            None => {
                self.node_of_pixel[pixel] = self.pixel.len() as u32;
                self.pixel.push(pixel as u32);
                self.segment.push(segment as u32);
                self.distance.push(distance);
                self.arc.push(arc);
            }
            Some(node) if distance < self.distance[node] => {
                self.segment[node] = segment as u32;
                self.distance[node] = distance;
                self.arc[node] = arc;
            }
            Some(_) => {}
        }
    }
}

/// The parameter `t` of the nearest point on the segment from `a` along `ab` (`length2` its squared
/// length) to the centre of pixel (`row`, `col`), and the squared distance to it.
fn nearest_on_segment(a: [f32; 2], ab: [f32; 2], length2: f32, row: usize, col: usize) -> (f32, f32) {
    let (px, py) = (col as f32 + 0.5 - a[0], row as f32 + 0.5 - a[1]);
    let t = if length2 > 0.0 { ((px * ab[0] + py * ab[1]) / length2).clamp(0.0, 1.0) } else { 0.0 };
    let (dx, dy) = (px - t * ab[0], py - t * ab[1]);
    (t, dx * dx + dy * dy)
}

/// A coordinate clamped into `0..size` pixels.
fn clip(v: f32, size: usize) -> usize {
    v.clamp(0.0, size as f32 - 1.0) as usize
}

/// The pixels (first and last column and row, inclusive) of the box `low` to `high` grown by
/// `band_px` and a pixel, within the image.
fn grown_box(image: &IndexImage, low: [f32; 2], high: [f32; 2], band_px: f32) -> ([usize; 2], [usize; 2]) {
    let reach = band_px + 1.0;
    (
        [clip(low[0] - reach, image.width), clip(low[1] - reach, image.height)],
        [clip(high[0] + reach, image.width), clip(high[1] + reach, image.height)],
    )
}

/// Calls `visit(row, col, t, d²)` for the pixels in `rows` within `band_px` of segment `i` (and a
/// few beyond), with `t` and `d²` as `nearest_on_segment` gives them. Each row is scanned over
/// the columns the band can reach there, a third fewer pixels than the segment's grown box.
fn scan_segment(
    image: &IndexImage,
    stroke: &CleanStroke,
    i: usize,
    band_px: f32,
    rows: std::ops::Range<usize>,
    mut visit: impl FnMut(usize, usize, f32, f32),
) {
    let (a, b) = (stroke.points[i], stroke.points[i + 1]);
    let ab = [b[0] - a[0], b[1] - a[1]];
    let length2 = ab[0] * ab[0] + ab[1] * ab[1];
    let (low, high) = ([a[0].min(b[0]), a[1].min(b[1])], [a[0].max(b[0]), a[1].max(b[1])]);
    let ([x0, y0], [x1, y1]) = grown_box(image, low, high, band_px);
    // a pixel within `reach` of the segment lies within `reach` of its rows' span across, and so
    // within sqrt(reach² - dy²) of its columns' span along the row (a pixel of margin for rounding)
    let reach = band_px + 1.0;
    for row in y0.max(rows.start)..=y1.min(rows.end.saturating_sub(1)) {
        let centre = row as f32 + 0.5;
        let dy = (low[1] - centre).max(centre - high[1]).max(0.0);
        if dy > reach {
            continue;
        }
        let half = (reach * reach - dy * dy).sqrt() + 1.0;
        let (from, to) = (clip(low[0] - half - 0.5, image.width).max(x0), clip(high[0] + half, image.width).min(x1));
        for col in from..=to {
            let (t, d2) = nearest_on_segment(a, ab, length2, row, col);
            visit(row, col, t, d2);
        }
    }
}

/// Rows per strip of the band's labelling: strips are labelled in parallel.
const STRIP_ROWS: usize = 16;

/// A pixel's label while strips are labelled: its nearest segment so far, the distance and arc
/// there, and the first segment that labelled it (which orders the nodes).
#[derive(Clone, Copy)]
struct Label {
    segment: u32,
    first: u32,
    distance: f32,
    arc: f32,
}

const UNLABELLED: Label = Label { segment: u32::MAX, first: u32::MAX, distance: f32::INFINITY, arc: 0.0 };

/// Label each object pixel within `band_px` of the stroke with its nearest segment among those where
/// the object's expected depth (the clean stroke's depth, interpolated) is within `depth_gap` of the
/// pixel's `Z`; at equal distances the earlier segment. Each segment scans only its own bounding
/// box. Nodes are numbered as a scan of segment after segment would number them on first
/// labelling: by that first segment, then by pixel (the search breaks cost ties by node). Strips of
/// rows are labelled in parallel, each taking the segments in order.
pub(crate) fn label_band(image: &IndexImage, stroke: &CleanStroke, band_px: f32, depth_gap: f32) -> Band {
    let width = image.width;
    // surely beyond the band, without a square root (the margin covers the rounding)
    let beyond2 = band_px * band_px * 1.001 + 1e-6;
    // the rows and columns any segment's box reaches
    let (mut low, mut high) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in &stroke.points {
        (low, high) = ([low[0].min(p[0]), low[1].min(p[1])], [high[0].max(p[0]), high[1].max(p[1])]);
    }
    let ([x0, y0], [x1, y1]) = grown_box(image, low, high, band_px);
    let span = x1 + 1 - x0;
    let strips: Vec<Vec<(usize, Label)>> = (y0..=y1)
        .step_by(STRIP_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|start| {
            let rows = start..(start + STRIP_ROWS).min(y1 + 1);
            let mut labels = vec![UNLABELLED; rows.len() * span];
            for i in 0..stroke.segment_count() {
                scan_segment(image, stroke, i, band_px, rows.clone(), |row, col, t, d2| {
                    if d2 > beyond2 {
                        return;
                    }
                    let d = d2.sqrt();
                    // the image is read only where the label could change: the boxes overlap, and
                    // most of a box lies beyond the band or nearer an earlier segment
                    let label = &mut labels[(row - rows.start) * span + col - x0];
                    if d > band_px || label.distance <= d {
                        return;
                    }
                    let p = row * width + col;
                    if image.id_at(p) >= 0 && (image.depth(p) - stroke.depth_at(i, t)).abs() <= depth_gap {
                        let first = if label.segment == u32::MAX { i as u32 } else { label.first };
                        *label = Label { segment: i as u32, first, distance: d, arc: stroke.arc_at(i, t) };
                    }
                });
            }
            let pixel = |k: usize| (rows.start + k / span) * width + x0 + k % span;
            labels.iter().enumerate().filter(|(_, l)| l.segment != u32::MAX).map(|(k, &l)| (pixel(k), l)).collect()
        })
        .collect();
    // number the nodes by first segment, then pixel: a counting sort of the pixels in order
    let mut starts = vec![0usize; stroke.segment_count() + 1];
    for &(_, label) in strips.iter().flatten() {
        starts[label.first as usize + 1] += 1;
    }
    for k in 1..starts.len() {
        starts[k] += starts[k - 1];
    }
    let count = starts[starts.len() - 1];
    let mut band = Band::empty(width * image.height);
    (band.pixel, band.segment, band.distance, band.arc) =
        (vec![0; count], vec![0; count], vec![0.0; count], vec![0.0; count]);
    for &(p, label) in strips.iter().flatten() {
        let node = starts[label.first as usize];
        starts[label.first as usize] += 1;
        band.node_of_pixel[p] = node as u32;
        band.pixel[node] = p as u32;
        band.segment[node] = label.segment;
        band.distance[node] = label.distance;
        band.arc[node] = label.arc;
    }
    band
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::stroke::clean_stroke;

    /// The labelling as first written, over every pixel of the image for each segment, read and
    /// judged, segment after segment.
    fn label_band_reading_every_pixel(image: &IndexImage, stroke: &CleanStroke, band_px: f32, gap: f32) -> Band {
        let mut band = Band::empty(image.width * image.height);
        for i in 0..stroke.segment_count() {
            let (a, b) = (stroke.points[i], stroke.points[i + 1]);
            let ab = [b[0] - a[0], b[1] - a[1]];
            for p in 0..image.width * image.height {
                let (row, col) = (p / image.width, p % image.width);
                let (t, d2) = nearest_on_segment(a, ab, ab[0] * ab[0] + ab[1] * ab[1], row, col);
                if image.id_at(p) < 0 || (image.depth(p) - stroke.depth_at(i, t)).abs() > gap {
                    continue;
                }
                let d = d2.sqrt();
                if d <= band_px {
                    band.offer(p, i, d, stroke.arc_at(i, t));
                }
            }
        }
        band
    }

    #[test]
    fn the_band_is_the_one_got_by_reading_every_pixel() {
        // a wavy rope at depth 5 crossing a bar at depth 3 in front, on an image with holes; a
        // stroke that wanders off the rope and back, with fractional band widths
        let (width, height) = (96, 64);
        let mut index = vec![-1; width * height];
        let mut depth = vec![0.0f32; width * height];
        for row in 0..height {
            for col in 0..width {
                let centre = 32.0 + 8.0 * (col as f32 / 9.0).sin();
                let p = row * width + col;
                if (40..46).contains(&col) {
                    (index[p], depth[p]) = (p as i32, 3.0);
                } else if (row as f32 - centre).abs() < 3.5 && (col * 7 + row) % 11 != 0 {
                    (index[p], depth[p]) = (p as i32, 5.0 + 0.01 * col as f32);
                }
            }
        }
        let image = IndexImage::new(width, height, &index, &depth).unwrap();
        let stroke: Vec<[f32; 2]> = (0..40)
            .map(|k| 2.0 + 2.3 * k as f32)
            .map(|x| [x, 32.0 + 9.0 * (x / 9.0).sin() + (x * 1.7).cos()])
            .collect();
        for band_px in [2.5, 6.0, 9.6] {
            let clean = clean_stroke(&image, &stroke, band_px, 0.3, 100.0, None).unwrap();
            let (ours, reference) = (
                label_band(&image, &clean, band_px, 0.3),
                label_band_reading_every_pixel(&image, &clean, band_px, 0.3),
            );
            assert!(ours.len() > 100);
            assert_eq!(ours.node_of_pixel, reference.node_of_pixel);
            assert_eq!(ours.pixel, reference.pixel);
            assert_eq!(ours.segment, reference.segment);
            assert_eq!(
                ours.distance.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                reference.distance.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
            );
            assert_eq!(
                ours.arc.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                reference.arc.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
            );
        }
    }
}
