//! Which points of a cloud are linked: two points are neighbours when they are at most `link`
//! apart, and a gap wider than that separates parts. Segmentation (docs/deformation.md,
//! `crate::segment`) grows the part over these links and finds the small parts attached to it.
//!
//! Points fall in a uniform grid of cells as wide as the link (or, growing a part, as its largest
//! link; see `Grid`): two points are linked when their cells are next to each other (27 cells
//! around a cell) and their `f32` squared distance is at most the link's. Points are linked only
//! within their group (a `u8`); `EXCLUDED` points have no links. The answers do not depend on the
//! order of work.
//!
//! ```
//! use sketchrodgs_polyline::proximity::{grow, linked_to, ELIGIBLE, EXCLUDED, OTHER, SEED};
//! let points = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.5, 0.0, 0.0], [0.6, 0.0, 0.0]];
//! let contact = linked_to(&points, &[0, 0, 1, EXCLUDED], 0, 1, 0.45).unwrap();
//! assert_eq!(contact, [None, Some(2), None, None]); // point 1 reaches point 2 of group 1
//! let grown = grow(&points, &[SEED, ELIGIBLE, ELIGIBLE, OTHER], 1.5, 0.15, 0.15).unwrap();
//! assert_eq!(grown.part, [true, true, false, false]); // a gap of 0.4 after the second
//! assert!(!grown.touched);
//! ```

use std::ops::Range;

use rayon::prelude::*;

/// Points of this group are linked to nothing.
pub const EXCLUDED: u8 = u8::MAX;

/// What makes a query impossible.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProximityError {
    #[error("link must be finite and > 0, got {0}")]
    BadLink(f32),
    #[error("{points} points but {groups} groups")]
    GroupCount { points: usize, groups: usize },
    #[error("point {0} is not finite")]
    NonFinitePoint(usize),
    #[error("points lie in {0} distinct cells along one axis, too many to index")]
    TooManyCells(usize),
    #[error("seed {seed} is not one of the {points} points")]
    SeedOutOfRange { seed: usize, points: usize },
    #[error("{flags} inside flags for {points} points")]
    InsideCount { flags: usize, points: usize },
}

/// The cell of `p` in a grid of `width`-wide cells: `floor(c / width)` per coordinate (without a
/// call to `floorf`, which the baseline x86-64 target makes of `f32::floor`).
fn cell_of(p: [f32; 3], width: f32) -> [i64; 3] {
    p.map(|c| {
        let x = c / width;
        let truncated = x as i64; // saturates far out, where x is whole anyway
        truncated.saturating_sub(i64::from(truncated as f32 > x))
    })
}

/// The squared distance between two points, summed in this order everywhere (a link is decided
/// the same way whichever query asks).
fn distance2(p: [f32; 3], q: [f32; 3]) -> f32 {
    let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// A cell as one integer, x | y | z, each coordinate's code (see `Codes`) in a field as wide as
/// the codes need (`Layout`, 64 bits in all): keys sort like the coordinates, and a neighbouring
/// cell's key is the key plus a constant.
type CellKey = u64;

/// How cell coordinates become codes, per axis: small whole numbers that keep the order and
/// which cells are next to each other, so that a neighbour's code (one more or less) stays within
/// its field.
enum Codes {
    /// The coordinate less `base` (two below the lowest): the grid's cells get codes from 2 up,
    /// and a cell next to one of them (an outside point's, `Grid::key_of`) from 1 up.
    Offset([i128; 3]),
    /// Points absurdly far apart for the cell width: ranks, in which a gap of several cells counts
    /// as one empty cell. Outside points cannot be placed.
    Ranked,
}

/// Ranked codes of one axis's coordinates (`Codes::Ranked`), at most twice as many as there
/// are points.
fn ranked(values: &[i64]) -> Vec<i64> {
    let mut distinct = values.to_vec();
    distinct.sort_unstable();
    distinct.dedup();
    let mut codes = Vec::with_capacity(distinct.len());
    for (i, &v) in distinct.iter().enumerate() {
        let gap = if i == 0 { 2 } else { (i128::from(v) - i128::from(distinct[i - 1])).min(2) as i64 };
        codes.push(codes.last().map_or(0, |&c| c) + gap);
    }
    values.iter().map(|v| distinct.binary_search(v).map_or(0, |i| codes[i])).collect()
}

/// The width of each code's field in a cell key: room for the grid's largest code plus two (a
/// neighbour of an outside point next to the grid).
#[derive(Clone, Copy)]
struct Layout {
    bits: [u32; 3],
}

impl Layout {
    /// The layout for codes up to `largest`, if it fits in a key.
    fn new(largest: [i128; 3]) -> Option<Self> {
        let bits = largest.map(|c| u128::BITS - (c.max(0) as u128 + 2).leading_zeros());
        (bits.iter().sum::<u32>() <= CellKey::BITS).then_some(Self { bits })
    }

    fn key(self, codes: [i64; 3]) -> CellKey {
        let [x, y, z] = codes.map(|c| c as CellKey);
        (((x << self.bits[1]) | y) << self.bits[2]) | z
    }

    fn width(self) -> u32 {
        self.bits.iter().sum()
    }

    /// The 9 columns (x + dx, y + dy) around a cell, as what to add to its key; with
    /// z - 1..=z + 1 in each, its 27 neighbours. The own column first: a search that stops at the
    /// first link mostly finds it there.
    fn columns(self) -> [i64; 9] {
        const STEPS: [[i64; 2]; 9] = [[0, 0], [-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0], [1, 1]];
        STEPS.map(|[dx, dy]| ((dx << self.bits[1]) + dy) << self.bits[2])
    }
}

/// The sorted positions of the points in the 9 columns around a cell.
type Neighbourhood = [Range<u32>; 9];

/// Sort keys by the bits from `shift` up, stably (the bits below, the input index, keep the
/// input order among equals): a least significant digit radix sort over only the bits that
/// differ between keys, 11 at a time (cells a few hundred apart along each axis and three groups
/// take three passes; a comparison sort of `u128` keys took four times as long).
fn radix_sort(keys: &mut Vec<u64>, mut shift: u32) {
    const DIGIT: u32 = 11;
    let Some(&first) = keys.first() else { return };
    let mut varying = keys.iter().fold(0, |acc, &key| acc | (key ^ first)) >> shift;
    let mut scratch = vec![0; keys.len()];
    while varying != 0 {
        let skip = varying.trailing_zeros();
        (shift, varying) = (shift + skip, varying >> skip);
        let digit = |key: u64| (key >> shift) as usize & ((1 << DIGIT) - 1);
        let mut start = [0_u32; (1 << DIGIT) + 1];
        for &key in keys.iter() {
            start[digit(key) + 1] += 1;
        }
        for d in 0..1 << DIGIT {
            start[d + 1] += start[d];
        }
        for &key in keys.iter() {
            let slot = &mut start[digit(key)];
            scratch[*slot as usize] = key;
            *slot += 1;
        }
        std::mem::swap(keys, &mut scratch);
        // (a shift past the top leaves no bits: `varying` ends)
        (shift, varying) = (shift + DIGIT, varying.checked_shr(DIGIT).unwrap_or(0));
    }
}

/// The grid: the points sorted by (cell, group, input index), the occupied cells in that order
/// with where their points start, and the runs of points around each. Sorted so, the points in
/// the three cells of a column (x, y, z - 1..=z + 1) are one run, and the runs around a whole
/// sorted list of cells are found in one pass per column (`neighbourhoods`), with no lookup per
/// point. A query of one group skips the others' points in the runs.
pub(crate) struct Grid {
    width: f32,
    /// At least the largest coordinate magnitude of the points (from their cells).
    farthest: f64,
    codes: Codes,
    layout: Layout,
    columns: [i64; 9],
    /// The points in sorted order, the input index of each, and its group.
    points: Vec<[f32; 3]>,
    index: Vec<u32>,
    group: Vec<u8>,
    /// The occupied cells in sorted order, and the first sorted point of each (`starts` has one
    /// more entry: the end).
    cells: Vec<CellKey>,
    starts: Vec<u32>,
    /// The position in `cells` of each sorted point's cell.
    point_cell: Vec<u32>,
    /// The runs of points around each cell.
    around: Vec<Neighbourhood>,
}

impl Grid {
    /// The grid of `points` (those not `EXCLUDED`), cells `width` wide, with the runs around
    /// every cell.
    pub(crate) fn new(points: &[[f32; 3]], group: &[u8], width: f32) -> Result<Self, ProximityError> {
        let mut grid = Self::sorted(points, group, width)?;
        grid.around = grid.neighbourhoods(&grid.cells);
        Ok(grid)
    }

    /// The grid without the runs around its cells (`Links` finds those of the cells it visits).
    fn sorted(points: &[[f32; 3]], group: &[u8], width: f32) -> Result<Self, ProximityError> {
        if !(width.is_finite() && width > 0.0) {
            return Err(ProximityError::BadLink(width));
        }
        if group.len() != points.len() {
            return Err(ProximityError::GroupCount { points: points.len(), groups: group.len() });
        }
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(ProximityError::NonFinitePoint(i));
        }
        // one pass: each member's cell, and the cells' extent
        let mut members: Vec<(u32, [i64; 3])> = Vec::with_capacity(points.len());
        let (mut low, mut high, mut top_group) = ([i64::MAX; 3], [i64::MIN; 3], 0);
        for (i, (&p, &g)) in points.iter().zip(group).enumerate() {
            if g != EXCLUDED {
                let cell = cell_of(p, width);
                for k in 0..3 {
                    (low[k], high[k]) = (low[k].min(cell[k]), high[k].max(cell[k]));
                }
                top_group = top_group.max(g);
                members.push((i as u32, cell));
            }
        }
        // codes offset from the lowest cell where they fit a key, else ranked
        let offset_layout = Layout::new(std::array::from_fn(|k| i128::from(high[k]) - i128::from(low[k]) + 2));
        let (codes, ranks, layout) = match offset_layout {
            Some(layout) => (Codes::Offset(low.map(|l| i128::from(l) - 2)), Vec::new(), layout),
            None if members.is_empty() => (Codes::Ranked, Vec::new(), Layout { bits: [0; 3] }),
            None => {
                let ranks: Vec<Vec<i64>> =
                    (0..3).map(|k| ranked(&members.iter().map(|m| m.1[k]).collect::<Vec<_>>())).collect();
                let largest = std::array::from_fn(|k| i128::from(ranks[k].iter().copied().max().unwrap_or(0)));
                let layout = Layout::new(largest).ok_or(ProximityError::TooManyCells(members.len()))?;
                (Codes::Ranked, ranks, layout)
            }
        };
        let code_of = |m: usize| -> [i64; 3] {
            if ranks.is_empty() {
                // (the offsets fit a key, so they fit an i64)
                std::array::from_fn(|k| members[m].1[k].wrapping_sub(low[k]).wrapping_add(2))
            } else {
                std::array::from_fn(|k| ranks[k][m])
            }
        };
        // one integer per point, (cell, group, input index), sorted once: a u64 where it fits
        let index_bits = u32::BITS - (points.len() as u32).leading_zeros();
        let group_bits = u8::BITS - top_group.leading_zeros();
        let below_cell = group_bits + index_bits;
        // a coordinate x in cell c has |x| <= max(|c|, |c + 1|) widths, less than a rounding more
        let cells_out = (0..3).map(|k| (low[k] as f64).abs().max((high[k] as f64 + 1.0).abs())).fold(0.0, f64::max);
        let mut grid = Self {
            width,
            farthest: cells_out * f64::from(width) * (1.0 + 1e-6),
            codes,
            layout,
            columns: layout.columns(),
            points: Vec::with_capacity(members.len()),
            index: Vec::with_capacity(members.len()),
            group: Vec::with_capacity(members.len()),
            cells: Vec::new(),
            starts: Vec::new(),
            point_cell: Vec::with_capacity(members.len()),
            around: Vec::new(),
        };
        if layout.width() + below_cell <= u64::BITS {
            let mut keys: Vec<u64> = (0..members.len())
                .map(|m| {
                    let i = members[m].0;
                    (((layout.key(code_of(m)) << group_bits) | u64::from(group[i as usize])) << index_bits)
                        | u64::from(i)
                })
                .collect();
            radix_sort(&mut keys, index_bits);
            let index_mask = (1 << index_bits) - 1;
            grid.fill(points, group, keys.iter().map(|&key| (key >> below_cell, (key & index_mask) as u32)));
        } else {
            let mut keys: Vec<u128> = (0..members.len())
                .map(|m| {
                    let i = members[m].0;
                    u128::from(layout.key(code_of(m))) << below_cell
                        | u128::from(group[i as usize]) << index_bits
                        | u128::from(i)
                })
                .collect();
            keys.sort_unstable();
            let index_mask = (1 << index_bits) - 1;
            grid.fill(
                points,
                group,
                keys.iter().map(|&key| ((key >> below_cell) as CellKey, (key & index_mask) as u32)),
            );
        }
        grid.starts.push(members.len() as u32);
        Ok(grid)
    }

    /// Lay out the points in sorted order: `sorted` gives each one's cell and input index.
    fn fill(&mut self, points: &[[f32; 3]], group: &[u8], sorted: impl Iterator<Item = (CellKey, u32)>) {
        for (k, (cell, i)) in sorted.enumerate() {
            if self.cells.last() != Some(&cell) {
                self.cells.push(cell);
                self.starts.push(k as u32);
            }
            self.point_cell.push(self.cells.len() as u32 - 1);
            self.index.push(i);
            self.group.push(group[i as usize]);
            self.points.push(points[i as usize]);
        }
    }

    fn len(&self) -> usize {
        self.points.len()
    }

    /// The key of the cell of an outside point `p`: `None` where no cell around it can hold a
    /// point of the grid. `Err(())` where the grid cannot place outside points.
    fn key_of(&self, p: [f32; 3]) -> Result<Option<CellKey>, ()> {
        let Codes::Offset(base) = self.codes else { return Err(()) };
        let cell = cell_of(p, self.width);
        let codes: [i128; 3] = std::array::from_fn(|k| i128::from(cell[k]) - base[k]);
        // the grid's cells have codes from 2 to the largest: a neighbour of one, 1 to one more
        let fit = (0..3).all(|k| codes[k] >= 1 && codes[k] < (1 << self.layout.bits[k]) - 1);
        Ok(fit.then(|| self.layout.key(codes.map(|c| c as i64))))
    }

    /// For each of `query` (cell keys in ascending order), the runs of points in the 9 columns
    /// around it: every point within a cell width of any point of the query cell. The first cell
    /// of a column at or after (x + dx, y + dy, z - 1) only moves forwards as the query cells
    /// rise, so each column is one pass (per block of queries, in parallel: a block's first seeks
    /// gallop from the start).
    fn neighbourhoods(&self, query: &[CellKey]) -> Vec<Neighbourhood> {
        const BLOCK: usize = 1024;
        let (cells, starts) = (&self.cells, &self.starts);
        let sweep = |block: &[CellKey]| {
            let (mut first, mut end) = ([0; 9], [0; 9]);
            block
                .iter()
                .map(|&q| {
                    std::array::from_fn(|c| {
                        // codes stay within their fields (see `Codes`): no carries between them
                        let centre = q.wrapping_add_signed(self.columns[c]);
                        first[c] = seek(cells, first[c], centre - 1, false);
                        end[c] = seek(cells, end[c].max(first[c]), centre + 1, true);
                        starts[first[c]]..starts[end[c]]
                    })
                })
                .collect::<Vec<Neighbourhood>>()
        };
        if query.len() <= BLOCK {
            return sweep(query);
        }
        query.par_chunks(BLOCK).flat_map_iter(sweep).collect()
    }

    /// The runs of sorted points in the 27 cells around sorted point `k` (itself included).
    fn around_point(&self, k: usize) -> &Neighbourhood {
        &self.around[self.point_cell[k] as usize]
    }

    /// Calls `visit(j, point, group)` for the sorted points `j` in `runs` until it returns true;
    /// whether one did. (Plain loops over slices: the candidates are the inner loop of every
    /// query.)
    #[inline]
    fn find_in(&self, runs: &Neighbourhood, mut visit: impl FnMut(usize, [f32; 3], u8) -> bool) -> bool {
        for run in runs {
            let (start, end) = (run.start as usize, run.end as usize);
            for ((j, &p), &g) in (start..end).zip(&self.points[start..end]).zip(&self.group[start..end]) {
                if visit(j, p, g) {
                    return true;
                }
            }
        }
        false
    }

    /// The sorted points of `group`, in order.
    fn of_group(&self, group: u8) -> impl Iterator<Item = usize> + '_ {
        (0..self.len()).filter(move |&k| self.group[k] == group)
    }
}

/// The first position at or after `at` whose key is not below `target` (`or_equal`: not at or
/// below it), keys ascending: a few steps forwards (it is mostly there or next, for a query as
/// dense as the keys), then a gallop (a sparse query's next cell may be far on).
#[inline]
fn seek(keys: &[CellKey], mut at: usize, target: CellKey, or_equal: bool) -> usize {
    let below = |key: CellKey| key < target || (or_equal && key == target);
    for _ in 0..4 {
        match keys.get(at) {
            Some(&key) if below(key) => at += 1,
            _ => return at,
        }
    }
    let mut step = 1;
    while at + step <= keys.len() && below(keys[at + step - 1]) {
        at += step;
        step *= 2;
    }
    at + keys[at..(at + step).min(keys.len())].partition_point(|&k| below(k))
}

/// For each point of group `from`, the lowest-numbered point of group `to` within `link` (None
/// where there is none, and for points of other groups).
pub fn linked_to(
    points: &[[f32; 3]],
    group: &[u8],
    from: u8,
    to: u8,
    link: f32,
) -> Result<Vec<Option<u32>>, ProximityError> {
    let grid = Grid::new(points, group, link)?;
    let mut found = vec![None; points.len()];
    if from == EXCLUDED || to == EXCLUDED {
        return Ok(found);
    }
    let link2 = link * link;
    let asked: Vec<usize> = grid.of_group(from).collect();
    let answers: Vec<Option<u32>> = asked
        .par_iter()
        .map(|&k| {
            let (q, mut best) = (grid.points[k], None);
            grid.find_in(grid.around_point(k), |j, p, g| {
                let original = grid.index[j];
                if g == to && best.is_none_or(|b| original < b) && distance2(q, p) <= link2 {
                    best = Some(original);
                }
                false
            });
            best
        })
        .collect();
    for (k, answer) in asked.into_iter().zip(answers) {
        found[grid.index[k] as usize] = answer;
    }
    Ok(found)
}

/// The links among points (within `link`, in cells `link` wide), found point by point: searching outward from a few points of a large cloud costs only
/// the cells searched (the runs around a cell are found when first asked for).
pub(crate) struct Links {
    grid: Grid,
    link: f32,
    /// The sorted position of each input point.
    sorted_at: Vec<u32>,
    /// The runs around each cell asked for so far (`u32::MAX`: not yet), in `runs`.
    runs_at: Vec<u32>,
    runs: Vec<Neighbourhood>,
}

impl Links {
    pub(crate) fn new(points: &[[f32; 3]], link: f32) -> Result<Self, ProximityError> {
        let grid = Grid::sorted(points, &vec![0; points.len()], link)?;
        let mut sorted_at = vec![0; points.len()];
        for (k, &i) in grid.index.iter().enumerate() {
            sorted_at[i as usize] = k as u32;
        }
        let runs_at = vec![u32::MAX; grid.cells.len()];
        Ok(Self { grid, link, sorted_at, runs_at, runs: Vec::new() })
    }

    /// Adds to `linked` the input points linked to input point `i` (itself excluded).
    pub(crate) fn linked_to(&mut self, i: usize, linked: &mut Vec<usize>) {
        let k = self.sorted_at[i] as usize;
        let cell = self.grid.point_cell[k] as usize;
        if self.runs_at[cell] == u32::MAX {
            self.runs_at[cell] = self.runs.len() as u32;
            let around = self.grid.neighbourhoods(&self.grid.cells[cell..=cell]);
            self.runs.extend(around);
        }
        let (grid, q, link2) = (&self.grid, self.grid.points[k], self.link * self.link);
        grid.find_in(&self.runs[self.runs_at[cell] as usize], |j, p, _| {
            if j != k && distance2(q, p) <= link2 {
                linked.push(grid.index[j] as usize);
            }
            false
        });
    }
}

/// Components of the links, searched depth-first one start at a time, each search stopping at the
/// first point that shows its component to be large: a later search that meets one of its points
/// learns that its component is large (a small one was searched whole, so no later search starts
/// in it or reaches it). A large body is not walked whole. Used for attached parts and
/// continuations (`crate::segment`, `crate::continuation`).
pub(crate) struct Components {
    links: Links,
    state: Vec<Search>,
    stack: Vec<usize>,
    linked: Vec<usize>,
}

/// Where the search stands with a point.
#[derive(Clone, Copy, PartialEq)]
enum Search {
    Unseen,
    /// In the component being searched.
    Found,
    /// In a component searched before.
    Done,
}

impl Components {
    pub(crate) fn new(points: &[[f32; 3]], link: f32) -> Result<Self, ProximityError> {
        let links = Links::new(points, link)?;
        let state = vec![Search::Unseen; points.len()];
        Ok(Self { links, state, stack: Vec::new(), linked: Vec::new() })
    }

    /// The component of point `start` into `component` (the points found, cleared first) and
    /// whether it is large: a point of it is `too_far`, or it meets a component searched before.
    /// None where a search before took `start`.
    pub(crate) fn search(
        &mut self,
        start: usize,
        too_far: impl Fn(usize) -> bool,
        component: &mut Vec<usize>,
    ) -> Option<bool> {
        if self.state[start] != Search::Unseen {
            return None;
        }
        let mut large = false;
        self.state[start] = Search::Found;
        component.clear();
        self.stack.push(start);
        'search: while let Some(i) = self.stack.pop() {
            component.push(i);
            if too_far(i) {
                large = true;
                break;
            }
            self.linked.clear();
            self.links.linked_to(i, &mut self.linked);
            for &j in &self.linked {
                match self.state[j] {
                    Search::Unseen => {
                        self.state[j] = Search::Found;
                        self.stack.push(j);
                    }
                    Search::Done => {
                        large = true; // a large component searched in part before
                        break 'search;
                    }
                    Search::Found => {}
                }
            }
        }
        component.append(&mut self.stack); // found, not searched from
        for &i in component.iter() {
            self.state[i] = Search::Done;
        }
        Some(large)
    }
}

/// Per point, whether it lies in a small cluster: a component of the points linked within `link`
/// that holds one of the `seeds` and spans at most `size` (its bounding box's diagonal, in f64).
/// Each search stops at the first point farther than `size` from its seed, whose component
/// therefore spans more: a large body next to the seeds is not walked whole. Segmentation's strays
/// (docs/deformation.md, "Segmentation"; `segment._with_strays`).
pub fn small_clusters(points: &[[f32; 3]], link: f32, seeds: &[usize], size: f64) -> Result<Vec<bool>, ProximityError> {
    if let Some(&seed) = seeds.iter().find(|&&seed| seed >= points.len()) {
        return Err(ProximityError::SeedOutOfRange { seed, points: points.len() });
    }
    let mut small = vec![false; points.len()];
    let mut components = Components::new(points, link)?;
    let mut component = Vec::new();
    let apart = |a: [f32; 3], b: [f32; 3]| {
        let d = [0, 1, 2].map(|k| f64::from(a[k]) - f64::from(b[k]));
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    for &seed in seeds {
        let origin = points[seed];
        if components.search(seed, |i| apart(points[i], origin) > size, &mut component) != Some(false) {
            continue;
        }
        let (mut low, mut high) = (points[seed], points[seed]);
        for &i in &component {
            for k in 0..3 {
                (low[k], high[k]) = (low[k].min(points[i][k]), high[k].max(points[i][k]));
            }
        }
        if apart(high, low) <= size {
            for &i in &component {
                small[i] = true;
            }
        }
    }
    Ok(small)
}

/// Per point, the cluster it lies in, numbered from 0, where that cluster lies within a shell: a
/// component of the points linked within `link` that holds one of the `seeds` and all of whose
/// points are `inside`; `None` elsewhere. Each search stops at the first point outside, whose
/// component runs on past the shell. Segmentation's haze of attached parts (docs/deformation.md,
/// "Segmentation"; `segment._with_haze`).
pub fn clusters_inside(
    points: &[[f32; 3]],
    link: f32,
    seeds: &[usize],
    inside: &[bool],
) -> Result<Vec<Option<u32>>, ProximityError> {
    if let Some(&seed) = seeds.iter().find(|&&seed| seed >= points.len()) {
        return Err(ProximityError::SeedOutOfRange { seed, points: points.len() });
    }
    if inside.len() != points.len() {
        return Err(ProximityError::InsideCount { flags: inside.len(), points: points.len() });
    }
    let mut cluster = vec![None; points.len()];
    let mut components = Components::new(points, link)?;
    let (mut component, mut count) = (Vec::new(), 0);
    for &seed in seeds {
        if components.search(seed, |i| !inside[i], &mut component) == Some(false) {
            for &i in &component {
                cluster[i] = Some(count);
            }
            count += 1;
        }
    }
    Ok(cluster)
}

/// Point kinds for [`grow`].
pub const SEED: u8 = 0;
pub const ELIGIBLE: u8 = 1;
pub const OTHER: u8 = 2;

/// What [`grow`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Grown {
    /// The link used: `spacings` times the seeds' median distance to their 4th-nearest seed,
    /// within `[link_min, link_max]`.
    pub link: f32,
    /// Per point: linked to a seed through seeds and eligible points.
    pub part: Vec<bool>,
    /// Whether an `OTHER` point lies within the link of the part.
    pub touched: bool,
}

/// Grow a part from its seeds (docs/deformation.md, "Segmentation"): the link from the seeds'
/// own spacing, then a breadth-first search from every seed over `SEED` and `ELIGIBLE` points.
pub fn grow(
    points: &[[f32; 3]],
    kind: &[u8],
    spacings: f32,
    link_min: f32,
    link_max: f32,
) -> Result<Grown, ProximityError> {
    let part = Part::grow(points, kind, spacings, link_min, link_max)?;
    Ok(Grown { link: part.link, part: part.members(), touched: part.touched })
}

/// A part grown from its seeds (`grow`), with the grid it grew in, which also answers which part
/// point another point touches (`Part::lowest_touching`).
pub(crate) struct Part {
    grid: Grid,
    /// How many points the part was grown among.
    count: usize,
    pub(crate) link: f32,
    /// Per sorted point of the grid: in the part.
    in_part: Vec<bool>,
    pub(crate) touched: bool,
}

impl Part {
    pub(crate) fn grow(
        points: &[[f32; 3]],
        kind: &[u8],
        spacings: f32,
        link_min: f32,
        link_max: f32,
    ) -> Result<Self, ProximityError> {
        if !(link_min > 0.0 && link_min <= link_max) {
            return Err(ProximityError::BadLink(link_min));
        }
        // one grid, cells as wide as the longest link, for the link and the search
        let grid = Grid::new(points, kind, link_max)?;
        let link = part_link(&grid, spacings, link_min, link_max);
        let link2 = link * link;
        // whether sorted point `k` is linked to a point around it that `wanted(j, group)`
        fn linked_to_any(grid: &Grid, link2: f32, k: usize, wanted: impl Fn(usize, u8) -> bool) -> bool {
            let q = grid.points[k];
            grid.find_in(grid.around_point(k), |j, p, g| wanted(j, g) && distance2(q, p) <= link2)
        }
        // Seeds are the part, and so is every eligible point that touches one (most of them).
        // Only the others need a search: those linked to a touching point, then those linked to
        // these, over eligible points only. (Searching from every touching point instead looked
        // around nearly every eligible point twice.)
        let eligible: Vec<usize> = grid.of_group(ELIGIBLE).collect();
        let touching: Vec<bool> =
            eligible.par_iter().map(|&k| linked_to_any(&grid, link2, k, |_, g| g == SEED)).collect();
        let mut in_part: Vec<bool> = grid.group.iter().map(|&g| g == SEED).collect();
        for (&k, &t) in eligible.iter().zip(&touching) {
            in_part[k] = t;
        }
        let joined: Vec<usize> = eligible
            .par_iter()
            .zip(&touching)
            .filter(|&(&k, &t)| !t && linked_to_any(&grid, link2, k, |j, g| g == ELIGIBLE && in_part[j]))
            .map(|(&k, _)| k)
            .collect();
        for &k in &joined {
            in_part[k] = true;
        }
        let mut queue = joined;
        while let Some(k) = queue.pop() {
            let q = grid.points[k];
            grid.find_in(grid.around_point(k), |j, p, g| {
                if g == ELIGIBLE && !in_part[j] && distance2(q, p) <= link2 {
                    in_part[j] = true;
                    queue.push(j);
                }
                false
            });
        }
        let others: Vec<usize> = grid.of_group(OTHER).collect();
        let touched = others.par_iter().any(|&k| linked_to_any(&grid, link2, k, |j, _| in_part[j]));
        Ok(Self { grid, count: points.len(), link, in_part, touched })
    }

    /// Per input point: in the part.
    pub(crate) fn members(&self) -> Vec<bool> {
        let mut part = vec![false; self.count];
        for (&i, &p) in self.grid.index.iter().zip(&self.in_part) {
            part[i as usize] = p;
        }
        part
    }

    /// For each of `queries`, the lowest input index of a part point within the link, as
    /// [`linked_to`] over the part and the queries finds it (in cells as wide as the link: a pair
    /// of points in cells two apart is not linked, however close the rounding puts them).
    ///
    /// The part's grid has cells `link_max` wide, so every point within the link of a query lies
    /// in the cells around the query's, unless the link is within rounding of `link_max` (and
    /// not equal, which is the same grid); then, or where the grid cannot place outside points,
    /// a grid of the part's points in link-wide cells answers instead.
    pub(crate) fn lowest_touching(&self, queries: &[[f32; 3]]) -> Result<Vec<Option<u32>>, ProximityError> {
        let grid = &self.grid;
        let (link, width) = (self.link, grid.width);
        // |x| / width rounds by half an ulp: cells of points within the link can be one further
        // apart than the distance says only if link > width (1 - 8u) - 4u max |x|
        let u = f64::from(f32::EPSILON) / 2.0;
        let farthest = queries.iter().flatten().fold(grid.farthest, |m, &c| m.max(f64::from(c.abs())));
        let separate = f64::from(width) * (1.0 - 8.0 * u) - 4.0 * u * farthest;
        let placed: Result<Vec<Option<CellKey>>, ()> = queries.iter().map(|&q| grid.key_of(q)).collect();
        let (Ok(placed), true) = (placed, link == width || f64::from(link) <= separate) else {
            return self.lowest_touching_in_link_cells(queries);
        };
        let mut keyed: Vec<(CellKey, usize)> =
            placed.into_iter().enumerate().filter_map(|(i, key)| Some((key?, i))).collect();
        keyed.sort_unstable();
        let around = grid.neighbourhoods(&keyed.iter().map(|k| k.0).collect::<Vec<_>>());
        let link2 = link * link;
        let answers: Vec<Option<u32>> = keyed
            .par_iter()
            .zip(&around)
            .map(|(&(_, i), runs)| {
                let (q, mut best) = (queries[i], None);
                let cell = cell_of(q, link);
                grid.find_in(runs, |j, p, _| {
                    let original = grid.index[j];
                    if self.in_part[j]
                        && best.is_none_or(|b| original < b)
                        && distance2(q, p) <= link2
                        && cell.iter().zip(cell_of(p, link)).all(|(a, b)| a.abs_diff(b) <= 1)
                    {
                        best = Some(original);
                    }
                    false
                });
                best
            })
            .collect();
        let mut found = vec![None; queries.len()];
        for (&(_, i), answer) in keyed.iter().zip(answers) {
            found[i] = answer;
        }
        Ok(found)
    }

    /// `lowest_touching` the long way: `linked_to` over the part's points (at their input
    /// indices) and the queries after them.
    fn lowest_touching_in_link_cells(&self, queries: &[[f32; 3]]) -> Result<Vec<Option<u32>>, ProximityError> {
        let mut points = vec![[0.0; 3]; self.count];
        let mut group = vec![EXCLUDED; self.count];
        for (k, (&i, &p)) in self.grid.index.iter().zip(&self.in_part).enumerate() {
            points[i as usize] = self.grid.points[k];
            if p {
                group[i as usize] = 1;
            }
        }
        points.extend_from_slice(queries);
        group.resize(points.len(), 0);
        let mut found = linked_to(&points, &group, 0, 1, self.link)?;
        Ok(found.split_off(self.count))
    }
}

/// The link for a part: `spacings` times the seeds' median distance to their 4th-nearest seed,
/// from about 2000 seeds (every n-th in the grid's order), kept within `[link_min, link_max]`.
fn part_link(grid: &Grid, spacings: f32, link_min: f32, link_max: f32) -> f32 {
    let seeds: Vec<usize> = grid.of_group(SEED).collect();
    let step = (seeds.len() / 2000).max(1);
    let sample: Vec<usize> = seeds.into_iter().step_by(step).collect();
    let mut fourth: Vec<f32> = sample
        .par_iter()
        .map(|&k| {
            let (q, mut nearest) = (grid.points[k], [f32::INFINITY; 4]);
            grid.find_in(grid.around_point(k), |j, p, g| {
                let d = distance2(q, p);
                if j != k && g == SEED && d < nearest[3] {
                    nearest[3] = d;
                    nearest.sort_unstable_by(f32::total_cmp);
                }
                false
            });
            nearest[3].sqrt()
        })
        .collect();
    if fourth.len() < 5 {
        return link_max;
    }
    let middle = fourth.len() / 2;
    let (_, median, _) = fourth.select_nth_unstable_by(middle, f32::total_cmp);
    (spacings * *median).clamp(link_min, link_max)
}

/// The median, over a sample of `points`, of the distance from each to its `k`-th nearest other
/// point: the spacing from which the continuations and the strays take their link
/// (python/sketchrodgs/segment.py, `_link`). The sample is every `points.len() / samples`-th point
/// (every point if there are fewer). Distances are `f64`, summed over x, y, z in that order before
/// the square root, as scipy's k-d tree sums them, so the result is the one its k-nearest query
/// gives. `None` for fewer than `k + 1` points or `k` 0.
///
/// The points are sorted along their longest extent; each sample scans outwards from its place
/// in that order until that coordinate alone lies farther than its `k`-th nearest so far (a part
/// is long and thin, so a scan meets few points that are not near).
pub fn median_neighbour_distance(points: &[[f32; 3]], k: usize, samples: usize) -> Option<f64> {
    let n = points.len();
    if k == 0 || n <= k {
        return None;
    }
    let points: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
    let extent = |a: usize| {
        let (low, high) =
            points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(p[a]), h.max(p[a])));
        high - low
    };
    let axis = (0..3).fold(0, |best, a| if extent(a) > extent(best) { a } else { best });
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_unstable_by(|&a, &b| points[a][axis].total_cmp(&points[b][axis]));
    let mut place = vec![0; n];
    for (at, &i) in order.iter().enumerate() {
        place[i] = at;
    }
    let sample: Vec<usize> = (0..n).step_by((n / samples.max(1)).max(1)).collect();
    let mut kth: Vec<f64> = sample
        .par_iter()
        .map(|&i| {
            let q = points[i];
            let mut nearest = vec![f64::INFINITY; k]; // squared, ascending
            let mut try_point = |j: usize| -> bool {
                let p = points[j];
                let along = p[axis] - q[axis];
                if along * along > nearest[k - 1] {
                    return false; // this one and all beyond it on this side are farther
                }
                let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                let d = dx * dx + dy * dy + dz * dz;
                if d < nearest[k - 1] {
                    nearest[k - 1] = d;
                    nearest.sort_unstable_by(f64::total_cmp);
                }
                true
            };
            for &j in &order[place[i] + 1..] {
                if !try_point(j) {
                    break;
                }
            }
            for &j in order[..place[i]].iter().rev() {
                if !try_point(j) {
                    break;
                }
            }
            nearest[k - 1].sqrt()
        })
        .collect();
    kth.sort_unstable_by(f64::total_cmp);
    let middle = kth.len() / 2;
    Some(if kth.len() % 2 == 1 { kth[middle] } else { (kth[middle - 1] + kth[middle]) / 2.0 })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Points along x every 0.1, with a gap of 0.5 after the 10th.
    fn chain() -> Vec<[f32; 3]> {
        (0..20).map(|i| [i as f32 * 0.1 + if i >= 10 { 0.5 } else { 0.0 }, 0.0, 0.0]).collect()
    }

    /// The component of every point over `Links`: labels 0, 1, ... in the order of each
    /// component's first point.
    fn components(points: &[[f32; 3]], link: f32) -> Vec<u32> {
        let mut links = Links::new(points, link).unwrap();
        let (mut label, mut next, mut linked) = (vec![u32::MAX; points.len()], 0, Vec::new());
        for start in 0..points.len() {
            if label[start] != u32::MAX {
                continue;
            }
            let mut stack = vec![start];
            label[start] = next;
            while let Some(i) = stack.pop() {
                linked.clear();
                links.linked_to(i, &mut linked);
                for &j in &linked {
                    if label[j] == u32::MAX {
                        label[j] = next;
                        stack.push(j);
                    }
                }
            }
            next += 1;
        }
        label
    }

    #[test]
    fn a_gap_wider_than_the_link_separates_components() {
        let points = chain();
        let labels = components(&points, 0.15);
        assert!(labels[..10].iter().all(|&l| l == 0) && labels[10..].iter().all(|&l| l == 1));
        let bridged = components(&points, 0.65);
        assert!(bridged.iter().all(|&l| l == 0));
    }

    #[test]
    fn groups_do_not_link_to_each_other() {
        let points = chain();
        let group: Vec<u8> = (0..20).map(|i| if i % 10 < 5 { 0 } else { 1 }).collect();
        let contact = linked_to(&points, &group, 0, 1, 0.15).unwrap();
        assert_eq!(contact[4], Some(5));
        assert_eq!(contact[3], None);
        assert_eq!(contact[14], Some(15));
        assert_eq!(contact[5], None); // group 1 is not `from`
    }

    #[test]
    fn components_match_a_brute_force_search() {
        // a random cloud: compare with a plain O(n^2) flood fill
        let mut state = 12345_u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as f32 / (1u64 << 31) as f32
        };
        let points: Vec<[f32; 3]> = (0..400).map(|_| [next(), next(), next() * 0.2]).collect();
        let group: Vec<u8> = (0..400).map(|i| if i % 7 == 0 { EXCLUDED } else { (i % 2) as u8 }).collect();
        let link = 0.08;
        let labels = components(&points, link);
        for i in 0..400 {
            for j in 0..400 {
                let d2: f32 = (0..3).map(|k| (points[i][k] - points[j][k]).powi(2)).sum();
                if d2 <= link * link {
                    assert_eq!(labels[i], labels[j]);
                }
            }
        }
        // and no two components are linked: every label's points are a flood fill of its first
        let mut seen = vec![false; 400];
        for start in 0..400 {
            if seen[start] {
                continue;
            }
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(i) = stack.pop() {
                assert_eq!(labels[i], labels[start]);
                for j in 0..400 {
                    let d2: f32 = (0..3).map(|k| (points[i][k] - points[j][k]).powi(2)).sum();
                    if !seen[j] && d2 <= link * link {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        // a far-away point changes nothing
        let mut spread = points.clone();
        spread.push([1.0e5, -1.0e5, 3.0e4]);
        let mut spread_group = group.clone();
        spread_group.push(0);
        assert_eq!(&components(&spread, link)[..400], &labels[..]);
        assert_eq!(
            linked_to(&spread, &spread_group, 0, 1, link).unwrap()[..400],
            linked_to(&points, &group, 0, 1, link).unwrap()[..]
        );
    }

    #[test]
    fn small_clusters_are_the_seeded_components_no_wider_than_the_size() {
        // clusters of a random cloud (link 0.05: many small ones, and a few long chains), seeded at
        // every third point: each point's answer is that of its whole component, searched whole
        let points = cloud(600, 7);
        let (link, size) = (0.05, 0.12);
        let seeds: Vec<usize> = (0..600).step_by(3).collect();
        let small = small_clusters(&points, link, &seeds, size).unwrap();
        let labels = components(&points, link);
        let count = *labels.iter().max().unwrap() as usize + 1;
        let (mut low, mut high) = (vec![[f32::INFINITY; 3]; count], vec![[f32::NEG_INFINITY; 3]; count]);
        let mut seeded = vec![false; count];
        for (i, &l) in labels.iter().enumerate() {
            for k in 0..3 {
                low[l as usize][k] = low[l as usize][k].min(points[i][k]);
                high[l as usize][k] = high[l as usize][k].max(points[i][k]);
            }
            seeded[l as usize] |= i % 3 == 0;
        }
        let spans = |l: usize| {
            let d = [0, 1, 2].map(|k| f64::from(high[l][k]) - f64::from(low[l][k]));
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        };
        let expected: Vec<bool> = labels.iter().map(|&l| seeded[l as usize] && spans(l as usize) <= size).collect();
        assert_eq!(small, expected);
        assert!(small.iter().any(|&s| s) && small.iter().zip(&labels).any(|(&s, &l)| !s && seeded[l as usize]));
        // the seeds' order does not matter, and a seed out of range is an error
        let reversed: Vec<usize> = seeds.iter().rev().copied().collect();
        assert_eq!(small_clusters(&points, link, &reversed, size).unwrap(), small);
        assert_eq!(
            small_clusters(&points, link, &[600], size),
            Err(ProximityError::SeedOutOfRange { seed: 600, points: 600 })
        );
    }

    #[test]
    fn clusters_inside_are_the_seeded_components_wholly_inside() {
        // clusters of a random cloud (link 0.05) inside a ball of 0.35 around the middle, seeded
        // at every third point: each point's answer is that of its whole component
        let points = cloud(600, 11);
        let link = 0.05;
        let inside: Vec<bool> =
            points.iter().map(|p| p.iter().map(|c| (c - 0.5) * (c - 0.5)).sum::<f32>() < 0.35 * 0.35).collect();
        let seeds: Vec<usize> = (0..600).step_by(3).collect();
        let cluster = clusters_inside(&points, link, &seeds, &inside).unwrap();
        let labels = components(&points, link);
        let count = *labels.iter().max().unwrap() as usize + 1;
        let (mut seeded, mut outside) = (vec![false; count], vec![false; count]);
        for (i, &l) in labels.iter().enumerate() {
            seeded[l as usize] |= i % 3 == 0;
            outside[l as usize] |= !inside[i];
        }
        for (i, &l) in labels.iter().enumerate() {
            assert_eq!(cluster[i].is_some(), seeded[l as usize] && !outside[l as usize], "point {i}");
        }
        // one number per component: two points share a number exactly when they share a component
        for i in (0..600).step_by(7) {
            for j in (0..600).step_by(5) {
                if let (Some(a), Some(b)) = (cluster[i], cluster[j]) {
                    assert_eq!(a == b, labels[i] == labels[j]);
                }
            }
        }
        assert!(cluster.iter().any(Option::is_some) && cluster.iter().zip(&inside).any(|(c, &i)| c.is_none() && i));
        assert_eq!(
            clusters_inside(&points, link, &seeds, &inside[1..]),
            Err(ProximityError::InsideCount { flags: 599, points: 600 })
        );
    }

    #[test]
    fn growth_stops_at_gaps_and_reports_what_touches_the_part() {
        // seeds along x every 0.1 (link from their spacing: 4th neighbour 0.2, x1.5 = 0.3), an
        // eligible chain off them, an eligible point across a gap, and an other point touching
        let mut points: Vec<[f32; 3]> = (0..30).map(|i| [i as f32 * 0.1, 0.0, 0.0]).collect();
        let mut kind = vec![SEED; 30];
        points.extend([[0.0, 0.25, 0.0], [0.0, 0.5, 0.0], [0.0, 1.5, 0.0], [2.0, 0.2, 0.0]]);
        kind.extend([ELIGIBLE, ELIGIBLE, ELIGIBLE, OTHER]);
        let grown = grow(&points, &kind, 1.5, 0.05, 0.4).unwrap();
        assert!((grown.link - 0.3).abs() < 1e-5, "{}", grown.link);
        assert!(grown.part[..32].iter().all(|&p| p) && !grown.part[32] && !grown.part[33]);
        assert!(grown.touched);
        kind[33] = ELIGIBLE;
        let again = grow(&points, &kind, 1.5, 0.05, 0.4).unwrap();
        assert!(again.part[33] && !again.touched);
        // the link stays within its bounds
        assert_eq!(grow(&points, &kind, 10.0, 0.05, 0.4).unwrap().link, 0.4);
    }

    /// A deterministic cloud in [0, 1) x [0, 1) x [0, 0.2).
    fn cloud(n: usize, seed: u64) -> Vec<[f32; 3]> {
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as f32 / (1u64 << 31) as f32
        };
        (0..n).map(|_| [next(), next(), next() * 0.2]).collect()
    }

    #[test]
    fn the_median_neighbour_distance_is_that_of_a_search_of_every_pair() {
        // a cloud, a thin noisy helix (the sort-and-scan's usual case) and points with duplicates
        let helix: Vec<[f32; 3]> = cloud(1500, 3)
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let s = i as f32 / 1500.0;
                [(6.0 * s).cos() + 0.01 * p[0], (6.0 * s).sin() + 0.01 * p[1], 3.0 * s + 0.01 * p[2]]
            })
            .collect();
        let duplicated: Vec<[f32; 3]> = cloud(700, 5).iter().map(|p| p.map(|c| (c * 8.0).round())).collect();
        for (points, k, samples) in
            [(cloud(2000, 9), 4, 500), (helix, 4, 500), (duplicated, 4, 100), (cloud(9, 1), 3, 500)]
        {
            let kth = |i: usize| {
                let q = points[i].map(f64::from);
                let mut d: Vec<f64> = (0..points.len())
                    .filter(|&j| j != i)
                    .map(|j| {
                        let p = points[j].map(f64::from);
                        let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                        dx * dx + dy * dy + dz * dz
                    })
                    .collect();
                d.sort_unstable_by(f64::total_cmp);
                d[k - 1].sqrt()
            };
            let mut all: Vec<f64> = (0..points.len()).step_by((points.len() / samples).max(1)).map(kth).collect();
            all.sort_unstable_by(f64::total_cmp);
            let m = all.len() / 2;
            let expected = if all.len() % 2 == 1 { all[m] } else { (all[m - 1] + all[m]) / 2.0 };
            assert_eq!(median_neighbour_distance(&points, k, samples), Some(expected));
        }
        assert_eq!(median_neighbour_distance(&cloud(4, 1), 4, 500), None);
        assert_eq!(median_neighbour_distance(&cloud(40, 1), 0, 500), None);
    }

    #[test]
    fn the_points_a_part_touches_are_those_linked_to_finds() {
        let points = cloud(3000, 7);
        let kind: Vec<u8> = (0..3000).map(|i| [SEED, ELIGIBLE, ELIGIBLE, OTHER][i % 4]).collect();
        let queries = cloud(500, 8);
        // the link well below the widest (the part's grid answers), equal to it (the same grid),
        // and within rounding below it (a grid of link-wide cells answers)
        for (spacings, link_min, link_max) in [(1.5, 0.01, 0.08), (100.0, 0.01, 0.03), (0.1, 0.03 * (1.0 - 1e-7), 0.03)]
        {
            let part = Part::grow(&points, &kind, spacings, link_min, link_max).unwrap();
            let mut all = points.clone();
            all.extend_from_slice(&queries);
            let mut group: Vec<u8> = part.members().iter().map(|&p| if p { 1 } else { EXCLUDED }).collect();
            group.resize(all.len(), 0);
            let expected = linked_to(&all, &group, 0, 1, part.link).unwrap();
            assert_eq!(part.lowest_touching(&queries).unwrap(), expected[3000..], "link {}", part.link);
            assert!(expected[3000..].iter().any(Option::is_some));
        }
    }

    #[test]
    fn points_far_apart_for_the_cell_width_are_still_linked_right() {
        // two clusters 1e30 apart with links of 0.05: the cells are ranked, not offset (the far
        // cluster's x is all 1e30 in f32, so it lies in a plane)
        let mut points = cloud(300, 3);
        points.extend(cloud(300, 4).iter().map(|p| [p[0] + 1e30, p[1], p[2]]));
        let link = 0.05_f32;
        let linked = |i: usize, j: usize| distance2(points[i], points[j]) <= link * link;
        // components: every linked pair shares a label, and each label is one flood fill
        let labels = components(&points, link);
        let mut seen = vec![false; 600];
        for start in 0..600 {
            if seen[start] {
                continue;
            }
            let (mut stack, mut members) = (vec![start], vec![]);
            seen[start] = true;
            while let Some(i) = stack.pop() {
                members.push(i);
                for (j, seen) in seen.iter_mut().enumerate() {
                    if !*seen && linked(i, j) {
                        *seen = true;
                        stack.push(j);
                    }
                }
            }
            assert!(members.iter().all(|&i| labels[i] == labels[start]));
            assert_eq!(labels.iter().filter(|&&l| l == labels[start]).count(), members.len());
        }
        // linked_to: the lowest linked point of the other group
        let group: Vec<u8> = (0..600).map(|i| (i % 3 == 0) as u8).collect();
        let found = linked_to(&points, &group, 0, 1, link).unwrap();
        for i in (0..600).filter(|&i| group[i] == 0) {
            assert_eq!(found[i], (0..600).find(|&j| group[j] == 1 && linked(i, j)).map(|j| j as u32));
        }
        // such a grid places no outside point: the part's answers come the long way
        let part = Part::grow(&points, &[SEED; 600], 1.5, 0.01, 0.05).unwrap();
        let queries = [points[5], points[305], [0.5, 0.5, 5.0]];
        let mut all = points.clone();
        all.extend_from_slice(&queries);
        let mut group = vec![1; 600];
        group.extend([0, 0, 0]);
        let expected = linked_to(&all, &group, 0, 1, part.link).unwrap();
        assert_eq!(part.lowest_touching(&queries).unwrap(), expected[600..]);
        assert!(expected[600] == Some(5) && expected[601].is_some_and(|c| c >= 300) && expected[602].is_none());
    }

    #[test]
    fn the_radix_sort_orders_by_the_high_bits_and_keeps_the_order_below() {
        let mut state = 5_u64;
        let keys: Vec<u64> = (0..5000_u64)
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 40) % 700) << 40 | ((state >> 20) % 3) << 13 | i
            })
            .collect();
        let mut sorted = keys.clone();
        radix_sort(&mut sorted, 13);
        let mut expected = keys;
        expected.sort_by_key(|k| k >> 13); // stable
        assert_eq!(sorted, expected);
    }

    #[test]
    fn bad_input_is_an_error() {
        let points = chain();
        assert_eq!(linked_to(&points, &[0; 20], 0, 1, 0.0).unwrap_err(), ProximityError::BadLink(0.0));
        assert!(matches!(linked_to(&points, &[0; 3], 0, 1, 0.1), Err(ProximityError::GroupCount { .. })));
        assert!(matches!(Links::new(&points, f32::NAN), Err(ProximityError::BadLink(_))));
        let mut bad = chain();
        bad[3][1] = f32::NAN;
        assert_eq!(linked_to(&bad, &[0; 20], 0, 1, 0.1).unwrap_err(), ProximityError::NonFinitePoint(3));
    }
}
