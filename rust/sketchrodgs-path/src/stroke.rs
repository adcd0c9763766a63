//! Stroke clean-up (docs/extraction.md, "Stroke clean-up"): the stroke is clipped to the image,
//! resampled densely and smoothed, and the depth it follows is chosen globally: the chain of
//! stroke samples whose depths agree, where the allowed depth change grows with the distance
//! along the stroke. No single sample decides, the stroke's direction does not matter, and ends
//! that overshoot the object (onto background or a neighbour) are trimmed instead of refused.

use std::cmp::Reverse;
use std::collections::BTreeSet;

use rayon::prelude::*;

use crate::width::{WIDE_CAP, Walks, median, normals};
use crate::{FLOOR_CELL, IndexImage, PathError};

/// Spacing of the resampled stroke, in pixels.
const SAMPLE_PX: f32 = 3.0;
/// Points this many apart measure the step between a stroke's points, for its noise
/// (`averaged_over_noise`): far enough apart that the noise adds little to their distance.
const NOISE_STEP_SPAN: usize = 8;
/// A stroke of fewer points does not measure its noise (a few second differences, most of them
/// the stroke's own bends): a stroke of a few points drawn by hand stays as it is.
const NOISE_MIN_POINTS: usize = 16;
/// A stroke is averaged where its noise exceeds this share of the step between its points ...
const NOISE_ONSET: f64 = 0.5;
/// ... over a standard deviation of about this many times its noise, in pixels along the stroke ...
const NOISE_WINDOW: f64 = 3.0;
/// ... and of at most this many points.
const NOISE_MAX_POINTS: f64 = 64.0;
/// Standard deviation of the Gaussian smoothing along the stroke, in pixels of arc. It takes out
/// hand jitter between the points a user drew; curves of the object are far wider than this.
const SMOOTH_SIGMA_PX: f32 = 6.0;
/// At most this many visible depth candidates per sample (the nearest surfaces to it), and as many
/// behind them.
const MAX_CANDIDATES: usize = 4;
/// A surface seen only behind another (a stem behind a leaf) scores this share of a visible one:
/// where both make a chain as long, the visible one is taken.
const HIDDEN_SCORE: f32 = 0.9;
/// The visible chain gives way to its rival at another depth under the same stroke where the rival
/// scores at least this share of it ... (`closer_rival`)
const RIVAL_SHARE: f32 = 0.8;
/// ... and its members lie this much nearer the stroke's samples on average (`Candidate::near`), and
/// score this much more (the score also counts how slender): the stroke follows it more closely.
const RIVAL_NEARER: f32 = 0.05;
/// The chain may run behind the front only where that scores this share more than the chain over
/// the visible surfaces alone.
const BEHIND_GAIN: f32 = 0.15;
/// ... and only where, cut to its first and last visible members, it spans this many radii on
/// screen at least: a shorter path makes a rod too short to extract (Polyline: at least 2 R).
const BEHIND_SPAN_R: f32 = 2.0;
/// ... or where it scores `BEHIND_GAIN` more over a stretch of at least this many radii on screen
/// in the middle, where the two chains differ (`gains_where_they_differ`).
const HIDDEN_STRETCH_R: f32 = 4.0;
/// Depth may change by this much per unit of lateral distance along the stroke between two chain
/// samples, on top of `3R`. It matters where the chain skips samples (over an occluder): between
/// neighbouring samples `3R` alone already follows a steeply receding part.
const DEPTH_SLOPE: f32 = 1.0;
/// Share of a surface's score lost when it is `WIDE_CAP` radii wider across the stroke than
/// `WIDE_FROM` (in proportion below that): the chain prefers the slender part to a leaf or body
/// beside it at a similar depth. Scores stay positive, so a wide stretch is still followed where
/// nothing slender competes (a part in front of a body measures wide there).
const WIDE_SCORE: f32 = 0.5;
/// An end run of the chain in front of the rest is an occluder the stroke ran on past the part's
/// end (`cut_occluder_ends`) if it spans at most this share of the chain's arc, lies on surfaces on
/// average `OCCLUDER_WIDE` radii wider than `WIDE_FROM`, and is joined by a step over the depth gap
/// or somewhere reaches `OCCLUDER_LEAF` radii wider (a leaf or body; `WIDE_CAP` is 4).
const OCCLUDER_END_SHARE: f32 = 0.15;
const OCCLUDER_WIDE: f32 = 0.5;
const OCCLUDER_LEAF: f32 = 3.5;
/// An end run in front on surfaces whose median is this many radii wider than `WIDE_FROM` is a leaf
/// sloping away in front of the part wherever it is joined, and is cut if it spans at most
/// `OCCLUDER_BROAD_SHARE` of the chain's arc (a stem seen from below, passing behind a leaf at its
/// end). A twig's fork measures less than half as wide.
const OCCLUDER_BROAD: f32 = 2.0;
const OCCLUDER_BROAD_SHARE: f32 = 0.5;
/// An end run from a step over the depth gap within `OCCLUDER_SHORT_R` radii on screen of the end
/// (and `OCCLUDER_BROAD_SHARE` of the arc), of two members or more, reaching more than this many
/// gaps in front of the member before the step, is cut however slender it is
/// (`cut_short_front_tail`): a part does not step towards the camera and end a few radii later. It
/// is the stroke running on over a nearer part where the stroked one passes behind it (a thicker
/// finger of the tree in front of the one stroked; docs/extraction.md, "Stroke clean-up").
const OCCLUDER_SHORT_STEP: f32 = 1.25;
const OCCLUDER_SHORT_R: f32 = 4.0;
/// Such a run of `TREND_MEMBERS` members or more is not cut where it is the part going on
/// (`is_the_part_going_on`), judged on the chain over the `TREND_R` radii on screen before the step:
/// - level with it: within `OCCLUDER_SHORT_STEP` gaps of its median depth (or of the member before
///   the step, where that is nearer). One member before the step can be a bump behind: a sprinkle
///   whose chain took the icing beside it for a stretch, 1 gap behind, then stepped back onto it;
/// - or going on as it went: within `OCCLUDER_SHORT_STEP` gaps of (or behind) the line fitted to its
///   depths, the run's own depth changing at least `TREND_SLOPE_SHARE` as fast the same way. A part
///   receding towards the camera, crossed by a bar in front, steps from the bar back onto itself
///   (the guitar stand's back foot behind a leg).
///
/// Over fewer members a run is judged on the member before the step alone: a node's few members
/// where a stem ends are kept under one stroke and cut under the next.
const TREND_R: f32 = 8.0;
const TREND_SLOPE_SHARE: f32 = 0.5;
const TREND_MEMBERS: usize = 8;
/// An end run that turns sharply in depth off the rest of the chain is a surface the stroke ran on
/// past the part's end (a leaf seen edge-on, the soil, a side stem behind): a part turns that
/// sharply only where it meets another. The turn is at the chain's farthest member (for a run
/// towards the camera; nearest, for one away from it) within `TURN_SHARE` of the chain's arc from
/// that end, and the farthest within the windows on both sides; the run reaches `TURN_FRONT_GAPS`
/// depth gaps in front of it (behind it), the depth-over-stroke slopes on the two sides, taken over
/// the run's length (`TURN_WINDOW_R` radii at least), differ by `TURN_DEG` or more, and the run is
/// not the part (not more slender than the other side by `TURN_WIDER` radii on average, nor as
/// slender and longer, each side's length taken beyond the apex's plateau: the members within
/// `TURN_FLAT_GAPS` depth gaps of it).
/// Depths are a running median over `2 TURN_MEDIAN + 1` members.
const TURN_SHARE: f32 = 0.6;
const TURN_DEG: f32 = 60.0;
const TURN_WINDOW_R: f32 = 4.0;
const TURN_FRONT_GAPS: f32 = 2.0;
const TURN_MEDIAN: usize = 2;
const TURN_SIGNS: [f32; 2] = [1.0, -1.0];
const TURN_WIDER: f32 = 0.2;
const TURN_FLAT_GAPS: f32 = 0.5;

/// The stroke after clean-up.
#[derive(Debug, Clone)]
pub(crate) struct CleanStroke {
    /// Samples from where the stroke first meets the object it follows to where it leaves it.
    pub points: Vec<[f32; 2]>,
    /// The depth the object has at each sample: the chosen surface's depth at chain samples,
    /// interpolated along the stroke in between (over an occluder or a gap).
    pub depth: Vec<f32>,
    /// At chain samples, the pixel of the chosen surface nearest the sample (`None` elsewhere).
    pub anchor: Vec<Option<usize>>,
    /// Screen arc length from the first sample, in pixels.
    pub arc: Vec<f32>,
    /// Unit normal of the stroke at each sample (the direction widths are measured in).
    pub normal: Vec<[f32; 2]>,
    /// Whether the chain runs behind what is in front of it somewhere (then the image is read from
    /// behind, see `floors`).
    pub behind: bool,
    /// Whether the layers behind the image, were they given, could give another chain: the
    /// visible one scores too little to be sure of.
    pub wants_behind: bool,
}

impl CleanStroke {
    pub fn segment_count(&self) -> usize {
        self.points.len().saturating_sub(1)
    }

    /// The object's expected depth at parameter `t` of segment `i`.
    pub fn depth_at(&self, i: usize, t: f32) -> f32 {
        self.depth[i] + t * (self.depth[i + 1] - self.depth[i])
    }

    /// Screen arc length at parameter `t` of segment `i`.
    pub fn arc_at(&self, i: usize, t: f32) -> f32 {
        self.arc[i] + t * (self.arc[i + 1] - self.arc[i])
    }

    /// The depth to read `image` from (`IndexImage::seen_from_cells`) so that what lies more than
    /// `depth_gap` in front of the object is seen through (docs/extraction.md, "What lies
    /// behind"): per cell of `FLOOR_CELL` pixels within `reach_px` of a sample, the object's
    /// expected depth at the nearest sample less `depth_gap`; the front elsewhere (`-inf`). Empty
    /// (the front everywhere) where the chain runs over visible surfaces only.
    pub fn floors(&self, image: &IndexImage, depth_gap: f32, reach_px: f32) -> Vec<f32> {
        if !self.behind {
            return Vec::new();
        }
        let (grid_x, grid_y) = (image.width.div_ceil(FLOOR_CELL), image.height.div_ceil(FLOOR_CELL));
        let half = FLOOR_CELL as f32 / 2.0;
        let reach = reach_px + half * std::f32::consts::SQRT_2;
        (0..grid_x * grid_y)
            .into_par_iter()
            .map(|cell| {
                let centre = [
                    (cell % grid_x) as f32 * FLOOR_CELL as f32 + half,
                    (cell / grid_x) as f32 * FLOOR_CELL as f32 + half,
                ];
                let nearest = self
                    .points
                    .iter()
                    .map(|p| (p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2))
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                match nearest {
                    Some((k, d2)) if d2 <= reach * reach => self.depth[k] - depth_gap,
                    _ => f32::NEG_INFINITY,
                }
            })
            .collect()
    }
}

/// A surface near a stroke sample: the depth of its pixel nearest the sample and how well it fits.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    depth: f32,
    score: f32,
    /// How near the sample its pixel lies: 1 on it, 0.5 at the band's edge (a factor of `score`).
    near: f32,
    pixel: usize,
    /// 0: visible at `pixel`; else seen only in that layer behind the front.
    layer: usize,
    /// Radii by which the surface is wider than `WIDE_FROM` across the stroke (0..`WIDE_CAP`).
    wide: f32,
}

/// The error for a stroke with no surface near any of its samples, counting its points outside the
/// image, which are not on background (docs/extraction.md, "Failures").
pub(crate) fn on_background(image: &IndexImage, stroke: &[[f32; 2]]) -> PathError {
    PathError::StrokeOnBackground { outside: points_outside(image, stroke), width: image.width, height: image.height }
}

/// How many of `stroke`'s points lie outside the image.
fn points_outside(image: &IndexImage, stroke: &[[f32; 2]]) -> usize {
    stroke.iter().filter(|p| image.pixel_at(p[0], p[1]).is_none()).count()
}

/// How many different points of the stroke lie inside the image (a point clicked three times is
/// one: the error then says 1, not 3).
fn distinct_inside(image: &IndexImage, stroke: &[[f32; 2]]) -> usize {
    let mut inside: Vec<[u32; 2]> =
        stroke.iter().filter(|p| image.pixel_at(p[0], p[1]).is_some()).map(|p| p.map(f32::to_bits)).collect();
    inside.sort_unstable();
    inside.dedup();
    inside.len()
}

/// Clip, resample, smooth, and choose the depth chain. `reach_px` is how far from a sample a
/// surface may be (the band half-width); `depth_gap` is `3R`; `focal_px` turns pixels of stroke
/// into lateral distance (0: unknown, then the allowed change stays `3R`); `slender_radius` `R`, if
/// given, lowers the score of surfaces much wider than `2R` (needs `focal_px`).
pub(crate) fn clean_stroke(
    image: &IndexImage,
    stroke: &[[f32; 2]],
    reach_px: f32,
    depth_gap: f32,
    focal_px: f32,
    slender_radius: Option<f32>,
) -> Result<CleanStroke, PathError> {
    if let Some(vertex) = stroke.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(PathError::NonFiniteStroke { vertex });
    }
    // resample first, so that a segment reaching in from outside the image keeps its inside part
    let dense = sample(&averaged_over_noise(&thinned(stroke)), image.width, image.height);
    let inside: Vec<[f32; 2]> = dense.into_iter().filter(|p| image.pixel_at(p[0], p[1]).is_some()).collect();
    let outside = points_outside(image, stroke);
    let too_short = |inside| PathError::StrokeTooShort { inside, outside, width: image.width, height: image.height };
    if inside.len() < 2 {
        return Err(too_short(distinct_inside(image, stroke)));
    }
    let (points, arc) = smooth(&inside);
    if points.len() < 2 {
        return Err(too_short(1));
    }
    let normal = normals(&points);
    let slender = slender_radius.filter(|_| focal_px > 0.0).map(|r| (r, focal_px));
    let candidates: Vec<Vec<Candidate>> = points
        .par_iter()
        .zip(&normal)
        .map_init(Walks::default, |walks, (&p, &n)| surfaces_near(image, walks, p, n, reach_px, depth_gap, slender))
        .collect();
    // The chain over the visible surfaces, and over those behind them too: the latter is taken
    // only where it scores clearly more (a stem behind leaves, not a detour at a node).
    let visible: Vec<Vec<Candidate>> =
        candidates.iter().map(|c| c.iter().copied().filter(|c| c.layer == 0).collect()).collect();
    let (chain, front_score) = depth_chain(&visible, &arc, depth_gap, focal_px);
    let (mut chain, front_score) = closer_rival(chain, front_score, &visible, &arc, depth_gap, focal_px);
    let mut behind = false;
    if image.has_behind() {
        let (all, score) = depth_chain(&candidates, &arc, depth_gap, focal_px);
        // the object is seen at the chain's ends: a part running behind something there is
        // most often one joining it (a branch behind its trunk)
        let seen = seen_stretch(&all, &arc, depth_gap, focal_px);
        if let Some((first, last)) = seen
            && (score > front_score * (1.0 + BEHIND_GAIN)
                || gains_where_they_differ(&all[first..=last], &chain, &arc, depth_gap, focal_px))
        {
            (chain, behind) = (all[first..=last].to_vec(), true);
        } else if seen.is_none() && hidden_all_along(&all, score, &chain, front_score) {
            (chain, behind) = (all, true);
        }
    }
    cut_occluder_ends(&mut chain, &arc, depth_gap, focal_px);
    // A surface behind scores at most HIDDEN_SCORE, so no chain over the layers behind scores more
    // than this bound: only a visible chain scoring clearly less than it can be beaten.
    let bound: f32 = visible.iter().map(|c| c.iter().map(|c| c.score).fold(HIDDEN_SCORE, f32::max)).sum();
    let wants_behind = !image.has_behind() && front_score * (1.0 + BEHIND_GAIN) < bound;
    if chain.len() < 2 {
        let on_object = candidates.iter().filter(|c| !c.is_empty()).count();
        return Err(if on_object == 0 {
            on_background(image, stroke)
        } else {
            PathError::StrokeBarelyOnObject { samples: on_object }
        });
    }
    // trim to the chain's first and last samples; interpolate the depth between chain samples
    let (first, last) = (chain[0].0, chain[chain.len() - 1].0);
    let depth = depth_along(&chain, &arc)[first..=last].to_vec();
    let mut anchor = vec![None; last - first + 1];
    for &(i, surface) in &chain {
        anchor[i - first] = Some(surface.pixel);
    }
    let arc = arc[first..=last].iter().map(|s| s - arc[first]).collect();
    Ok(CleanStroke {
        points: points[first..=last].to_vec(),
        depth,
        anchor,
        arc,
        normal: normal[first..=last].to_vec(),
        behind,
        wants_behind,
    })
}

/// The chain over `candidates`, `chain` scoring `score`, or its rival at another depth: the best
/// chain over the surfaces more than `depth_gap` from `chain`'s depth along the stroke. Where the
/// stroke runs between two parts at different depths (two fingers of a tree side by side, a jittered
/// stroke over their seam), their totals nearly tie, and the part is the one the stroke follows more
/// closely: the rival is taken where it scores at least `RIVAL_SHARE` of `score` and its members
/// lie `RIVAL_NEARER` nearer the samples and score `RIVAL_NEARER` more, on average
/// (docs/extraction.md, "Stroke clean-up", **A rival at another depth**).
fn closer_rival(
    chain: Vec<(usize, Candidate)>,
    score: f32,
    candidates: &[Vec<Candidate>],
    arc: &[f32],
    depth_gap: f32,
    focal_px: f32,
) -> (Vec<(usize, Candidate)>, f32) {
    if chain.is_empty() {
        return (chain, score);
    }
    let elsewhere: Vec<Vec<Candidate>> = candidates
        .iter()
        .zip(depth_along(&chain, arc))
        .map(|(c, z)| c.iter().copied().filter(|c| (c.depth - z).abs() > depth_gap).collect())
        .collect();
    let (rival, rival_score) = depth_chain(&elsewhere, arc, depth_gap, focal_px);
    // per member, how near the samples and its score (which also counts how slender): a part on a
    // surface measures as wide as it, and a strip of that surface beside it is nearer but not
    // more slender; where the part hides behind a limb, the limb under the stroke is nearer but wide
    let means = |members: &[(usize, Candidate)]| {
        let count = members.len().max(1) as f32;
        let sum = members.iter().fold((0.0, 0.0), |(near, scored), m| (near + m.1.near, scored + m.1.score));
        (sum.0 / count, sum.1 / count)
    };
    let ((rival_near, rival_scored), (chain_near, chain_scored)) = (means(&rival), means(&chain));
    if rival.len() >= 2
        && rival_score >= RIVAL_SHARE * score
        && rival_near > chain_near + RIVAL_NEARER
        && rival_scored > chain_scored + RIVAL_NEARER
    {
        (rival, rival_score)
    } else {
        (chain, score)
    }
}

/// The depth of `chain` at every sample of the stroke (`arc` its samples' arc lengths): between two
/// members, along the arc from one to the other; before the first and after the last, theirs.
fn depth_along(chain: &[(usize, Candidate)], arc: &[f32]) -> Vec<f32> {
    let (Some(first), Some(last)) = (chain.first(), chain.last()) else {
        return vec![0.0; arc.len()];
    };
    let mut depth = vec![first.1.depth; arc.len()];
    depth[last.0..].fill(last.1.depth);
    for pair in chain.windows(2) {
        let ((i, a), (j, b)) = (pair[0], pair[1]);
        for k in i..=j {
            let t = if arc[j] > arc[i] { (arc[k] - arc[i]) / (arc[j] - arc[i]) } else { 0.0 };
            depth[k] = a.depth + t * (b.depth - a.depth);
        }
    }
    depth
}

/// The positions in the chain behind, `behind`, of its first and last visible members, where they
/// lie over a rod apart on screen (`BEHIND_SPAN_R`; `arc` the samples' arc lengths); None where it
/// is seen nowhere or over less. (At two samples at least: a chain behind seen at one runs behind
/// the part itself, as the floor under a rope lying on it, where the rope measures as wide as the
/// floor. Over two radii: cut to two neighbouring samples, a chain behind made a path of one pixel
/// on a sprinkle seen close up, and the stroke was refused.)
fn seen_stretch(behind: &[(usize, Candidate)], arc: &[f32], depth_gap: f32, focal_px: f32) -> Option<(usize, usize)> {
    let first = behind.iter().position(|m| m.1.layer == 0)?;
    let last = behind.iter().rposition(|m| m.1.layer == 0)?;
    let span = arc[behind[last].0] - arc[behind[first].0];
    (last > first && span >= on_screen(BEHIND_SPAN_R, depth_gap, focal_px, behind[first].1.depth))
        .then_some((first, last))
}

/// Whether the chain behind, `behind` (scoring `score`), seen nowhere under the stroke or over less
/// than a rod (`seen_stretch` None), is the part: over a visible chain `front` (scoring
/// `front_score`) whose surfaces are `OCCLUDER_BROAD` radii wider than the part on average, a leaf
/// or body the whole stroke lies on (the upper half of a stem that a leaf hides), and scoring
/// `BEHIND_GAIN` more (docs/extraction.md, "What lies behind", Seen nowhere).
fn hidden_all_along(behind: &[(usize, Candidate)], score: f32, front: &[(usize, Candidate)], front_score: f32) -> bool {
    let broad = || front.iter().map(|m| m.1.wide).sum::<f32>() / front.len() as f32 >= OCCLUDER_BROAD;
    behind.len() >= 2 && !front.is_empty() && score > front_score * (1.0 + BEHIND_GAIN) && broad()
}

/// Whether the chain behind, `behind` (cut to its visible ends), scores `BEHIND_GAIN` more than the
/// visible chain over the stretch where the two differ, where that stretch lies between members
/// they share, spans `HIDDEN_STRETCH_R` radii on screen at least, and the visible chain runs over a
/// leaf or body there (its surfaces `OCCLUDER_BROAD` radii wider than the part on average): a stem
/// passing behind a leaf in the middle of a long stroke, whose gain the shared rest dilutes below
/// `BEHIND_GAIN` over the whole chain.
fn gains_where_they_differ(
    behind: &[(usize, Candidate)],
    visible: &[(usize, Candidate)],
    arc: &[f32],
    depth_gap: f32,
    focal_px: f32,
) -> bool {
    let (Some(start), Some(end)) = (behind.first(), behind.last()) else {
        return false;
    };
    let split = depth_gap / 3.0;
    // each chain's member at a sample (chains take at most one per sample)
    let at = |chain: &[(usize, Candidate)]| {
        let mut by_sample = vec![None; arc.len()];
        for &(i, c) in chain {
            by_sample[i] = Some(c);
        }
        by_sample
    };
    let (on_behind, on_visible) = (at(behind), at(visible));
    let same = |a: Option<Candidate>, b: Option<Candidate>| match (a, b) {
        (Some(a), Some(b)) => a.layer == b.layer && (a.depth - b.depth).abs() <= split,
        (None, None) => true,
        _ => false,
    };
    // (within the chain behind: what the visible chain has beyond it, the cut to its ends drops)
    let differs = |i: &usize| !same(on_behind[*i], on_visible[*i]);
    let (Some(from), Some(to)) = ((start.0..=end.0).find(differs), (start.0..=end.0).rfind(differs)) else {
        return false;
    };
    if from <= start.0
        || to >= end.0
        || arc[to] - arc[from] < on_screen(HIDDEN_STRETCH_R, depth_gap, focal_px, start.1.depth)
    {
        return false;
    }
    let within = |chain: &[Option<Candidate>]| chain[from..=to].iter().flatten().map(|c| c.score).sum::<f32>();
    let wides: Vec<f32> = on_visible[from..=to].iter().flatten().map(|c| c.wide).collect();
    let broad = !wides.is_empty() && wides.iter().sum::<f32>() / wides.len() as f32 >= OCCLUDER_BROAD;
    broad && within(&on_behind) > within(&on_visible) * (1.0 + BEHIND_GAIN)
}

/// Cut the ends of `chain` that lie on an occluder the stroke ran on past the part's end (a leaf in
/// front of a stem at the soil), which the rod would hook onto: an end run reaching more than the
/// depth gap in front of the member before it, spanning at most `OCCLUDER_END_SHARE` of the
/// chain's arc, on surfaces `OCCLUDER_WIDE` radii wider than the part on average, and either joined
/// by a step over the gap (the chain may make one where it skips samples) or reaching
/// `OCCLUDER_LEAF` somewhere (a leaf sloping back to the stem, joined without a step). A longer run
/// in front, up to `OCCLUDER_BROAD_SHARE` of the arc, is cut where its median is `OCCLUDER_BROAD`
/// radii wider (a leaf the stem passes behind at its end, sloping towards the camera). A run behind
/// the rest, or as slender as the part, is kept: that is the part going on (a stem receding from
/// its junction, a twig into its fork), unless it turns off the part sharply in depth (`TURN_DEG`),
/// or it is a short run stepped well in front (`OCCLUDER_SHORT_STEP`; `focal_px` 0 leaves these
/// two rules out).
fn cut_occluder_ends(chain: &mut Vec<(usize, Candidate)>, arc: &[f32], depth_gap: f32, focal_px: f32) {
    let Some((first, last)) = chain.first().zip(chain.last()) else {
        return;
    };
    let chain_arc = arc[last.0] - arc[first.0];
    cut_occluder_tail(chain, arc, depth_gap, chain_arc);
    cut_short_front_tail(chain, arc, depth_gap, chain_arc, focal_px);
    cut_turn_tail(chain, arc, depth_gap, chain_arc, focal_px);
    chain.reverse();
    cut_occluder_tail(chain, arc, depth_gap, chain_arc);
    cut_short_front_tail(chain, arc, depth_gap, chain_arc, focal_px);
    cut_turn_tail(chain, arc, depth_gap, chain_arc, focal_px);
    chain.reverse();
}

/// `radii` radii in pixels at `depth` (the depth gap is 3 R).
fn on_screen(radii: f32, depth_gap: f32, focal_px: f32, depth: f32) -> f32 {
    radii * depth_gap / 3.0 * focal_px / depth
}

/// Least-squares slope of `depth` over the distance of `at` from `origin` (px along the stroke);
/// None for fewer than 3 points.
fn depth_slope(at: &[f32], depth: &[f32], origin: f32) -> Option<f32> {
    let xs: Vec<f32> = at.iter().map(|a| (a - origin).abs()).collect();
    LineFit::of(&xs, depth).map(|line| line.slope)
}

/// The least-squares line of depth over arc (px along the stroke): through the means, with a slope.
struct LineFit {
    at: f32,
    depth: f32,
    slope: f32,
}

impl LineFit {
    /// None for fewer than 3 points or all at one place.
    fn of(at: &[f32], depth: &[f32]) -> Option<Self> {
        if at.len() < 3 {
            return None;
        }
        let n = at.len() as f32;
        let ma = at.iter().sum::<f32>() / n;
        let mz = depth.iter().sum::<f32>() / n;
        let saa: f32 = at.iter().map(|a| (a - ma) * (a - ma)).sum();
        let saz: f32 = at.iter().zip(depth).map(|(a, z)| (a - ma) * (z - mz)).sum();
        (saa > 0.0).then(|| LineFit { at: ma, depth: mz, slope: saz / saa })
    }

    fn depth_at(&self, at: f32) -> f32 {
        self.depth + self.slope * (at - self.at)
    }
}

/// The turn rule (`TURN_DEG`) for the last members of `chain`, towards the camera and away from it.
fn cut_turn_tail(chain: &mut Vec<(usize, Candidate)>, arc: &[f32], depth_gap: f32, chain_arc: f32, focal_px: f32) {
    for sign in TURN_SIGNS {
        cut_turn_tail_signed(chain, arc, depth_gap, chain_arc, focal_px, sign);
    }
}

/// `cut_turn_tail` with the depths multiplied by `sign` (1: a run towards the camera; -1: away).
fn cut_turn_tail_signed(
    chain: &mut Vec<(usize, Candidate)>,
    arc: &[f32],
    depth_gap: f32,
    chain_arc: f32,
    focal_px: f32,
    sign: f32,
) {
    let n = chain.len();
    if n < 7 || focal_px <= 0.0 {
        return;
    }
    // a single Gaussian's centre can sit a few radii off the part's axis: judge a running median
    let depth: Vec<f32> = (0..n)
        .map(|k| {
            let mut near: Vec<f32> = chain[k.saturating_sub(TURN_MEDIAN)..(k + TURN_MEDIAN + 1).min(n)]
                .iter()
                .map(|m| sign * m.1.depth)
                .collect();
            median(&mut near)
        })
        .collect();
    let at: Vec<f32> = chain.iter().map(|m| arc[m.0]).collect();
    let end_arc = at[n - 1];
    let Some(apex) = (1..n - 1)
        .filter(|&k| (at[k] - end_arc).abs() <= chain_arc * TURN_SHARE)
        .max_by(|&a, &b| depth[a].total_cmp(&depth[b]))
    else {
        return;
    };
    let nearest = depth[apex + 1..].iter().copied().fold(f32::INFINITY, f32::min);
    if nearest >= depth[apex] - TURN_FRONT_GAPS * depth_gap {
        return;
    }
    // Which side of the apex is the part: the more slender, else the longer.
    let mean_wide = |side: &[(usize, Candidate)]| side.iter().map(|m| m.1.wide).sum::<f32>() / side.len() as f32;
    let (run_wide, inner_wide) = (mean_wide(&chain[apex + 1..]), mean_wide(&chain[..apex]));
    // The run's length leaves out the apex's plateau, the members within `TURN_FLAT_GAPS` of its
    // depth around it: which of them is the apex is a tie that a pixel's shift of the stroke breaks
    // either way, and it moved a flat valley's length from one side to the other. The plateau
    // counts for the other side where the run comes towards the camera: a part lying level and then
    // a run in front is what the stroke ran on over past the part (a cradle's other hook crossing
    // in front). A run away from a level stretch can be the part receding (a sprinkle over the
    // icing's rim), and there the plateau counts for neither side (docs/extraction.md, "Stroke
    // clean-up", 6).
    let flat = TURN_FLAT_GAPS * depth_gap;
    let (mut low, mut high) = (apex, apex);
    while low > 0 && depth[low - 1] >= depth[apex] - flat {
        low -= 1;
    }
    while high + 1 < n && depth[high + 1] >= depth[apex] - flat {
        high += 1;
    }
    let inner_end = if sign > 0.0 { at[high] } else { at[low] };
    let (run_span, inner_span) = ((end_arc - at[high]).abs(), (inner_end - at[0]).abs());
    if run_wide < inner_wide - TURN_WIDER || (run_wide <= inner_wide + TURN_WIDER && run_span > inner_span) {
        return;
    }
    // the slopes are taken over the run's length on both sides (`TURN_WINDOW_R` radii at least, in
    // pixels at the apex's depth; the gap is 3 R): a bump of a few radii in a receding part is not
    // a turn
    let window = on_screen(TURN_WINDOW_R, depth_gap, focal_px, chain[apex].1.depth).max(run_span);
    let side = |range: std::ops::Range<usize>| {
        let keep: Vec<usize> = range.filter(|&k| (at[k] - at[apex]).abs() <= window).collect();
        let xs: Vec<f32> = keep.iter().map(|&k| at[k]).collect();
        let zs: Vec<f32> = keep.iter().map(|&k| depth[k]).collect();
        depth_slope(&xs, &zs, at[apex])
    };
    // the apex is the farthest member on both sides, not where the end's share happens to stop
    let inner_max =
        (0..apex).filter(|&k| (at[k] - at[apex]).abs() <= window).map(|k| depth[k]).fold(f32::MIN, f32::max);
    if inner_max > depth[apex] {
        return;
    }
    let (Some(before), Some(after)) = (side(0..apex + 1), side(apex..n)) else {
        return;
    };
    // dz per unit of lateral distance, both taken towards the end (the slope before the apex was
    // taken away from it)
    let to_world = focal_px / chain[apex].1.depth;
    let (before, after) = (-before * to_world, after * to_world);
    let cos = (1.0 + before * after) / ((1.0 + before * before).sqrt() * (1.0 + after * after).sqrt());
    let turn = cos.clamp(-1.0, 1.0).acos().to_degrees();
    if after < before && turn >= TURN_DEG {
        chain.truncate(apex + 1);
    }
}

/// `cut_occluder_ends` for the last members of `chain`, in whichever direction it runs.
fn cut_occluder_tail(chain: &mut Vec<(usize, Candidate)>, arc: &[f32], depth_gap: f32, chain_arc: f32) {
    let n = chain.len();
    let step = (1..n).rev().find(|&k| (chain[k].1.depth - chain[k - 1].1.depth).abs() > depth_gap);
    // where the last run of wide surfaces begins (within three members of the end), stepping over up
    // to two narrower members in it
    let mut wide_run = None;
    for k in (0..n).rev() {
        if chain[k].1.wide >= OCCLUDER_WIDE {
            wide_run = Some(k);
        } else if wide_run.unwrap_or(n) - k > 2 {
            break;
        }
    }
    for (start, stepped) in [(step, true), (wide_run, false)] {
        let Some(k) = start.filter(|&k| k > 0) else { continue };
        let run = &chain[k..];
        let mean_wide = run.iter().map(|m| m.1.wide).sum::<f32>() / run.len() as f32;
        let peak = run.iter().map(|m| m.1.wide).fold(0.0, f32::max);
        let nearest = run.iter().map(|m| m.1.depth).fold(f32::INFINITY, f32::min);
        let span = (arc[run[run.len() - 1].0] - arc[run[0].0]).abs();
        let leaf =
            span <= chain_arc * OCCLUDER_END_SHARE && mean_wide >= OCCLUDER_WIDE && (stepped || peak >= OCCLUDER_LEAF);
        let mut wides: Vec<f32> = run.iter().map(|m| m.1.wide).collect();
        let median_wide = median(&mut wides);
        let broad = span <= chain_arc * OCCLUDER_BROAD_SHARE && median_wide >= OCCLUDER_BROAD;
        if nearest < chain[k - 1].1.depth - depth_gap && (leaf || broad) {
            chain.truncate(k);
            return;
        }
    }
}

/// The short-run rule (`OCCLUDER_SHORT_STEP`) for the last members of `chain`: the run from a step
/// within `OCCLUDER_SHORT_R` radii of the end, the last such step first (a run may step twice, onto
/// a nearer part and then onto one nearer still).
fn cut_short_front_tail(
    chain: &mut Vec<(usize, Candidate)>,
    arc: &[f32],
    depth_gap: f32,
    chain_arc: f32,
    focal_px: f32,
) {
    let n = chain.len();
    if n < 3 || focal_px <= 0.0 {
        return;
    }
    let end = &chain[n - 1];
    // R in pixels at the end's depth (the gap is 3 R)
    let reach = on_screen(OCCLUDER_SHORT_R, depth_gap, focal_px, end.1.depth).min(chain_arc * OCCLUDER_BROAD_SHARE);
    // the nearest depth of the run from member k to the end, kept as k moves inwards
    let mut nearest = end.1.depth;
    for k in (1..n - 1).rev() {
        if (arc[end.0] - arc[chain[k].0]).abs() > reach {
            return;
        }
        nearest = nearest.min(chain[k].1.depth);
        let before = chain[k - 1].1.depth;
        if (chain[k].1.depth - before).abs() > depth_gap
            && nearest < before - OCCLUDER_SHORT_STEP * depth_gap
            && !is_the_part_going_on(chain, arc, k, nearest, depth_gap, focal_px)
        {
            chain.truncate(k);
            return;
        }
    }
}

/// Whether the end run `chain[k..]`, whose nearest depth is `nearest`, is the part going on
/// (`TREND_R`): level with the chain before the step, or going on as it went.
fn is_the_part_going_on(
    chain: &[(usize, Candidate)],
    arc: &[f32],
    k: usize,
    nearest: f32,
    depth_gap: f32,
    focal_px: f32,
) -> bool {
    let run = &chain[k..];
    if run.len() < TREND_MEMBERS {
        return false;
    }
    let step = arc[chain[k - 1].0];
    let window = on_screen(TREND_R, depth_gap, focal_px, chain[k - 1].1.depth);
    let before: Vec<&(usize, Candidate)> = chain[..k].iter().filter(|m| (step - arc[m.0]).abs() <= window).collect();
    let mut depths: Vec<f32> = before.iter().map(|m| m.1.depth).collect();
    let level = median(&mut depths).min(chain[k - 1].1.depth);
    if nearest >= level - OCCLUDER_SHORT_STEP * depth_gap {
        return true;
    }
    let (at, depth): (Vec<f32>, Vec<f32>) = before.iter().map(|m| (arc[m.0], m.1.depth)).unzip();
    let Some(trend) = LineFit::of(&at, &depth) else {
        return false;
    };
    let (at, depth): (Vec<f32>, Vec<f32>) = run.iter().map(|m| (arc[m.0], m.1.depth)).unzip();
    let Some(own) = LineFit::of(&at, &depth) else {
        return false;
    };
    own.slope * trend.slope >= TREND_SLOPE_SHARE * trend.slope * trend.slope
        && run.iter().all(|m| m.1.depth >= trend.depth_at(arc[m.0]) - OCCLUDER_SHORT_STEP * depth_gap)
}

/// The stroke without points closer than `SAMPLE_PX / 2` to the last one kept (the stroke's last
/// point takes the place of the last one kept): a stroke of one point per tenth of a pixel, as a
/// tablet can give, is sampled as one of points a few pixels apart is, not 30 times as densely
/// (with a 200 px band that took 73 s).
fn thinned(stroke: &[[f32; 2]]) -> Vec<[f32; 2]> {
    let mut vertices: Vec<[f32; 2]> = Vec::with_capacity(stroke.len());
    for (i, &p) in stroke.iter().enumerate() {
        let close = vertices.last().is_some_and(|q: &[f32; 2]| (p[0] - q[0]).hypot(p[1] - q[1]) < 0.5 * SAMPLE_PX);
        let last = i + 1 == stroke.len();
        if !close || (last && vertices.len() == 1) {
            vertices.push(p); // (a stroke of two close points stays two)
        } else if last && let Some(kept) = vertices.last_mut() {
            *kept = p;
        }
    }
    vertices
}

/// The stroke's points averaged over their noise where they lie closer together than twice it
/// (docs/extraction.md, "Stroke clean-up", **Points closer than their noise**): each interior
/// point becomes the Gaussian-weighted mean of its neighbours by index, with a standard deviation
/// of `3 sqrt(noise^2 - (step / 2)^2) / step` points, the window shrinking symmetrically at the
/// ends, which stay.
/// The noise is estimated from the points' second differences (their median norm over
/// `sqrt(6) sqrt(2 ln 2)`, that of two-axis Gaussian noise), the step from the distance between
/// points `NOISE_STEP_SPAN` apart (a curve's step a little short). A stroke drawn by hand, sparse
/// or dense, has a noise well under its step and stays as it is, to the bit, and so does one of
/// fewer than `NOISE_MIN_POINTS` points.
fn averaged_over_noise(points: &[[f32; 2]]) -> Vec<[f32; 2]> {
    let n = points.len();
    if n < NOISE_MIN_POINTS {
        return points.to_vec();
    }
    let p: Vec<[f64; 2]> = points.iter().map(|q| [f64::from(q[0]), f64::from(q[1])]).collect();
    let norm = |a: [f64; 2]| a[0].hypot(a[1]);
    // in f64, so that no difference of finite points overflows; a median too big for f32 is inf
    let mut bends: Vec<f32> = p
        .windows(3)
        .map(|w| norm([w[0][0] - 2.0 * w[1][0] + w[2][0], w[0][1] - 2.0 * w[1][1] + w[2][1]]) as f32)
        .collect();
    let span = NOISE_STEP_SPAN.min(n - 1);
    let mut steps: Vec<f32> =
        p.iter().zip(&p[span..]).map(|(a, b)| (norm([b[0] - a[0], b[1] - a[1]]) / span as f64) as f32).collect();
    let noise = f64::from(median(&mut bends)) / (6.0_f64.sqrt() * (2.0 * std::f64::consts::LN_2).sqrt());
    let step = f64::from(median(&mut steps));
    let onset = NOISE_ONSET * step;
    if !(noise.is_finite() && step.is_finite() && noise > onset) {
        return points.to_vec();
    }
    // in points: nothing at the onset, `NOISE_WINDOW` times the noise well past it (a stroke of pure
    // noise, drawn nowhere, is averaged over `NOISE_MAX_POINTS` at most, so its cost stays linear)
    let sigma = (NOISE_WINDOW * (noise * noise - onset * onset).sqrt() / step).min(NOISE_MAX_POINTS);
    (0..n)
        .map(|i| {
            let half = (3.0 * sigma).min(i as f64).min((n - 1 - i) as f64).floor() as usize;
            let (mut sum, mut weight) = ([0.0_f64; 2], 0.0_f64);
            for (j, q) in p.iter().enumerate().take(i + half + 1).skip(i - half) {
                let w = (-0.5 * ((j as f64 - i as f64) / sigma).powi(2)).exp();
                sum = [sum[0] + w * q[0], sum[1] + w * q[1]];
                weight += w;
            }
            [(sum[0] / weight) as f32, (sum[1] / weight) as f32]
        })
        .collect()
}

/// Points every `SAMPLE_PX` along the polyline `vertices` (kept), on the image (`width` x `height`
/// pixels) only: the samples of a segment are those of the whole segment that lie within
/// `SAMPLE_PX` of the image, so a stroke reaching far outside costs no more than its part inside
/// (a stroke 1e20 pixels long asked for more samples than memory holds).
fn sample(vertices: &[[f32; 2]], width: usize, height: usize) -> Vec<[f32; 2]> {
    let Some(&first) = vertices.first() else { return Vec::new() };
    let (low, high) = ([-SAMPLE_PX as f64; 2], [width as f64 + SAMPLE_PX as f64, height as f64 + SAMPLE_PX as f64]);
    let mut out = vec![first];
    for w in vertices.windows(2) {
        let (a, b) = (w[0], w[1]);
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        if length == 0.0 {
            continue;
        }
        let steps = (length / SAMPLE_PX).ceil().max(1.0) as usize;
        // the segment's parameters on the grown image (Liang-Barsky), then the samples there
        let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
        for k in 0..2 {
            let (from, delta) = (f64::from(a[k]), f64::from(b[k]) - f64::from(a[k]));
            if delta == 0.0 {
                if from < low[k] || from > high[k] {
                    (t0, t1) = (1.0, 0.0);
                }
                continue;
            }
            let (u, v) = ((low[k] - from) / delta, (high[k] - from) / delta);
            (t0, t1) = (t0.max(u.min(v)), t1.min(u.max(v)));
        }
        if t0 > t1 {
            continue;
        }
        let first_step = ((t0 * steps as f64).floor() as usize).max(1);
        let last_step = ((t1 * steps as f64).ceil() as usize).min(steps);
        out.extend((first_step..=last_step).map(|s| {
            let t = s as f32 / steps as f32;
            [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
        }));
    }
    out
}

/// Gaussian smoothing along arc length with a window that shrinks symmetrically at the ends, so the
/// ends stay where the user put them. Returns the points and their arc lengths.
fn smooth(points: &[[f32; 2]]) -> (Vec<[f32; 2]>, Vec<f32>) {
    let arc = arc_lengths(points);
    let total = arc[arc.len() - 1];
    let smoothed: Vec<[f32; 2]> = (0..points.len())
        .map(|i| {
            let half = (3.0 * SMOOTH_SIGMA_PX).min(arc[i]).min(total - arc[i]);
            let (mut sum, mut weight) = ([0.0_f32; 2], 0.0_f32);
            let (mut j, mut k) = (i, i);
            while j > 0 && arc[i] - arc[j - 1] <= half {
                j -= 1;
            }
            while k + 1 < points.len() && arc[k + 1] - arc[i] <= half {
                k += 1;
            }
            for (q, s) in points[j..=k].iter().zip(&arc[j..=k]) {
                let w = (-0.5 * ((s - arc[i]) / SMOOTH_SIGMA_PX).powi(2)).exp();
                sum = [sum[0] + w * q[0], sum[1] + w * q[1]];
                weight += w;
            }
            [sum[0] / weight, sum[1] / weight]
        })
        .collect();
    let mut out: Vec<[f32; 2]> = Vec::with_capacity(smoothed.len());
    for p in smoothed {
        if out.last().is_none_or(|q| (p[0] - q[0]).hypot(p[1] - q[1]) > 1e-3) {
            out.push(p);
        }
    }
    let arc = arc_lengths(&out);
    (out, arc)
}

fn arc_lengths(points: &[[f32; 2]]) -> Vec<f32> {
    let mut arc = Vec::with_capacity(points.len());
    let mut s = 0.0;
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            s += (p[0] - points[i - 1][0]).hypot(p[1] - points[i - 1][1]);
        }
        arc.push(s);
    }
    arc
}

/// The surfaces within `reach_px` of `point`: its object pixels, in every layer the image has
/// (the front and those behind it), grouped by depth (a gap over a third of `depth_gap` starts a
/// new surface), each represented by its pixel nearest the point. A surface scores higher the
/// nearer it is, the less it is wider across the stroke (direction `normal`) than the part (given
/// `slender` = (R, focal length)), and when it is visible there rather than behind another. A
/// surface of the front with no solid pixel here is a haze, not a surface (docs/extraction.md,
/// "Stroke clean-up" 2).
fn surfaces_near(
    image: &IndexImage,
    walks: &mut Walks,
    point: [f32; 2],
    normal: [f32; 2],
    reach_px: f32,
    depth_gap: f32,
    slender: Option<(f32, f32)>,
) -> Vec<Candidate> {
    let split = depth_gap / 3.0;
    let reach = reach_px.ceil() as i64;
    let (cx, cy) = (point[0].floor() as i64, point[1].floor() as i64);
    let mut pixels: Vec<(f32, f32, usize, usize)> = Vec::new(); // (depth, distance, pixel, layer)
    for row in (cy - reach).max(0)..=(cy + reach).min(image.height as i64 - 1) {
        for col in (cx - reach).max(0)..=(cx + reach).min(image.width as i64 - 1) {
            let p = row as usize * image.width + col as usize;
            let (dx, dy) = (col as f32 + 0.5 - point[0], row as f32 + 0.5 - point[1]);
            let d = (dx * dx + dy * dy).sqrt(); // not hypot: a libm call per pixel, for no gain here
            if d <= reach_px.max(0.75) {
                image.layers_at(p, |layer, z| pixels.push((z, d, p, layer)));
            }
        }
    }
    // by layer, then depth, ties in pixel order (the scan's order); each layer is grouped on its
    // own, so that a leaf sloping back towards a stem hidden behind it does not merge with the
    // stem into one surface
    let order = depth_order(&pixels);
    let mut surfaces: Vec<Surface> = Vec::new();
    let mut last_z = f32::NAN;
    for &i in &order {
        let (z, d, p, layer) = pixels[i];
        let previous_z = std::mem::replace(&mut last_z, z);
        // layers behind offer solid pixels only (`layers_at`); a surface's first solid pixel settles it
        let solid = |p: usize| layer > 0 || image.covered(p);
        match surfaces.last_mut() {
            Some(s) if s.layer == layer && z - previous_z <= split => {
                s.count += 1;
                s.solid = s.solid || solid(p);
                if d < s.distance {
                    (s.depth, s.distance, s.pixel) = (z, d, p);
                }
            }
            _ => surfaces.push(Surface { depth: z, distance: d, count: 1, pixel: p, layer, solid: solid(p) }),
        }
    }
    // a lone pixel is a stray Gaussian unless it is right under the point; a surface without a
    // solid pixel is a haze (a big faint Gaussian owning the pixels beside a stalk, 0.04 opaque)
    surfaces.retain(|s| s.solid && (s.count >= 2 || s.distance <= 1.0));
    surfaces.sort_by(|a, b| a.distance.total_cmp(&b.distance));
    // the nearest visible ones and the nearest behind, each on their own: what lies behind never
    // crowds out a visible surface (the chain over visible ones is the same with layers or without)
    let (mut visible, mut hidden) = (0, 0);
    surfaces.retain(|s| {
        let count = if s.layer == 0 { &mut visible } else { &mut hidden };
        *count += 1;
        *count <= MAX_CANDIDATES
    });
    surfaces
        .iter()
        .map(|s| {
            let near = 1.0 - 0.5 * (s.distance / reach_px.max(1.0)).min(1.0);
            // a surface behind another is measured on what lies behind the depth gap in front of it
            let seen = if s.layer == 0 { *image } else { image.seen_from_depth(s.depth - depth_gap) };
            let wide = slender.map_or(0.0, |(radius, focal)| walks.excess_width(&seen, s.pixel, normal, focal, radius));
            let hidden = if s.layer == 0 { 1.0 } else { HIDDEN_SCORE };
            Candidate {
                depth: s.depth,
                score: hidden * near * (1.0 - WIDE_SCORE * wide / WIDE_CAP),
                near,
                pixel: s.pixel,
                layer: s.layer,
                wide,
            }
        })
        .collect()
}

/// One surface near a stroke sample, as `surfaces_near` groups them.
struct Surface {
    /// Depth of its pixel nearest the sample.
    depth: f32,
    /// That pixel's distance from the sample.
    distance: f32,
    /// How many pixels it has within reach.
    count: usize,
    /// That pixel.
    pixel: usize,
    /// 0: visible; else the layer behind the front it lies in.
    layer: usize,
    /// Whether any of its pixels is solid (accumulated opacity at least 0.5 where known).
    solid: bool,
}

/// The bits of `z`, flipped so that they order as `f32::total_cmp` orders the values.
pub(crate) fn ordered_bits(z: f32) -> u32 {
    let bits = z.to_bits();
    if bits >> 31 == 1 { !bits } else { bits | 0x8000_0000 }
}

/// The positions of `pixels` (depth, distance, pixel, layer) by layer, then depth, then position.
/// Sorted as one 64-bit key (a layer's 8 bits, the depth's 32, the position's 24), which takes a
/// fifth of a trace's instructions less than a wider key; a disc too large for that (a band of
/// thousands of pixels) takes a stable sort instead.
fn depth_order(pixels: &[(f32, f32, usize, usize)]) -> Vec<usize> {
    const POSITION_BITS: u32 = 24;
    if pixels.len() >> POSITION_BITS == 0 && pixels.iter().all(|px| px.3 < 1 << 8) {
        let mut keys: Vec<u64> = (pixels.iter().enumerate())
            .map(|(i, &(z, _, _, layer))| {
                ((layer as u64) << (32 + POSITION_BITS)) | (u64::from(ordered_bits(z)) << POSITION_BITS) | i as u64
            })
            .collect();
        keys.sort_unstable();
        keys.iter().map(|&key| (key & ((1 << POSITION_BITS) - 1)) as usize).collect()
    } else {
        let mut order: Vec<usize> = (0..pixels.len()).collect();
        order.sort_by_key(|&i| (pixels[i].3, ordered_bits(pixels[i].0)));
        order
    }
}

/// The chain of (sample, surface) with the largest total score (returned with it) whose consecutive members agree in
/// depth: `|dz| <= depth_gap + DEPTH_SLOPE * lateral`, lateral being the stroke length between them
/// at that depth. Exact dynamic programming over all pairs (the stroke has a few hundred samples).
/// Each node's best predecessor is the first compatible one in order of falling score: along a
/// chain that is nearly always one of the last few, so the search rarely looks at many.
fn depth_chain(
    candidates: &[Vec<Candidate>],
    arc: &[f32],
    depth_gap: f32,
    focal_px: f32,
) -> (Vec<(usize, Candidate)>, f32) {
    let nodes: Vec<(usize, Candidate)> =
        candidates.iter().enumerate().flat_map(|(i, c)| c.iter().map(move |&c| (i, c))).collect();
    // lateral distance per pixel of arc is depth / focal (none when the focal length is unknown)
    let per_px = if focal_px > 0.0 { 1.0 / focal_px } else { 0.0 };
    let compatible = |(i, a): (usize, Candidate), (j, b): (usize, Candidate)| {
        (a.depth - b.depth).abs() <= depth_gap + DEPTH_SLOPE * (arc[j] - arc[i]) * a.depth.min(b.depth) * per_px
    };
    let mut best = vec![0.0_f32; nodes.len()];
    let mut previous = vec![usize::MAX; nodes.len()];
    // the nodes of earlier samples by falling total score, the first node first among equals
    // (scores are positive, so their bits order as they do)
    let mut ranked: BTreeSet<(Reverse<u32>, usize)> = BTreeSet::new();
    let mut start_of_sample = 0; // first node of the current sample: only earlier samples link
    for b in 0..nodes.len() {
        if b > 0 && nodes[b].0 != nodes[b - 1].0 {
            ranked.extend((start_of_sample..b).map(|a| (Reverse(best[a].to_bits()), a)));
            start_of_sample = b;
        }
        let from = ranked.iter().map(|&(_, a)| a).find(|&a| compatible(nodes[a], nodes[b]));
        best[b] = from.map_or(0.0, |a| best[a]) + nodes[b].1.score;
        previous[b] = from.unwrap_or(usize::MAX);
    }
    let Some(mut node) = (0..nodes.len()).max_by(|&a, &b| best[a].total_cmp(&best[b])) else {
        return (Vec::new(), 0.0);
    };
    let total = best[node];
    let mut chain = vec![nodes[node]];
    while previous[node] != usize::MAX {
        node = previous[node];
        chain.push(nodes[node]);
    }
    chain.reverse();
    (chain, total)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chain by the plain all-pairs recurrence, for comparison.
    fn depth_chain_by_all_pairs(candidates: &[Vec<Candidate>], arc: &[f32], gap: f32, focal: f32) -> Vec<usize> {
        let nodes: Vec<(usize, Candidate)> =
            candidates.iter().enumerate().flat_map(|(i, c)| c.iter().map(move |&c| (i, c))).collect();
        let (mut best, mut previous) = (vec![0.0_f32; nodes.len()], vec![usize::MAX; nodes.len()]);
        for b in 0..nodes.len() {
            let (j, cb) = nodes[b];
            best[b] = cb.score;
            for a in (0..b).filter(|&a| nodes[a].0 < j) {
                let (i, ca) = nodes[a];
                let lateral = (arc[j] - arc[i]) * ca.depth.min(cb.depth) / focal;
                if (ca.depth - cb.depth).abs() <= gap + DEPTH_SLOPE * lateral && best[a] + cb.score > best[b] {
                    (best[b], previous[b]) = (best[a] + cb.score, a);
                }
            }
        }
        let mut node = (0..nodes.len()).max_by(|&a, &b| best[a].total_cmp(&best[b])).unwrap_or(0);
        let mut chain = vec![nodes[node].0];
        while previous[node] != usize::MAX {
            node = previous[node];
            chain.push(nodes[node].0);
        }
        chain.reverse();
        chain
    }

    /// The samples of `sample` before they were kept to the image: every segment sampled whole.
    fn resample_whole(stroke: &[[f32; 2]]) -> Vec<[f32; 2]> {
        let mut out = vec![stroke[0]];
        for w in stroke.windows(2) {
            let (a, b) = (w[0], w[1]);
            let length = (b[0] - a[0]).hypot(b[1] - a[1]);
            if length > 0.0 {
                let steps = (length / SAMPLE_PX).ceil().max(1.0) as usize;
                out.extend((1..=steps).map(|s| {
                    let t = s as f32 / steps as f32;
                    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
                }));
            }
        }
        out
    }

    #[test]
    fn resampling_keeps_to_the_image_and_thins_dense_strokes() {
        let on_image = |p: &&[f32; 2]| p[0] >= 0.0 && p[1] >= 0.0 && p[0] < 64.0 && p[1] < 48.0;
        let mut next = numbers_below(11);
        for _ in 0..300 {
            // points anywhere within 40 px of the 64x48 image, many of them off it
            let count = 2 + next(8) as usize;
            let stroke: Vec<[f32; 2]> =
                (0..count).map(|_| [next(1600) as f32 * 0.1 - 40.0, next(1300) as f32 * 0.1 - 40.0]).collect();
            if stroke.windows(2).any(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]) < 0.5 * SAMPLE_PX) {
                continue; // thinned: not the same vertices
            }
            let kept: Vec<[f32; 2]> = sample(&thinned(&stroke), 64, 48).iter().filter(on_image).copied().collect();
            let whole: Vec<[f32; 2]> = resample_whole(&stroke).iter().filter(on_image).copied().collect();
            assert_eq!(kept, whole);
        }
        // 0.1 px apart: samples 1.5 px apart, where a stroke of two points has them 3 px apart
        let dense: Vec<[f32; 2]> = (0..=600).map(|i| [i as f32 * 0.1, 10.0]).collect();
        let samples = sample(&thinned(&dense), 64, 48);
        assert_eq!(samples.first(), Some(&[0.0, 10.0]));
        assert_eq!(samples.last(), dense.last());
        assert!((20..=45).contains(&samples.len()), "{} samples", samples.len());
        // 1e20 px long: the samples on the image and a little around it only
        assert!(sample(&thinned(&[[10.0, 10.0], [1e20, 10.0]]), 64, 48).len() < 100);
    }

    #[test]
    fn points_closer_than_their_noise_are_averaged_and_a_drawn_stroke_is_not() {
        let mut next = numbers_below(5);
        let mut gaussian = move || {
            // Box-Muller from two uniform numbers in (0, 1]
            let (u, v) = ((1 + next(1 << 20)) as f32 / (1 << 20) as f32, next(1 << 20) as f32 / (1 << 20) as f32);
            (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
        };
        let off_line =
            |points: &[[f32; 2]]| points.iter().map(|p| (p[1] - 100.0).abs()).sum::<f32>() / points.len() as f32;
        // 50 points 3 px apart along y = 100, 6 px of noise on each: a zigzag across a stem
        let noisy: Vec<[f32; 2]> =
            (0..50).map(|i| [10.0 + 3.0 * i as f32 + 6.0 * gaussian(), 100.0 + 6.0 * gaussian()]).collect();
        let averaged = averaged_over_noise(&noisy);
        assert_eq!((averaged[0], averaged[49]), (noisy[0], noisy[49]), "the ends stay");
        assert!(
            off_line(&averaged) < 0.35 * off_line(&noisy),
            "{} px off the line, {} before",
            off_line(&averaged),
            off_line(&noisy)
        );
        // the same noise on points 25 px apart (drawn by hand, jittered), a few of them, a dense
        // stroke drawn without noise (a mouse's pixels) and a dense circle stay to the bit
        let sparse: Vec<[f32; 2]> =
            (0..30).map(|i| [10.0 + 25.0 * i as f32 + 6.0 * gaussian(), 100.0 + 6.0 * gaussian()]).collect();
        let pixels: Vec<[f32; 2]> =
            (0..80).map(|i| [10.0 + 2.0 * i as f32, (100.0 + 0.37 * i as f32).round()]).collect();
        let circle: Vec<[f32; 2]> = (0..100)
            .map(|i| [100.0 + 40.0 * (i as f32 * 0.06).cos(), 100.0 + 40.0 * (i as f32 * 0.06).sin()])
            .collect();
        for stroke in [&sparse, &sparse[..12].to_vec(), &pixels, &circle] {
            assert_eq!(&averaged_over_noise(stroke), stroke);
        }
        // points too far apart for f32 differences: left as they are, never NaN
        let huge: Vec<[f32; 2]> = (0..20).map(|i| [if i % 2 == 0 { 3e38 } else { -3e38 }, i as f32]).collect();
        assert_eq!(averaged_over_noise(&huge), huge);
    }

    /// A repeatable stream of numbers: each call gives one below its argument.
    fn numbers_below(seed: u64) -> impl FnMut(u64) -> u64 {
        let mut state = seed;
        move |n| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) % n
        }
    }

    #[test]
    fn the_depth_order_is_a_stable_sort_by_layer_and_depth() {
        // depths in few values (ties happen), on three layers, and once with a layer past the key's
        // 8 bits, which takes the stable sort
        let mut next = numbers_below(777_u64);
        for top_layer in [2, 300] {
            let pixels: Vec<(f32, f32, usize, usize)> =
                (0..500).map(|p| (next(40) as f32 * 0.25 - 3.0, 1.0, p, next(3) as usize * (top_layer / 2))).collect();
            let mut expected: Vec<usize> = (0..pixels.len()).collect();
            expected.sort_by(|&a, &b| pixels[a].3.cmp(&pixels[b].3).then(pixels[a].0.total_cmp(&pixels[b].0)));
            assert_eq!(depth_order(&pixels), expected, "top layer {top_layer}");
        }
    }

    #[test]
    fn a_rival_the_stroke_follows_more_closely_is_taken_at_a_near_tie_only() {
        // 40 samples 3 px apart: one surface under all of them at the band's edge (depth 1), another
        // under the last `near` of them, close to the samples (depth 2), `wide` radii too wide; no
        // chain steps between them
        let arc: Vec<f32> = (0..40).map(|i| 3.0 * i as f32).collect();
        let depth_taken = |count: usize, edge: f32, wide: f32| {
            let surface = |i: usize, depth: f32, near: f32, wide: f32| {
                let score = near * (1.0 - WIDE_SCORE * wide / WIDE_CAP);
                Candidate { depth, score, near, pixel: i, layer: 0, wide }
            };
            let candidates: Vec<Vec<Candidate>> = (0..40)
                .map(|i| {
                    let mut here = vec![surface(i, 1.0, edge, 0.0)];
                    if i >= 40 - count {
                        here.push(surface(i, 2.0, 0.99, wide));
                    }
                    here
                })
                .collect();
            let (chain, score) = depth_chain(&candidates, &arc, 0.03, 500.0);
            assert!(chain.iter().all(|m| m.1.depth == 1.0), "the best chain is the longer one");
            let (chain, _) = closer_rival(chain, score, &candidates, &arc, 0.03, 500.0);
            chain[0].1.depth
        };
        // 22 close samples (21.8) against 40 at the edge (24): the stroke follows the near one
        assert_eq!(depth_taken(22, 0.6, 0.0), 2.0);
        // 15 (14.9): not a tie
        assert_eq!(depth_taken(15, 0.6, 0.0), 1.0);
        // 36 close samples against 40 nearly as close (0.95): not nearer by 0.05
        assert_eq!(depth_taken(36, 0.95, 0.0), 1.0);
        // a rival nearer the samples but wider: 30 samples 1.6 radii too wide (0.79 each, 23.8)
        // against 40 slender ones at 0.7 (28) still scores 0.05 more each, and is taken; 36 samples
        // 2 radii too wide (0.74 each, 26.7) do not (a leaf under the stroke, the part beside it)
        assert_eq!(depth_taken(30, 0.7, 1.6), 2.0);
        assert_eq!(depth_taken(36, 0.7, 2.0), 1.0);
    }

    #[test]
    fn the_ranked_search_finds_the_chain_all_pairs_find() {
        // surfaces at a few depths, on and off in runs, with scores in quarter steps (ties happen)
        let mut next = numbers_below(12345_u64);
        for _ in 0..50 {
            let samples = 20 + next(80) as usize;
            let arc: Vec<f32> = (0..samples).map(|i| 3.0 * i as f32).collect();
            let candidates: Vec<Vec<Candidate>> = (0..samples)
                .map(|i| {
                    (0..next(4))
                        .map(|k| Candidate {
                            depth: 1.0 + 0.05 * next(6) as f32 + 0.001 * i as f32,
                            score: 0.25 * (1 + next(4)) as f32,
                            near: 1.0,
                            pixel: i * 4 + k as usize,
                            layer: 0,
                            wide: 0.0,
                        })
                        .collect()
                })
                .collect();
            let chain: Vec<usize> = depth_chain(&candidates, &arc, 0.03, 500.0).0.iter().map(|c| c.0).collect();
            let expected = depth_chain_by_all_pairs(&candidates, &arc, 0.03, 500.0);
            if candidates.iter().any(|c| !c.is_empty()) {
                assert_eq!(chain, expected);
            }
        }
    }

    #[test]
    fn an_end_run_onto_a_wide_surface_in_front_is_cut_and_nothing_else() {
        // 30 samples 3 px apart on the part at depth 1 (depth gap 0.03); the last or first `count`
        // members are replaced by a run at `depth`, stepping to it at once or sloping to it
        let arc: Vec<f32> = (0..30).map(|i| 3.0 * i as f32).collect();
        let member =
            |i: usize, depth: f32, wide: f32| (i, Candidate { depth, score: 1.0, near: 1.0, pixel: i, layer: 0, wide });
        let cut = |at_end: bool, count: usize, depth: f32, wide: f32, sloping: bool| {
            let mut chain: Vec<_> = (0..30).map(|i| member(i, 1.0, 0.0)).collect();
            for j in 0..count {
                let i = if at_end { 30 - count + j } else { count - 1 - j }; // j-th member from the part
                let t = if sloping { (j + 1) as f32 / count as f32 } else { 1.0 };
                chain[i] = member(i, 1.0 + t * (depth - 1.0), wide);
            }
            cut_occluder_ends(&mut chain, &arc, 0.03, 0.0);
            30 - chain.len()
        };
        for at_end in [true, false] {
            assert_eq!(cut(at_end, 3, 0.9, 2.0, false), 3, "a step onto a wide surface in front: cut");
            assert_eq!(cut(at_end, 4, 0.9, 4.0, true), 4, "a leaf sloping away in front: cut");
            assert_eq!(cut(at_end, 4, 0.9, 1.5, true), 0, "sloping onto something not as wide as a leaf");
            assert_eq!(cut(at_end, 3, 1.1, 4.0, false), 0, "behind: the part going on");
            assert_eq!(cut(at_end, 3, 0.9, 0.0, false), 0, "as slender as the part");
            assert_eq!(cut(at_end, 3, 0.98, 4.0, false), 0, "within the depth gap");
            assert_eq!(cut(at_end, 10, 0.9, 1.5, false), 0, "over 15 % of the chain, not broad");
            assert_eq!(cut(at_end, 10, 0.85, 3.0, true), 10, "a broad leaf over a third of the chain");
            assert_eq!(cut(at_end, 16, 0.85, 3.0, true), 0, "a broad surface over half the chain");
        }
    }

    #[test]
    fn a_short_slender_run_stepped_well_in_front_is_cut_and_a_longer_or_nearer_one_is_not() {
        // 60 slender members 3 px apart on the part at depth 1; focal 1000 px and the gap 0.03, so
        // R = 0.01 is about 10.5 px at the run's depth 0.95 (4 R = 42 px). The last or first
        // `count` members step to `depth` at once.
        let arc: Vec<f32> = (0..60).map(|i| 3.0 * i as f32).collect();
        let part = || -> Vec<_> {
            (0..60)
                .map(|i| (i, Candidate { depth: 1.0, score: 1.0, near: 1.0, pixel: i, layer: 0, wide: 0.0 }))
                .collect()
        };
        let cut = |at_end: bool, count: usize, depth: f32, focal_px: f32| {
            let mut chain = part();
            for j in 0..count {
                chain[if at_end { 59 - j } else { j }].1.depth = depth;
            }
            cut_occluder_ends(&mut chain, &arc, 0.03, focal_px);
            60 - chain.len()
        };
        for at_end in [true, false] {
            assert_eq!(cut(at_end, 3, 0.95, 1000.0), 3, "a few radii on a nearer part: cut");
            assert_eq!(cut(at_end, 12, 0.95, 1000.0), 12, "33 px, under 4 R: cut");
            assert_eq!(cut(at_end, 18, 0.95, 1000.0), 0, "51 px, over 4 R: the part going on");
            assert_eq!(cut(at_end, 1, 0.95, 1000.0), 0, "one member");
            assert_eq!(cut(at_end, 3, 0.965, 1000.0), 0, "within 1.25 depth gaps");
            assert_eq!(cut(at_end, 3, 1.05, 1000.0), 0, "behind: the part going on");
            assert_eq!(cut(at_end, 3, 0.95, 0.0), 0, "no focal length: radii on screen unknown");
        }
        // a run stepping twice: four members 1.5 gaps in front, then one more 1.3 gaps in front of
        // them (a single member is not a run of its own; from the first step it is)
        let mut chain = part();
        for m in &mut chain[55..59] {
            m.1.depth = 0.955;
        }
        chain[59].1.depth = 0.915;
        cut_occluder_ends(&mut chain, &arc, 0.03, 1000.0);
        assert_eq!(chain.len(), 55, "cut at the first step");
    }

    #[test]
    fn a_run_stepped_in_front_that_goes_on_as_the_chain_went_is_kept() {
        // 60 slender members 3 px apart, focal 1000 px, the gap 0.03 (R = 0.01, 10-13 px on screen).
        // A foot receding towards the camera (depth 1 - 0.0012 per px), a bar in front of it over
        // members 40-47 (flat at member 39's depth), then the last `count` members step 1.1 gaps
        // in front of the bar, each at `depth(arc)`: 33 px, under 4 R, so the short-run rule cuts
        // them unless they go on as the chain before them went.
        let arc: Vec<f32> = (0..60).map(|i| 3.0 * i as f32).collect();
        let receding = |a: f32| 1.0 - 0.0012 * a;
        let cut = |count: usize, depth: &dyn Fn(f32) -> f32| {
            let mut chain: Vec<_> = (0..60)
                .map(|i| {
                    (
                        i,
                        Candidate {
                            depth: receding(arc[i.min(39)]),
                            score: 1.0,
                            near: 1.0,
                            pixel: i,
                            layer: 0,
                            wide: 0.0,
                        },
                    )
                })
                .collect();
            for m in &mut chain[60 - count..] {
                m.1.depth = depth(arc[m.0]);
            }
            cut_occluder_ends(&mut chain, &arc, 0.03, 1000.0);
            60 - chain.len()
        };
        assert_eq!(cut(12, &receding), 0, "the foot going on beyond the bar: kept");
        assert_eq!(cut(12, &|_| 0.8), 12, "a nearer part, flat: cut");
        assert_eq!(
            cut(12, &|a| receding(a) - 0.2 * (a - 144.0) / 33.0),
            12,
            "coming on far faster, past the line: cut"
        );
        assert_eq!(cut(12, &|a| 0.815 + 0.0006 * (a - 144.0)), 12, "receding the other way: cut");
        assert_eq!(cut(6, &receding), 6, "6 members: too few to tell a trend");
    }

    #[test]
    fn a_run_stepped_in_front_of_a_bump_behind_is_kept_where_level_with_the_chain() {
        // 60 members 3 px apart at depth 1, focal 1000 px, the gap 0.03 (R = 0.01, 10 px on screen):
        // the `bump` members before the last `count` lie 1.2 gaps behind (the icing beside a
        // sprinkle), and the run after them 1.2 gaps in front of the bump, 0.01 nearer than the part.
        let arc: Vec<f32> = (0..60).map(|i| 3.0 * i as f32).collect();
        let cut = |bump: usize, count: usize| {
            let mut chain: Vec<_> = (0..60)
                .map(|i| (i, Candidate { depth: 1.0, score: 1.0, near: 1.0, pixel: i, layer: 0, wide: 0.0 }))
                .collect();
            for m in &mut chain[60 - count - bump..60 - count] {
                m.1.depth = 1.036;
            }
            for m in &mut chain[60 - count..] {
                m.1.depth = 0.99;
            }
            cut_occluder_ends(&mut chain, &arc, 0.03, 1000.0);
            60 - chain.len()
        };
        assert_eq!(cut(3, 10), 0, "level with the chain before the bump: kept");
        assert_eq!(cut(3, 6), 6, "6 members: judged on the member before the step");
        assert_eq!(cut(20, 10), 10, "a stretch behind as long as the window's median: cut");
    }

    #[test]
    fn a_stem_behind_a_leaf_in_the_middle_gains_over_its_stretch_though_not_over_all() {
        // 100 samples 3 px apart, focal 1000 px, depth 1, the gap 0.03 (R = 0.01, 10 px on screen,
        // 4 R = 40 px). Both chains follow the stem seen (score 1) but over `stretch`, where the
        // visible chain runs over a leaf 0.1 in front (score 0.5, `wide` radii wider) and the chain
        // behind on the stem hidden under it (0.9 x 0.87): 0.78 against 0.5 there, 1.56 x, while
        // over all (40 of 100 samples) 91.2 against 80, 1.14 x, under the 15 % of `BEHIND_GAIN`.
        let arc: Vec<f32> = (0..100).map(|i| 3.0 * i as f32).collect();
        let stem = |i: usize| (i, Candidate { depth: 1.0, score: 1.0, near: 1.0, pixel: i, layer: 0, wide: 0.0 });
        let gains = |stretch: std::ops::Range<usize>, wide: f32| {
            let visible: Vec<_> = (0..100)
                .map(|i| match stretch.contains(&i) {
                    true => (i, Candidate { depth: 0.9, score: 0.5, near: 1.0, pixel: i, layer: 0, wide }),
                    false => stem(i),
                })
                .collect();
            let behind: Vec<_> = (0..100)
                .map(|i| match stretch.contains(&i) {
                    true => (i, Candidate { depth: 1.0, score: 0.78, near: 1.0, pixel: i, layer: 1, wide: 0.0 }),
                    false => stem(i),
                })
                .collect();
            gains_where_they_differ(&behind, &visible, &arc, 0.03, 1000.0)
        };
        assert!(gains(30..70, 3.0), "a leaf over the middle: the stem behind it");
        assert!(!gains(30..70, 1.0), "a narrow surface over the middle (a fork's far side) stays");
        assert!(!gains(0..40, 3.0), "at an end: the cut to the visible ends decides");
        assert!(!gains(60..100, 3.0), "at the other end likewise");
        assert!(!gains(50..63, 3.0), "13 samples, 36 px from the first to the last: under 4 R");
        assert!(gains(50..65, 3.0), "15 samples, 42 px: over 4 R");
    }

    #[test]
    fn a_part_seen_nowhere_is_the_chain_behind_only_where_the_stroke_lies_on_a_leaf_or_body() {
        // 40 samples 3 px apart (focal 1000 px, depth 1, the gap 0.03: R 10 px on screen, a rod's
        // 2 R 20 px): in front a surface `wide` radii wider than the part (score 0.5), behind it a
        // slender one (0.9 x 0.95), seen at its last `40 - hidden` samples
        let arc: Vec<f32> = (0..40).map(|i| 3.0 * i as f32).collect();
        let chains = |wide: f32, hidden: usize| {
            let front: Vec<_> = (0..40)
                .map(|i| (i, Candidate { depth: 0.9, score: 0.5, near: 1.0, pixel: i, layer: 0, wide }))
                .collect();
            let behind: Vec<_> = (0..40)
                .map(|i| {
                    let layer = usize::from(i < hidden);
                    (i, Candidate { depth: 1.0, score: 0.855, near: 1.0, pixel: i, layer, wide: 0.0 })
                })
                .collect();
            seen_stretch(&behind, &arc, 0.03, 1000.0).is_none()
                && hidden_all_along(&behind, 0.855 * 40.0, &front, 0.5 * 40.0)
        };
        assert!(chains(3.0, 40), "a leaf over the whole stroke: the stem behind it");
        assert!(!chains(1.0, 40), "a slender surface in front (a rope on a floor) stays");
        assert!(chains(3.0, 34), "seen over 15 px, under a rod: the stem behind it");
        assert!(!chains(3.0, 32), "seen over 21 px: the cut to the visible ends decides");
    }

    #[test]
    fn an_end_run_turning_sharply_off_the_part_is_cut_and_a_bend_or_a_bump_is_not() {
        // Members 3 px apart, focal 1000 px at depth ~1 (a pixel is 0.001 wide there), R = 0.01
        // (the depth gap 0.03). `profile(x)` is the depth at x px along the stroke.
        let cut = |count: usize, profile: &dyn Fn(f32) -> f32, wide: &dyn Fn(usize) -> f32, at_end: bool| {
            let arc: Vec<f32> = (0..count).map(|i| 3.0 * i as f32).collect();
            let mut chain: Vec<_> = (0..count)
                .map(|i| {
                    (i, Candidate { depth: profile(arc[i]), score: 1.0, near: 1.0, pixel: i, layer: 0, wide: wide(i) })
                })
                .collect();
            if !at_end {
                // the same chain drawn from the other end
                let depths: Vec<f32> = chain.iter().rev().map(|m| m.1.depth).collect();
                let wides: Vec<f32> = chain.iter().rev().map(|m| m.1.wide).collect();
                for (k, m) in chain.iter_mut().enumerate() {
                    (m.1.depth, m.1.wide) = (depths[k], wides[k]);
                }
            }
            cut_occluder_ends(&mut chain, &arc, 0.03, 1000.0);
            count - chain.len()
        };
        let slender = |_: usize| 0.0;
        // receding at 45 degrees for 165 px, then 25 members (75 px, 7.5 R) back towards the camera
        let peak = |x: f32| if x <= 165.0 { 1.0 + 0.001 * x } else { 1.165 - 0.001 * (x - 165.0) };
        for at_end in [true, false] {
            // (cut at the turn, within a member: the depths are judged by a running median)
            assert!((24..=25).contains(&cut(81, &peak, &slender, at_end)), "a 90 degree turn towards the camera: cut");
            let valley = |x: f32| 2.0 - peak(x);
            assert!((24..=25).contains(&cut(81, &valley, &slender, at_end)), "a 90 degree turn away from it: cut");
            // flat, then 35 degrees towards the camera over 150 px (10.5 R in front): a bend
            let bend = |x: f32| if x <= 297.0 { 1.0 } else { 1.0 - 0.0007 * (x - 297.0) };
            assert_eq!(cut(150, &bend, &slender, at_end), 0, "a gentle bend is the part");
            // receding, with one centre 4 R off and a dip of 3 R
            let bumpy = |x: f32| {
                1.0 + 0.0005 * x
                    + if x == 120.0 {
                        0.04
                    } else if (123.0..=150.0).contains(&x) {
                        -0.03
                    } else {
                        0.0
                    }
            };
            assert_eq!(cut(81, &bumpy, &slender, at_end), 0, "a bump is no turn");
            // the turn again, but the run after it is slender and the longer side wide
            let wide_before = |i: usize| if i < 55 { 3.0 } else { 0.0 };
            assert_eq!(cut(81, &peak, &wide_before, at_end), 0, "the slender side is the part");
            // a valley with a flat bottom (x 21-39 px): gently up to the start, steeply behind over
            // the last 30 px. Both sides are as slender, and beyond the bottom (what lies within half
            // a gap of it) the run is the longer: the part, wherever along the bottom the apex falls.
            // Measured from the bottom's member nearest the end, the other side was the longer (39
            // px against 30) and the run was cut.
            let flat_valley = |x: f32| {
                if x < 21.0 {
                    1.0 + 0.0008 * (21.0 - x)
                } else if x <= 39.0 {
                    1.0
                } else {
                    1.0 + 0.0025 * (x - 39.0)
                }
            };
            assert_eq!(cut(24, &flat_valley, &slender, at_end), 0, "the longer side beyond a flat bottom is the part");
            // a part lying level for 60 px after 30 px receding gently, then a bar crossing in front
            // that the stroke runs on over for 48 px, 63 degrees towards the camera (a cradle's
            // other hook): the level stretch is the part, and counts for its side (about 95 px
            // against 42). Beyond the plateau alone (15 px of the lead-in) the bar was the longer,
            // and kept.
            let level_then_bar = |x: f32| {
                if x < 30.0 {
                    1.0 + 0.001 * x
                } else if x <= 90.0 {
                    1.03
                } else {
                    1.03 - 0.002 * (x - 90.0)
                }
            };
            assert!(
                (16..=17).contains(&cut(47, &level_then_bar, &slender, at_end)),
                "a bar in front after a level part: cut"
            );
        }
    }
}
