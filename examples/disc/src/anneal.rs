//! Annealing the softness (the lesson's last move: what the softness buys and what it costs):
//! tau goes from large to small while the fit tracks the minimum, and the learning rate
//! shrinks with it.
//!
//! Why this schedule: it starts at the largest softness whose loss landscape still has a
//! single valley at the truth (softer ones grow false valleys, and eventually make the truth a
//! maximum), so a descent from anywhere in the range heads for the truth. It ends where the 64
//! uniform samples per ray still resolve the sheet: a thinner sheet is under-sampled, and the
//! loss then grows ripples with false minima near the truth. Sharpening further is not needed
//! for the position, because the scene is symmetric about x = 0, so the soft loss's minimum is
//! at the truth for every tau that has one there. Tau and the learning rate fall
//! geometrically; the rate starts above the lesson's to cross the flat far field quickly and
//! ends small so that the last steps settle instead of rattling. `docs/disc.md` gives the
//! measured outcome from 25 starts.

use clap::Args;
use fogray::tape::TapeError;

use crate::adam::{descend, Adam};
use crate::error::DiscError;
use crate::experiments::{Fit, Renderer};
use crate::hard;
use crate::setup::Setup;

/// The softness schedule.
#[derive(Debug, Clone, Copy, Args)]
pub struct Schedule {
    /// Softness at the first annealed step (m).
    #[arg(long, default_value_t = 0.3)]
    pub tau_start: f64,
    /// Softness at the last annealed step (m).
    #[arg(long, default_value_t = 0.1)]
    pub tau_end: f64,
    /// Learning rate at the first annealed step.
    #[arg(long, default_value_t = 0.1)]
    pub lr_start: f64,
    /// Learning rate at the last annealed step.
    #[arg(long, default_value_t = 0.002)]
    pub lr_end: f64,
    /// Number of annealed steps.
    #[arg(long, default_value_t = 200)]
    pub anneal_steps: usize,
}

impl Default for Schedule {
    fn default() -> Self {
        Schedule {
            tau_start: 0.3,
            tau_end: 0.1,
            lr_start: 0.1,
            lr_end: 0.002,
            anneal_steps: 200,
        }
    }
}

impl Schedule {
    /// Softness and learning rate at step `k` of `n`: geometric from start to end.
    pub fn at(&self, k: usize) -> (f64, f64) {
        let f = if self.anneal_steps > 1 {
            k as f64 / (self.anneal_steps - 1) as f64
        } else {
            1.0
        };
        let geo = |a: f64, b: f64| a * (b / a).powf(f);
        (geo(self.tau_start, self.tau_end), geo(self.lr_start, self.lr_end))
    }

    /// Checks the schedule.
    pub fn validate(&self) -> Result<(), DiscError> {
        for (name, v) in [
            ("tau-start", self.tau_start),
            ("tau-end", self.tau_end),
            ("lr-start", self.lr_start),
            ("lr-end", self.lr_end),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(DiscError::Setting {
                    name,
                    value: v,
                    rule: "positive",
                });
            }
        }
        if self.anneal_steps == 0 {
            return Err(DiscError::Usage("--anneal-steps must be at least 1"));
        }
        Ok(())
    }
}

/// Adam on the soft loss with the softness and learning rate of `schedule` (`adam`'s moments
/// and guard; its learning rate and number of steps are the schedule's).
pub fn fit_annealed(setup: &Setup, start: f64, schedule: &Schedule, adam: &Adam) -> Result<Fit, TapeError> {
    let path = descend(adam.config(), start, schedule.anneal_steps, |k, x| {
        let (tau, lr) = schedule.at(k);
        Ok((setup.soft(x, tau)?.slope, lr))
    })?;
    let end = *path.last().unwrap_or(&start);
    let tau = (0..schedule.anneal_steps)
        .map(|k| schedule.at(k).0)
        .chain([schedule.tau_end])
        .collect();
    Ok(Fit {
        renderer: Renderer::Soft,
        start,
        end,
        path,
        tau,
        pixels_wrong: hard::mismatches(&setup.rays, end, setup.scene.radius, &setup.truth, hard::hits),
    })
}
