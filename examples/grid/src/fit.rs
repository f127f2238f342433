//! The fit: Adam on the raw grid of a [`GridModel`], minimising the mean squared error of
//! random batches of training rays against the exact photographs, with the test PSNR on the
//! held-out views measured at intervals (outside the training clock).
//!
//! ```
//! use fogray_grid::dataset::Dataset;
//! use fogray_grid::fit::{fit, Budget, FitConfig};
//! use fogray_grid::{photographs::photographs, ring::Ring, scene::Scene};
//!
//! let ring = Ring::new(8, 2, 12)?;
//! let data = Dataset::new(&ring, &photographs(&Scene::default(), &ring), Scene::default().background)?;
//! let config = FitConfig { grid: 12, batch: 256, budget: Budget::Steps(5), ..FitConfig::default() };
//! let result = fit::<f32>(&data, &config, &mut |_| {})?;
//! assert_eq!(result.log.last().unwrap().step, 5);
//! assert_eq!(result.renders.len(), 2); // one per test view
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use fogray::ops::prior::TotalVariation;
use fogray::ops::rays::{Aabb, RayBatch};
use fogray::ops::sample::{CellPoints, Jitter, OccupancyConfig, OccupancyGrid, PackedSamples, Spacing, Uniform};
use fogray::ops::{GeometryError, GridError, SampleError};
use fogray::tape::optim::{Adam, AdamConfig};
use fogray::tape::params::ParamError;
use fogray::tape::{Float, Tape, TapeError};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;
use serde::Serialize;
use thiserror::Error;

use crate::batch::TrainingTable;
use crate::dataset::Dataset;
use crate::images::{psnr, ImageError};
use crate::model::{GridModel, Method, BOUNDS};
use crate::profile::{Phases, StepProfile};
use crate::state::{Start, TrainingState};

/// Why a fit could not run.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FitError {
    /// A setting outside its range.
    #[error("{0}")]
    Config(String),
    /// From the tape or an op on it.
    #[error(transparent)]
    Tape(#[from] TapeError),
    /// From a sampler or the occupancy grid.
    #[error(transparent)]
    Sample(#[from] SampleError),
    /// From the rays.
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// From the grid field.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// From the parameter store or the optimiser.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// From the test PSNR.
    #[error(transparent)]
    Image(#[from] ImageError),
}

/// Where samples go along each ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampling {
    /// Every half voxel across the box.
    Uniform,
    /// Every half voxel, but only in the cells of an occupancy grid (one cell per voxel) that
    /// the current density marks as occupied; every cell counts as occupied for the first
    /// [`OCCUPANCY_WARMUP`] steps, then the grid is refreshed every [`OCCUPANCY_EVERY`].
    Occupancy,
}

/// Steps before the first refresh of the occupancy grid: a fresh model is a thin fog with no
/// cell above the threshold, and a cell once empty gets no samples to grow back from, so the
/// density must first have gathered where the matter is.
pub const OCCUPANCY_WARMUP: usize = 64;

/// Steps between refreshes of the occupancy grid.
pub const OCCUPANCY_EVERY: usize = 16;

/// When training stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// After this many steps.
    Steps(usize),
    /// Once this many seconds of training (evaluations excluded) have passed.
    Seconds(f64),
}

/// The fit's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitConfig {
    /// Nodes per axis of the grid (at least 2).
    pub grid: usize,
    /// Training rays per step (at least 1).
    pub batch: usize,
    /// When to stop.
    pub budget: Budget,
    /// Fused ops or taped twins.
    pub method: Method,
    /// Uniform or occupancy sampling.
    pub sampling: Sampling,
    /// Seed of the batches.
    pub seed: u64,
    /// Adam's learning rate, until [`ANNEAL_START`] of the budget.
    pub lr: f64,
    /// Adam's learning rate at the end of the budget: from [`ANNEAL_START`] on, the rate falls
    /// geometrically from `lr` to `lr_final` (equal to `lr` for a constant rate).
    pub lr_final: f64,
    /// The density's shift (raw 0 is density `softplus(shift)`).
    pub shift: f64,
    /// Test evaluations over the budget (evenly spaced, plus one at the start and the end).
    pub evaluations: usize,
    /// Coarse to fine: start at a quarter of `grid` nodes per axis, double at [`GROWTH`]
    /// fractions of the budget (trilinear resampling, fresh Adam moments).
    pub grow: bool,
    /// Weight of the total-variation prior on the raw grid added to the loss
    /// ([`TotalVariation`]); 0 for none.
    pub smoothness: f64,
}

/// The fraction of the budget from which the learning rate anneals from `lr` to `lr_final`.
/// Adam at a constant rate keeps the grid jittering about its fit; shrinking the steps over
/// the last part settles it.
pub const ANNEAL_START: f64 = 0.6;

/// Adam's learning rate at `fraction` of the budget (see [`FitConfig::lr_final`]).
pub fn learning_rate(config: &FitConfig, fraction: f64) -> f64 {
    if fraction <= ANNEAL_START {
        return config.lr;
    }
    let u = ((fraction - ANNEAL_START) / (1.0 - ANNEAL_START)).min(1.0);
    config.lr * (config.lr_final / config.lr).powf(u)
}

/// Fractions of the budget at which a growing grid doubles its nodes per axis.
pub const GROWTH: [f64; 2] = [0.1, 0.3];

/// The grid's nodes per axis from each fraction of the budget on.
fn stages(config: &FitConfig) -> Vec<(f64, usize)> {
    let n = config.grid;
    if !config.grow || n < 8 {
        return vec![(0.0, n)];
    }
    vec![(0.0, n.div_ceil(4)), (GROWTH[0], n.div_ceil(2)), (GROWTH[1], n)]
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            grid: 64,
            batch: 8192,
            budget: Budget::Seconds(60.0),
            method: Method::Fused,
            sampling: Sampling::Occupancy,
            seed: 0,
            lr: 0.2,
            lr_final: 0.02,
            shift: -4.0,
            evaluations: 20,
            grow: true,
            smoothness: 1.5e-4,
        }
    }
}

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
    /// Training samples so far, over all rays of all steps (what a step's cost grows with).
    pub samples: usize,
}

/// What a fit returns.
#[derive(Debug)]
pub struct FitResult<F: Float> {
    /// The evaluations, in order.
    pub log: Vec<LogEntry>,
    /// Test PSNR at the end.
    pub final_test_psnr: f64,
    /// Training seconds, evaluations excluded.
    pub seconds: f64,
    /// Mean samples per training ray over this call's steps (NaN if it took none).
    pub samples_per_ray_mean: f64,
    /// Fraction of occupied cells at the end (1 with uniform sampling).
    pub occupied_fraction: f64,
    /// Final renders of the test views `[W][W][3]`, unclamped, in view order.
    pub renders: Vec<Array3<f64>>,
    /// The fitted model.
    pub model: GridModel<F>,
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

/// The sampler of a fit.
enum Sampler {
    Uniform,
    Occupancy(OccupancyGrid),
}

impl Sampler {
    fn occupancy(&self) -> Option<&OccupancyGrid> {
        match self {
            Sampler::Uniform => None,
            Sampler::Occupancy(g) => Some(g),
        }
    }
}

/// Samples `rays` every `step` across the box, or keeps only the samples whose midpoints lie in
/// occupied cells of `occupancy` (its midpoint sampler: the march's pieces, less up to two at
/// each run of occupied cells, tested in vector lanes instead of a walk through every cell).
fn sample_rays<F: Float>(
    occupancy: Option<&OccupancyGrid>,
    rays: &RayBatch<F>,
    step: f64,
) -> Result<PackedSamples<F>, FitError> {
    let clip = Aabb::new(BOUNDS.0, BOUNDS.1)?.clip(rays);
    Ok(match occupancy {
        None => Uniform::new(Spacing::Step(step))?.sample(rays, &clip)?,
        Some(g) => g.march_midpoints(rays, &clip, step, Jitter::None)?,
    })
}

/// An occupancy grid as a fit of `grid` nodes per axis keeps one: one cell per voxel, a cell
/// occupied while a step of half the final voxel through it would stop at least 1 % of the
/// light. Every cell is occupied until its first update.
///
/// Errors: fewer than 2 nodes.
pub fn occupancy_grid(grid: usize) -> Result<OccupancyGrid, FitError> {
    if grid < 2 {
        return Err(FitError::Config("--grid must be at least 2".into()));
    }
    let final_step = 1.0 / (grid - 1) as f64;
    Ok(OccupancyGrid::new(
        Aabb::new(BOUNDS.0, BOUNDS.1)?,
        grid - 1,
        OccupancyConfig::opacity(final_step, 0.01)?,
    )?)
}

fn batch_of<F: Float>(o: &Array2<f64>, d: &Array2<f64>, rows: &[usize]) -> Result<RayBatch<F>, FitError> {
    Ok(RayBatch::new(rows_of(o, rows), rows_of(d, rows))?)
}

/// The rows `rows` of `[P, 3]` table `a`, converted to `F`. A direct copy: ndarray's
/// `select` concatenates one view per row, which costs more than the copy itself.
fn rows_of<F: Float>(a: &Array2<f64>, rows: &[usize]) -> Array2<F> {
    Array2::from_shape_fn((rows.len(), a.ncols()), |(k, c)| F::lit(a[[rows[k], c]]))
}

/// Renders rays in chunks without recording a backward, as `[R, 3]` f64.
fn render_rays<F: Float>(
    model: &GridModel<F>,
    occupancy: Option<&OccupancyGrid>,
    origins: &Array2<f64>,
    directions: &Array2<f64>,
    background: [f64; 3],
    method: Method,
) -> Result<Array2<f64>, FitError> {
    const CHUNK: usize = 8192;
    let n = origins.nrows();
    let mut out = Array2::zeros((n, 3));
    let mut tape = Tape::<F>::new();
    // No backward: the ops keep no record and no residuals.
    tape.set_grad_enabled(false);
    for start in (0..n).step_by(CHUNK) {
        let rows: Vec<usize> = (start..(start + CHUNK).min(n)).collect();
        let rays = batch_of::<F>(origins, directions, &rows)?;
        let samples = sample_rays(occupancy, &rays, model.voxel() / 2.0)?;
        let color = model.render(&mut tape, samples, background, method)?;
        let values = tape.value(color)?;
        for (k, &r) in rows.iter().enumerate() {
            for c in 0..3 {
                out[[r, c]] = values[[k, c]].as_f64();
            }
        }
        tape.clear();
    }
    Ok(out)
}

/// Renders every test view, `[W][W][3]` each, unclamped: every half voxel across the box, or
/// only in the occupied cells of `occupancy`. A model fitted with an occupancy grid is rendered
/// with it, as it was trained: its empty cells got no samples, so whatever density they hold
/// was never fitted.
pub fn render_test_views<F: Float>(
    model: &GridModel<F>,
    data: &Dataset,
    method: Method,
    occupancy: Option<&OccupancyGrid>,
) -> Result<Vec<Array3<f64>>, FitError> {
    data.test
        .iter()
        .map(|t| {
            let w = t.photograph.shape()[0];
            let flat = render_rays(model, occupancy, &t.origins, &t.directions, data.background, method)?;
            flat.into_shape_with_order((w, w, 3))
                .map_err(|e| FitError::Config(e.to_string()))
        })
        .collect()
}

fn test_psnr(renders: &[Array3<f64>], data: &Dataset) -> Result<f64, FitError> {
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = data.test.iter().map(|t| t.photograph.view()).collect();
    Ok(psnr(&r, &e)?)
}

fn check(config: &FitConfig) -> Result<(), FitError> {
    let bad = |what: &str| Err(FitError::Config(what.into()));
    if config.grid < 2 {
        return bad("--grid must be at least 2");
    }
    if config.batch == 0 {
        return bad("--batch must be at least 1");
    }
    if !(config.lr.is_finite() && config.lr > 0.0) {
        return bad("--lr must be finite and positive");
    }
    if !(config.lr_final.is_finite() && config.lr_final > 0.0) {
        return bad("--lr-final must be finite and positive");
    }
    match config.budget {
        Budget::Steps(0) => bad("--steps must be at least 1"),
        Budget::Seconds(s) if !(s.is_finite() && s > 0.0) => bad("--seconds must be finite and positive"),
        _ => Ok(()),
    }
}

/// Fits a grid to `data` (see the [module docs](self)); calls `progress` after every step.
/// A fresh fit to its budget: [`fit_from`] with no start and no stop flag.
pub fn fit<F: Float>(
    data: &Dataset,
    config: &FitConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitResult<F>, FitError> {
    fit_from(data, config, None, None, progress)
}

/// Fits a grid to `data` from `start` (a saved fit: model, Adam's moments, step, training
/// seconds, growth stage and position in the batch stream) or afresh, until the budget, which
/// counts the steps and seconds of `start` too, is spent or `stop` is raised (checked before
/// each step, so the step under way is finished). Calls `progress` after every step.
///
/// Continuing a fit stopped at step `k` takes the same steps, bit for bit, as the fit that
/// was never stopped, given the same `config` (growth and the learning rate's anneal happen at
/// fractions of the budget, so the first part must have had the same budget, or no growth and
/// a constant rate; a finished fit continued with a larger budget starts its anneal again
/// from where the new budget puts it) and a budget of steps (a budget
/// of seconds stops where the clock says). The occupancy grid is part of the state; a start
/// without one (or one saved by a uniform fit) begins with every cell occupied until the next
/// refresh.
///
/// Test views are rendered as the model is trained: with the occupancy grid under occupancy
/// sampling ([`render_test_views`]).
///
/// Errors: a setting out of range ([`FitError::Config`]), or an error of the ops.
pub fn fit_from<F: Float>(
    data: &Dataset,
    config: &FitConfig,
    start: Option<Start<F>>,
    stop: Option<&AtomicBool>,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitResult<F>, FitError> {
    check(config)?;
    let stages = stages(config);
    let (mut model, resumed) = match start {
        Some(s) => (s.model, Some(s.training)),
        None => (GridModel::<F>::new(stages[0].1, config.shift)?, None),
    };
    let stage = resumed.as_ref().map_or(0, |t| t.stage);
    if stages.get(stage).map(|s| s.1) != Some(model.nodes()) {
        return Err(FitError::Config(format!(
            "the saved grid ({} nodes per axis, growth stage {stage}) is not a stage of this fit's --grid {}",
            model.nodes(),
            config.grid
        )));
    }
    let mut next_stage = stage + 1;
    // The final grid's half voxel sets the threshold: it means the same at every stage.
    let mut sampler = match config.sampling {
        Sampling::Uniform => Sampler::Uniform,
        Sampling::Occupancy => Sampler::Occupancy(occupancy_grid(config.grid)?),
    };
    if let (Sampler::Occupancy(grid), Some(state)) = (&mut sampler, resumed.as_ref().and_then(|t| t.occupancy.as_ref()))
    {
        grid.restore(state)?;
    }
    let prior = TotalVariation::new(config.smoothness).map_err(|e| FitError::Config(format!("--tv: {e}")))?;
    let adam_config = AdamConfig {
        lr: config.lr,
        ..AdamConfig::default()
    };
    let mut adam = Adam::new(adam_config)?;
    // StdRng's generator, named so that its position in the stream can be saved.
    let mut rng = ChaCha12Rng::seed_from_u64(config.seed);
    let (mut seconds, mut step) = (0.0, 0usize);
    if let Some(t) = resumed {
        rng.set_word_pos(t.batch_stream);
        (seconds, step) = (t.seconds, t.step);
        if let Some(state) = t.adam {
            adam.restore(model.params(), model.grid_id(), state)?;
        }
    }
    let first_step = step;
    let mut interrupted = false;
    let mut tape = Tape::<F>::new();
    // A few clock reads a step: nothing beside a step's milliseconds.
    tape.set_profiling(true);
    let mut phases = Phases::default();
    let table = TrainingTable::<F>::new(data);
    let pixels = table.pixels();
    let (mut loss, mut samples_total) = (f64::NAN, 0usize);
    let fraction = |step: usize, seconds: f64| match config.budget {
        Budget::Steps(n) => step as f64 / n as f64,
        Budget::Seconds(s) => seconds / s,
    };
    let evaluate =
        |model: &GridModel<F>, sampler: &Sampler, step, seconds, loss, samples| -> Result<LogEntry, FitError> {
            let renders = render_test_views(model, data, config.method, sampler.occupancy())?;
            Ok(LogEntry {
                step,
                seconds,
                train_loss: loss,
                test_psnr: test_psnr(&renders, data)?,
                samples,
            })
        };
    let mut log = vec![evaluate(&model, &sampler, step, seconds, loss, samples_total)?];
    let mut next_eval = (fraction(step, seconds) * config.evaluations as f64).floor() as usize + 1;
    while fraction(step, seconds) < 1.0 {
        if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
            interrupted = true;
            break;
        }
        let start = Instant::now();
        if next_stage < stages.len() && fraction(step, seconds) >= stages[next_stage].0 {
            model = model.resampled(stages[next_stage].1)?;
            adam = Adam::new(adam_config)?;
            next_stage += 1;
        }
        adam.set_lr(learning_rate(config, fraction(step, seconds)))?;
        let mut clock = Instant::now();
        let mut lap = |phase: &mut std::time::Duration| {
            let now = Instant::now();
            *phase += now - clock;
            clock = now;
        };
        let rows: Vec<usize> = (0..config.batch).map(|_| rng.gen_range(0..pixels)).collect();
        let batch = table.gather(&rows)?;
        lap(&mut phases.batch);
        let samples = sample_rays(sampler.occupancy(), &batch.rays, model.voxel() / 2.0)?;
        samples_total += samples.len();
        lap(&mut phases.sample);
        let target = tape.constant(batch.colors);
        let grid = tape.param_from(model.params(), model.grid_id())?;
        let mse = model.photometric_loss(&mut tape, grid, samples, data.background, target, config.method)?;
        loss = tape.value(mse)?.iter().next().map_or(f64::NAN, |v| v.as_f64());
        let objective = if config.smoothness > 0.0 {
            let smooth = prior.apply(&mut tape, grid)?;
            tape.add(mse, smooth)?
        } else {
            mse
        };
        lap(&mut phases.forward);
        let grads = tape.backward(objective)?;
        lap(&mut phases.backward);
        tape.clear();
        adam.step(model.params_mut(), &grads)?;
        tape.recycle(grads);
        lap(&mut phases.optimiser);
        step += 1;
        if let Sampler::Occupancy(grid) = &mut sampler {
            if step >= OCCUPANCY_WARMUP && step % OCCUPANCY_EVERY == 0 {
                let m = &model;
                grid.update(|p| m.densities(p), CellPoints::CentreAndRandom { seed: step as u64 })?;
            }
        }
        lap(&mut phases.occupancy);
        seconds += start.elapsed().as_secs_f64();
        progress(Progress {
            step,
            fraction: fraction(step, seconds).min(1.0),
        });
        let done = fraction(step, seconds) >= 1.0;
        if done || fraction(step, seconds) * config.evaluations as f64 >= next_eval as f64 {
            log.push(evaluate(&model, &sampler, step, seconds, loss, samples_total)?);
            next_eval = (fraction(step, seconds) * config.evaluations as f64).floor() as usize + 1;
        }
    }
    let renders = render_test_views(&model, data, config.method, sampler.occupancy())?;
    let occupancy = match sampler {
        Sampler::Occupancy(g) => Some(g),
        Sampler::Uniform => None,
    };
    let training = TrainingState {
        step,
        seconds,
        stage: next_stage - 1,
        batch_stream: rng.get_word_pos(),
        adam: adam.state(model.params(), model.grid_id())?,
        occupancy: occupancy.as_ref().map(OccupancyGrid::state),
    };
    let occupied_fraction = occupancy.as_ref().map_or(1.0, |g| g.occupied_fraction());
    Ok(FitResult {
        final_test_psnr: test_psnr(&renders, data)?,
        log,
        seconds,
        samples_per_ray_mean: samples_total as f64 / ((step - first_step) * config.batch) as f64,
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
