//! [`SplatSettings`]: the budget, learning rates and densification schedule of a splat fit.
//! The policies are 3DGS's; the numbers are not. Two cores take a few hundred steps a minute
//! where 3DGS takes 30,000 on a GPU, so the schedule is in fractions of the budget (a budget
//! of seconds densifies in proportion), the rates are raised about tenfold (from 3DGS's,
//! each raise measured on lego's held-out views at 60 s), the start is 10,000 splats (fewer
//! splats are more steps), and the gradient threshold is for the gradient of the 3-D means,
//! which fogray's op gives, not of 3DGS's 2-D ones.

use crate::error::FitError;
use crate::settings::{Budget, FitSettings};

/// How a splat fit runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SplatSettings {
    /// The budget: steps (each renders one training view) or training seconds.
    pub budget: Budget,
    /// Seed of the view order, the backgrounds and a random start.
    pub seed: u64,
    /// Splats of a random start.
    pub initial_splats: usize,
    /// The colours' spherical-harmonics degree, 0 to 3.
    pub degree: usize,
    /// Whether a training view with alpha is composited over a random colour each step (as
    /// the grid's rays are), so that no splat paints the background.
    pub random_background: bool,
    /// The means' rate at the start and at the end, times the scene extent (decays
    /// exponentially between).
    pub means_lr: [f64; 2],
    /// The log-scales' rate.
    pub log_scales_lr: f64,
    /// The quaternions' rate.
    pub quats_lr: f64,
    /// The opacity logits' rate.
    pub opacity_lr: f64,
    /// The colour coefficients' rate.
    pub colors_lr: f64,
    /// The fraction of the budget from which splats are densified.
    pub densify_from: f64,
    /// The fraction of the budget from which they no longer are.
    pub densify_until: f64,
    /// Steps between two densifications.
    pub densify_every: usize,
    /// The mean mean-gradient norm above which a splat is cloned or split.
    pub grad_threshold: f64,
    /// The largest scale (times the scene extent) of a splat that is cloned, not split.
    pub dense_fraction: f64,
    /// Splats below this opacity are pruned.
    pub min_opacity: f64,
    /// Steps between two opacity resets (0: never); none after `densify_until`.
    pub reset_every: usize,
    /// The most splats a densification may make.
    pub max_splats: usize,
}

impl Default for SplatSettings {
    fn default() -> Self {
        SplatSettings {
            budget: Budget::Steps(30_000),
            seed: 0,
            initial_splats: 10_000,
            degree: 1,
            random_background: true,
            means_lr: [4e-3, 4e-5],
            log_scales_lr: 3e-2,
            quats_lr: 1e-3,
            opacity_lr: 1e-1,
            colors_lr: 1e-1,
            densify_from: 0.05,
            densify_until: 0.6,
            densify_every: 50,
            grad_threshold: 5e-5,
            dense_fraction: 0.01,
            min_opacity: 0.005,
            reset_every: 3000,
            max_splats: 1_000_000,
        }
    }
}

impl SplatSettings {
    /// The splat settings of a fit: its budget, seed, colour degree and random background,
    /// the rest as [`SplatSettings::default`].
    pub(crate) fn of_fit(settings: &FitSettings) -> Self {
        SplatSettings {
            budget: settings.budget(),
            seed: settings.seed,
            degree: settings.sh_degree,
            random_background: settings.random_background,
            ..SplatSettings::default()
        }
    }

    /// Errors: a zero budget, period or count, a degree above 3, or a rate, threshold or
    /// fraction that is negative or not finite ([`FitError::Setting`]).
    pub(crate) fn check(&self) -> Result<(), FitError> {
        let rates = [
            self.means_lr[0],
            self.means_lr[1],
            self.log_scales_lr,
            self.quats_lr,
            self.opacity_lr,
            self.colors_lr,
            self.grad_threshold,
            self.dense_fraction,
            self.min_opacity,
            self.densify_from,
            self.densify_until,
        ];
        if rates.iter().any(|r| !(r.is_finite() && *r >= 0.0)) || self.means_lr.contains(&0.0) {
            return Err(FitError::Setting {
                flag: "splat rates, thresholds and fractions",
                value: None,
                rule: format!("must be finite and >= 0 (means' > 0): {rates:?}"),
            });
        }
        let budget_ok = match self.budget {
            Budget::Steps(n) => n > 0,
            Budget::Seconds(s) => s.is_finite() && s > 0.0,
        };
        if !budget_ok || self.densify_every == 0 || self.max_splats == 0 || self.initial_splats == 0 {
            return Err(FitError::Setting {
                flag: "a splat fit's budget, densification period, initial count and cap",
                value: None,
                rule: "must be positive".into(),
            });
        }
        if self.degree > 3 {
            return Err(FitError::Setting {
                flag: "a splat colour degree",
                value: None,
                rule: format!("of {} (0 to 3)", self.degree),
            });
        }
        Ok(())
    }
}
