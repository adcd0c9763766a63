//! What continues a part past one of its ends (docs/deformation.md, "Continuations"): a stem's
//! tip with its leaves past where the stroke stopped, a branch's twigs past its tip. When that
//! end is free it carries them; left behind, they hang where the tip was and tear from it.
//!
//! Over the links among the centres near the end (`proximity`), the components that touch the
//! end's part rows (`seeds`), lie mostly past the end and fit within `size` of its vertex go.
//! A component that runs on further (the rest of the plant, the trunk) stays: the search stops
//! at its first row beyond `size`.

use crate::proximity::{Components, ProximityError};

/// The rows of `points` (centres not bound to the rod, near one of its ends) that continue the
/// part past that end, ascending: the components of the links (`link` apart) that hold a row of
/// `seeds` (rows touching the end's part rows), lie within `size` of the end `vertex` and have at
/// least half of their rows past it (`(p - vertex) . outward > 0`).
pub fn continuation(
    points: &[[f32; 3]],
    seeds: &[u32],
    vertex: [f64; 3],
    outward: [f64; 3],
    size: f64,
    link: f32,
) -> Result<Vec<u32>, ProximityError> {
    if seeds.is_empty() {
        return Ok(Vec::new());
    }
    let offset = |p: [f32; 3]| [0, 1, 2].map(|k| f64::from(p[k]) - vertex[k]);
    let too_far = |p: [f32; 3]| offset(p).iter().map(|d| d * d).sum::<f64>() > size * size;
    let past = |p: [f32; 3]| offset(p).iter().zip(outward).map(|(d, o)| d * o).sum::<f64>() > 0.0;
    let mut components = Components::new(points, link)?;
    let (mut goes, mut component) = (Vec::new(), Vec::new());
    let mut seeds = seeds.to_vec();
    seeds.sort_unstable();
    for &start in &seeds {
        if components.search(start as usize, |i| too_far(points[i]), &mut component) == Some(false) {
            let beyond = component.iter().filter(|&&i| past(points[i])).count();
            if 2 * beyond >= component.len() {
                goes.extend(component.iter().map(|&i| i as u32));
            }
        }
    }
    goes.sort_unstable();
    Ok(goes)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Points every 0.1 from `from` along `step` (0.1 long), `count` of them.
    fn line(from: [f32; 3], step: [f32; 3], count: usize) -> Vec<[f32; 3]> {
        (0..count).map(|i| [0, 1, 2].map(|k| from[k] + i as f32 * step[k])).collect()
    }

    #[test]
    fn a_small_part_past_the_end_goes_and_what_runs_on_stays() {
        // the end at the origin, the rod along -x; a twig past it along +x (0.05 .. 0.45)
        let twig = line([0.05, 0.0, 0.0], [0.1, 0.0, 0.0], 5);
        let (vertex, outward) = ([0.0; 3], [1.0, 0.0, 0.0]);
        assert_eq!(continuation(&twig, &[0], vertex, outward, 0.5, 0.12).unwrap(), [0, 1, 2, 3, 4]);
        // the same twig running on to 1.45: larger than the size, it stays
        let long = line([0.05, 0.0, 0.0], [0.1, 0.0, 0.0], 15);
        assert!(continuation(&long, &[0], vertex, outward, 0.5, 0.12).unwrap().is_empty());
        // a twig beside the end, along -x (the rod's side): not past the end, it stays
        let beside = line([-0.05, 0.05, 0.0], [-0.1, 0.0, 0.0], 4);
        assert!(continuation(&beside, &[0], vertex, outward, 0.5, 0.12).unwrap().is_empty());
        // nothing touches the end: nothing goes
        assert!(continuation(&twig, &[], vertex, outward, 0.5, 0.12).unwrap().is_empty());
    }

    #[test]
    fn components_are_judged_apart_and_a_gap_ends_one() {
        // a small twig (rows 0..3), a gap of 0.5, then a long run (rows 3..); a second seed in
        // the long run: the twig goes, the run stays, whatever the order of the seeds
        let mut points = line([0.05, 0.0, 0.0], [0.1, 0.0, 0.0], 3);
        points.extend(line([0.05, 0.5, 0.0], [0.1, 0.0, 0.0], 12));
        let (vertex, outward) = ([0.0; 3], [1.0, 0.0, 0.0]);
        for seeds in [[0, 3], [3, 0]] {
            assert_eq!(continuation(&points, &seeds, vertex, outward, 0.6, 0.12).unwrap(), [0, 1, 2]);
        }
    }
}
