//! Segmentation and binding (docs/deformation.md, "Segmentation"): which Gaussians follow a rod,
//! and where each sits on the rest polyline, from the scene's centres in one call.
//!
//! Three sets, found over the links between centres (`proximity`):
//! - the part: grown from the centres within R of the axis over linked centres within
//!   `grow * R` of it and within the rod's extent along it, less a surface of another colour the
//!   part lies on (`surface_left_out`, where colours are given);
//! - attached parts: components of the links among the other centres that touch the part and are
//!   small (every piece within `attach_size` of where it joins, or within `attach_size_fewer` where
//!   it holds no more centres than the part, none within a link of the searched region's edge).
//!   Each rides with the part centre it joins at; within `end_margin * R` of a rod end only what
//!   lies past that end is attached.
//!
//! Every decision is the one of the NumPy implementation this replaced (kept as the test oracle,
//! `tests/reference/segment_reference.py`), to the bit: a `f32` distance is compared with a radius
//! in `f32` (as NumPy compares a `float32` array with a Python float), and the arc lengths come
//! from the caller.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::proximity::{self, ProximityError};
use crate::{Nearest, PolylineError, nearest_on_polyline, rows_in_box};

/// What segmentation needs besides the polyline and the scene. Lengths are in world units unless
/// a field says radii.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentParams {
    /// R, the rod's radius.
    pub radius: f64,
    /// The part's cross-section reaches `grow * R` from the axis (radii).
    pub grow: f64,
    /// The link is `link_spacings` times the part's median distance to its 4th-nearest
    /// neighbour, kept within `[link_min, link_max]` (radii).
    pub link_spacings: f32,
    pub link_min: f64,
    pub link_max: f64,
    /// The largest attached part; `None`: nothing is attached.
    pub attach_size: Option<f64>,
    /// The largest attached part that holds no more centres than the part itself (a leaf on its
    /// stem; a pot under a stem's base holds more): `None` or less than `attach_size`, that.
    pub attach_size_fewer: Option<f64>,
    /// Within this many radii of a rod end, only what lies past the end is attached.
    pub end_margin: f64,
}

/// Where each Gaussian that follows the rod sits on the rest polyline, ordered by scene row.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Binding {
    /// Rows of the scene.
    pub rows: Vec<u32>,
    /// Polyline segment `i` (between vertices `i` and `i + 1`) and the parameter on it: the
    /// Gaussian's own nearest point, or for an attached one the point where its part joins.
    pub segment: Vec<u32>,
    pub t: Vec<f32>,
    /// The centre minus that rest point.
    pub offset: Vec<[f32; 3]>,
    /// The distance from the centre to the polyline.
    pub distance: Vec<f32>,
    /// Rides rigidly with the point where its attached part joins.
    pub attached: Vec<bool>,
    /// The colours that told a surface under the part from it, where one was left out
    /// (`surface_left_out`).
    pub surface: Option<Surface>,
}

/// A surface left out of the part: its colour and the part's (RGB).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    pub part_colour: [f32; 3],
    pub colour: [f32; 3],
}

impl Surface {
    /// Whether `colour` is nearer the surface's colour than the part's.
    pub fn has(&self, colour: &[f32; 3]) -> bool {
        colour_distance(colour, &self.colour) < colour_distance(colour, &self.part_colour)
    }
}

/// What makes segmentation impossible.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SegmentError {
    #[error(transparent)]
    Polyline(#[from] PolylineError),
    #[error(transparent)]
    Proximity(#[from] ProximityError),
    #[error("{name} must be finite and {bound}, got {value}")]
    BadParameter { name: &'static str, bound: &'static str, value: f64 },
    #[error("{arcs} arc lengths for {vertices} polyline vertices")]
    ArcCount { vertices: usize, arcs: usize },
    #[error("{colours} colours for {means} centres")]
    ColourCount { means: usize, colours: usize },
}

/// A surface counts as another colour than the part's where the two colours lie further apart
/// than this many times the part's own spread (the median distance of its seeds' colours from
/// their median), and at least `SURFACE_LEAST_GAP` (RGB in 0..1, Euclidean): the thresholds of the
/// radius told by colour (docs/extraction.md, "A part lying on a surface").
const SURFACE_SPREADS: f32 = 4.0;
const SURFACE_LEAST_GAP: f32 = 0.2;
/// Fewer seeds or surface centres than this tell no colour.
const SURFACE_LEAST_CENTRES: usize = 8;
/// A surface is a sheet: its centres near the part scatter along their mean direction from the axis
/// (its thickness) by at most this share of their scatter across it, beside the axis (its width;
/// standard deviations). The floor under a rope: 0.04-0.05, about 0.3 with its heights scattered
/// by 0.4 R (at 0.25 that floor stayed bound); a clean half tube, 0.5; a tree branch's side in
/// shade, which is another colour too: 0.70-0.99.
const SHEET_FLATNESS: f64 = 0.4;

/// A part lying on a surface of another colour (a cable on a table, a rope on a floor;
/// docs/deformation.md, "Segmentation", **A surface under the part**): the surface runs through
/// the part's reach beside the axis, and every centre of it there would be grown into the part.
///
/// The surface's colour is the median of the centres just past the reach beside the rod (`kind`
/// `OTHER`, not past an end), the part's the median of the seeds nearer their own median than the
/// surface's (the surface passes within R of the axis). Where the two colours differ
/// (`SURFACE_SPREADS`) and the centres nearer the surface's colour form a sheet beside the axis
/// (`SHEET_FLATNESS`), those centres are left out (`OTHER`). Elsewhere nothing changes: a stem
/// among leaves of its own green, a branch whose baked shading darkens one side.
fn surface_left_out(kind: &mut [u8], near: &Centres, colours: &[[f32; 3]], rod: &Rod) -> Option<Surface> {
    let vertices = rod.polyline.len();
    let pick = |wanted: &dyn Fn(usize) -> bool| -> Vec<[f32; 3]> {
        (0..kind.len()).filter(|&i| wanted(i)).map(|i| colours[i]).collect()
    };
    let seeds = pick(&|i| kind[i] == proximity::SEED);
    let surface = pick(&|i| kind[i] == proximity::OTHER && which_end(&near.nearest[i], vertices).is_none());
    if seeds.len() < SURFACE_LEAST_CENTRES || surface.len() < SURFACE_LEAST_CENTRES {
        return None;
    }
    let surface_colour = median_colour(&surface);
    let first = median_colour(&seeds);
    let own: Vec<[f32; 3]> =
        seeds.into_iter().filter(|c| colour_distance(c, &first) <= colour_distance(c, &surface_colour)).collect();
    if own.len() < SURFACE_LEAST_CENTRES {
        return None;
    }
    let part_colour = median_colour(&own);
    let spread = median(&mut own.iter().map(|c| colour_distance(c, &part_colour)).collect::<Vec<_>>());
    if colour_distance(&part_colour, &surface_colour) <= (SURFACE_SPREADS * spread).max(SURFACE_LEAST_GAP) {
        return None;
    }
    let surface = Surface { part_colour, colour: surface_colour };
    let left_out: Vec<usize> =
        (0..kind.len()).filter(|&i| kind[i] != proximity::OTHER && surface.has(&colours[i])).collect();
    if left_out.len() < SURFACE_LEAST_CENTRES || !is_sheet(&left_out, near, rod) {
        return None;
    }
    for i in left_out {
        kind[i] = proximity::OTHER;
    }
    Some(surface)
}

/// Whether the centres `which` of `near` lie in a sheet beside the axis (`SHEET_FLATNESS`): their
/// offsets from their nearest points on the polyline, along the mean of those offsets' directions
/// and across it (perpendicular to that and to the polyline there).
fn is_sheet(which: &[usize], near: &Centres, rod: &Rod) -> bool {
    let (offsets, tangents): (Vec<DVec3>, Vec<DVec3>) = which
        .iter()
        .map(|&i| {
            let (n, p) = (&near.nearest[i], near.points[i]);
            let a = DVec3::from(rod.polyline[n.segment as usize]);
            let b = DVec3::from(rod.polyline[n.segment as usize + 1]);
            (Vec3::from(p).as_dvec3() - a.lerp(b, f64::from(n.t)), (b - a).normalize_or_zero())
        })
        .unzip();
    let direction = offsets.iter().map(|o| o.normalize_or_zero()).sum::<DVec3>().normalize_or_zero();
    if direction == DVec3::ZERO {
        return false;
    }
    let deviation = |values: Vec<f64>| {
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt()
    };
    let thickness = deviation(offsets.iter().map(|o| o.dot(direction)).collect());
    let width = deviation(offsets.iter().zip(&tangents).map(|(o, t)| o.dot(t.cross(direction))).collect());
    thickness <= SHEET_FLATNESS * width
}

/// The per-channel median.
fn median_colour(colours: &[[f32; 3]]) -> [f32; 3] {
    std::array::from_fn(|c| median(&mut colours.iter().map(|v| v[c]).collect::<Vec<_>>()))
}

/// The middle value (the upper one of an even count); `values` is reordered and not empty.
fn median(values: &mut [f32]) -> f32 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f32::total_cmp).1
}

fn colour_distance(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    Vec3::from(*a).distance(Vec3::from(*b))
}

/// The Gaussians (centres `means`) that follow the rod on `polyline`, bound (see the module
/// docs). `arc` is the arc length at each vertex and `length` the rod's length, as the caller
/// measures them (a sum in another order may differ from the last arc length in the last bits).
/// `colours` (RGB per row of `means`, when known) keep a surface the part lies on out of it
/// (`surface_left_out`).
pub fn segment_and_bind(
    polyline: &[[f64; 3]],
    arc: &[f64],
    length: f64,
    means: &[[f32; 3]],
    colours: Option<&[[f32; 3]]>,
    params: &SegmentParams,
) -> Result<Binding, SegmentError> {
    let vertices = polyline.len();
    if vertices < 2 {
        return Err(PolylineError::TooFewVertices(vertices).into());
    }
    if let Some(i) = polyline.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        return Err(PolylineError::NonFiniteVertex(i).into());
    }
    if arc.len() != vertices {
        return Err(SegmentError::ArcCount { vertices, arcs: arc.len() });
    }
    let radius = checked("radius", params.radius, Bound::Positive)?;
    let part_reach = checked("grow", params.grow, Bound::NotNegative)? * radius;
    checked("end_margin", params.end_margin, Bound::NotNegative)?;
    checked("length", length, Bound::NotNegative)?;
    if let Some(size) = params.attach_size {
        checked("attach_size", size, Bound::NotNegative)?;
    }
    if let Some(size) = params.attach_size_fewer {
        checked("attach_size_fewer", size, Bound::NotNegative)?;
    }
    if let Some(colours) = colours
        && colours.len() != means.len()
    {
        return Err(SegmentError::ColourCount { means: means.len(), colours: colours.len() });
    }
    let rod = Rod { polyline, polyline32: polyline.iter().map(|v| v.map(|c| c as f32)).collect(), means };

    // The part: exact nearest points of everything within its reach (and a link more, where what
    // touches it from outside lies).
    let near = rod.within(part_reach + params.link_max * radius, &[], false)?;
    // The rod's extent: a centre past an end vertex is the part's within R of it (the end cap);
    // what continues past that is not.
    let (part_reach32, radius32) = (part_reach as f32, radius as f32);
    let mut kind: Vec<u8> = near
        .nearest
        .iter()
        .map(|n| {
            let at_end = which_end(n, vertices).is_some();
            let eligible = n.distance <= part_reach32 && (!at_end || n.distance <= radius32);
            match (eligible, n.distance <= radius32) {
                (true, true) => proximity::SEED,
                (true, false) => proximity::ELIGIBLE,
                _ => proximity::OTHER,
            }
        })
        .collect();
    let surface = colours.and_then(|colours| {
        let colour_of: Vec<[f32; 3]> = near.rows.iter().map(|&r| colours[r as usize]).collect();
        surface_left_out(&mut kind, &near, &colour_of, &rod)
    });
    let link_bounds = ((params.link_min * radius) as f32, (params.link_max * radius) as f32);
    let part = proximity::Part::grow(&near.points, &kind, params.link_spacings, link_bounds.0, link_bounds.1)?;
    let in_part = part.members();
    // whose (segment, t) each row takes: its own, or where its attached part joins (near rows,
    // then the rows around them searched for attached parts)
    let mut home: Vec<Option<u32>> = (0..near.rows.len() as u32).map(|i| in_part[i as usize].then_some(i)).collect();
    let mut attached = vec![false; near.rows.len()];
    let mut around = Centres::default();
    if let (Some(attach_size), true) = (params.attach_size, part.touched) {
        let sizes = (attach_size, params.attach_size_fewer.map_or(attach_size, |s| s.max(attach_size)));
        let link = f64::from(part.link);
        // what a part can reach from where it joins, plus two links (a larger body shows itself
        // by coming within a link of the edge)
        let reach = part_reach + sizes.1 + 2.0 * link;
        around = rod.within(reach, &near.rows, true)?;
        let joined = attached_parts(&near, &around, &part, &in_part, part_reach, reach, sizes)?;
        let ends = |row: usize| match row.checked_sub(near.rows.len()) {
            None => which_end(&near.nearest[row], vertices),
            Some(a) => which_end(&around.nearest[a], vertices),
        };
        let margin = params.end_margin * radius;
        let (rows, contact) = not_from_a_neighbour(&joined, &near.nearest, arc, ends, length, margin);
        home.resize(near.rows.len() + around.rows.len(), None);
        attached.resize(home.len(), false);
        for (row, contact) in rows.into_iter().zip(contact) {
            (home[row], attached[row]) = (Some(contact), true);
        }
    }
    Ok(Binding { surface, ..bind(&rod, &near, &around, &home, &attached) })
}

enum Bound {
    Positive,
    NotNegative,
}

fn checked(name: &'static str, value: f64, bound: Bound) -> Result<f64, SegmentError> {
    let (ok, bound) = match bound {
        Bound::Positive => (value > 0.0, "> 0"),
        Bound::NotNegative => (value >= 0.0, ">= 0"),
    };
    if ok && value.is_finite() { Ok(value) } else { Err(SegmentError::BadParameter { name, bound, value }) }
}

/// Which end of the rod a nearest point is (the query point lies past it), if either.
fn which_end(nearest: &Nearest, vertices: usize) -> Option<usize> {
    if nearest.segment == 0 && nearest.t <= 0.0 {
        Some(0)
    } else if nearest.segment as usize + 2 == vertices && nearest.t >= 1.0 {
        Some(1)
    } else {
        None
    }
}

/// The rest polyline (`f64`, and as the nearest-point queries take it) and the scene's centres.
struct Rod<'a> {
    polyline: &'a [[f64; 3]],
    polyline32: Vec<[f32; 3]>,
    means: &'a [[f32; 3]],
}

/// Centres of the scene near the rod: rows (ascending), their points, and their nearest points on
/// the polyline.
#[derive(Default)]
struct Centres {
    rows: Vec<u32>,
    points: Vec<[f32; 3]>,
    nearest: Vec<Nearest>,
}

impl Rod<'_> {
    /// The centres within `reach` of the polyline, less the rows `except` (ascending). A box
    /// around the polyline grown by `reach` cuts the scene first, its `f32` bounds rounded
    /// outwards; the distance is compared with `reach` in `f64` and, where `rounded_too`, in
    /// `f32` too (as the NumPy filter of a `float32` array with a Python float did).
    fn within(&self, reach: f64, except: &[u32], rounded_too: bool) -> Result<Centres, PolylineError> {
        let bound = |pick: fn(f64, f64) -> f64, start: f64, grow: f64| -> [f64; 3] {
            std::array::from_fn(|k| self.polyline.iter().map(|v| v[k]).fold(start, pick) + grow)
        };
        let low = bound(f64::min, f64::INFINITY, -reach).map(|c| (c as f32).next_down());
        let high = bound(f64::max, f64::NEG_INFINITY, reach).map(|c| (c as f32).next_up());
        let mut rows = rows_in_box(self.means, low, high);
        if !except.is_empty() {
            let mut skip = except.iter().peekable();
            rows.retain(|&r| {
                while skip.next_if(|&&e| e < r).is_some() {}
                skip.peek() != Some(&&r)
            });
        }
        let points: Vec<[f32; 3]> = rows.iter().map(|&r| self.means[r as usize]).collect();
        let found = nearest_on_polyline(&self.polyline32, &points, reach)?;
        let reach32 = reach as f32;
        let count = found.iter().flatten().count();
        let mut centres = Centres {
            rows: Vec::with_capacity(count),
            points: Vec::with_capacity(count),
            nearest: Vec::with_capacity(count),
        };
        for (k, nearest) in found.into_iter().enumerate() {
            if let Some(n) = nearest.filter(|n| !rounded_too || n.distance <= reach32) {
                centres.rows.push(rows[k]);
                centres.points.push(points[k]);
                centres.nearest.push(n);
            }
        }
        Ok(centres)
    }
}

/// The small parts attached to the part: (row, contact) of each of their rows, rows numbered over
/// `near` then `around`, the contact the part row (of `near`) it joins at.
///
/// A part is a component of the links among the other rows (not the part's). It is small when
/// it touches the part, none of it comes within a link of the searched region's edge (`reach`
/// less a link from the axis; a large body runs on past it), and it fits in a ball around where
/// it joins (the contact of its first row that has one): of `sizes.0`, or of `sizes.1` (the
/// larger) where it holds no more rows than the part.
///
/// Only the components that touch the part matter, so they are searched outward from their
/// touching rows, lowest first (the first search in a component starts at its first touching
/// row), and a search stops at the first row that makes its component large, leaving the rest
/// of the component unsearched: a later search that meets one of its rows learns that its
/// component is large, and one that does not meet any finds a row that shows it.
fn attached_parts(
    near: &Centres,
    around: &Centres,
    part: &proximity::Part,
    in_part: &[bool],
    part_reach: f64,
    reach: f64,
    sizes: (f64, f64),
) -> Result<Vec<(usize, u32)>, ProximityError> {
    // the other rows: near rows not in the part, then the around rows (all of them)
    let others: Vec<usize> = (0..near.rows.len())
        .filter(|&i| !in_part[i])
        .chain(near.rows.len()..near.rows.len() + around.rows.len())
        .collect();
    if others.is_empty() || !in_part.iter().any(|&p| p) {
        return Ok(Vec::new());
    }
    let of = |row: usize| match row.checked_sub(near.rows.len()) {
        None => (near.points[row], near.nearest[row].distance),
        Some(a) => (around.points[a], around.nearest[a].distance),
    };
    let (points, distance): (Vec<[f32; 3]>, Vec<f32>) = others.iter().map(|&row| of(row)).unzip();
    // The part row each other row reaches. The part lies within `part_reach` of the axis, so
    // only rows within a link more can reach it (a margin of 1e-5 covers the rounding of the
    // distances, 1e-7 of them): the around rows, past `part_reach + link_max`, never do unless
    // the link is within that margin of its largest.
    let within = ((part_reach + f64::from(part.link)) * (1.0 + 1e-5)) as f32;
    let asked: Vec<usize> = (0..others.len()).filter(|&o| distance[o] <= within).collect();
    let asked_points: Vec<[f32; 3]> = asked.iter().map(|&o| points[o]).collect();
    let touching: Vec<(usize, u32)> = asked
        .into_iter()
        .zip(part.lowest_touching(&asked_points)?)
        .filter_map(|(o, contact)| Some((o, contact?)))
        .collect();
    // a row makes its component large: past the shell, or farther from the contact than the
    // size (the spread as NumPy's norm in float32 measures it: ((x^2 + y^2) + z^2), rooted)
    let shell = (reach - f64::from(part.link)) as f32;
    let (size, size_fewer) = (sizes.0 as f32, sizes.1 as f32);
    let spread = |o: usize, contact: u32| {
        let (p, q) = (points[o], near.points[contact as usize]);
        let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    let too_far = |o: usize, contact: u32| distance[o] > shell || spread(o, contact) > size_fewer;
    let part_rows = in_part.iter().filter(|&&p| p).count();
    let mut components = proximity::Components::new(&points, part.link)?;
    let (mut joined, mut component) = (Vec::new(), Vec::new());
    for (start, contact) in touching {
        if components.search(start, |o| too_far(o, contact), &mut component) == Some(false)
            && (component.len() <= part_rows || component.iter().all(|&o| spread(o, contact) <= size))
        {
            joined.extend(component.iter().map(|&o| (others[o], contact)));
        }
    }
    joined.sort_unstable();
    Ok(joined)
}

/// Drop the attached parts that join within `margin` of a rod end but lie beside the rod rather
/// than past that end: there the rod meets what it is joined to, and a part touching it (a leaf
/// of the main stem at a side stem's base) belongs to that. A part here is what joins at one
/// contact; it stays when at least half of its rows lie past the end (`ends`).
fn not_from_a_neighbour(
    joined: &[(usize, u32)],
    nearest: &[Nearest],
    arc: &[f64],
    ends: impl Fn(usize) -> Option<usize>,
    length: f64,
    margin: f64,
) -> (Vec<usize>, Vec<u32>) {
    // where along the rod each contact lies
    let along = |c: u32| {
        let n = &nearest[c as usize];
        let s = n.segment as usize;
        arc[s] + f64::from(n.t) * (arc[s + 1] - arc[s])
    };
    let mut keep = vec![true; joined.len()];
    for end in 0..2 {
        let near_end: Vec<usize> = (0..joined.len())
            .filter(|&k| if end == 0 { along(joined[k].1) < margin } else { along(joined[k].1) > length - margin })
            .collect();
        // per contact: how many of its rows lie past this end, of how many
        let mut tally: std::collections::BTreeMap<u32, (usize, usize)> = std::collections::BTreeMap::new();
        for &k in &near_end {
            let entry = tally.entry(joined[k].1).or_default();
            entry.0 += usize::from(ends(joined[k].0) == Some(end));
            entry.1 += 1;
        }
        for &k in &near_end {
            let (past, total) = tally[&joined[k].1];
            if 2 * past < total {
                keep[k] = false;
            }
        }
    }
    joined.iter().zip(&keep).filter(|(_, keep)| **keep).map(|(&joined, _)| joined).unzip()
}

/// The binding, ordered by scene row: each row with a home, at its home's nearest point, with
/// its offset from that rest point (`a + t (b - a)` in `f64`, the offset rounded to `f32`).
fn bind(rod: &Rod, near: &Centres, around: &Centres, home: &[Option<u32>], attached: &[bool]) -> Binding {
    // the near rows and the around rows, each ascending by row: merged
    let mut bound: Vec<(u32, u32, f32, bool)> = Vec::with_capacity(home.iter().flatten().count());
    let (near_home, around_home) = home.split_at(near.rows.len());
    let (mut i, mut a) = (0, 0);
    loop {
        while near_home.get(i).is_some_and(Option::is_none) {
            i += 1;
        }
        while around_home.get(a).is_some_and(Option::is_none) {
            a += 1;
        }
        let near_first = match (near_home.get(i).copied().flatten(), around_home.get(a).copied().flatten()) {
            (None, None) => break,
            (Some(_), Some(_)) => near.rows[i] < around.rows[a],
            (next, _) => next.is_some(),
        };
        let (row, centres, k) = if near_first { (i, near, i) } else { (near.rows.len() + a, around, a) };
        if let Some(h) = home[row] {
            bound.push((centres.rows[k], h, centres.nearest[k].distance, attached[row]));
        }
        (i, a) = if near_first { (i + 1, a) } else { (i, a + 1) };
    }
    let offset = |&(row, home, _, _): &(u32, u32, f32, bool)| -> [f32; 3] {
        let n = &near.nearest[home as usize];
        let (a, b) = (rod.polyline[n.segment as usize], rod.polyline[n.segment as usize + 1]);
        let (t, centre) = (f64::from(n.t), rod.means[row as usize]);
        std::array::from_fn(|k| (f64::from(centre[k]) - (a[k] + t * (b[k] - a[k]))) as f32)
    };
    Binding {
        rows: bound.iter().map(|b| b.0).collect(),
        segment: bound.iter().map(|b| near.nearest[b.1 as usize].segment).collect(),
        t: bound.iter().map(|b| near.nearest[b.1 as usize].t).collect(),
        offset: bound.par_iter().map(offset).collect(),
        distance: bound.iter().map(|b| b.2).collect(),
        attached: bound.iter().map(|b| b.3).collect(),
        surface: None,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    const R: f64 = 0.05;

    fn params() -> SegmentParams {
        SegmentParams {
            radius: R,
            grow: 2.5,
            link_spacings: 1.5,
            link_min: 0.2,
            link_max: 0.75,
            attach_size: Some(8.0 * R),
            attach_size_fewer: None,
            end_margin: 3.0,
        }
    }

    /// A straight rod along x from 0 to 1 (21 vertices), its arc lengths, and around it: a tube
    /// of rings at 0.9 R, a stalk from the tube at x = 0.5 out to 4 R with a blob at its tip, and
    /// a point across a gap.
    fn scene() -> (Vec<[f64; 3]>, Vec<f64>, Vec<[f32; 3]>) {
        let polyline: Vec<[f64; 3]> = (0..21).map(|i| [i as f64 * 0.05, 0.0, 0.0]).collect();
        let arc = polyline.iter().map(|v| v[0]).collect();
        let mut means = Vec::new();
        for i in 0..=200 {
            for k in 0..12 {
                let a = k as f32 * std::f32::consts::TAU / 12.0;
                means.push([i as f32 * 0.005, 0.045 * a.cos(), 0.045 * a.sin()]);
            }
        }
        for k in 0..30 {
            means.push([0.5, 0.045 + k as f32 * 0.005, 0.0]); // stalk, up to 3.9 R
        }
        for k in 0..25 {
            means.push([0.49 + (k % 5) as f32 * 0.005, 0.2 + (k / 5) as f32 * 0.005, 0.0]); // blob
        }
        means.push([0.5, 0.0, 0.5]); // 10 R away
        (polyline, arc, means)
    }

    #[test]
    fn the_tube_follows_and_the_blob_on_its_stalk_rides_where_the_stalk_joins() {
        let (polyline, arc, means) = scene();
        let binding = segment_and_bind(&polyline, &arc, 1.0, &means, None, &params()).unwrap();
        let tube = 201 * 12;
        assert!(binding.rows.windows(2).all(|w| w[0] < w[1]));
        let bound = |row: usize| binding.rows.binary_search(&(row as u32)).ok();
        assert!((0..tube).all(|row| bound(row).is_some_and(|b| !binding.attached[b])));
        assert!(bound(means.len() - 1).is_none());
        // the blob is attached; it takes the (segment, t) of a stalk or tube point near x = 0.5
        let blob: Vec<usize> = (tube + 30..tube + 55).map(|row| bound(row).unwrap()).collect();
        assert!(blob.iter().all(|&b| binding.attached[b]));
        let (segment, t) = (binding.segment[blob[0]], binding.t[blob[0]]);
        assert!(blob.iter().all(|&b| binding.segment[b] == segment && binding.t[b] == t));
        assert!((f64::from(segment) + f64::from(t)) * 0.05 - 0.5 < 0.02);
        // offsets: the centre less the rest point
        for (k, &row) in binding.rows.iter().enumerate() {
            let rest = (f64::from(binding.segment[k]) + f64::from(binding.t[k])) * 0.05;
            assert!((f64::from(means[row as usize][0]) - rest - f64::from(binding.offset[k][0])).abs() < 1e-6);
        }
        // nothing attached when asked so, and the blob then stays
        let none =
            segment_and_bind(&polyline, &arc, 1.0, &means, None, &SegmentParams { attach_size: None, ..params() });
        let none = none.unwrap();
        assert!(!none.attached.iter().any(|&a| a) && !none.rows.contains(&(tube as u32 + 40)));
    }

    #[test]
    fn a_part_past_the_size_rides_along_only_when_it_holds_no_more_centres_than_the_part() {
        // the blob reaches past 1 R from where its stalk leaves the part, within 8 R
        let (polyline, arc, mut means) = scene();
        let blob_row = 201 * 12 + 40;
        let sizes = SegmentParams { attach_size: Some(R), attach_size_fewer: Some(8.0 * R), ..params() };
        let blob_rides = |means: &[[f32; 3]], params: &SegmentParams| {
            let binding = segment_and_bind(&polyline, &arc, 1.0, means, None, params).unwrap();
            binding.rows.binary_search(&blob_row).is_ok_and(|b| binding.attached[b])
        };
        assert!(blob_rides(&means, &sizes));
        assert!(!blob_rides(&means, &SegmentParams { attach_size_fewer: None, ..sizes.clone() }));
        // the blob made denser than the tube (2,500 centres more where it lies): it stays
        for k in 0..2500 {
            means.push([0.49 + (k % 50) as f32 * 0.0004, 0.2 + (k / 50) as f32 * 0.0004, 0.0]);
        }
        assert!(!blob_rides(&means, &sizes));
        assert!(blob_rides(&means, &SegmentParams { attach_size: Some(8.0 * R), ..sizes }));
    }

    #[test]
    fn bad_input_is_an_error() {
        let (polyline, arc, means) = scene();
        let bad = |polyline: &[[f64; 3]], arc: &[f64], params: SegmentParams| {
            segment_and_bind(polyline, arc, 1.0, &means, None, &params).unwrap_err().to_string()
        };
        assert!(bad(&polyline[..1], &arc[..1], params()).contains("at least 2 vertices"));
        let mut nan = polyline.clone();
        nan[3][1] = f64::NAN;
        assert!(bad(&nan, &arc, params()).contains("vertex 3 is not finite"));
        assert!(bad(&polyline, &arc[..5], params()).contains("5 arc lengths for 21"));
        assert!(bad(&polyline, &arc, SegmentParams { radius: 0.0, ..params() }).contains("radius must be"));
        assert!(bad(&polyline, &arc, SegmentParams { grow: f64::NAN, ..params() }).contains("grow must be"));
        assert!(bad(&polyline, &arc, SegmentParams { link_min: 0.0, ..params() }).contains("link must be"));
        let fewer = SegmentParams { attach_size_fewer: Some(f64::NAN), ..params() };
        assert!(bad(&polyline, &arc, fewer).contains("attach_size_fewer must be finite"));
        let far = vec![[1e30_f32, 0.0, 0.0]];
        assert!(segment_and_bind(&polyline, &arc, 1.0, &far, None, &params()).unwrap().rows.is_empty());
        let short = vec![[0.5_f32; 3]; means.len() - 1];
        let err = segment_and_bind(&polyline, &arc, 1.0, &means, Some(&short), &params()).unwrap_err();
        assert!(err.to_string().contains(&format!("{} colours for {} centres", means.len() - 1, means.len())));
    }

    /// The tube of `scene` (orange, its lower half `lower` where given), lying on a floor at y = R
    /// (+y down) of centres 0.2 R apart out to 4 R beside the axis, coloured `floor`.
    fn tube_on_floor(lower: Option<[f32; 3]>, floor: [f32; 3]) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, usize) {
        let (_, _, means) = scene();
        let tube: Vec<[f32; 3]> = means[..201 * 12].to_vec();
        let orange = [0.8, 0.5, 0.2];
        let mut colours: Vec<[f32; 3]> =
            tube.iter().map(|p| if p[1] > 0.0 { lower.unwrap_or(orange) } else { orange }).collect();
        let mut all = tube;
        let count = all.len();
        for i in 0..=100 {
            for k in -20..=20 {
                all.push([i as f32 * 0.01, R as f32, k as f32 * 0.01]);
                colours.push(floor);
            }
        }
        (all, colours, count)
    }

    #[test]
    fn a_floor_of_another_colour_under_the_part_is_left_out_and_a_shaded_side_or_a_floor_of_its_colour_is_not() {
        let (polyline, arc, _) = scene();
        let bound = |means: &[[f32; 3]], colours: &[[f32; 3]]| {
            segment_and_bind(
                &polyline,
                &arc,
                1.0,
                means,
                Some(colours),
                &SegmentParams { attach_size: None, ..params() },
            )
            .unwrap()
            .rows
        };
        // a grey floor: the whole tube is bound and no floor centre is
        let (means, colours, tube) = tube_on_floor(None, [0.5, 0.45, 0.4]);
        let rows = bound(&means, &colours);
        assert_eq!(rows, (0..tube as u32).collect::<Vec<_>>());
        // without colours the floor within 2.5 R is bound, as before
        let blind =
            segment_and_bind(&polyline, &arc, 1.0, &means, None, &SegmentParams { attach_size: None, ..params() });
        assert!(blind.unwrap().rows.len() > tube + 500);
        // a floor of the tube's own colour tells nothing: bound as before
        let (means, colours, tube) = tube_on_floor(None, [0.8, 0.5, 0.2]);
        assert!(bound(&means, &colours).len() > tube + 500);
        // a tube whose lower half is shaded like the floor, with no floor: all of it is bound
        let (means, colours, tube) = tube_on_floor(Some([0.5, 0.45, 0.4]), [0.5, 0.45, 0.4]);
        let (shaded, shaded_colours) = (&means[..tube], &colours[..tube]);
        let mut around = shaded.to_vec();
        let mut around_colours = shaded_colours.to_vec();
        for i in 0..=100 {
            for k in 0..8 {
                // what lies just past the reach, the colour of the shaded side: a rail beside it
                around.push([i as f32 * 0.01, -2.8 * R as f32, (k as f32 - 3.5) * 0.1 * R as f32]);
                around_colours.push([0.5, 0.45, 0.4]);
            }
        }
        let rows = bound(&around, &around_colours);
        assert!((0..tube as u32).all(|r| rows.binary_search(&r).is_ok()));
    }
}
