//! The band of pixels around the stroke, each labelled with its nearest depth-compatible stroke
//! segment (docs/extraction.md, "Search"). Band pixels become the nodes of the search graph.

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

    /// Whether `pixel` is labelled already with a segment at most `distance` away.
    fn labelled_within(&self, pixel: usize, distance: f32) -> bool {
        self.node(pixel).is_some_and(|node| self.distance[node] <= distance)
    }

    /// Label `pixel` with `segment` at `distance` (and `arc`) unless a segment at most as far has it:
    /// strict, so at a shared vertex the earlier segment keeps the pixel.
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

/// Calls `visit(pixel, t, d²)` for every pixel of segment `i`'s bounding box grown by `band_px`:
/// `t` the parameter of the nearest point on the segment to the pixel's centre, `d²` the squared
/// distance to it.
fn scan_segment(
    image: &IndexImage,
    stroke: &CleanStroke,
    i: usize,
    band_px: f32,
    mut visit: impl FnMut(usize, f32, f32),
) {
    let (a, b) = (stroke.points[i], stroke.points[i + 1]);
    let ab = [b[0] - a[0], b[1] - a[1]];
    let length2 = ab[0] * ab[0] + ab[1] * ab[1];
    let clip = |v: f32, size: usize| v.clamp(0.0, size as f32 - 1.0) as usize;
    let (x0, x1) =
        (clip(a[0].min(b[0]) - band_px - 1.0, image.width), clip(a[0].max(b[0]) + band_px + 1.0, image.width));
    let (y0, y1) =
        (clip(a[1].min(b[1]) - band_px - 1.0, image.height), clip(a[1].max(b[1]) + band_px + 1.0, image.height));
    for row in y0..=y1 {
        for col in x0..=x1 {
            let (px, py) = (col as f32 + 0.5 - a[0], row as f32 + 0.5 - a[1]);
            let t = if length2 > 0.0 { ((px * ab[0] + py * ab[1]) / length2).clamp(0.0, 1.0) } else { 0.0 };
            let (dx, dy) = (px - t * ab[0], py - t * ab[1]);
            visit(row * image.width + col, t, dx * dx + dy * dy);
        }
    }
}

/// Label each object pixel within `band_px` of the stroke with its nearest segment among those where
/// the object's expected depth (the clean stroke's depth, interpolated) is within `depth_gap` of the
/// pixel's `Z`. Each segment scans only its own bounding box.
pub(crate) fn label_band(image: &IndexImage, stroke: &CleanStroke, band_px: f32, depth_gap: f32) -> Band {
    let mut band = Band::empty(image.width * image.height);
    // surely beyond the band, without a square root (the margin covers the rounding)
    let beyond2 = band_px * band_px * 1.001 + 1e-6;
    for i in 0..stroke.segment_count() {
        scan_segment(image, stroke, i, band_px, |p, t, d2| {
            if d2 > beyond2 {
                return;
            }
            let d = d2.sqrt();
            // the image is read only where the label could change: the boxes overlap, and most
            // of a box lies beyond the band or nearer an earlier segment
            if d > band_px || band.labelled_within(p, d) {
                return;
            }
            if image.id_at(p) >= 0 && (image.depth(p) - stroke.depth_at(i, t)).abs() <= depth_gap {
                band.offer(p, i, d, stroke.arc_at(i, t));
            }
        });
    }
    band
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::stroke::clean_stroke;

    /// The labelling as first written: every pixel of each segment's box read, then judged.
    fn label_band_reading_every_pixel(image: &IndexImage, stroke: &CleanStroke, band_px: f32, gap: f32) -> Band {
        let mut band = Band::empty(image.width * image.height);
        for i in 0..stroke.segment_count() {
            scan_segment(image, stroke, i, band_px, |p, t, d2| {
                if image.id_at(p) < 0 || (image.depth(p) - stroke.depth_at(i, t)).abs() > gap {
                    return;
                }
                let d = d2.sqrt();
                if d <= band_px {
                    band.offer(p, i, d, stroke.arc_at(i, t));
                }
            });
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
