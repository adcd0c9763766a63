//! Gravity that keeps the captured shape (docs/contact.md): with the rest shape from
//! `hold_under_gravity`, a captured hanging cable and a drooping cantilever stay where they are
//! until pulled, and come back after a release; a shape no rest shape can hold is an error.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sketchrodgs_rod::{DVec3, ElasticRod, RodError, RodParams, SolverSettings, World};

const DT: f64 = 1.0 / 60.0;
const R: f64 = 0.005;

fn params() -> RodParams {
    RodParams { radius: R, gravity: [0.0, -9.81, 0.0], ..RodParams::default() }
}

/// A catenary hanging between (±0.3, 0): y = a cosh(x / a) - a cosh(0.3 / a).
fn catenary(n: usize) -> Vec<[f64; 3]> {
    let a = 0.25;
    (0..n)
        .map(|i| {
            let x = -0.3 + 0.6 * i as f64 / (n - 1) as f64;
            [x, a * (x / a).cosh() - a * (0.3 / a).cosh(), 0.0]
        })
        .collect()
}

fn largest_deviation(rod: &ElasticRod, shape: &[[f64; 3]]) -> f64 {
    rod.positions().iter().zip(shape).fold(0.0, |m, (p, s)| m.max((*p - DVec3::from_array(*s)).length()))
}

/// Steps `seconds` of dynamics at rest and returns the largest deviation from `shape` on the way.
fn rest_for(world: &mut World, id: usize, shape: &[[f64; 3]], seconds: f64) -> f64 {
    let mut worst: f64 = 0.0;
    for _ in 0..(seconds / DT).round() as usize {
        let reports = world.step(DT).unwrap();
        assert!(reports[0].converged);
        worst = worst.max(largest_deviation(world.rod(id).unwrap(), shape));
    }
    worst
}

#[test]
fn a_captured_hanging_cable_stays_and_comes_back() {
    let shape = catenary(41);
    // a soft cable: it stretches visibly under its own weight
    let mut rod = ElasticRod::new(&shape, RodParams { youngs_modulus: 1.0e5, ..params() }).unwrap();
    rod.clamp(0).unwrap();
    rod.clamp(40).unwrap();
    // without the rest shape it sags on its own
    let mut sagging = World::new();
    let id = sagging.add(rod.clone());
    assert!(rest_for(&mut sagging, id, &shape, 1.0) > 0.1 * R);

    let report = rod.hold_under_gravity(&SolverSettings::default()).unwrap();
    assert!(report.deviation <= 5e-3 * R, "{report:?}");
    let mut world = World::new();
    let id = world.add(rod);
    let at_rest = rest_for(&mut world, id, &shape, 5.0);
    assert!(at_rest <= 0.01 * R, "after 5 s at rest it moved {:.4} R", at_rest / R);
    // pulled sideways and let go, it swings back to the captured shape
    world.rod_mut(id).unwrap().grab(20, [0.0, shape[20][1], 0.08]).unwrap();
    world.step_many(DT, 30).unwrap();
    world.rod_mut(id).unwrap().release();
    world.step_many(DT, 600).unwrap();
    let back = largest_deviation(world.rod(id).unwrap(), &shape);
    assert!(back <= 0.05 * R, "10 s after the release it is {:.3} R away", back / R);
}

#[test]
fn a_drooping_cantilever_stays() {
    // a branch clamped at its root, drooping by its own weight (an arc, tip 0.06 below)
    let shape: Vec<[f64; 3]> = (0..31)
        .map(|i| {
            let x = 0.3 * i as f64 / 30.0;
            [x, -0.06 * (x / 0.3) * (x / 0.3), 0.0]
        })
        .collect();
    let mut rod = ElasticRod::new(&shape, RodParams { youngs_modulus: 1.0e8, ..params() }).unwrap();
    rod.clamp(0).unwrap();
    rod.hold_under_gravity(&SolverSettings::default()).unwrap();
    let mut world = World::new();
    let id = world.add(rod);
    let at_rest = rest_for(&mut world, id, &shape, 5.0);
    assert!(at_rest <= 0.01 * R, "after 5 s at rest it moved {:.4} R", at_rest / R);
}

#[test]
fn a_shape_no_rest_shape_holds_is_an_error() {
    // pinned at its root only: nothing holds a moment, the branch swings down
    let shape: Vec<[f64; 3]> = (0..21).map(|i| [0.2 * i as f64 / 20.0, 0.0, 0.0]).collect();
    let mut rod = ElasticRod::new(&shape, params()).unwrap();
    rod.pin(0).unwrap();
    let before = rod.positions().to_vec();
    let err = rod.hold_under_gravity(&SolverSettings::default()).unwrap_err();
    assert!(matches!(err, RodError::CannotHold { .. }), "{err:?}");
    assert!(err.to_string().contains("cannot carry its weight"), "{err}");
    assert_eq!(rod.positions(), &before[..], "the rod is left as it was");
    // without gravity there is nothing to hold
    let mut weightless = ElasticRod::new(&shape, RodParams { gravity: [0.0; 3], ..params() }).unwrap();
    assert_eq!(weightless.hold_under_gravity(&SolverSettings::default()).unwrap().iterations, 0);
}
