//! A fit to a budget: [`fit`] steps a [`Trainer`] until its budget is spent (a session's fit,
//! resumed or stopped by Ctrl-C, runs the same loop), with the test PSNR on the held-out views
//! measured at intervals (outside the training clock), and returns the fitted model with its
//! log ([`FitResult`]).

use std::sync::atomic::AtomicBool;

use fogray_ops::sample::OccupancyGrid;
use fogray_tape::Float;
use ndarray::{Array3, ArrayView3};
use serde::Serialize;

use crate::dataset::{Dataset, View};
use crate::error::FitError;
use crate::metrics::{psnr, ssim, SSIM_WINDOW};
use crate::model::RadianceField;
use crate::profile::ProfileTable;
use crate::render::{render_picture, RenderOptions, RenderedView};
use crate::settings::FitSettings;
use crate::state::{Start, TrainingState};
use crate::trainer::{run_budget, Trainer};

/// One line of the log.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LogEntry {
    /// Steps done.
    pub step: usize,
    /// Training seconds so far (evaluations excluded).
    pub seconds: f64,
    /// The last step's loss (mean over rays and channels of the squared error); NaN at step 0.
    pub train_loss: f64,
    /// Test PSNR (dB) over all test views.
    pub test_psnr: f64,
    /// Test SSIM, the mean over the test views; NaN for views smaller than its window.
    pub test_ssim: f64,
    /// Training samples so far, over all rays of all steps (what a step's cost grows with).
    pub samples: usize,
}

/// What a fit returns.
#[derive(Debug)]
pub struct FitResult<F: Float, M> {
    /// The evaluations, in order.
    pub log: Vec<LogEntry>,
    /// Test PSNR at the end.
    pub final_test_psnr: f64,
    /// Test SSIM at the end.
    pub final_test_ssim: f64,
    /// Training seconds, evaluations excluded.
    pub seconds: f64,
    /// Mean samples per training ray over this call's steps (NaN if it took none).
    pub samples_per_ray_mean: f64,
    /// Fraction of occupied cells at the end (1 with uniform sampling).
    pub occupied_fraction: f64,
    /// Final renders of the test views `[H][W][3]`, unclamped, in view order.
    pub renders: Vec<Array3<f64>>,
    /// The same final renders with their opacity and depth, in view order.
    pub held_out: Vec<RenderedView>,
    /// The fitted model.
    pub model: M,
    /// Where the fit stopped, beyond the model: with it (as a [`Start`]), [`Trainer::new`]
    /// continues the fit.
    pub training: TrainingState<F>,
    /// Whether the fit stopped early because its stop flag was raised.
    pub interrupted: bool,
    /// The final occupancy grid, with occupancy sampling.
    pub occupancy: Option<OccupancyGrid>,
    /// Where this call's training time went, phase by phase and op by op, in milliseconds a
    /// step (as a session's report shows it).
    pub profile: ProfileTable,
}

/// Progress reported after every step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Steps done.
    pub step: usize,
    /// Fraction of the budget used, in `[0, 1]`.
    pub fraction: f64,
}

/// Renders every test view of `data` from `model` (colour only, unclamped), with the
/// occupancy grid a model fitted with one was trained with.
///
/// Errors: the ops' errors.
#[cfg(test)]
pub(crate) fn render_test_views<F: Float, M: RadianceField<F>>(
    model: &M,
    data: &Dataset,
    settings: &FitSettings,
    occupancy: Option<&OccupancyGrid>,
) -> Result<Vec<Array3<f64>>, FitError> {
    render_views(model, &data.test.iter().collect::<Vec<_>>(), data, settings, occupancy)
}

/// Renders `views` (colour only, unclamped) over `data`'s background.
fn render_views<F: Float, M: RadianceField<F>>(
    model: &M,
    views: &[&View],
    data: &Dataset,
    settings: &FitSettings,
    occupancy: Option<&OccupancyGrid>,
) -> Result<Vec<Array3<f64>>, FitError> {
    let options = RenderOptions {
        background: data.background,
        method: settings.method,
        depth: false,
    };
    views
        .iter()
        .map(|v| {
            let (origins, directions) = v.rays();
            Ok(render_picture(model, occupancy, &origins, &directions, v.size(), &options)?.color)
        })
        .collect()
}

/// The PSNR of `model` on `count` of its own training views (all of them if there are fewer):
/// views `i n / count` of the `n`, for `i` in `0..count`, spread through the training list as
/// the held-out views are through the file. Beside the held-out PSNR, the gap says how much
/// better the fit reproduces the views it was trained on than new ones: a model that has
/// learnt the scene has a small gap; one that has learnt its training views, a large one.
///
/// Errors: a count of 0, the ops' errors.
pub(crate) fn training_views_psnr<F: Float, M: RadianceField<F>>(
    model: &M,
    data: &Dataset,
    settings: &FitSettings,
    occupancy: Option<&OccupancyGrid>,
    count: usize,
) -> Result<f64, FitError> {
    if count == 0 {
        return Err(FitError::Config("training_views_psnr: a count of at least 1".into()));
    }
    let chosen = data.spread_training_views(count);
    let renders = render_views(model, &chosen, data, settings, occupancy)?;
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = chosen.iter().map(|v| v.image.view()).collect();
    Ok(psnr(&r, &e)?)
}

impl<F: Float, M: RadianceField<F>> FitResult<F, M> {}

/// The PSNR of `renders` against the test views' pictures.
///
/// Errors: renders that do not match the views.
#[cfg(test)]
pub(crate) fn test_psnr(renders: &[Array3<f64>], data: &Dataset) -> Result<f64, FitError> {
    held_out_psnr(&renders.iter().map(|a| a.view()).collect::<Vec<_>>(), data)
}

/// [`test_psnr`] of renders held as views.
pub(crate) fn held_out_psnr(colors: &[ArrayView3<f64>], data: &Dataset) -> Result<f64, FitError> {
    let e: Vec<_> = data.test.iter().map(|t| t.image.view()).collect();
    Ok(psnr(colors, &e)?)
}

/// The SSIM of renders held as views against the test views' pictures (NaN when a test
/// view is smaller than the SSIM window).
pub(crate) fn held_out_ssim(colors: &[ArrayView3<f64>], data: &Dataset) -> Result<f64, FitError> {
    if data.test.iter().any(|t| t.size().iter().any(|&n| n < SSIM_WINDOW)) {
        return Ok(f64::NAN);
    }
    let e: Vec<_> = data.test.iter().map(|t| t.image.view()).collect();
    Ok(ssim(colors, &e)?)
}

/// Fits a fresh model to `data` for its budget: a [`Trainer`] stepped through it, evaluated
/// `settings.evaluations` times on the way and once at the end (with depth, for a report).
/// Calls `progress` after every step.
///
/// ```
/// use fogray_fit::dense::DenseGrid;
/// use fogray_fit::settings::FitSettings;
/// use fogray_fit::dataset::{Dataset, View};
/// use fogray_fit::train::fit;
/// use fogray_ops::{Intrinsics, PinholeCamera};
/// use ndarray::{Array2, Array3};
///
/// let k = Intrinsics::from_vertical_fov(8, 8, 0.7)?;
/// let views = [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, -3.0, 0.0]].map(|eye| {
///     let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
///     View::new("v", &camera, Array3::from_elem((8, 8, 3), 0.25)).unwrap()
/// });
/// let [a, b, c] = views;
/// let data = Dataset::new(vec![a, b], vec![c], [1.0; 3])?;
/// let settings = FitSettings { grid: 12, batch: 64, steps: Some(5), ..FitSettings::default() };
/// let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {})?;
/// assert_eq!(result.log.last().unwrap().step, 5);
/// assert_eq!(result.renders.len(), 1); // one per test view
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// Errors: as [`Trainer::new`] and [`Trainer::step`].
pub fn fit<F: Float, M: RadianceField<F>>(
    data: &Dataset,
    settings: &FitSettings,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitResult<F, M>, FitError> {
    fit_from(data, settings, None, None, progress)
}

/// Fits a model to `data` from `start` (a saved fit: model, Adam's moments, step, training
/// seconds, growth stage and position in the batch stream) or afresh, until the budget, which
/// counts the steps and seconds of `start` too, is spent or `stop` is raised (checked before
/// each step, so the step under way is finished): a [`Trainer`] stepped through its budget,
/// evaluated `settings.evaluations` times on the way and once at the end (with depth, for a
/// report). Calls `progress` after every step.
///
/// Continuing a fit stopped at step `k` takes the same steps, bit for bit, as the fit that
/// was never stopped, given the same settings (growth and the learning rate's anneal happen at
/// fractions of the budget, so the first part must have had the same budget, or no growth and
/// a constant rate) and a budget of steps (a budget of seconds stops where the clock says).
///
/// Errors: as [`Trainer::new`] and [`Trainer::step`].
pub(crate) fn fit_from<F: Float, M: RadianceField<F>>(
    data: &Dataset,
    settings: &FitSettings,
    start: Option<Start<F, M>>,
    stop: Option<&AtomicBool>,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitResult<F, M>, FitError> {
    let mut trainer = Trainer::<F, M>::new(data, settings, start)?;
    let run = run_budget(&mut trainer, settings.evaluations, stop, &mut |p, _| progress(p))?;
    let last = match run.last {
        Some(e) => e,
        None => trainer.evaluate(true)?,
    };
    let (log, interrupted) = (run.log, run.interrupted);
    let steps_taken = trainer.steps_taken();
    let samples_per_ray_mean = trainer.samples() as f64 / (steps_taken * settings.batch) as f64;
    let training = trainer.state()?;
    let profile = trainer.profile().table();
    let seconds = trainer.seconds();
    let (model, occupancy) = trainer.into_parts();
    Ok(FitResult {
        final_test_psnr: last.entry.test_psnr,
        final_test_ssim: last.entry.test_ssim,
        log,
        seconds,
        samples_per_ray_mean,
        occupied_fraction: occupancy.as_ref().map_or(1.0, |g| g.occupied_fraction()),
        renders: last.views.iter().map(|v| v.color.clone()).collect(),
        held_out: last.views,
        model,
        training,
        interrupted,
        occupancy,
        profile,
    })
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod negative_tests;
