//! Fused against taped over the same steps: the time each method takes to the same PSNR.
//!
//! A fit's schedule (the grid's growth, the learning rate's annealing) is a fraction of its
//! budget. Partway through a timed run, the faster method is therefore still on a coarser grid
//! at a higher rate than a run of that length would be, and where the curves flatten, the
//! first time one run passes the other's final PSNR says more about the schedule than about
//! the ops (the first crossing of [`fused_vs_taped`](crate::curves::fused_vs_taped)). The
//! fused ops and their taped twins do the same arithmetic, so over the same number of steps,
//! each with its schedule over those steps, the two end at the same PSNR up to rounding: the
//! ratio of their training seconds is the speed-up to that PSNR.
//!
//! The taped run is long and the fused one short, and a shared machine's speed can move by a
//! tenth or more within minutes, so a pair that trains again runs fused, taped, then fused
//! again: the taped run lies between the two fused runs, and the speed-up takes their mean.

use serde::Serialize;

use fogray_fit::dataset::Dataset;
use fogray_fit::settings::Method;
use fogray_fit::settings::{Budget, FitSettings};
use fogray_fit::train::Progress;

use super::config::{shared_name, RunConfig};
use super::run::{run_config, ConfigRun, SweepOptions};
use super::SweepError;

/// Test evaluations of an extra run: only its final PSNR is reported (evaluations are off the
/// clock either way; fewer of them shorten the sweep).
const EXTRA_RUN_EVALUATIONS: usize = 1;

/// One method's run of a pair.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StepsRun {
    /// Steps done.
    pub steps: usize,
    /// Training seconds, evaluations excluded.
    pub seconds: f64,
    /// Test PSNR at the end (dB).
    pub final_test_psnr: f64,
}

impl StepsRun {
    fn of(run: &ConfigRun) -> Self {
        StepsRun {
            steps: run.steps,
            seconds: run.seconds,
            final_test_psnr: run.final_test_psnr,
        }
    }
}

/// A fused and a taped run of the same steps, each with its schedule over those steps.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SameSteps {
    /// The steps of both (those the taped configuration made in the sweep's budget).
    pub steps: usize,
    /// Whether the pair was run for this comparison (a budget of seconds) rather than taken
    /// from the sweep's runs (a budget of steps, which already are such a pair).
    pub extra_runs: bool,
    /// The fused run (with extra runs, the one before the taped run).
    pub fused: StepsRun,
    /// With extra runs, the fused run again, after the taped run (the same steps and, the fit
    /// being deterministic, the same PSNR to the bit; only its seconds differ).
    pub fused_again: Option<StepsRun>,
    /// The taped run.
    pub taped: StepsRun,
    /// Taped seconds over [`SameSteps::fused_seconds`]; `None` if the fused runs took no time.
    pub speedup: Option<f64>,
}

impl SameSteps {
    /// The fused runs' mean training seconds.
    pub fn fused_seconds(&self) -> f64 {
        match self.fused_again {
            Some(again) => 0.5 * (self.fused.seconds + again.seconds),
            None => self.fused.seconds,
        }
    }
}

/// Fused against taped over the same steps for every sampling and precision that `options`
/// runs with both methods, each named by [`shared_name`] (`"uniform"`, `"occupancy-f64"`).
/// `runs` are the sweep's runs of `options.configs` ([`run_configs`](super::run_configs)), in
/// that order.
///
/// With a budget of steps the sweep's own runs are the pairs. With a budget of seconds, each
/// pair trains again (fused, taped, then fused again: see the module docs) for the steps the
/// taped run made, with one evaluation (at its end); `progress` hears each extra
/// run's name (such as `"taped-occupancy, 826 steps"`, and `"fused-occupancy, 826 steps,
/// again"`) and its fit's progress. A taped run that made no step gives no pair.
///
/// Errors: [`SweepError::Config`] if `runs` are not the runs of `options.configs`; a fit's
/// error.
pub fn same_steps(
    data: &Dataset,
    options: &SweepOptions,
    runs: &[ConfigRun],
    progress: &mut dyn FnMut(&str, Progress),
) -> Result<Vec<(String, SameSteps)>, SweepError> {
    let names_match =
        runs.len() == options.configs.len() && runs.iter().zip(&options.configs).all(|(r, c)| r.name == c.to_string());
    if !names_match {
        return Err(SweepError::Config(
            "the runs are not those of the report's configurations".into(),
        ));
    }
    let mut pairs = Vec::new();
    for (fused_config, fused) in options.configs.iter().zip(runs) {
        if fused_config.method != Method::Fused {
            continue;
        }
        let taped_config = RunConfig {
            method: Method::Taped,
            ..*fused_config
        };
        let Some(taped) = options
            .configs
            .iter()
            .position(|c| *c == taped_config)
            .map(|i| &runs[i])
        else {
            continue;
        };
        if taped.steps == 0 {
            continue;
        }
        let name = shared_name(fused.sampling, fused.precision);
        let (fused_run, fused_again, taped_run) = match options.fit.budget() {
            Budget::Steps(_) => (StepsRun::of(fused), None, StepsRun::of(taped)),
            Budget::Seconds(_) => {
                let mut run = |config: &RunConfig, again: &str| -> Result<StepsRun, SweepError> {
                    let fit_config = FitSettings {
                        method: config.method,
                        sampling: config.sampling,
                        precision: config.precision,
                        evaluations: EXTRA_RUN_EVALUATIONS,
                        ..options.fit.with_budget(Budget::Steps(taped.steps))
                    };
                    let label = format!("{config}, {} steps{again}", taped.steps);
                    let mut report = |p| progress(&label, p);
                    let run = run_config(data, config, &fit_config, options.slice_pixels, &mut report)?;
                    Ok(StepsRun::of(&run))
                };
                let before = run(fused_config, "")?;
                let taped_run = run(&taped_config, "")?;
                let after = run(fused_config, ", again")?;
                (before, Some(after), taped_run)
            }
        };
        let mut pair = SameSteps {
            steps: taped.steps,
            extra_runs: fused_again.is_some(),
            fused: fused_run,
            fused_again,
            taped: taped_run,
            speedup: None,
        };
        let fused_seconds = pair.fused_seconds();
        pair.speedup = (fused_seconds > 0.0).then(|| pair.taped.seconds / fused_seconds);
        pairs.push((name, pair));
    }
    Ok(pairs)
}
