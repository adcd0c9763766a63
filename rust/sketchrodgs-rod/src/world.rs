//! Several rods stepped together, touching the scene and each other (docs/contact.md).

use std::sync::Arc;

use crate::contact::{CapsuleTree, Obstacles, closest_parameters};
use crate::{DistanceField, ElasticRod, RodError, SolverSettings, StepReport};

/// How far apart (in radii) a rod's own edges are measured at the start of a step, at most: it
/// need not search them for self-contact until a vertex has moved half that far.
const CLEARANCE_RADII: f64 = 4.0;

/// A rod's clearance is carried over from its last step (less what it moved since) while at least
/// this many radii remain; below, it is measured again.
const KEEP_CLEARANCE_RADII: f64 = 1.0;

/// Rounds of [`World::separate_rods`] over all edge pairs.
const SEPARATION_ROUNDS: usize = 4;

/// What contact a [`World`] simulates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSettings {
    /// Rods do not enter the scene's distance field ([`World::set_field`]), where one is set.
    pub scene: bool,
    /// Rods do not pass through each other, nor through themselves.
    pub rods: bool,
    /// Coulomb friction coefficient against the scene (0: none).
    pub friction: f64,
}

impl Default for ContactSettings {
    fn default() -> Self {
        Self { scene: true, rods: true, friction: 0.0 }
    }
}

/// A set of rods advanced by one call. Each step, every rod sees the scene's distance field and
/// the other rods (and its own far edges) where they are at the start of its step.
#[derive(Debug, Clone, Default)]
pub struct World {
    rods: Vec<ElasticRod>,
    /// Solver settings used by [`World::step`] (pass them to [`ElasticRod::solve_static`]).
    pub settings: SolverSettings,
    /// Which contacts [`World::step`] simulates.
    pub contact: ContactSettings,
    field: Option<Arc<DistanceField>>,
}

impl World {
    /// An empty world with default solver settings.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a rod; returns its index.
    pub fn add(&mut self, rod: ElasticRod) -> usize {
        self.rods.push(rod);
        self.rods.len() - 1
    }

    /// Removes and returns rod `index` (later indices shift down by one).
    pub fn remove(&mut self, index: usize) -> Result<ElasticRod, RodError> {
        self.check(index)?;
        Ok(self.rods.remove(index))
    }

    pub fn len(&self) -> usize {
        self.rods.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rods.is_empty()
    }

    fn check(&self, index: usize) -> Result<(), RodError> {
        let len = self.rods.len();
        if index < len { Ok(()) } else { Err(RodError::RodOutOfRange { rod: index, len }) }
    }

    /// Rod `index`.
    pub fn rod(&self, index: usize) -> Result<&ElasticRod, RodError> {
        self.check(index)?;
        Ok(&self.rods[index])
    }

    /// Rod `index`, mutably (boundary conditions, grabs).
    pub fn rod_mut(&mut self, index: usize) -> Result<&mut ElasticRod, RodError> {
        self.check(index)?;
        Ok(&mut self.rods[index])
    }

    /// All rods.
    pub fn rods(&self) -> &[ElasticRod] {
        &self.rods
    }

    /// The scene's signed distance field the rods do not enter (None: no scene contact).
    pub fn set_field(&mut self, field: Option<DistanceField>) {
        self.field = field.map(Arc::new);
    }

    /// The scene's distance field, if set.
    pub fn field(&self) -> Option<&DistanceField> {
        self.field.as_deref()
    }

    /// Advances every rod by `dt` seconds; one report per rod, in order.
    pub fn step(&mut self, dt: f64) -> Result<Vec<StepReport>, RodError> {
        let settings = self.settings;
        let mut reports = Vec::with_capacity(self.rods.len());
        for i in 0..self.rods.len() {
            let obstacles = self.obstacles_of(i);
            let rod = &mut self.rods[i];
            rod.set_obstacles(obstacles);
            reports.push(rod.step(dt, &settings)?);
            rod.apply_friction(self.contact.friction, dt);
        }
        if self.contact.rods {
            self.separate_rods(dt);
        }
        Ok(reports)
    }

    /// Pushes apart, after a step of `h`, the edges of rods (and the far edges of one rod) that
    /// came closer than their radii: each rod steps against where the others were, so two moving
    /// towards each other can overlap by a step's motion. The closest points of each overlapping
    /// pair move apart along their separation, shared between the two edges' free vertices (a held
    /// vertex does not move), a few rounds over all pairs.
    fn separate_rods(&mut self, h: f64) {
        let mut nudged = vec![false; self.rods.len()];
        for _ in 0..SEPARATION_ROUNDS {
            let mut moved = false;
            for i in 0..self.rods.len() {
                for j in i..self.rods.len() {
                    if (i != j || self.rods[i].may_touch_itself()) && self.separate_pair(i, j, h) {
                        (moved, nudged[i], nudged[j]) = (true, true, true);
                    }
                }
            }
            if !moved {
                break;
            }
        }
        for (rod, _) in self.rods.iter_mut().zip(&nudged).filter(|(_, n)| **n) {
            rod.after_nudges();
        }
    }

    /// One round over the edge pairs of rods `i` and `j` (`i == j`: the rod's far edges); whether
    /// anything moved.
    fn separate_pair(&mut self, i: usize, j: usize, h: f64) -> bool {
        let (ra, rb) = (self.rods[i].params().radius, self.rods[j].params().radius);
        let skip = if i == j { self.rods[i].own_skip() } else { 0 };
        let near = CapsuleTree::new(self.rods[j].capsules());
        let mut pairs = Vec::new();
        // pairs whose boxes come within a diameter more than touching: nudges in this round move
        // edges by up to an overlap, the rest are caught in the next round
        for (e, edge) in self.rods[i].capsules().iter().enumerate() {
            let earlier = if i == j { 0..e + skip + 1 } else { 0..0 }; // each pair once, no neighbours
            near.each_near(edge.a.min(edge.b), edge.a.max(edge.b), 3.0 * ra, earlier, |f, _| pairs.push((e, f)));
        }
        let mut moved = false;
        for (e, f) in pairs {
            let (p0, p1) = (self.rods[i].positions()[e], self.rods[i].positions()[e + 1]);
            let (q0, q1) = (self.rods[j].positions()[f], self.rods[j].positions()[f + 1]);
            let (s, t) = closest_parameters(p0, p1, q0, q1);
            let away = p0.lerp(p1, s) - q0.lerp(q1, t);
            let dist = away.length();
            let overlap = ra + rb - dist;
            if overlap <= 0.0 || dist <= 1e-12 {
                continue;
            }
            let normal = away / dist;
            // the movable vertices of each side and how much of the move each takes
            let side = |rod: &ElasticRod, k: usize, u: f64| {
                [(k, 1.0 - u), (k + 1, u)].map(|(v, w)| if rod.is_held(v) { (v, 0.0) } else { (v, w) })
            };
            let (wa, wb) = (side(&self.rods[i], e, s), side(&self.rods[j], f, t));
            let (ma, mb) = (wa[0].1 + wa[1].1, wb[0].1 + wb[1].1);
            if ma + mb <= 0.0 {
                continue;
            }
            // each side's share of the separation, over its movable weight
            let (share_a, share_b) = (ma / (ma + mb), mb / (ma + mb));
            for (v, w) in wa {
                if w > 0.0 {
                    let weight = w / (wa[0].1 * wa[0].1 + wa[1].1 * wa[1].1);
                    self.rods[i].nudge(v, normal * (overlap * share_a * weight), h);
                }
            }
            for (v, w) in wb {
                if w > 0.0 {
                    let weight = w / (wb[0].1 * wb[0].1 + wb[1].1 * wb[1].1);
                    self.rods[j].nudge(v, -normal * (overlap * share_b * weight), h);
                }
            }
            moved = true;
        }
        moved
    }

    /// What rod `i` touches in the coming step.
    fn obstacles_of(&self, i: usize) -> Obstacles {
        let mut obstacles =
            Obstacles { field: self.field.clone().filter(|_| self.contact.scene), ..Obstacles::default() };
        if self.contact.rods {
            let mut others = Vec::new();
            for (j, other) in self.rods.iter().enumerate() {
                if j == i {
                    obstacles.own = CapsuleTree::new(other.capsules());
                    obstacles.own_skip = other.own_skip();
                    obstacles.own_start = other.positions().to_vec();
                    let r = other.params().radius;
                    obstacles.own_radius = r;
                    // the last step's clearance, less what the rod has moved since, while that
                    // still says much (a lower bound: the far edges came closer by at most that)
                    let kept = other.clearance_since_last_step(obstacles.own_skip);
                    obstacles.own_clearance = match kept {
                        Some(c) if c >= KEEP_CLEARANCE_RADII * r => c,
                        _ => obstacles.own.clearance(obstacles.own_skip, CLEARANCE_RADII * r),
                    };
                } else {
                    others.extend(other.capsules());
                }
            }
            obstacles.others = CapsuleTree::new(others);
        }
        obstacles
    }

    /// Advances every rod by `dt`, `count` times; reports summed per rod.
    pub fn step_many(&mut self, dt: f64, count: usize) -> Result<Vec<StepReport>, RodError> {
        let mut total: Vec<StepReport> = vec![StepReport { converged: true, ..StepReport::default() }; self.rods.len()];
        for _ in 0..count {
            for (t, r) in total.iter_mut().zip(self.step(dt)?) {
                t.substeps += r.substeps;
                t.newton_iterations += r.newton_iterations;
                t.rejected += r.rejected;
                t.converged &= r.converged;
            }
        }
        Ok(total)
    }
}
