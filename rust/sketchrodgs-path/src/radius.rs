//! The radius from the image (docs/extraction.md, "Radius"): half the object's width across the
//! stroke (see `width`), in world units at its depth, the median over the stroke's samples on it.

use std::ops::Range;

use crate::search::WALK_RADII;
use crate::stroke::{CleanStroke, clean_stroke, on_background};
use crate::width::{Walks, colour_distance, median, median_colour};
use crate::{IndexImage, PathError, TraceParams};

/// The first radius is the median of the slender cluster of half-widths (`slender_cluster`): the
/// lowest run of them within this factor of its least that holds at least `CLUSTER_SHARE` of them.
/// At a fifth, a stroke starting along a stem's edge (8 narrow widths of 38, spread 2.6 x) made
/// that run, and the first `R` came out at 0.36 of the part's (docs/extraction.md, "Radius").
const CLUSTER_RATIO: f32 = 3.0;
const CLUSTER_SHARE: f32 = 0.25;
/// But a run within this factor that holds over this share of the widths is the part's, however
/// many narrower ones lie below it: a leg crossing in front of the stand's back foot cut 13 of its
/// 51 widths to 0.1-0.4 of the foot's, and those were the lowest run holding a quarter (the first
/// `R` 0.30 of the foot's, the estimate 0.39; docs/extraction.md, "Radius").
const MAJORITY_RATIO: f32 = 1.5;
const MAJORITY_SHARE: f32 = 0.5;
/// Where the two runs' samples meet along the stroke (3 samples: 9 px) is where their depths are
/// compared.
const NEIGHBOUR_SAMPLES: usize = 3;
/// Where the Gaussians' colours are known, the final widths are also measured stopping where the
/// colour is off the part's (`part_colour`: farther than `COLOUR_SPREADS` times the part's own
/// median spread, `COLOUR_OFF_LEAST` at least), and that median is the estimate where the plain one
/// is over `COLOUR_RATIO` times it: a part lying on a surface at its own depth (a rope on a floor,
/// a sprinkle on icing) has no depth edge beside it, and its plain widths run on over the surface
/// (3-7 x). Real parts' colours scatter (bark, shading), and the colour widths alone came out at
/// 0.5-0.7 of the plain ones on a twig and a sprinkle whose plain widths are right.
const COLOUR_SPREADS: f32 = 4.0;
const COLOUR_RATIO: f32 = 2.0;
const COLOUR_OFF_LEAST: f32 = 0.2;
/// The colour widths are not taken where at least this share of the plain walks end on both sides
/// where nothing is shown, or on a surface more than `OUTLINED_BEHIND_R` plain radii behind: the
/// part is outlined against the background, or against what lies well behind it, and its plain
/// widths are its silhouette's. A tree branch whose baked shading changes across it measured 2.3 x
/// narrower by colour (0.52 R) where 31 of its 46 walks were outlined against the background; a
/// branch in front of the trunk (23 R behind it), 0.5 x. A sprinkle on the icing has neither: its
/// walks run over the icing and may end on a surface a few radii behind it, not counted (any
/// threshold from 3 to 10 R gives the same real-capture numbers).
const OUTLINED_SHARE: f32 = 0.5;
const OUTLINED_BEHIND_R: f32 = 6.0;
/// A walk outlined in the part's colour on both sides is the part from silhouette to silhouette,
/// though its depths split in clusters: a flat bar seen obliquely shows two faces, and the centres
/// of their big Gaussians, which give the pixels' depths, lie more than the 8 px floor apart
/// (a stand leg's widths fell in two groups, 0.08-0.52 and 0.62-1.14 `R`). That width counts where
/// it is at most this many times the cluster's: a same-coloured surface outlined with the part (a
/// leaf behind a stem) is often wider. At 2 the stand legs' views stayed 1.50 and 1.56 x apart; at
/// 4, or without a bound, 10 and 9 of the turned views came out outside 0.7-1.4 x `R` instead of 7
/// (docs/extraction.md, "Radius", A flat bar's faces).
const OUTLINE_RATIO: usize = 3;

/// What [`estimate_radius`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadiusEstimate {
    /// `R`, in world units.
    pub radius: f32,
    /// The image came without the layers behind it, and with them the estimate might measure
    /// something else (a part behind leaves rather than the leaves): give them and estimate again.
    pub wants_behind: bool,
}

/// Estimate `R` from the object's visible width under `stroke`. `params.focal_px` must be > 0;
/// `params.radius` is ignored. Two passes: the widths under every sample give a first `R` (their
/// slender cluster: where leaves in front cover most of the stroke, their median is a leaf's), with
/// which the stroke is cleaned (`3R` depth gaps); the median width at the clean chain's samples is
/// the estimate, so samples over an occluder or past the object's end do not count.
pub fn estimate_radius(
    image: &IndexImage,
    stroke: &[[f32; 2]],
    params: &TraceParams,
) -> Result<RadiusEstimate, PathError> {
    let focal = params.focal_px;
    if !(focal.is_finite() && focal > 0.0) {
        return Err(PathError::BadParameter { name: "focal_px", value: f64::from(focal) });
    }
    let band_px = if params.band_px > 0.0 { params.band_px } else { TraceParams::default_band_px(image.width, 0.0) };
    let max_px = image.width.max(image.height) / 8;
    // pass 1: a loose clean-up (any depth) only to get the resampled, smoothed samples
    let loose = clean_stroke(image, stroke, band_px, f32::INFINITY, 0.0, None)?;
    let mut under: Vec<Option<usize>> =
        loose.points.iter().map(|p| image.pixel_at(p[0], p[1]).filter(|&q| image.covered(q))).collect();
    if under.iter().all(Option::is_none) {
        // a stroke along the part's silhouette, just off it: measure from the nearest covered pixel
        // within the band (the search reaches the part from there too)
        under = loose.points.iter().map(|&p| nearest_covered(image, p, band_px)).collect();
    }
    let (first, _) = half_widths(image, &loose, &under, focal, max_px, None, None);
    let gap_at = |r: f32| crate::depth_gap(image, stroke, r, focal);
    let Some(rough) = slender_cluster(&first, gap_at) else { return Err(on_background(image, stroke)) };
    // pass 2: the depth-consistent chain at that radius
    let gap = gap_at(rough);
    // Whether the chain runs behind what is in front is decided as the search decides it, with
    // surfaces much wider than the first estimate scoring lower (docs/extraction.md, "What lies
    // behind"): a part seen behind leaves is then measured rather than the leaves. Where it stays
    // in front, the chain is the plain one.
    let slender = clean_stroke(image, stroke, band_px, gap, focal, Some(rough))?;
    let wants_behind = slender.wants_behind;
    let clean = if slender.behind { slender } else { clean_stroke(image, stroke, band_px, gap, focal, None)? };
    // what lies more than the gap in front of the chain is seen through (as the search does)
    let rough_px = crate::depth_under(image, stroke).map_or(0.0, |z| rough * focal / z);
    let floors = clean.floors(image, gap, band_px + WALK_RADII * rough_px);
    let image = &image.seen_from_cells(&floors);
    // measure from the pixel under the sample where it is on the chain's surface, else from the
    // surface's pixel nearest the sample
    let anchors: Vec<Option<usize>> = clean
        .anchor
        .iter()
        .zip(&clean.points)
        .map(|(a, p)| {
            let a = (*a)?;
            let under = image
                .pixel_at(p[0], p[1])
                .filter(|&q| image.covered(q) && (image.depth(q) - image.depth(a)).abs() <= rough);
            under.or(Some(a).filter(|&q| image.covered(q)))
        })
        .collect();
    // the part's colour, where the Gaussians' colours are known: the median at the anchors
    let colour = part_colour(image, &anchors);
    let median_width = |widths: Vec<[f32; 2]>| median(&mut widths.iter().map(|w| w[0]).collect::<Vec<f32>>());
    let (widths, behind) = half_widths(image, &clean, &anchors, focal, max_px, None, colour);
    let mut radius = if widths.is_empty() { rough } else { median_width(widths) };
    let outlined = behind.iter().filter(|&&b| b > OUTLINED_BEHIND_R * radius).count();
    let outlined_share = outlined as f32 / behind.len().max(1) as f32;
    if let Some(colour) = colour.filter(|_| outlined_share < OUTLINED_SHARE) {
        let (in_colour, _) = half_widths(image, &clean, &anchors, focal, max_px, Some(colour), None);
        let by_colour = if in_colour.is_empty() { radius } else { median_width(in_colour) };
        if radius > COLOUR_RATIO * by_colour {
            radius = by_colour;
        }
    }
    Ok(RadiusEstimate { radius, wants_behind })
}

/// The covered pixel nearest `point` within `reach` pixels, if any.
fn nearest_covered(image: &IndexImage, point: [f32; 2], reach: f32) -> Option<usize> {
    let steps = reach.ceil() as i64;
    let (cx, cy) = (point[0].floor() as i64, point[1].floor() as i64);
    let mut best: Option<(f32, usize)> = None;
    for row in (cy - steps).max(0)..=(cy + steps).min(image.height as i64 - 1) {
        for col in (cx - steps).max(0)..=(cx + steps).min(image.width as i64 - 1) {
            let (dx, dy) = (col as f32 + 0.5 - point[0], row as f32 + 0.5 - point[1]);
            let d = (dx * dx + dy * dy).sqrt();
            let q = row as usize * image.width + col as usize;
            if d <= reach && best.is_none_or(|(bd, _)| d < bd) && image.covered(q) {
                best = Some((d, q));
            }
        }
    }
    best.map(|(_, q)| q)
}

/// The half-widths in world units at the samples that have a pixel (walks stopping where the
/// colour is off `colour`, if given), each with that pixel's depth, and for each how far behind
/// the part its walk's silhouette lies on both sides (`Walks::outlined_behind`). With `outline`
/// (the part's colour), a walk outlined in that colour takes its width between the silhouettes
/// where that is at most `OUTLINE_RATIO` times its depth cluster's (`Walks::outline_width`).
fn half_widths(
    image: &IndexImage,
    stroke: &CleanStroke,
    pixels: &[Option<usize>],
    focal: f32,
    max_px: usize,
    colour: Option<([f32; 3], f32)>,
    outline: Option<([f32; 3], f32)>,
) -> (Vec<[f32; 2]>, Vec<f32>) {
    let mut walks = Walks::default();
    let mut behind = Vec::new();
    let widths: Vec<[f32; 2]> = pixels
        .iter()
        .zip(&stroke.normal)
        .filter_map(|(p, n)| p.filter(|_| n != &[0.0, 0.0]).map(|p| (p, n)))
        .map(|(p, &n)| {
            let mut width = walks.cross_width(image, p, n, focal, max_px, colour);
            if let Some(outlined) = outline.and_then(|c| walks.outline_width(image, c))
                && outlined <= OUTLINE_RATIO * width
            {
                width = width.max(outlined);
            }
            behind.push(walks.outlined_behind());
            let z = image.depth(p);
            [0.5 * width as f32 * z / focal, z]
        })
        .collect();
    (widths, behind)
}

/// The part's colour and how far from it a Gaussian of the part may be: the per-channel median of
/// the colours of the Gaussians at `pixels`, and `COLOUR_SPREADS` times the median distance of
/// those colours from it (`COLOUR_OFF_LEAST` at least); None without colours.
fn part_colour(image: &IndexImage, pixels: &[Option<usize>]) -> Option<([f32; 3], f32)> {
    let colours: Vec<[f32; 3]> = pixels.iter().filter_map(|p| image.colour((*p)?)).collect();
    if colours.is_empty() {
        return None;
    }
    let centre = median_colour(&colours);
    let mut off: Vec<f32> = colours.iter().map(|&c| colour_distance(c, centre)).collect();
    let spread = median(&mut off);
    Some((centre, (COLOUR_SPREADS * spread).max(COLOUR_OFF_LEAST)))
}

/// The first radius: the median of the part's cluster of half-widths, given in stroke order, each
/// with the depth where it was measured. That is the lowest run of them spanning at most
/// `CLUSTER_RATIO` (from its least) that holds `CLUSTER_SHARE` of them, at least 3: the part's
/// widths, where wider things under the stroke (leaves over a stem, seen from below) outnumber
/// them. But the fullest run within `MAJORITY_RATIO` is the part's where it holds `MAJORITY_SHARE`
/// of them, lies wholly above the lowest run (widths spread evenly are one part's), and does not lie
/// in front of it (`in_front`, by `gap(R)`, `R` the lowest run's): then the lowest are cut short by
/// something thin in front of the part, while a majority in front is the leaf that hides it. The
/// median of all where no run holds enough; None for none.
fn slender_cluster(widths: &[[f32; 2]], gap: impl Fn(f32) -> f32) -> Option<f32> {
    let mut order: Vec<usize> = (0..widths.len()).collect();
    order.sort_by(|&a, &b| widths[a][0].total_cmp(&widths[b][0]));
    let width = |k: usize| widths[order[k]][0];
    let need = |share: f32| ((share * widths.len() as f32).ceil() as usize).max(3);
    let run_from = |k: usize, ratio: f32| k..order.partition_point(|&i| widths[i][0] <= width(k) * ratio);
    let median_width =
        |run: &Range<usize>| median(&mut order[run.clone()].iter().map(|&i| widths[i][0]).collect::<Vec<f32>>());
    let lowest = (0..order.len())
        .map(|k| run_from(k, CLUSTER_RATIO))
        .find(|run| width(run.start) > 0.0 && run.len() >= need(CLUSTER_SHARE));
    let fullest = (0..order.len())
        .map(|k| run_from(k, MAJORITY_RATIO))
        .max_by_key(|run| (run.len(), usize::MAX - run.start))
        .filter(|run| width(run.start) > 0.0 && run.len() >= need(MAJORITY_SHARE));
    match (lowest, fullest) {
        (Some(low), Some(full))
            if low.end <= full.start
                && !in_front(widths, &order[full.clone()], &order[low.clone()], gap(median_width(&low))) =>
        {
            Some(median_width(&full))
        }
        (Some(low), _) => Some(median_width(&low)),
        // (a majority is a run of a quarter too)
        (None, _) if widths.is_empty() => None,
        (None, _) => Some(median_width(&(0..order.len()))),
    }
}

/// Whether the samples `front` (indices into `widths`, in stroke order) lie more than `gap` in front
/// of the samples `back`: the median, over the samples of `back` with one of `front` within
/// `NEIGHBOUR_SAMPLES` along the stroke, of the nearest one's depth less theirs, is below `-gap`.
/// Compared where they meet, since a part may recede steeply along the stroke. None meeting: false.
fn in_front(widths: &[[f32; 2]], front: &[usize], back: &[usize], gap: f32) -> bool {
    let mut steps: Vec<f32> = back
        .iter()
        .filter_map(|&i| {
            let nearest =
                front.iter().copied().min_by_key(|j| j.abs_diff(i)).filter(|j| j.abs_diff(i) <= NEIGHBOUR_SAMPLES)?;
            Some(widths[nearest][1] - widths[i][1])
        })
        .collect();
    !steps.is_empty() && median(&mut steps) < -gap
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::slender_cluster;

    #[test]
    fn the_slender_cluster_is_the_parts_widths_not_a_short_narrow_run() {
        // half-widths (1e-4) under the capture-size bench's stroke, which starts along the stem's
        // edge: 8 narrow ones (7 there), the stem's (65-72), leaves and their edges
        let widths: Vec<[f32; 2]> = [
            39, 39, 45, 26, 21, 17, 17, 65, 65, 65, 65, 403, 58, 92, 65, 26, 71, 142, 187, 213, 232, 244, 251, 296,
            250, 66, 72, 72, 72, 66, 85, 143, 137, 182, 483, 124, 72, 221,
        ]
        .iter()
        .map(|&w| [w as f32, 1000.0])
        .collect();
        let rough = slender_cluster(&widths, |r| 3.0 * r).unwrap();
        assert!((60.0..=75.0).contains(&rough), "{rough}");
        // where the part's widths are a quarter of them, the wider things in front are left out,
        // though most of them lie within 1.5 x of each other
        let under_leaves: Vec<[f32; 2]> = (0..40)
            .map(|i| if i % 4 == 0 { [10.0 + (i % 3) as f32, 100.0] } else { [40.0 + i as f32, 50.0] })
            .collect();
        let rough = slender_cluster(&under_leaves, |r| 3.0 * r).unwrap();
        assert!((10.0..=12.0).contains(&rough), "{rough}");
    }

    #[test]
    fn a_majority_of_the_widths_within_one_and_a_half_times_is_the_parts() {
        // half-widths (1e-3) under the stroke along the stand's back foot (held-out, az090): a leg
        // crossing in front cuts 10 of them in a row, and the walks pick up scattered small ones
        let widths: Vec<[f32; 2]> = [
            58, 63, 70, 67, 14, 42, 52, 60, 59, 57, 55, 18, 24, 22, 17, 15, 4, 21, 23, 23, 25, 60, 58, 66, 17, 64, 56,
            2, 4, 10, 59, 16, 55, 70, 43, 34, 45, 76, 61, 61, 67, 71, 29, 16, 53, 66, 69, 69, 73, 71, 80,
        ]
        .iter()
        .enumerate()
        .map(|(i, &w)| [w as f32, 1000.0 - 5.0 * i as f32])
        .collect();
        let rough = slender_cluster(&widths, |r| 3.0 * r).unwrap();
        assert!((55.0..=70.0).contains(&rough), "{rough}");
        // a majority in front of the narrow ones is what hides the part (a leaf), not the part
        let in_front: Vec<[f32; 2]> = widths.iter().map(|&[w, z]| [w, if w > 50.0 { z - 200.0 } else { z }]).collect();
        let rough = slender_cluster(&in_front, |r| 3.0 * r).unwrap();
        assert!(rough < 30.0, "{rough}");
        // without the majority (a third of the foot's widths taken away), the lowest run of a
        // quarter is taken, as for a stem seen through its leaves
        let fewer: Vec<[f32; 2]> = widths.iter().copied().filter(|&[w, _]| !(53.0..=66.0).contains(&w)).collect();
        let rough = slender_cluster(&fewer, |r| 3.0 * r).unwrap();
        assert!(rough < 30.0, "{rough}");
        // widths spread evenly (a sprinkle, 1e-5), half of them within 1.5 x of each other: the
        // lowest run reaches into that half, and is taken
        let even: Vec<[f32; 2]> = [24, 34, 39, 34, 31, 17, 22, 41, 27, 51, 61, 51, 49, 46, 41, 15, 51, 49]
            .iter()
            .map(|&w| [w as f32, 1000.0])
            .collect();
        let rough = slender_cluster(&even, |r| 3.0 * r).unwrap();
        assert!((30.0..=35.0).contains(&rough), "{rough}");
    }
}
