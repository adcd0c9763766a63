//! Several rods stepped together.

use crate::{ElasticRod, RodError, SolverSettings, StepReport};

/// A set of independent rods (no rod-rod contact) advanced by one call.
#[derive(Debug, Clone, Default)]
pub struct World {
    rods: Vec<ElasticRod>,
    /// Solver settings used by [`World::step`] (pass them to [`ElasticRod::solve_static`]).
    pub settings: SolverSettings,
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

    /// Advances every rod by `dt` seconds; one report per rod, in order.
    pub fn step(&mut self, dt: f64) -> Result<Vec<StepReport>, RodError> {
        let settings = self.settings;
        self.rods.iter_mut().map(|r| r.step(dt, &settings)).collect()
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
