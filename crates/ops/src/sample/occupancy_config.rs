//! How the occupancy grid turns densities into occupancy: the threshold, the decay, and
//! where in each cell the density is evaluated.

use crate::error::{Op, OpsError};

/// When a cell counts as occupied: its density estimate above a threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// `estimate > density` (finite, non-negative).
    Density(f64),
    /// The opacity `1 - exp(-estimate * step)` of one marching step above `opacity` (in
    /// (0, 1)), i.e. `estimate > -ln(1 - opacity) / step`: a threshold that means the same
    /// whatever the step.
    Opacity {
        /// The marching step (finite, positive).
        step: f64,
        /// The least opacity of one step that counts (in (0, 1)).
        opacity: f64,
    },
}

/// How the grid turns densities into occupancy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OccupancyConfig {
    threshold: Threshold,
    decay: f64,
    refresh: Refresh,
}

/// When a training loop refreshes the grid ([`OccupancyGrid::update_every_n_steps`](super::OccupancyGrid::update_every_n_steps)):
/// every `every` steps from step `warmup` on.
///
/// A fresh model is a thin fog with no cell above the threshold, and a cell once empty gets
/// no samples to grow back from, so the density must first gather where the matter is: until
/// `warmup` every cell stays occupied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refresh {
    /// Steps before the first refresh.
    pub warmup: usize,
    /// Steps between refreshes (at least 1).
    pub every: usize,
}

impl Default for Refresh {
    /// From step 64, every 16 steps.
    fn default() -> Self {
        Refresh { warmup: 64, every: 16 }
    }
}

impl Refresh {
    /// Whether the grid is refreshed after step `step` (steps counted from 1).
    pub fn is_due(&self, step: usize) -> bool {
        step >= self.warmup && step % self.every == 0
    }

    /// The first step after which the grid is refreshed: the first multiple of `every` at or
    /// after `warmup`.
    pub fn first_due(&self) -> usize {
        self.warmup.div_ceil(self.every.max(1)) * self.every.max(1)
    }
}

pub(crate) fn config_error(what: &'static str, value: f64, rule: &'static str) -> OpsError {
    OpsError::Config {
        op: Op::Occupancy,
        what,
        value,
        rule,
    }
}

impl OccupancyConfig {
    /// Occupied where one step of length `step` is more than `opacity` opaque
    /// ([`Threshold::Opacity`]; 0.01 is the usual choice), with decay 0.95.
    /// Errors: `step` not finite and positive, `opacity` outside (0, 1).
    pub fn opacity(step: f64, opacity: f64) -> Result<Self, OpsError> {
        if !(step.is_finite() && step > 0.0) {
            return Err(config_error("step", step, "must be finite and positive"));
        }
        if !(opacity > 0.0 && opacity < 1.0) {
            return Err(config_error("opacity threshold", opacity, "must be in (0, 1)"));
        }
        Ok(OccupancyConfig {
            threshold: Threshold::Opacity { step, opacity },
            decay: 0.95,
            refresh: Refresh::default(),
        })
    }

    /// Occupied where the estimate exceeds `density` ([`Threshold::Density`]), decay 0.95.
    /// Errors: `density` not finite and non-negative.
    pub fn density(density: f64) -> Result<Self, OpsError> {
        if !(density.is_finite() && density >= 0.0) {
            return Err(config_error(
                "density threshold",
                density,
                "must be finite and non-negative",
            ));
        }
        Ok(OccupancyConfig {
            threshold: Threshold::Density(density),
            decay: 0.95,
            refresh: Refresh::default(),
        })
    }

    /// Sets the decay in `[0, 1]`: each update makes `estimate = max(estimate * decay, new)`,
    /// so a cell whose matter went away is forgotten gradually (0 forgets at once, 1 never).
    pub fn with_decay(mut self, decay: f64) -> Result<Self, OpsError> {
        if !(0.0..=1.0).contains(&decay) {
            return Err(config_error("decay", decay, "must be in [0, 1]"));
        }
        self.decay = decay;
        Ok(self)
    }

    /// Sets when a training loop refreshes the grid (default: [`Refresh::default`]).
    /// Errors: `every` is 0.
    pub fn with_refresh(mut self, refresh: Refresh) -> Result<Self, OpsError> {
        if refresh.every == 0 {
            return Err(config_error("refresh interval", 0.0, "must be at least 1 step"));
        }
        self.refresh = refresh;
        Ok(self)
    }

    /// When a training loop refreshes the grid.
    pub fn refresh(&self) -> Refresh {
        self.refresh
    }

    /// The threshold.
    pub fn threshold(&self) -> Threshold {
        self.threshold
    }

    /// The decay.
    pub fn decay(&self) -> f64 {
        self.decay
    }

    /// The density above which a cell is occupied.
    pub fn density_threshold(&self) -> f64 {
        match self.threshold {
            Threshold::Density(d) => d,
            // -ln(1 - a) as -ln_1p(-a): exact for small a, where 1 - a would round.
            Threshold::Opacity { step, opacity } => -(-opacity).ln_1p() / step,
        }
    }
}

/// Where in each cell the density is evaluated by [`OccupancyGrid::update`](super::OccupancyGrid::update).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellPoints {
    /// The cell centre. Matter that does not reach a cell's centre (the rim of a ball, a
    /// thin wall) leaves that cell empty and the marcher skips it: prefer
    /// [`CellPoints::CentreAndRandom`] with a new seed per update, which finds such cells
    /// over a few updates (the decay keeps them).
    Centre,
    /// One uniform random point per cell (seeded; use a new seed per update, so that
    /// matter smaller than a cell is found over time).
    Random {
        /// Seed of the draws.
        seed: u64,
    },
    /// The centre and one random point; the cell's new value is the larger density.
    CentreAndRandom {
        /// Seed of the draws.
        seed: u64,
    },
}
