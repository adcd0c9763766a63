//! Which points of a cloud are linked: two points are neighbours when they are at most `link`
//! apart, and a gap wider than that separates parts. Segmentation (docs/deformation.md) grows the
//! part over these links and finds the small parts attached to it.
//!
//! Points fall in a uniform grid of `link`-wide cells (see `Cells`). Points are linked only within
//! their group (a `u8`); `EXCLUDED` points have no links. The answers do not depend on the order
//! of work.
//!
//! ```
//! use sketchrodgs_polyline::proximity::{linked_components, linked_to, EXCLUDED};
//! let points = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.5, 0.0, 0.0], [0.6, 0.0, 0.0]];
//! let labels = linked_components(&points, &[0, 0, 0, EXCLUDED], 0.15).unwrap();
//! assert_eq!(labels, [0, 0, 1, u32::MAX]); // a gap of 0.4 between the first two and the third
//! let contact = linked_to(&points, &[0, 0, 1, 1], 0, 1, 0.45).unwrap();
//! assert_eq!(contact, [None, Some(2), None, None]); // point 1 reaches point 2 of group 1
//! ```

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

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
}

/// A cell of the grid and a group.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Key([i64; 3], u8);

impl std::hash::Hash for Key {
    fn hash<H: Hasher>(&self, state: &mut H) {
        let [x, y, z] = self.0.map(|c| c as u64);
        state.write_u64(
            x.wrapping_mul(0x9e37_79b9_7f4a_7c15)
                ^ y.wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
                ^ z.wrapping_mul(0x1656_67b1_9e37_79f9)
                ^ u64::from(self.1),
        );
    }
}

/// The key mixes itself (`Key::hash`); the default SipHash made the cell lookups the bulk of the
/// work.
#[derive(Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = i ^ (i >> 29);
    }
}

/// The grid: the points sorted by (group, cell), so that a cell's points lie together in memory,
/// and each (cell, group)'s range of them. Cells are `link` wide, so a point's neighbours lie in
/// its own cell and the 26 around it.
struct Cells {
    link: f32,
    /// The points in sorted order, and the input index of each.
    sorted: Vec<[f32; 3]>,
    index: Vec<u32>,
    /// The cell and group of each sorted point.
    cell: Vec<[i64; 3]>,
    group: Vec<u8>,
    /// Each (cell, group)'s range of sorted points.
    ranges: HashMap<Key, (u32, u32), BuildHasherDefault<KeyHasher>>,
}

/// The offsets to the 13 cells "after" a cell: with the cell itself they cover every pair of
/// neighbouring cells once.
const HALF: [[i64; 3]; 13] = [
    [1, -1, -1],
    [1, -1, 0],
    [1, -1, 1],
    [1, 0, -1],
    [1, 0, 0],
    [1, 0, 1],
    [1, 1, -1],
    [1, 1, 0],
    [1, 1, 1],
    [0, 1, -1],
    [0, 1, 0],
    [0, 1, 1],
    [0, 0, 1],
];

impl Cells {
    fn new(points: &[[f32; 3]], group: &[u8], link: f32) -> Result<Self, ProximityError> {
        if !(link.is_finite() && link > 0.0) {
            return Err(ProximityError::BadLink(link));
        }
        if group.len() != points.len() {
            return Err(ProximityError::GroupCount { points: points.len(), groups: group.len() });
        }
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(ProximityError::NonFinitePoint(i));
        }
        // the keys computed once (sorting by a computed key would floor them at every comparison)
        let mut keyed: Vec<(u8, [i64; 3], u32)> = (0..points.len())
            .filter(|&i| group[i] != EXCLUDED)
            .map(|i| (group[i], points[i].map(|c| (c / link).floor() as i64), i as u32))
            .collect();
        keyed.sort_unstable();
        let order: Vec<u32> = keyed.iter().map(|k| k.2).collect();
        let sorted: Vec<[f32; 3]> = order.iter().map(|&i| points[i as usize]).collect();
        let cell: Vec<[i64; 3]> = keyed.iter().map(|k| k.1).collect();
        let groups: Vec<u8> = keyed.iter().map(|k| k.0).collect();
        let mut ranges: HashMap<Key, (u32, u32), BuildHasherDefault<KeyHasher>> = HashMap::default();
        let mut start = 0;
        for k in 1..=cell.len() {
            if k == cell.len() || cell[k] != cell[start] || groups[k] != groups[start] {
                ranges.insert(Key(cell[start], groups[start]), (start as u32, k as u32));
                start = k;
            }
        }
        Ok(Self { link, sorted, index: order, cell, group: groups, ranges })
    }

    fn linked(&self, a: usize, b: usize) -> bool {
        let (p, q) = (self.sorted[a], self.sorted[b]);
        (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2) <= self.link * self.link
    }

    /// The sorted positions of the points of `group` in the cell at `offset` from `cell`.
    fn get(&self, cell: [i64; 3], offset: [i64; 3], group: u8) -> std::ops::Range<usize> {
        let c = [cell[0] + offset[0], cell[1] + offset[1], cell[2] + offset[2]];
        self.ranges.get(&Key(c, group)).map_or(0..0, |&(a, b)| a as usize..b as usize)
    }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let up = parent[parent[i as usize] as usize];
        parent[i as usize] = up; // path halving
        i = up;
    }
    i
}

/// Join the sets of sorted points `a` and `b` if they are linked (and not already joined).
fn link_pair(cells: &Cells, parent: &mut [u32], a: usize, b: usize) {
    let (ra, rb) = (find(parent, a as u32), find(parent, b as u32));
    if ra != rb && cells.linked(a, b) {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

/// The connected component of every point, over links within `link` between points of the same
/// group: labels 0, 1, ... in the order of each component's first point; `u32::MAX` for
/// `EXCLUDED` points.
pub fn linked_components(points: &[[f32; 3]], group: &[u8], link: f32) -> Result<Vec<u32>, ProximityError> {
    let cells = Cells::new(points, group, link)?;
    let mut parent: Vec<u32> = (0..cells.sorted.len() as u32).collect();
    for &(start, end) in cells.ranges.values() {
        let (start, end) = (start as usize, end as usize);
        let (cell, g) = (cells.cell[start], cells.group[start]);
        for a in start..end {
            for b in a + 1..end {
                link_pair(&cells, &mut parent, a, b);
            }
        }
        for offset in HALF {
            for b in cells.get(cell, offset, g) {
                for a in start..end {
                    link_pair(&cells, &mut parent, a, b);
                }
            }
        }
    }
    // labels in the order of the input: a component's label is the rank of its first point
    let mut root_of = vec![u32::MAX; points.len()];
    for k in 0..cells.sorted.len() {
        root_of[cells.index[k] as usize] = find(&mut parent, k as u32);
    }
    let mut label = vec![u32::MAX; points.len()];
    let mut of_root: HashMap<u32, u32> = HashMap::new(); // (once per point: SipHash is fine)
    for i in 0..points.len() {
        if root_of[i] != u32::MAX {
            let next = of_root.len() as u32;
            label[i] = *of_root.entry(root_of[i]).or_insert(next);
        }
    }
    Ok(label)
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
    let cells = Cells::new(points, group, link)?;
    let mut found = vec![None; points.len()];
    if from == EXCLUDED || to == EXCLUDED {
        return Ok(found);
    }
    let nearest = |k: usize| -> Option<u32> {
        let mut best: Option<u32> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for j in cells.get(cells.cell[k], [dx, dy, dz], to) {
                        let original = cells.index[j];
                        if best.is_none_or(|b| original < b) && cells.linked(k, j) {
                            best = Some(original);
                        }
                    }
                }
            }
        }
        best
    };
    let asked: Vec<usize> = (0..cells.sorted.len()).filter(|&k| group[cells.index[k] as usize] == from).collect();
    let answers: Vec<Option<u32>> = asked.par_iter().map(|&k| nearest(k)).collect();
    for (&k, answer) in asked.iter().zip(answers) {
        found[cells.index[k] as usize] = answer;
    }
    Ok(found)
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
    if !(link_min > 0.0 && link_min <= link_max) {
        return Err(ProximityError::BadLink(link_min));
    }
    // one grid, cells as wide as the longest link, for the link and the search
    let cells = Cells::new(points, &vec![0; points.len()], link_max)?;
    let kind_of = |k: usize| kind[cells.index[k] as usize];
    // the link: the seeds' median 4th-neighbour distance among seeds, from about 2000 of them
    let seeds: Vec<usize> = (0..cells.sorted.len()).filter(|&k| kind_of(k) == SEED).collect();
    let step = (seeds.len() / 2000).max(1);
    let mut fourth: Vec<f32> = seeds
        .iter()
        .step_by(step)
        .map(|&k| {
            let mut nearest = [f32::INFINITY; 4];
            cells.each_near(k, |j| {
                let d = cells.distance2(k, j);
                if j != k && kind_of(j) == SEED && d < nearest[3] {
                    nearest[3] = d;
                    nearest.sort_unstable_by(f32::total_cmp);
                }
            });
            nearest[3].sqrt()
        })
        .collect();
    let link = if fourth.len() < 5 {
        link_max
    } else {
        let middle = fourth.len() / 2;
        let (_, median, _) = fourth.select_nth_unstable_by(middle, f32::total_cmp);
        (spacings * *median).clamp(link_min, link_max)
    };
    let link2 = link * link;
    let near = |k: usize, want: &dyn Fn(usize) -> bool| {
        let mut found = false;
        cells.each_near(k, |j| found |= !found && want(j) && cells.distance2(k, j) <= link2);
        found
    };
    // Seeds are the part. Scanning from them would cost a look around every one; instead the
    // eligible points that touch a seed start a search over eligible points only.
    let eligible: Vec<usize> = (0..cells.sorted.len()).filter(|&k| kind_of(k) == ELIGIBLE).collect();
    let touching: Vec<bool> = eligible.par_iter().map(|&k| near(k, &|j| kind_of(j) == SEED)).collect();
    let mut part: Vec<bool> = (0..cells.sorted.len()).map(|k| kind_of(k) == SEED).collect();
    let mut queue: Vec<usize> = eligible.iter().zip(&touching).filter(|pair| *pair.1).map(|pair| *pair.0).collect();
    for &k in &queue {
        part[k] = true;
    }
    while let Some(k) = queue.pop() {
        cells.each_near(k, |j| {
            if kind_of(j) == ELIGIBLE && !part[j] && cells.distance2(k, j) <= link2 {
                part[j] = true;
                queue.push(j);
            }
        });
    }
    let others: Vec<usize> = (0..cells.sorted.len()).filter(|&k| kind_of(k) == OTHER).collect();
    let touched = others.par_iter().any(|&k| near(k, &|j| part[j]));
    let mut out = vec![false; points.len()];
    for (k, &p) in part.iter().enumerate() {
        out[cells.index[k] as usize] = p;
    }
    Ok(Grown { link, part: out, touched })
}

impl Cells {
    fn distance2(&self, a: usize, b: usize) -> f32 {
        let (p, q) = (self.sorted[a], self.sorted[b]);
        (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)
    }

    /// Calls `visit(j)` for every sorted point `j` in the cells around sorted point `k` (its group).
    fn each_near(&self, k: usize, mut visit: impl FnMut(usize)) {
        let group = 0; // `grow` puts every point in group 0
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for j in self.get(self.cell[k], [dx, dy, dz], group) {
                        visit(j);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Points along x every 0.1, with a gap of 0.5 after the 10th.
    fn chain() -> Vec<[f32; 3]> {
        (0..20).map(|i| [i as f32 * 0.1 + if i >= 10 { 0.5 } else { 0.0 }, 0.0, 0.0]).collect()
    }

    #[test]
    fn a_gap_wider_than_the_link_separates_components() {
        let points = chain();
        let labels = linked_components(&points, &[0; 20], 0.15).unwrap();
        assert!(labels[..10].iter().all(|&l| l == 0) && labels[10..].iter().all(|&l| l == 1));
        let bridged = linked_components(&points, &[0; 20], 0.65).unwrap();
        assert!(bridged.iter().all(|&l| l == 0));
    }

    #[test]
    fn groups_do_not_link_to_each_other() {
        let points = chain();
        let group: Vec<u8> = (0..20).map(|i| if i % 10 < 5 { 0 } else { 1 }).collect();
        let labels = linked_components(&points, &group, 0.15).unwrap();
        assert_eq!(labels[0], labels[4]);
        assert_ne!(labels[4], labels[5]);
        assert_ne!(labels[9], labels[10]); // both group 1 but across the gap
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
        let labels = linked_components(&points, &group, link).unwrap();
        for i in 0..400 {
            for j in 0..400 {
                let d2: f32 = (0..3).map(|k| (points[i][k] - points[j][k]).powi(2)).sum();
                if group[i] != EXCLUDED && group[i] == group[j] && d2 <= link * link {
                    assert_eq!(labels[i], labels[j]);
                }
            }
        }
        // and no two components are linked: every label's points are a flood fill of its first
        let mut seen = vec![false; 400];
        for start in 0..400 {
            if seen[start] || group[start] == EXCLUDED {
                continue;
            }
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(i) = stack.pop() {
                assert_eq!(labels[i], labels[start]);
                for j in 0..400 {
                    let d2: f32 = (0..3).map(|k| (points[i][k] - points[j][k]).powi(2)).sum();
                    if !seen[j] && group[j] == group[i] && d2 <= link * link {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        assert!(labels.iter().zip(&group).all(|(&l, &g)| (l == u32::MAX) == (g == EXCLUDED)));
        // a far-away point changes nothing
        let mut spread = points.clone();
        spread.push([1.0e5, -1.0e5, 3.0e4]);
        let mut spread_group = group.clone();
        spread_group.push(0);
        assert_eq!(&linked_components(&spread, &spread_group, link).unwrap()[..400], &labels[..]);
        assert_eq!(
            linked_to(&spread, &spread_group, 0, 1, link).unwrap()[..400],
            linked_to(&points, &group, 0, 1, link).unwrap()[..]
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

    #[test]
    fn bad_input_is_an_error() {
        let points = chain();
        assert_eq!(linked_components(&points, &[0; 20], 0.0).unwrap_err(), ProximityError::BadLink(0.0));
        assert!(matches!(linked_components(&points, &[0; 3], 0.1), Err(ProximityError::GroupCount { .. })));
        let mut bad = chain();
        bad[3][1] = f32::NAN;
        assert_eq!(linked_to(&bad, &[0; 20], 0, 1, 0.1).unwrap_err(), ProximityError::NonFinitePoint(3));
    }
}
