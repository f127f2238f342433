//! Where a fit's training time went: the wall time of each phase of a step, and the tape's
//! time op by op ([`fogray_tape::Profile`]), summed over the steps of one fit
//! ([`FitResult::profile`](crate::train::FitResult::profile)). Fused against taped, the two
//! tables say what the fused ops buy and what both share.

use std::time::Duration;

use fogray_tape::Profile;
use serde::Serialize;

/// The phases of a training step, in order.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Phases {
    /// Drawing the batch and gathering its rays and colours.
    pub batch: Duration,
    /// Placing the samples along the rays (uniform, or the occupancy grid's midpoint sampler).
    pub sample: Duration,
    /// The render, the loss and the prior, recorded on the tape.
    pub forward: Duration,
    /// The backward sweep.
    pub backward: Duration,
    /// Clearing the tape and Adam's update.
    pub optimiser: Duration,
    /// Refreshing the occupancy grid (every few steps).
    pub occupancy: Duration,
}

/// A fit's step profile. The training seconds also hold what no phase does: the learning
/// rate's update and, at the growth stages, the grid's resampling.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct StepProfile {
    /// Steps profiled.
    pub steps: usize,
    /// Wall time per phase, summed over the steps.
    pub phases: Phases,
    /// The tape's op times over the steps (the test renders are not counted).
    pub ops: Profile,
}

/// A phase as written out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct PhaseRow {
    /// The phase's name.
    pub name: &'static str,
    /// Milliseconds a step.
    pub ms: f64,
}

/// An op of the tape as written out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct OpRow {
    /// The op's name.
    pub name: &'static str,
    /// Calls a step.
    pub calls_per_step: f64,
    /// Forward milliseconds a step.
    pub forward_ms: f64,
    /// Backward milliseconds a step.
    pub backward_ms: f64,
}

/// A fit's step profile as written out by `fogray fit --profile` and `fogray-grid fit
/// --profile`: milliseconds a step, phase by phase and op by op.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProfileTable {
    /// Steps profiled.
    pub(crate) steps: usize,
    /// The phases, in step order.
    pub(crate) phases: Vec<PhaseRow>,
    /// The tape's ops, the most time first.
    pub(crate) ops: Vec<OpRow>,
}

impl StepProfile {
    /// Means per step in milliseconds (zeros when no step was taken).
    pub(crate) fn table(&self) -> ProfileTable {
        // With no step every sum is zero, and so is every mean.
        let steps = self.steps.max(1) as f64;
        let per_step = |d: Duration| 1e3 * d.as_secs_f64() / steps;
        let p = &self.phases;
        let phase = |name, d| PhaseRow { name, ms: per_step(d) };
        ProfileTable {
            steps: self.steps,
            phases: vec![
                phase("batch", p.batch),
                phase("sample", p.sample),
                phase("forward", p.forward),
                phase("backward", p.backward),
                phase("optimiser", p.optimiser),
                phase("occupancy", p.occupancy),
            ],
            ops: self
                .ops
                .by_time()
                .into_iter()
                .map(|(name, t)| OpRow {
                    name,
                    calls_per_step: t.forward_calls as f64 / steps,
                    forward_ms: per_step(t.forward),
                    backward_ms: per_step(t.backward),
                })
                .collect(),
        }
    }
}

impl std::fmt::Display for ProfileTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "where a step went (ms a step, mean over {} steps):", self.steps)?;
        for r in &self.phases {
            writeln!(f, "  {:<12} {:>9.3}", r.name, r.ms)?;
        }
        writeln!(f, "the tape's ops (calls a step, forward ms, backward ms):")?;
        for r in &self.ops {
            writeln!(
                f,
                "  {:<24} {:>6.2} {:>9.3} {:>9.3}",
                r.name, r.calls_per_step, r.forward_ms, r.backward_ms
            )?;
        }
        Ok(())
    }
}
