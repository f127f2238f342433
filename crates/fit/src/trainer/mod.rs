//! The trainer: a fit as a value that takes one step at a time. [`Trainer::step`] draws a
//! batch of training rays, records the model's loss on a tape, runs the backward and Adam,
//! with its policies around the step (the grid's growth, the learning rate's schedule, the
//! occupancy grid's refresh);
//! [`Trainer::evaluate`] renders the held-out views (colour, opacity and, if asked, depth in
//! one pass) and scores them; [`Trainer::state`] is what a checkpoint saves to resume it.
//!
//! A user's training loop:
//!
//! ```
//! use fogray_fit::dataset::{Dataset, View};
//! use fogray_fit::dense::DenseGrid;
//! use fogray_fit::settings::FitSettings;
//! use fogray_fit::trainer::Trainer;
//! use fogray_ops::{Intrinsics, PinholeCamera};
//! use ndarray::Array3;
//!
//! let k = Intrinsics::from_vertical_fov(8, 8, 0.7)?;
//! let views = [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, -3.0, 0.0]].map(|eye| {
//!     let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
//!     View::new("v", &camera, Array3::from_elem((8, 8, 3), 0.25)).unwrap()
//! });
//! let [a, b, c] = views;
//! let data = Dataset::new(vec![a, b], vec![c], [1.0; 3])?;
//! let settings = FitSettings { grid: 12, batch: 64, steps: Some(40), ..FitSettings::default() };
//! let mut trainer = Trainer::<f32, DenseGrid<f32>>::new(&data, &settings, None)?;
//! let before = trainer.evaluate(false)?.entry.test_psnr;
//! while !trainer.is_done() {
//!     trainer.step()?;
//! }
//! let after = trainer.evaluate(false)?.entry.test_psnr;
//! assert!(after > before + 3.0, "{before} -> {after}");
//! assert_eq!(trainer.state()?.step, 40);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub(crate) mod budget;
pub(crate) mod growth;
pub(crate) mod policy;
pub(crate) mod rate;
pub(crate) mod refresh;
#[cfg(test)]
mod resume_tests;
#[cfg(test)]
mod tests;

use std::time::{Duration, Instant};

use fogray_ops::sample::OccupancyGrid;
use fogray_tape::optim::{Adam, AdamConfig};
use fogray_tape::{Float, Tape};
use ndarray::Array2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;

pub(crate) use budget::{run_budget, Stepper};
pub(crate) use growth::Growth;
pub(crate) use policy::{StepContext, StepPolicy};
pub(crate) use rate::LearningRate;
pub(crate) use refresh::OccupancyRefresh;

use crate::batch::TrainingTable;
use crate::dataset::Dataset;
use crate::error::FitError;
use crate::model::{RadianceField, TrainingBackground};
use crate::profile::{Phases, StepProfile};
use crate::render::{render_picture, RenderOptions, RenderedView};
use crate::sampling::occupancy_grid;
use crate::settings::{Budget, FitSettings, Sampling};
use crate::state::{Start, TrainingState};
use crate::train::{held_out_psnr, held_out_ssim, LogEntry};

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Steps done, this one included.
    pub step: usize,
    /// The step's photometric loss (mean squared error over rays and channels).
    pub loss: f64,
    /// Samples the step's rays took.
    pub samples: usize,
    /// The fraction of the budget spent, at most 1.
    pub fraction: f64,
}

/// The held-out views rendered by the model as it is, and their scores.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// The log's line for this evaluation.
    pub entry: LogEntry,
    /// Each held-out view's render (colour unclamped, opacity, depth if asked), in view order.
    pub views: Vec<RenderedView>,
}

impl Evaluation {
    /// `views` (`data`'s held-out views rendered, in order) scored against their pictures, at
    /// the trainer's `step`, training `seconds`, last `train_loss` and `samples` so far. SSIM is
    /// NaN (not measured) when a view is smaller than its window, so that tiny test scenes still
    /// fit.
    ///
    /// Errors: renders that do not match the views.
    pub(crate) fn scored(
        views: Vec<RenderedView>,
        data: &Dataset,
        step: usize,
        seconds: f64,
        train_loss: f64,
        samples: usize,
    ) -> Result<Evaluation, FitError> {
        let colors: Vec<_> = views.iter().map(|v| v.color.view()).collect();
        let entry = LogEntry {
            step,
            seconds,
            train_loss,
            test_psnr: held_out_psnr(&colors, data)?,
            test_ssim: held_out_ssim(&colors, data)?,
            samples,
        };
        Ok(Evaluation { entry, views })
    }
}

/// A fit in progress (see the [module docs](self)).
pub struct Trainer<'d, F: Float, M> {
    data: &'d Dataset,
    settings: FitSettings,
    model: M,
    optimiser: Adam<F>,
    occupancy: Option<OccupancyGrid>,
    growth: Growth,
    rate: LearningRate,
    refresh: OccupancyRefresh,
    /// The batches' generator (StdRng's, named so that its position can be saved).
    rng: ChaCha12Rng,
    table: TrainingTable<'d>,
    tape: Tape<F>,
    step: usize,
    first_step: usize,
    seconds: f64,
    loss: f64,
    samples: usize,
    phases: Phases,
}

impl<'d, F: Float, M: RadianceField<F>> Trainer<'d, F, M> {
    /// A trainer of `data` with `settings`, from `start` (a saved fit: model, Adam's moments,
    /// step, training seconds, growth stage, position in the batch stream, occupancy grid) or
    /// afresh. A start without an occupancy grid begins with every cell occupied until the
    /// next refresh.
    ///
    /// Errors: a setting out of range or a learned background for views with alpha
    /// ([`FitError::Config`]), a start whose model is not a growth stage of these settings.
    pub fn new(data: &'d Dataset, settings: &FitSettings, start: Option<Start<F, M>>) -> Result<Self, FitError> {
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
        let (model, resumed) = match start {
            Some(s) => (s.model, s.training),
            None => (
                M::fresh(settings, Growth::first_nodes(settings))?,
                TrainingState::default(),
            ),
        };
        let mut occupancy = match settings.sampling {
            Sampling::Uniform => None,
            Sampling::Occupancy => Some(occupancy_grid(model.bounds(), settings.grid)?),
        };
        if let (Some(grid), Some(state)) = (&mut occupancy, &resumed.occupancy) {
            grid.restore(state)?;
        }
        if let Some(grid) = &mut occupancy {
            grid.set_known_cells(model.known_cells(grid)?)?;
        }
        let first_refresh = occupancy
            .as_ref()
            .filter(|_| M::PRUNED_BY_OCCUPANCY)
            .map(|grid| grid.config().refresh().first_due());
        let growth = Growth::new(settings, resumed.stage, model.nodes(), first_refresh)?;
        let mut optimiser = Adam::new(AdamConfig {
            lr: settings.lr,
            ..AdamConfig::default()
        })?;
        for (name, state) in resumed.adam {
            let id = model
                .params()
                .id(&name)
                .ok_or_else(|| FitError::Config(format!("Adam's state names no parameter of the model: {name:?}")))?;
            optimiser.restore(model.params(), id, state)?;
        }
        let mut rng = ChaCha12Rng::seed_from_u64(settings.seed);
        rng.set_word_pos(resumed.batch_stream);
        let mut tape = Tape::<F>::new();
        // A few clock reads a step: nothing beside a step's milliseconds.
        tape.set_profiling(true);
        Ok(Trainer {
            data,
            settings: *settings,
            model,
            optimiser,
            occupancy,
            growth,
            rate: LearningRate::new(settings),
            refresh: OccupancyRefresh,
            rng,
            table: TrainingTable::new(data),
            tape,
            step: resumed.step,
            first_step: resumed.step,
            seconds: resumed.seconds,
            loss: f64::NAN,
            samples: 0,
            phases: Phases::default(),
        })
    }

    /// The fraction of the budget spent (steps or training seconds).
    pub(crate) fn fraction(&self) -> f64 {
        match self.settings.budget() {
            Budget::Steps(n) => self.step as f64 / n as f64,
            Budget::Seconds(s) => self.seconds / s,
        }
    }

    /// Whether the budget is spent.
    pub fn is_done(&self) -> bool {
        self.fraction() >= 1.0
    }

    /// The model as it is now.
    pub(crate) fn model(&self) -> &M {
        &self.model
    }

    /// The occupancy grid, with occupancy sampling.
    pub(crate) fn occupancy(&self) -> Option<&OccupancyGrid> {
        self.occupancy.as_ref()
    }

    /// Steps done.
    pub(crate) fn steps(&self) -> usize {
        self.step
    }

    /// Training seconds so far (evaluations excluded).
    pub(crate) fn seconds(&self) -> f64 {
        self.seconds
    }

    /// Training samples over all of this trainer's steps.
    pub(crate) fn samples(&self) -> usize {
        self.samples
    }

    /// Steps this trainer took (a resumed fit's earlier steps not counted).
    pub(crate) fn steps_taken(&self) -> usize {
        self.step - self.first_step
    }

    /// One training step: the policies before it (growth, learning rate), a random batch of
    /// training rays (each over a random colour for pictures with alpha and
    /// [`FitSettings::random_background`]), the loss, its backward and Adam's update, then the
    /// policies after it (the occupancy refresh). Its time counts toward a budget of seconds.
    ///
    /// Errors: an error of the ops or of a policy; the trainer should then be dropped.
    pub fn step(&mut self) -> Result<StepReport, FitError> {
        let start = Instant::now();
        let fraction = self.fraction();
        let mut at = StepContext {
            step: self.step,
            fraction,
            model: &mut self.model,
            optimiser: &mut self.optimiser,
            occupancy: &mut self.occupancy,
        };
        self.growth.before_step(&mut at)?;
        self.rate.before_step(&mut at)?;
        let mut clock = Instant::now();
        let mut lap = |phase: &mut Duration| {
            let now = Instant::now();
            *phase += now - clock;
            clock = now;
        };
        let pixels = self.table.pixels();
        let rows: Vec<usize> = (0..self.settings.batch)
            .map(|_| self.rng.gen_range(0..pixels))
            .collect();
        let batch = self.table.gather::<F>(&rows)?;
        // A random colour per ray, from the same stream after the rows (none without alpha,
        // so that a fit of opaque pictures draws the stream it always drew).
        let (background, colors) = match (&batch.alpha, self.settings.random_background) {
            (Some(_), true) => {
                let drawn = Array2::from_shape_simple_fn((rows.len(), 3), || F::lit(self.rng.gen::<f64>()));
                let colors = batch.colors_over(self.data.background, drawn.view())?;
                (TrainingBackground::PerRay(drawn), colors)
            }
            _ => (TrainingBackground::Shared(self.data.background), batch.colors),
        };
        lap(&mut self.phases.batch);
        let space = at.model.space();
        let samples = space.sample(at.occupancy.as_ref(), &batch.rays, at.model.sample_step())?;
        let taken = samples.len();
        self.samples += taken;
        lap(&mut self.phases.sample);
        let target = self.tape.constant(colors);
        let objective = at.model.training_loss(
            &mut self.tape,
            &batch.rays,
            samples,
            background,
            target,
            self.settings.method,
        )?;
        self.loss = self
            .tape
            .value(objective.photometric)?
            .iter()
            .next()
            .map_or(f64::NAN, |v| v.as_f64());
        lap(&mut self.phases.forward);
        let grads = self.tape.backward(objective.objective)?;
        lap(&mut self.phases.backward);
        self.tape.clear();
        at.optimiser.step(at.model.params_mut(), &grads)?;
        self.tape.recycle(grads);
        lap(&mut self.phases.optimiser);
        // The policies after the step see it counted.
        at.step += 1;
        self.step = at.step;
        self.refresh.after_step(&mut at)?;
        lap(&mut self.phases.occupancy);
        self.seconds += start.elapsed().as_secs_f64();
        Ok(StepReport {
            step: self.step,
            loss: self.loss,
            samples: taken,
            fraction: self.fraction().min(1.0),
        })
    }

    /// Renders every held-out view from the model as it is (colour, opacity, and the depth if
    /// `depth`), over the dataset's background with the occupancy grid, and scores them (off
    /// the training clock).
    ///
    /// Errors: the ops' errors.
    pub fn evaluate(&self, depth: bool) -> Result<Evaluation, FitError> {
        let views = render_views(&self.model, self.occupancy.as_ref(), self.data, &self.settings, depth)?;
        Evaluation::scored(views, self.data, self.step, self.seconds, self.loss, self.samples)
    }

    /// Where the fit stands beyond its model: with the model, [`Trainer::new`] continues it
    /// exactly.
    ///
    /// Errors: an optimiser state that cannot be read.
    pub fn state(&self) -> Result<TrainingState<F>, FitError> {
        let params = self.model.params();
        let mut adam = Vec::new();
        for id in params.ids() {
            if let Some(state) = self.optimiser.state(params, id)? {
                adam.push((params.name(id)?.to_string(), state));
            }
        }
        Ok(TrainingState {
            step: self.step,
            seconds: self.seconds,
            stage: self.growth.stage(),
            batch_stream: self.rng.get_word_pos(),
            adam,
            occupancy: self.occupancy.as_ref().map(OccupancyGrid::state),
        })
    }

    /// Where this trainer's training time went, phase by phase and op by op.
    pub(crate) fn profile(&mut self) -> StepProfile {
        StepProfile {
            steps: self.steps_taken(),
            phases: self.phases,
            ops: self.tape.take_profile().unwrap_or_default(),
        }
    }

    /// The model and the occupancy grid, ending the fit.
    pub(crate) fn into_parts(self) -> (M, Option<OccupancyGrid>) {
        (self.model, self.occupancy)
    }
}

impl<F: Float, M: RadianceField<F>> Stepper for Trainer<'_, F, M> {
    fn step(&mut self) -> Result<StepReport, FitError> {
        Trainer::step(self)
    }
    fn evaluate(&self, depth: bool) -> Result<Evaluation, FitError> {
        Trainer::evaluate(self, depth)
    }
    fn fraction(&self) -> f64 {
        Trainer::fraction(self)
    }
    fn steps(&self) -> usize {
        Trainer::steps(self)
    }
}

/// `data`'s held-out views rendered by `model` with `occupancy` over the data's background.
///
/// Errors: the ops' errors.
pub(crate) fn render_views<F: Float, M: RadianceField<F>>(
    model: &M,
    occupancy: Option<&OccupancyGrid>,
    data: &Dataset,
    settings: &FitSettings,
    depth: bool,
) -> Result<Vec<RenderedView>, FitError> {
    let options = RenderOptions {
        background: data.background,
        method: settings.method,
        depth,
    };
    data.test
        .iter()
        .map(|v| {
            let (origins, directions) = v.rays();
            render_picture(model, occupancy, &origins, &directions, v.size(), &options)
        })
        .collect()
}
