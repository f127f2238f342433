//! The training loop: Adam on a model's parameters, minimising the mean squared error of random
//! batches of training rays (plus the model's priors), each ray over the dataset's background
//! or, for pictures with alpha and [`FitSettings::random_background`], over a random colour of
//! its own against its picture composited over that colour, with the schedules of
//! [`schedule`](crate::schedule) (learning rate, coarse-to-fine growth), the occupancy grid's
//! own refresh policy, and the test PSNR on the held-out views measured at intervals (outside
//! the training clock).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use fogray_ops::sample::{CellPoints, OccupancyGrid};
use fogray_tape::optim::{Adam, AdamConfig};
use fogray_tape::{Float, Tape};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;
use serde::Serialize;

use crate::batch::TrainingTable;
use crate::dataset::{Dataset, View};
use crate::error::FitError;
use crate::metrics::{psnr, ssim, SSIM_WINDOW};
use crate::model::{RadianceField, TrainingBackground};
use crate::profile::{Phases, StepProfile};
use crate::render::{render_picture, RenderOptions};
use crate::sampling::{occupancy_grid, sample_rays};
use crate::schedule::{growth_stages, learning_rate};
use crate::settings::{Budget, FitSettings, Sampling};
use crate::state::{Start, TrainingState};

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
    /// Test SSIM, the mean over the test views ([`ssim`](crate::metrics::ssim)); NaN for views
    /// smaller than its window.
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
    /// The fitted model.
    pub model: M,
    /// Where the fit stopped, beyond the model: with it, [`fit_from`] continues the fit.
    pub training: TrainingState<F>,
    /// Whether the fit stopped early because its stop flag was raised.
    pub interrupted: bool,
    /// The final occupancy grid, with occupancy sampling.
    pub occupancy: Option<OccupancyGrid>,
    /// Where this call's training time went, phase by phase and op by op.
    pub profile: StepProfile,
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
pub fn render_test_views<F: Float, M: RadianceField<F>>(
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
pub fn training_views_psnr<F: Float, M: RadianceField<F>>(
    model: &M,
    data: &Dataset,
    settings: &FitSettings,
    occupancy: Option<&OccupancyGrid>,
    count: usize,
) -> Result<f64, FitError> {
    if count == 0 {
        return Err(FitError::Config("training_views_psnr: a count of at least 1".into()));
    }
    let n = data.train.len();
    let count = count.min(n);
    let chosen: Vec<&View> = (0..count).map(|i| &data.train[i * n / count]).collect();
    let renders = render_views(model, &chosen, data, settings, occupancy)?;
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = chosen.iter().map(|v| v.image.view()).collect();
    Ok(psnr(&r, &e)?)
}

impl<F: Float, M: RadianceField<F>> FitResult<F, M> {
    /// [`training_views_psnr`] of the fitted model on as many of `data`'s training views as it
    /// has held-out ones, with the fit's occupancy grid: the figure to set beside
    /// [`FitResult::final_test_psnr`].
    ///
    /// Errors: the ops' errors.
    pub fn training_views_psnr(&self, data: &Dataset, settings: &FitSettings) -> Result<f64, FitError> {
        training_views_psnr(&self.model, data, settings, self.occupancy.as_ref(), data.test.len())
    }
}

/// The PSNR of `renders` against the test views' pictures.
///
/// Errors: renders that do not match the views.
pub fn test_psnr(renders: &[Array3<f64>], data: &Dataset) -> Result<f64, FitError> {
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = data.test.iter().map(|t| t.image.view()).collect();
    Ok(psnr(&r, &e)?)
}

/// The mean SSIM of `renders` against the test views' pictures; NaN (not measured) when a
/// view is smaller than SSIM's 11 x 11 window, so that tiny test scenes still fit.
///
/// Errors: renders that do not match the views.
pub fn test_ssim(renders: &[Array3<f64>], data: &Dataset) -> Result<f64, FitError> {
    if data.test.iter().any(|t| t.size().iter().any(|&n| n < SSIM_WINDOW)) {
        return Ok(f64::NAN);
    }
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = data.test.iter().map(|t| t.image.view()).collect();
    Ok(ssim(&r, &e)?)
}

/// Fits a fresh model to `data` for its budget: [`fit_from`] with no start and no stop flag.
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
/// Errors: as [`fit_from`].
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
/// each step, so the step under way is finished). Calls `progress` after every step.
///
/// Continuing a fit stopped at step `k` takes the same steps, bit for bit, as the fit that
/// was never stopped, given the same settings (growth and the learning rate's anneal happen at
/// fractions of the budget, so the first part must have had the same budget, or no growth and
/// a constant rate) and a budget of steps (a budget of seconds stops where the clock says).
/// The occupancy grid is part of the state; a start without one begins with every cell
/// occupied until the next refresh.
///
/// Errors: a setting out of range or a learned background for views with alpha
/// ([`FitError::Config`]), a start whose model is not a growth
/// stage of these settings, or an error of the ops.
pub fn fit_from<F: Float, M: RadianceField<F>>(
    data: &Dataset,
    settings: &FitSettings,
    start: Option<Start<F, M>>,
    stop: Option<&AtomicBool>,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitResult<F, M>, FitError> {
    settings.check()?;
    if settings.learn_background && data.train.iter().any(|v| v.alpha.is_some()) {
        // Its pictures say where the background shows; a learned one would only see the
        // colour they were composited over.
        return Err(FitError::Config(
            "--learn-background is for views without alpha: these have alpha (their training rays are \
             composited over random colours instead, --random-background)"
                .into(),
        ));
    }
    let stages = growth_stages(settings);
    let (mut model, resumed) = match start {
        Some(s) => (s.model, Some(s.training)),
        None => (M::fresh(settings, stages[0].1)?, None),
    };
    let stage = resumed.as_ref().map_or(0, |t| t.stage);
    if stages.get(stage).map(|s| s.1) != Some(model.nodes()) {
        return Err(FitError::Config(format!(
            "the saved grid ({} nodes per axis, growth stage {stage}) is not a stage of this fit's --grid {}",
            model.nodes(),
            settings.grid
        )));
    }
    let mut next_stage = stage + 1;
    let bounds = model.bounds();
    let mut occupancy = match settings.sampling {
        Sampling::Uniform => None,
        Sampling::Occupancy => Some(occupancy_grid(bounds, settings.grid)?),
    };
    if let (Some(grid), Some(state)) = (&mut occupancy, resumed.as_ref().and_then(|t| t.occupancy.as_ref())) {
        grid.restore(state)?;
    }
    if let Some(grid) = &mut occupancy {
        grid.set_known_cells(model.known_cells(grid)?)?;
    }
    let adam_config = AdamConfig {
        lr: settings.lr,
        ..AdamConfig::default()
    };
    let mut adam = Adam::new(adam_config)?;
    // StdRng's generator, named so that its position in the stream can be saved.
    let mut rng = ChaCha12Rng::seed_from_u64(settings.seed);
    let (mut seconds, mut step) = (0.0, 0usize);
    if let Some(t) = resumed {
        rng.set_word_pos(t.batch_stream);
        (seconds, step) = (t.seconds, t.step);
        for (name, state) in t.adam {
            let id = model
                .params()
                .id(&name)
                .ok_or_else(|| FitError::Config(format!("Adam's state names no parameter of the model: {name:?}")))?;
            adam.restore(model.params(), id, state)?;
        }
    }
    let first_step = step;
    // A model pruned by the occupancy grid grows to stage k no sooner than k first refreshes
    // in: a short budget's growth would otherwise come before the first refresh and keep the
    // whole lattice. (A function of the step alone, so that a resumed fit grows where the
    // uninterrupted one did.)
    let first_refresh = occupancy
        .as_ref()
        .filter(|_| M::PRUNED_BY_OCCUPANCY)
        .map(|grid| grid.config().refresh().first_due());
    let grown_enough = |stage: usize, step: usize| first_refresh.is_none_or(|first| step >= stage * first);
    let mut interrupted = false;
    let mut tape = Tape::<F>::new();
    // A few clock reads a step: nothing beside a step's milliseconds.
    tape.set_profiling(true);
    let mut phases = Phases::default();
    let table = TrainingTable::new(data);
    let pixels = table.pixels();
    let (mut loss, mut samples_total) = (f64::NAN, 0usize);
    let fraction = |step: usize, seconds: f64| match settings.budget() {
        Budget::Steps(n) => step as f64 / n as f64,
        Budget::Seconds(s) => seconds / s,
    };
    let evaluate = |model: &M, occupancy: Option<&OccupancyGrid>, step, seconds, loss, samples| {
        let renders = render_test_views(model, data, settings, occupancy)?;
        Ok::<_, FitError>(LogEntry {
            step,
            seconds,
            train_loss: loss,
            test_psnr: test_psnr(&renders, data)?,
            test_ssim: test_ssim(&renders, data)?,
            samples,
        })
    };
    let mut log = vec![evaluate(
        &model,
        occupancy.as_ref(),
        step,
        seconds,
        loss,
        samples_total,
    )?];
    let mut next_eval = (fraction(step, seconds) * settings.evaluations as f64).floor() as usize + 1;
    while fraction(step, seconds) < 1.0 {
        if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
            interrupted = true;
            break;
        }
        let start = Instant::now();
        if next_stage < stages.len()
            && fraction(step, seconds) >= stages[next_stage].0
            && grown_enough(next_stage, step)
        {
            model = model.resampled(stages[next_stage].1, occupancy.as_ref())?;
            if let Some(grid) = &mut occupancy {
                grid.set_known_cells(model.known_cells(grid)?)?;
            }
            adam = Adam::new(adam_config)?;
            next_stage += 1;
        }
        adam.set_lr(learning_rate(settings, fraction(step, seconds)))?;
        let mut clock = Instant::now();
        let mut lap = |phase: &mut std::time::Duration| {
            let now = Instant::now();
            *phase += now - clock;
            clock = now;
        };
        let rows: Vec<usize> = (0..settings.batch).map(|_| rng.gen_range(0..pixels)).collect();
        let batch = table.gather::<F>(&rows)?;
        // A random colour per ray, from the same stream after the rows (none without alpha,
        // so that a fit of opaque pictures draws the stream it always drew).
        let (background, colors) = match (&batch.alpha, settings.random_background) {
            (Some(_), true) => {
                let drawn = Array2::from_shape_simple_fn((rows.len(), 3), || F::lit(rng.gen::<f64>()));
                let colors = batch.colors_over(data.background, drawn.view())?;
                (TrainingBackground::PerRay(drawn), colors)
            }
            _ => (TrainingBackground::Shared(data.background), batch.colors),
        };
        lap(&mut phases.batch);
        let samples = sample_rays(&bounds, occupancy.as_ref(), &batch.rays, model.sample_step())?;
        samples_total += samples.len();
        lap(&mut phases.sample);
        let target = tape.constant(colors);
        let objective = model.training_loss(&mut tape, &batch.rays, samples, background, target, settings.method)?;
        loss = tape
            .value(objective.photometric)?
            .iter()
            .next()
            .map_or(f64::NAN, |v| v.as_f64());
        lap(&mut phases.forward);
        let grads = tape.backward(objective.objective)?;
        lap(&mut phases.backward);
        tape.clear();
        adam.step(model.params_mut(), &grads)?;
        tape.recycle(grads);
        lap(&mut phases.optimiser);
        step += 1;
        if let Some(grid) = &mut occupancy {
            let m = &model;
            let points = CellPoints::CentreAndRandom { seed: step as u64 };
            let refreshed = grid.update_every_n_steps(step, |p| m.densities(p), points)?;
            // A refresh before any density has reached the threshold (a slow learning rate, a
            // faint scene) would empty every cell, and a grid with no sample left never trains
            // again: until some cell is above the threshold, every cell stays occupied.
            if refreshed && grid.occupied_fraction() == 0.0 {
                grid.occupy_all();
            }
        }
        lap(&mut phases.occupancy);
        seconds += start.elapsed().as_secs_f64();
        progress(Progress {
            step,
            fraction: fraction(step, seconds).min(1.0),
        });
        let done = fraction(step, seconds) >= 1.0;
        if done || fraction(step, seconds) * settings.evaluations as f64 >= next_eval as f64 {
            log.push(evaluate(
                &model,
                occupancy.as_ref(),
                step,
                seconds,
                loss,
                samples_total,
            )?);
            next_eval = (fraction(step, seconds) * settings.evaluations as f64).floor() as usize + 1;
        }
    }
    let renders = render_test_views(&model, data, settings, occupancy.as_ref())?;
    let mut adam_states = Vec::new();
    for id in model.params().ids() {
        if let Some(state) = adam.state(model.params(), id)? {
            adam_states.push((model.params().name(id)?.to_string(), state));
        }
    }
    let training = TrainingState {
        step,
        seconds,
        stage: next_stage - 1,
        batch_stream: rng.get_word_pos(),
        adam: adam_states,
        occupancy: occupancy.as_ref().map(OccupancyGrid::state),
    };
    let occupied_fraction = occupancy.as_ref().map_or(1.0, |g| g.occupied_fraction());
    Ok(FitResult {
        final_test_psnr: test_psnr(&renders, data)?,
        final_test_ssim: test_ssim(&renders, data)?,
        log,
        seconds,
        samples_per_ray_mean: samples_total as f64 / ((step - first_step) * settings.batch) as f64,
        occupied_fraction,
        renders,
        model,
        training,
        interrupted,
        occupancy,
        profile: StepProfile {
            steps: step - first_step,
            phases,
            ops: tape.take_profile().unwrap_or_default(),
        },
    })
}
