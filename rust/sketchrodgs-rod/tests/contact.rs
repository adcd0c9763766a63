//! Contact (docs/contact.md): rods do not enter the scene's distance field, nor each other, at
//! pulls far past the obstacle, and the grab gives way to contact.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sketchrodgs_rod::{ContactSettings, DVec3, DistanceField, ElasticRod, RodParams, World};

const DT: f64 = 1.0 / 60.0;
const R: f64 = 0.01;

fn straight(n: usize, from: [f64; 3], to: [f64; 3]) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let t = i as f64 / (n - 1) as f64;
            [from[0] + t * (to[0] - from[0]), from[1] + t * (to[1] - from[1]), from[2] + t * (to[2] - from[2])]
        })
        .collect()
}

/// The half-space z < 0 (a table whose top is z = 0) on a grid over [-1, 1]² x [-0.5, 0.5].
fn table(spacing: f64) -> DistanceField {
    let origin = [-1.0, -1.0, -0.5];
    let dims = [(2.0 / spacing) as usize + 1, (2.0 / spacing) as usize + 1, (1.0 / spacing) as usize + 1];
    let mut values = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
    for k in 0..dims[2] {
        for _ in 0..dims[1] {
            for _ in 0..dims[0] {
                values.push((origin[2] + k as f64 * spacing) as f32);
            }
        }
    }
    DistanceField::new(origin, spacing, dims, values).unwrap()
}

fn rod_params() -> RodParams {
    RodParams { radius: R, ..RodParams::default() }
}

/// A rod 4 R above the table, clamped at both ends, its middle pulled to 20 R below the top and
/// held there: its surface never goes into the table by more than 0.05 R.
#[test]
fn a_rod_pulled_into_the_table_stays_on_it() {
    let mut world = World::new();
    world.set_field(Some(table(R / 2.0)));
    let id =
        world.add(ElasticRod::new(&straight(41, [-0.2, 0.0, 4.0 * R], [0.2, 0.0, 4.0 * R]), rod_params()).unwrap());
    let rod = world.rod_mut(id).unwrap();
    rod.clamp(0).unwrap();
    rod.clamp(40).unwrap();
    let mut deepest = f64::INFINITY;
    for frame in 1..=90 {
        let depth = 4.0 * R - 24.0 * R * (frame as f64 / 60.0).min(1.0);
        world.rod_mut(id).unwrap().grab(20, [0.0, 0.0, depth]).unwrap();
        let reports = world.step(DT).unwrap();
        assert!(reports[0].converged, "frame {frame}: {:?}", reports[0]);
        let x = world.rod(id).unwrap().positions();
        assert!(x.iter().all(|p| p.is_finite()));
        let lowest = x
            .iter()
            .chain(&x.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect::<Vec<_>>())
            .fold(f64::INFINITY, |m, p| m.min(p.z));
        deepest = deepest.min(lowest - R);
    }
    assert!(deepest >= -0.05 * R, "the rod's surface went {:.3} R into the table", -deepest / R);
    // the grabbed vertex rests on the table, not at its target 20 R below the top
    let held = world.rod(id).unwrap().positions()[20];
    assert!((held.z - R).abs() < 0.05 * R, "grabbed vertex at z = {:.3} R", held.z / R);
}

/// The same pull with the scene contact off goes through the table.
#[test]
fn without_scene_contact_the_rod_goes_through() {
    let mut world = World::new();
    world.set_field(Some(table(R / 2.0)));
    world.contact = ContactSettings { scene: false, ..ContactSettings::default() };
    let id =
        world.add(ElasticRod::new(&straight(41, [-0.2, 0.0, 4.0 * R], [0.2, 0.0, 4.0 * R]), rod_params()).unwrap());
    let rod = world.rod_mut(id).unwrap();
    rod.clamp(0).unwrap();
    rod.clamp(40).unwrap();
    rod.grab(20, [0.0, 0.0, -16.0 * R]).unwrap();
    world.step_many(DT, 30).unwrap();
    assert!((world.rod(id).unwrap().positions()[20].z + 16.0 * R).abs() < 1e-9);
}

/// Two rods 40 R long crossing 4 R apart; the upper one's middle is pulled down through the lower
/// one, by up to a rod's length: they do not pass through each other.
#[test]
fn crossing_rods_pulled_into_each_other_do_not_pass() {
    for pull in [24.0, 44.0] {
        crossing_pull(pull);
    }
}

fn crossing_pull(pull: f64) {
    let mut world = World::new();
    let a = world.add(ElasticRod::new(&straight(41, [-0.2, 0.0, 0.0], [0.2, 0.0, 0.0]), rod_params()).unwrap());
    let b = world.add(ElasticRod::new(&straight(41, [0.0, -0.2, 4.0 * R], [0.0, 0.2, 4.0 * R]), rod_params()).unwrap());
    for id in [a, b] {
        let rod = world.rod_mut(id).unwrap();
        rod.clamp(0).unwrap();
        rod.clamp(40).unwrap();
    }
    let mut closest = f64::INFINITY;
    for frame in 1..=90 {
        let z = 4.0 * R - pull * R * (frame as f64 / 60.0).min(1.0);
        world.rod_mut(b).unwrap().grab(20, [0.0, 0.0, z]).unwrap();
        let reports = world.step(DT).unwrap();
        assert!(reports.iter().all(|r| r.converged), "frame {frame}: {reports:?}");
        let (xa, xb) = (world.rod(a).unwrap().positions(), world.rod(b).unwrap().positions());
        closest = closest.min(polyline_distance(xa, xb));
    }
    assert!(closest >= 2.0 * R - 0.05 * R, "pull {pull} R: the rods' axes came {:.3} R apart", closest / R);
    // and the lower rod was pushed down: it gave way rather than being passed
    let middle = world.rod(a).unwrap().positions()[20];
    assert!(middle.z < -2.0 * R, "lower rod middle at {:.2?} R", middle / R);
}

/// A hairpin: two arms 4 R apart joined by a half turn, both ends clamped; the middle of one arm
/// pulled 20 R across the other does not pass through it.
#[test]
fn a_rod_does_not_pass_through_itself() {
    let mut points = straight(41, [-0.2, 2.0 * R, 0.0], [0.2, 2.0 * R, 0.0]);
    for k in 1..10 {
        let angle = std::f64::consts::PI * (0.5 - k as f64 / 10.0);
        points.push([0.2 + 2.0 * R * angle.cos(), 2.0 * R * angle.sin(), 0.0]);
    }
    points.extend(straight(41, [0.2, -2.0 * R, 0.0], [-0.2, -2.0 * R, 0.0]));
    let n = points.len();
    let mut world = World::new();
    let id = world.add(ElasticRod::new(&points, rod_params()).unwrap());
    world.rod_mut(id).unwrap().clamp(0).unwrap();
    world.rod_mut(id).unwrap().clamp(n - 1).unwrap();
    let mut closest = f64::INFINITY;
    for frame in 1..=90 {
        let y = 2.0 * R - 22.0 * R * (frame as f64 / 60.0).min(1.0);
        world.rod_mut(id).unwrap().grab(20, [0.0, y, 0.0]).unwrap();
        let reports = world.step(DT).unwrap();
        assert!(reports[0].converged, "frame {frame}: {:?}", reports[0]);
        let x = world.rod(id).unwrap().positions();
        closest = closest.min(polyline_distance(&x[10..31], &x[n - 31..n - 10]));
    }
    assert!(closest >= 2.0 * R - 0.05 * R, "the arms came {:.3} R apart (2 R is touching)", closest / R);
    // the other arm was pushed along, not passed
    assert!(world.rod(id).unwrap().positions()[n - 21].y < -10.0 * R);
}

/// Friction stops a rod sliding on the table sooner.
#[test]
fn friction_slows_a_rod_sliding_on_the_table() {
    let slide = |friction: f64| {
        let mut world = World::new();
        world.set_field(Some(table(R / 2.0)));
        world.contact.friction = friction;
        let params = RodParams { gravity: [0.0, 0.0, -9.81], ..rod_params() };
        let id = world.add(ElasticRod::new(&straight(21, [-0.1, 0.0, R], [0.1, 0.0, R]), params).unwrap());
        world.rod_mut(id).unwrap().set_velocities(&vec![[1.0, 0.0, 0.0]; 21]).unwrap();
        world.step_many(DT, 30).unwrap();
        world.rod(id).unwrap().positions()[10].x
    };
    let (free, rough) = (slide(0.0), slide(0.5));
    assert!(free > 0.2, "without friction it slides on (the rod's own damping slows it): {free}");
    assert!(rough < 0.8 * free, "with friction {rough}, without {free}");
}

#[test]
fn bad_fields_are_errors() {
    assert!(DistanceField::new([0.0; 3], 0.0, [2, 2, 2], vec![0.0; 8]).is_err());
    assert!(DistanceField::new([0.0; 3], 0.1, [1, 2, 2], vec![0.0; 4]).is_err());
    assert!(DistanceField::new([0.0; 3], 0.1, [2, 2, 2], vec![0.0; 7]).is_err());
    assert!(DistanceField::new([f64::NAN, 0.0, 0.0], 0.1, [2, 2, 2], vec![0.0; 8]).is_err());
    assert!(DistanceField::new([0.0; 3], 0.1, [2, 2, 2], vec![0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0]).is_err());
    let field = table(0.1);
    let (d, g) = field.sample(DVec3::new(0.1, 0.2, 0.25)).unwrap();
    assert!((d - 0.25).abs() < 1e-6 && (g - DVec3::Z).length() < 1e-6);
    assert!(field.sample(DVec3::new(5.0, 0.0, 0.0)).is_none());
}

/// Smallest distance between the segments of two polylines.
fn polyline_distance(a: &[DVec3], b: &[DVec3]) -> f64 {
    let mut best = f64::INFINITY;
    for sa in a.windows(2) {
        for sb in b.windows(2) {
            best = best.min(segment_distance(sa[0], sa[1], sb[0], sb[1]));
        }
    }
    best
}

/// Distance between segments (p0, p1) and (q0, q1), by sampling finely (a test helper: exact enough).
fn segment_distance(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> f64 {
    let mut best = f64::INFINITY;
    for s in 0..=32 {
        let p = p0.lerp(p1, s as f64 / 32.0);
        let d = q1 - q0;
        let t = ((p - q0).dot(d) / d.length_squared().max(1e-300)).clamp(0.0, 1.0);
        best = best.min((p - (q0 + t * d)).length());
    }
    best
}
