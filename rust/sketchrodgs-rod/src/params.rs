//! Material and solver parameters, in SI units.

use crate::RodError;

/// Material of a rod with a solid circular cross-section. All values in SI units; the scene's
/// length unit is taken to be the metre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RodParams {
    /// Cross-section radius `r` in m (the paper's `R`). Default 0.01.
    pub radius: f64,
    /// Young's modulus `E` (Pa): stretching stiffness `EA` and bending stiffness `EI`. Default 1e7
    /// (stiff rubber).
    pub youngs_modulus: f64,
    /// Shear modulus `G` (Pa) for the twisting stiffness `GJ`. `None` derives it from
    /// `poisson_ratio` as `E / (2 (1 + nu))`. Default `None`.
    pub shear_modulus: Option<f64>,
    /// Poisson ratio `nu` (-), used only when `shear_modulus` is `None`. Default 0.5.
    pub poisson_ratio: f64,
    /// Density `rho` (kg/m^3): lumped vertex masses `rho A l` and twist inertia `rho J l`.
    /// Default 1000.
    pub density: f64,
    /// Viscous (mass-proportional Rayleigh) damping rate `alpha` (1/s): every degree of
    /// freedom feels `-alpha * mass * velocity`. Default 2.
    pub damping: f64,
    /// Gravitational acceleration (m/s^2). Default zero (off).
    pub gravity: [f64; 3],
}

impl Default for RodParams {
    fn default() -> Self {
        Self {
            radius: 0.01,
            youngs_modulus: 1.0e7,
            shear_modulus: None,
            poisson_ratio: 0.5,
            density: 1000.0,
            damping: 2.0,
            gravity: [0.0; 3],
        }
    }
}

impl RodParams {
    /// Checks every field: positive radius, moduli and density, `-1 < nu <= 0.5`, damping
    /// `>= 0`, finite gravity; and that the cross-section's area, moments, stiffnesses and mass
    /// per length are normal finite numbers.
    pub fn validate(&self) -> Result<(), RodError> {
        let positive = |name, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(RodError::InvalidParameter { name, value, reason: "must be positive and finite" })
            }
        };
        positive("radius", self.radius)?;
        positive("youngs_modulus", self.youngs_modulus)?;
        positive("density", self.density)?;
        if let Some(g) = self.shear_modulus {
            positive("shear_modulus", g)?;
        }
        let nu = self.poisson_ratio;
        if !(nu.is_finite() && nu > -1.0 && nu <= 0.5) {
            return Err(RodError::InvalidParameter {
                name: "poisson_ratio",
                value: nu,
                reason: "must lie in (-1, 0.5]",
            });
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return Err(RodError::InvalidParameter {
                name: "damping",
                value: self.damping,
                reason: "must be >= 0 and finite",
            });
        }
        if let Some(&g) = self.gravity.iter().find(|g| !g.is_finite()) {
            return Err(RodError::InvalidParameter { name: "gravity", value: g, reason: "must be finite" });
        }
        // What the solver computes from them must be a number too: a radius of 1e300 makes the
        // cross-section infinite (and every step NaN), one of 1e-200 makes it vanish. The radius is
        // blamed first, then the modulus or density that multiplies its powers.
        let usable = |v: f64| v.is_finite() && v >= f64::MIN_POSITIVE;
        let blamed = if ![self.area(), self.second_moment(), self.polar_moment()].into_iter().all(usable) {
            Some(("radius", self.radius))
        } else if !(usable(self.stretch_stiffness()) && usable(self.bend_stiffness())) {
            Some(("youngs_modulus", self.youngs_modulus))
        } else if !usable(self.twist_stiffness()) {
            Some(self.shear_modulus.map_or(("youngs_modulus", self.youngs_modulus), |g| ("shear_modulus", g)))
        } else if !usable(self.density * self.area()) {
            Some(("density", self.density))
        } else {
            None
        };
        if let Some((name, value)) = blamed {
            let reason = "makes the cross-section's stiffness or mass overflow or vanish (SI units: m, Pa, kg/m^3)";
            return Err(RodError::InvalidParameter { name, value, reason });
        }
        Ok(())
    }

    /// Cross-section area `A = pi r^2` (m^2).
    pub fn area(&self) -> f64 {
        std::f64::consts::PI * self.radius * self.radius
    }

    /// Second moment of area `I = pi r^4 / 4` (m^4).
    pub fn second_moment(&self) -> f64 {
        std::f64::consts::PI * self.radius.powi(4) / 4.0
    }

    /// Polar moment `J = pi r^4 / 2` (m^4).
    pub fn polar_moment(&self) -> f64 {
        std::f64::consts::PI * self.radius.powi(4) / 2.0
    }

    /// Shear modulus `G` (Pa), given or derived from `E` and `nu`.
    pub fn shear(&self) -> f64 {
        self.shear_modulus.unwrap_or(self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio)))
    }

    /// Stretching stiffness `EA` (N).
    pub fn stretch_stiffness(&self) -> f64 {
        self.youngs_modulus * self.area()
    }

    /// Bending stiffness `EI` (N m^2).
    pub fn bend_stiffness(&self) -> f64 {
        self.youngs_modulus * self.second_moment()
    }

    /// Twisting stiffness `GJ` (N m^2).
    pub fn twist_stiffness(&self) -> f64 {
        self.shear() * self.polar_moment()
    }
}

/// Settings of the implicit solver shared by every rod of a [`crate::World`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverSettings {
    /// Newton stops when the largest position update is below `tolerance * rod length` and the
    /// largest twist update below `tolerance` radians. Default 1e-7.
    pub tolerance: f64,
    /// Newton iterations per (sub)step before the step is retried as two half steps. Default 50:
    /// a rod sliding far along a curved obstacle in one step (a released stem springing back past
    /// a leaf) needs many short line-searched iterations, which halving the step does not shorten.
    pub max_iterations: usize,
    /// How many times a failing step may be halved (`2^depth` substeps at most). Default 8.
    pub max_halvings: u32,
    /// Newton iterations of a quasi-static solve. Default 200.
    pub max_static_iterations: usize,
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self { tolerance: 1.0e-7, max_iterations: 50, max_halvings: 8, max_static_iterations: 200 }
    }
}

impl SolverSettings {
    /// Checks that the tolerance is positive and the iteration counts non-zero.
    pub fn validate(&self) -> Result<(), RodError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(RodError::InvalidParameter {
                name: "tolerance",
                value: self.tolerance,
                reason: "must be positive and finite",
            });
        }
        if self.max_iterations == 0 || self.max_static_iterations == 0 {
            return Err(RodError::InvalidParameter {
                name: "max_iterations",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        if self.max_halvings > 20 {
            return Err(RodError::InvalidParameter {
                name: "max_halvings",
                value: f64::from(self.max_halvings),
                reason: "must be at most 20",
            });
        }
        Ok(())
    }
}
