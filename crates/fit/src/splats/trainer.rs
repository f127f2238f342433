//! [`SplatTrainer`]: a splat fit one step at a time, with the grid trainer's public shape
//! (`new`, `step`, `evaluate`, `state`, `profile`). A step renders one whole training view (a
//! grid step draws random rays), takes the L1 loss against its picture, runs the backward and
//! Adam, and calls the policies around it: [`SplatRates`] before, [`Densify`] and
//! [`OpacityReset`] after, in that order.

use std::time::Instant;

use fogray_ops::splat::SplatRender;
use fogray_tape::optim::{Adam, AdamConfig};
use fogray_tape::{Float, Tape};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;

use super::densify::Densify;
use super::model::SplatModel;
use super::policies::{OpacityReset, SplatRates};
use super::settings::SplatSettings;
use crate::dataset::{Dataset, View};
use crate::error::FitError;
use crate::profile::{Phases, StepProfile};
use crate::render::RenderedView;
use crate::settings::Budget;
use crate::trainer::{Evaluation, StepContext, StepPolicy, StepReport, Stepper};

/// A splat fit in progress (see the [module docs](self)).
pub(crate) struct SplatTrainer<'d, F: Float> {
    data: &'d Dataset,
    settings: SplatSettings,
    model: SplatModel<F>,
    optimiser: Adam<F>,
    rates: SplatRates,
    densify: Densify,
    reset: OpacityReset,
    /// The view order's and backgrounds' generator.
    rng: ChaCha12Rng,
    tape: Tape<F>,
    step: usize,
    seconds: f64,
    loss: f64,
    phases: Phases,
}

/// The scene's extent as 3DGS takes it: 1.1 times the largest distance of a training camera
/// from their mean centre (1 for a single camera, so that rates stay positive).
pub(crate) fn scene_extent(data: &Dataset) -> f64 {
    let centres: Vec<[f64; 3]> = data.train.iter().map(|v| v.camera.centre()).collect();
    let n = centres.len().max(1) as f64;
    let mean = [0, 1, 2].map(|a| centres.iter().map(|c| c[a]).sum::<f64>() / n);
    let far = centres
        .iter()
        .map(|c| (0..3).map(|a| (c[a] - mean[a]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max);
    if far > 0.0 {
        1.1 * far
    } else {
        1.0
    }
}

/// `view`'s picture as the op's image layout `[h w, 3]`, over `background` where it has
/// alpha (its own background elsewhere).
fn target<F: Float>(view: &View, dataset_background: [f64; 3], background: [f64; 3]) -> Array2<F> {
    let (h, w, _) = view.image.dim();
    Array2::from_shape_fn((h * w, 3), |(p, c)| {
        let (r, col) = (p / w, p % w);
        let own = view.image[[r, col, c]];
        let over = match &view.alpha {
            Some(alpha) => own + (background[c] - dataset_background[c]) * (1.0 - alpha[[r, col]]),
            None => own,
        };
        F::lit(over)
    })
}

impl<'d, F: Float> SplatTrainer<'d, F> {
    /// A trainer of `model` on `data` with `settings`.
    ///
    /// Errors: settings out of range, a model larger than the settings' cap, colours of
    /// another degree than the settings' ([`FitError::Config`], [`FitError::TooManySplats`]).
    pub(crate) fn new(data: &'d Dataset, settings: &SplatSettings, model: SplatModel<F>) -> Result<Self, FitError> {
        settings.check()?;
        if model.len() > settings.max_splats {
            return Err(FitError::TooManySplats {
                count: model.len(),
                cap: settings.max_splats,
            });
        }
        if model.degree() != settings.degree {
            return Err(FitError::Config(format!(
                "splats of colour degree {} for a fit of degree {}",
                model.degree(),
                settings.degree
            )));
        }
        let extent = scene_extent(data);
        let optimiser = Adam::new(AdamConfig {
            lr: 1.0,
            ..AdamConfig::default()
        })?;
        let mut tape = Tape::<F>::new();
        tape.set_profiling(true);
        Ok(SplatTrainer {
            data,
            settings: *settings,
            model,
            optimiser,
            rates: SplatRates::new(settings, extent),
            densify: Densify::new(settings, extent, settings.seed.wrapping_add(1)),
            reset: OpacityReset::new(settings),
            rng: ChaCha12Rng::seed_from_u64(settings.seed),
            tape,
            step: 0,
            seconds: 0.0,
            loss: f64::NAN,
            phases: Phases::default(),
        })
    }

    /// The model as it is now.
    pub(crate) fn model(&self) -> &SplatModel<F> {
        &self.model
    }

    /// The fraction of the budget spent (steps or training seconds).
    pub(crate) fn fraction(&self) -> f64 {
        match self.settings.budget {
            Budget::Steps(n) => self.step as f64 / n as f64,
            Budget::Seconds(s) => self.seconds / s,
        }
    }

    /// Whether the budget is spent.
    #[cfg(test)]
    pub(crate) fn is_done(&self) -> bool {
        self.fraction() >= 1.0
    }

    /// One step on a random training view (see the [module docs](self)); its time counts in
    /// [`SplatTrainer::seconds`].
    ///
    /// Errors: the ops' (too many tile intersections), a policy's (too many splats); the
    /// trainer should then be dropped.
    pub(crate) fn step(&mut self) -> Result<StepReport, FitError> {
        let start = Instant::now();
        let mut occupancy = None;
        let fraction = self.fraction();
        let mut at = StepContext {
            step: self.step,
            fraction,
            model: &mut self.model,
            optimiser: &mut self.optimiser,
            occupancy: &mut occupancy,
        };
        self.rates.before_step(&mut at)?;
        let view = &self.data.train[self.rng.gen_range(0..self.data.train.len())];
        let background = if self.settings.random_background && view.alpha.is_some() {
            [0, 1, 2].map(|_| self.rng.gen::<f64>())
        } else {
            self.data.background
        };
        let op = SplatRender::new(&view.camera, background)?;
        let tape = &mut self.tape;
        let vars = at.model.vars(tape, view.camera.centre())?;
        let image = op.apply(tape, &vars)?;
        let exact = tape.constant(target::<F>(view, self.data.background, background));
        let diff = tape.sub(image, exact)?;
        let abs = tape.abs(diff)?;
        let loss = tape.mean(abs)?;
        self.loss = tape.value(loss)?.iter().next().map_or(f64::NAN, |v| v.as_f64());
        let forward_end = Instant::now();
        let grads = tape.backward(loss)?;
        let backward_end = Instant::now();
        tape.clear();
        if let Some(g) = grads.param(at.model.ids().means) {
            at.model.observe(g)?;
        }
        at.optimiser.step(at.model.params_mut(), &grads)?;
        let optimiser_end = Instant::now();
        at.step += 1;
        self.step = at.step;
        // The budget fraction after the step, as the grid's policies see it.
        let elapsed = start.elapsed().as_secs_f64();
        at.fraction = match self.settings.budget {
            Budget::Steps(n) => at.step as f64 / n as f64,
            Budget::Seconds(s) => (self.seconds + elapsed) / s,
        };
        self.densify.after_step(&mut at)?;
        self.reset.after_step(&mut at)?;
        self.phases.forward += forward_end - start;
        self.phases.backward += backward_end - forward_end;
        self.phases.optimiser += optimiser_end - backward_end;
        self.seconds += start.elapsed().as_secs_f64();
        Ok(StepReport {
            step: self.step,
            loss: self.loss,
            samples: 0,
            fraction: self.fraction().min(1.0),
        })
    }

    /// The held-out views rendered by the model as it is over the dataset's background, with
    /// their opacity (from a second render: the image is linear in the background), and
    /// scored. Splats have no depth yet.
    ///
    /// Errors: the ops'.
    pub(crate) fn evaluate(&self) -> Result<Evaluation, FitError> {
        let views = self
            .data
            .test
            .iter()
            .map(|v| render_view(&self.model, v, self.data.background))
            .collect::<Result<Vec<_>, _>>()?;
        Evaluation::scored(views, self.data, self.step, self.seconds, self.loss, 0)
    }

    /// Where the training time went, phase by phase and op by op.
    pub(crate) fn profile(&mut self) -> StepProfile {
        StepProfile {
            steps: self.step,
            phases: self.phases,
            ops: self.tape.take_profile().unwrap_or_default(),
        }
    }

    /// Training seconds so far.
    pub(crate) fn seconds(&self) -> f64 {
        self.seconds
    }

    /// Steps done.
    pub(crate) fn steps(&self) -> usize {
        self.step
    }

    /// The model, ending the fit.
    pub(crate) fn into_model(self) -> SplatModel<F> {
        self.model
    }
}

impl<F: Float> Stepper for SplatTrainer<'_, F> {
    fn step(&mut self) -> Result<StepReport, FitError> {
        SplatTrainer::step(self)
    }
    /// Without depth, which splats do not render yet.
    fn evaluate(&self, _depth: bool) -> Result<Evaluation, FitError> {
        SplatTrainer::evaluate(self)
    }
    fn fraction(&self) -> f64 {
        SplatTrainer::fraction(self)
    }
    fn steps(&self) -> usize {
        SplatTrainer::steps(self)
    }
}

/// `view` rendered by `model` over `background`: colour, opacity, no depth.
///
/// Errors: the ops'.
pub(crate) fn render_view<F: Float>(
    model: &SplatModel<F>,
    view: &View,
    background: [f64; 3],
) -> Result<RenderedView, FitError> {
    let [h, w] = view.size();
    let black = model.render(&view.camera, [0.0; 3])?;
    let white = model.render(&view.camera, [1.0; 3])?;
    // C(b) = C(0) + T b: the transmittance is what white adds.
    let transmittance = |p: usize| {
        (0..3)
            .map(|c| white[[p, c]].as_f64() - black[[p, c]].as_f64())
            .sum::<f64>()
            / 3.0
    };
    let color = Array3::from_shape_fn((h, w, 3), |(r, c, k)| {
        let p = r * w + c;
        black[[p, k]].as_f64() + transmittance(p) * background[k]
    });
    let opacity = Array2::from_shape_fn((h, w), |(r, c)| 1.0 - transmittance(r * w + c));
    Ok(RenderedView {
        color,
        opacity,
        depth: None,
    })
}
