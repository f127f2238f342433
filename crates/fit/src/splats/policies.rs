//! The splat fit's two small policies: [`SplatRates`] (3DGS's per-parameter learning rates,
//! the means' decaying) and [`OpacityReset`] (every few thousand steps, every opacity back
//! to at most 0.01, so that splats that only hide others must earn their opacity again and
//! the useless ones fall under the pruning threshold).

use fogray_tape::Float;

use super::model::SplatModel;
use super::settings::SplatSettings;
use crate::error::FitError;
use crate::trainer::{StepContext, StepPolicy};

/// The opacity a reset caps every splat's at (3DGS's).
pub(crate) const RESET_OPACITY: f64 = 0.01;

/// Per-parameter learning rates, set before every step (the optimiser's base rate is 1 and
/// each parameter's scale is its rate, so a densification's new optimiser gets them back).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SplatRates {
    settings: SplatSettings,
    extent: f64,
}

impl SplatRates {
    /// The rates of `settings` in a scene of extent `extent`.
    pub(crate) fn new(settings: &SplatSettings, extent: f64) -> Self {
        SplatRates {
            settings: *settings,
            extent,
        }
    }

    /// The means' rate at budget fraction `t` in `[0, 1]`: log-linear between the settings'
    /// two, times the extent (a scene twice as large moves its splats twice as far).
    pub(crate) fn means_rate(&self, t: f64) -> f64 {
        let [a, b] = self.settings.means_lr;
        let t = t.clamp(0.0, 1.0);
        (a.ln() * (1.0 - t) + b.ln() * t).exp() * self.extent
    }
}

impl<F: Float> StepPolicy<F, SplatModel<F>> for SplatRates {
    fn before_step(&mut self, at: &mut StepContext<'_, F, SplatModel<F>>) -> Result<(), FitError> {
        let ids = at.model.ids();
        let s = self.settings;
        at.optimiser.set_lr(1.0)?;
        at.optimiser.set_lr_scale(ids.means, self.means_rate(at.fraction))?;
        at.optimiser.set_lr_scale(ids.log_scales, s.log_scales_lr)?;
        at.optimiser.set_lr_scale(ids.quats, s.quats_lr)?;
        at.optimiser.set_lr_scale(ids.opacity_logits, s.opacity_lr)?;
        at.optimiser.set_lr_scale(ids.sh, s.colors_lr)?;
        Ok(())
    }
}

/// Caps every opacity at [`RESET_OPACITY`] every `reset_every` steps while the fit still
/// densifies (see the [module docs](self)): a reset after the last densification would leave
/// no time to earn the opacity back.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OpacityReset {
    every: usize,
    until: f64,
}

impl OpacityReset {
    /// The resets of `settings` (`reset_every` steps, 0: never; until `densify_until`).
    pub(crate) fn new(settings: &SplatSettings) -> Self {
        OpacityReset {
            every: settings.reset_every,
            until: settings.densify_until,
        }
    }
}

impl<F: Float> StepPolicy<F, SplatModel<F>> for OpacityReset {
    fn after_step(&mut self, at: &mut StepContext<'_, F, SplatModel<F>>) -> Result<(), FitError> {
        if self.every == 0 || at.step == 0 || at.step % self.every != 0 || at.fraction >= self.until {
            return Ok(());
        }
        let id = at.model.ids().opacity_logits;
        let cap = F::lit((RESET_OPACITY / (1.0 - RESET_OPACITY)).ln());
        for v in at.model.params_mut().get_mut(id)?.iter_mut() {
            if *v > cap {
                *v = cap;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splats::model::SplatArraysOwned;
    use fogray_tape::optim::{Adam, AdamConfig};
    use ndarray::{arr1, arr2, Array2};

    #[test]
    fn reset_caps_opacity_on_its_steps_only() {
        let mut model = SplatModel::<f64>::new(
            SplatArraysOwned {
                means: Array2::zeros((2, 3)),
                log_scales: Array2::zeros((2, 3)),
                quats: arr2(&[[1.0, 0.0, 0.0, 0.0]; 2]),
                opacity_logits: arr1(&[3.0, -6.0]),
                sh: Array2::zeros((2, 3)),
            },
            0,
        )
        .unwrap();
        let mut adam = Adam::new(AdamConfig::default()).unwrap();
        let mut occupancy = None;
        let mut reset = OpacityReset::new(&SplatSettings::default());
        for (step, first) in [(2999, 3.0), (3000, (0.01f64 / 0.99).ln())] {
            let mut at = StepContext {
                step,
                fraction: 0.25,
                model: &mut model,
                optimiser: &mut adam,
                occupancy: &mut occupancy,
            };
            reset.after_step(&mut at).unwrap();
            let a = model.arrays().unwrap();
            assert!((a.opacity_logits[0] - first).abs() < 1e-12);
            assert_eq!(a.opacity_logits[1], -6.0, "below the cap: unchanged");
        }
        // Past the last densification, no reset: nothing would earn its opacity back.
        let id = model.ids().opacity_logits;
        model.params_mut().get_mut(id).unwrap()[0] = 3.0;
        let mut at = StepContext {
            step: 6000,
            fraction: 0.7,
            model: &mut model,
            optimiser: &mut adam,
            occupancy: &mut occupancy,
        };
        reset.after_step(&mut at).unwrap();
        assert_eq!(model.arrays().unwrap().opacity_logits[0], 3.0);
    }

    #[test]
    fn means_rate_decays_from_the_first_to_the_last() {
        let settings = SplatSettings {
            means_lr: [1.6e-4, 1.6e-6],
            ..SplatSettings::default()
        };
        let r = SplatRates::new(&settings, 2.0);
        assert!((r.means_rate(0.0) - 3.2e-4).abs() < 1e-15);
        assert!((r.means_rate(1.0) - 3.2e-6).abs() < 1e-17);
        // Half way, the geometric mean: 1.6e-5 x 2.
        assert!((r.means_rate(0.5) - 3.2e-5).abs() < 1e-15);
    }
}
