//! Running the report's fits, one after another (they are timed, so never side by side), and
//! keeping of each what the report shows: its log and figures, and pictures of its final model.

use fogray::tape::Float;
use ndarray::Array3;
use serde::Serialize;

use crate::slices::{model_density_planes, occupancy_planes, PlaneImage};
use fogray::fit::dataset::Dataset;
use fogray::fit::dense::DenseGrid;
use fogray::fit::settings::FitSettings;
use fogray::fit::train::{fit, FitResult, LogEntry, Progress};

use fogray::fit::settings::Precision;

use super::configuration::RunConfig;
use super::ReportError;

/// What the report runs.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportOptions {
    /// The settings every fit shares (grid, batch, budget, seed, ...); each configuration sets
    /// the method and the sampling.
    pub fit: FitSettings,
    /// The configurations, in the order they run (at least one, no repeats).
    pub configs: Vec<RunConfig>,
    /// Pixels per side of the density slices (at least 1).
    pub slice_pixels: usize,
}

/// One configuration's fit: the fit's JSON figures (as `fogray-grid fit --json` prints them)
/// with the configuration's name, and pictures of the final model (not serialised).
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

/// What the report draws of a final model.
#[derive(Debug, Clone, Default)]
pub struct FinalPictures {
    /// The test views' renders `[W][W][3]`, in view order.
    pub renders: Vec<Array3<f64>>,
    /// The density on the three planes through the centre.
    pub density: Vec<PlaneImage>,
    /// The occupancy grid's middle planes (occupancy sampling only).
    pub occupancy: Option<Vec<PlaneImage>>,
}

fn check(options: &ReportOptions) -> Result<(), ReportError> {
    if options.configs.is_empty() {
        return Err(ReportError::Config("no configuration to run".into()));
    }
    for (i, c) in options.configs.iter().enumerate() {
        if options.configs[..i].contains(c) {
            return Err(ReportError::Config(format!("configuration {c} is given twice")));
        }
    }
    if options.slice_pixels == 0 {
        return Err(ReportError::Config("slices need at least 1 pixel per side".into()));
    }
    Ok(())
}

fn keep<F: Float>(
    config: &RunConfig,
    result: FitResult<F, DenseGrid<F>>,
    slice_pixels: usize,
) -> Result<ConfigRun, ReportError> {
    let density = model_density_planes(&result.model, slice_pixels)?;
    let occupancy = match &result.occupancy {
        Some(grid) => Some(occupancy_planes(grid).map_err(fogray::fit::FitError::from)?),
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
            density,
            occupancy,
        },
    })
}

/// Fits `data` with `fit_config` in the precision of `config` (whose method and sampling
/// `fit_config` is expected to carry), and keeps what the report shows of the fit.
pub(crate) fn run_config(
    data: &Dataset,
    config: &RunConfig,
    fit_config: &FitSettings,
    slice_pixels: usize,
    progress: &mut dyn FnMut(Progress),
) -> Result<ConfigRun, ReportError> {
    match config.precision {
        Precision::F32 => keep(
            config,
            fit::<f32, DenseGrid<f32>>(data, fit_config, progress)?,
            slice_pixels,
        ),
        Precision::F64 => keep(
            config,
            fit::<f64, DenseGrid<f64>>(data, fit_config, progress)?,
            slice_pixels,
        ),
    }
}

/// Fits every configuration of `options` to `data` in turn; `progress` hears the index of the
/// configuration running and its fit's progress.
///
/// Errors: [`ReportError::Config`] for no configuration, a repeated one or 0 slice pixels
/// (before anything runs); a fit's error.
pub fn run_configs(
    data: &Dataset,
    options: &ReportOptions,
    progress: &mut dyn FnMut(usize, Progress),
) -> Result<Vec<ConfigRun>, ReportError> {
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
