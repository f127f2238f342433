//! Running a sweep's fits, one after another (they are timed, so never side by side), and
//! keeping of each what a report shows: its log and figures, and pictures of its final model.

use fogray_fit::dataset::Dataset;
use fogray_fit::dispatch::{with_field_kind, FieldKind, FieldWork};
use fogray_fit::model::RadianceField;
use fogray_fit::settings::{FitSettings, SceneBox};
use fogray_fit::train::{fit, FitResult, LogEntry, Progress};
use fogray_fit::FitError;
use fogray_tape::Float;
use ndarray::Array3;
use serde::Serialize;

use super::config::RunConfig;
use super::SweepError;
use crate::slices::{model_density_planes, occupancy_planes, PlaneImage};

/// What a sweep runs.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepOptions {
    /// The settings every fit shares (grid, batch, budget, seed, model, ...); each
    /// configuration sets the method, the sampling and the precision.
    pub fit: FitSettings,
    /// The configurations, in the order they run (at least one, no repeats).
    pub configs: Vec<RunConfig>,
    /// Pixels per side of the density slices (at least 1).
    pub slice_pixels: usize,
}

/// One configuration's fit: the fit's figures (as `fogray-grid fit --json` prints them, for
/// JSON) with the configuration's name, and pictures of the final model (not serialised).
#[derive(Debug, Clone, Serialize)]
pub struct ConfigRun {
    /// `METHOD-SAMPLING[-PRECISION]`.
    pub name: String,
    /// `"fused"` or `"taped"`.
    pub method: &'static str,
    /// `"uniform"` or `"occupancy"`.
    pub sampling: &'static str,
    /// `"f32"` or `"f64"`.
    pub precision: &'static str,
    /// The evaluations, in order.
    pub log: Vec<LogEntry>,
    /// Test PSNR at the end (dB).
    pub final_test_psnr: f64,
    /// Training seconds, evaluations excluded.
    pub seconds: f64,
    /// Steps done.
    pub steps: usize,
    /// Mean samples per training ray over all steps.
    pub samples_per_ray_mean: f64,
    /// Fraction of occupied cells at the end (1 with uniform sampling).
    pub occupied_fraction: f64,
    /// Pictures of the final model.
    #[serde(skip)]
    pub pictures: FinalPictures,
}

/// What a report draws of a final model.
#[derive(Debug, Clone)]
pub struct FinalPictures {
    /// The test views' renders `[H][W][3]`, in view order.
    pub renders: Vec<Array3<f64>>,
    /// The box the density planes cut through (the fit's [`FitSettings::model_box`]).
    pub density_box: SceneBox,
    /// The density on the three planes through the centre of `density_box`.
    pub density: Vec<PlaneImage>,
    /// The occupancy grid's middle planes (occupancy sampling only).
    pub occupancy: Option<Vec<PlaneImage>>,
}

impl Default for FinalPictures {
    /// No pictures, over the unit box.
    fn default() -> Self {
        FinalPictures {
            renders: Vec::new(),
            density_box: SceneBox::UNIT,
            density: Vec::new(),
            occupancy: None,
        }
    }
}

fn check(options: &SweepOptions) -> Result<(), SweepError> {
    if options.configs.is_empty() {
        return Err(SweepError::Config("no configuration to run".into()));
    }
    for (i, c) in options.configs.iter().enumerate() {
        if options.configs[..i].contains(c) {
            return Err(SweepError::Config(format!("configuration {c} is given twice")));
        }
    }
    if options.slice_pixels == 0 {
        return Err(SweepError::Config("slices need at least 1 pixel per side".into()));
    }
    Ok(())
}

fn keep<F: Float, M: RadianceField<F>>(
    config: &RunConfig,
    result: FitResult<F, M>,
    density_box: SceneBox,
    slice_pixels: usize,
) -> Result<ConfigRun, SweepError> {
    let density = model_density_planes(&result.model, &density_box, slice_pixels)?;
    let occupancy = match &result.occupancy {
        Some(grid) => Some(occupancy_planes(grid).map_err(FitError::from)?),
        None => None,
    };
    Ok(ConfigRun {
        name: config.to_string(),
        method: config.method.name(),
        sampling: config.sampling.name(),
        precision: config.precision.name(),
        steps: result.log.last().map_or(0, |e| e.step),
        log: result.log,
        final_test_psnr: result.final_test_psnr,
        seconds: result.seconds,
        samples_per_ray_mean: result.samples_per_ray_mean,
        occupied_fraction: result.occupied_fraction,
        pictures: FinalPictures {
            renders: result.renders,
            density_box,
            density,
            occupancy,
        },
    })
}

/// Fits `data` with `fit_config` (whose method, sampling and precision are expected to be
/// `config`'s) with the model it names, and keeps what a report shows of the fit.
pub(crate) fn run_config(
    data: &Dataset,
    config: &RunConfig,
    fit_config: &FitSettings,
    slice_pixels: usize,
    progress: &mut dyn FnMut(Progress),
) -> Result<ConfigRun, SweepError> {
    let work = FitAndKeep {
        data,
        config,
        fit_config,
        slice_pixels,
        progress,
    };
    // A sweep keeps density slices and grid statistics, which splats have not.
    let field = FieldKind::try_from(fit_config.model).map_err(|_| {
        SweepError::Config("a sweep fits grids; splats are fitted with `fogray fit --model splats`".into())
    })?;
    with_field_kind(config.precision, field, work)
}

/// [`run_config`]'s work, for one model type.
struct FitAndKeep<'a> {
    data: &'a Dataset,
    config: &'a RunConfig,
    fit_config: &'a FitSettings,
    slice_pixels: usize,
    progress: &'a mut dyn FnMut(Progress),
}

impl FieldWork for FitAndKeep<'_> {
    type Output = Result<ConfigRun, SweepError>;

    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
        let result = fit::<F, M>(self.data, self.fit_config, self.progress)?;
        keep(self.config, result, self.fit_config.model_box(), self.slice_pixels)
    }
}

/// Fits every configuration of `options` to `data` in turn; `progress` hears the index of the
/// configuration running and its fit's progress.
///
/// Errors: [`SweepError::Config`] for no configuration, a repeated one or 0 slice pixels
/// (before anything runs); a fit's error.
pub fn run_configs(
    data: &Dataset,
    options: &SweepOptions,
    progress: &mut dyn FnMut(usize, Progress),
) -> Result<Vec<ConfigRun>, SweepError> {
    check(options)?;
    let mut runs = Vec::with_capacity(options.configs.len());
    for (i, config) in options.configs.iter().enumerate() {
        let fit_config = FitSettings {
            method: config.method,
            sampling: config.sampling,
            precision: config.precision,
            ..options.fit
        };
        let mut report = |p| progress(i, p);
        runs.push(run_config(
            data,
            config,
            &fit_config,
            options.slice_pixels,
            &mut report,
        )?);
    }
    Ok(runs)
}

/// The run with the highest final test PSNR (the first of equals); `None` for no runs.
pub fn best(runs: &[ConfigRun]) -> Option<&ConfigRun> {
    runs.iter()
        .reduce(|a, b| if b.final_test_psnr > a.final_test_psnr { b } else { a })
}
