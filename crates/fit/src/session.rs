//! A session: what a tool does around a fit, written once for every tool. It merges a
//! resumed fit's settings with the flags given ([`resume_settings`]), loads the checkpoint,
//! runs the fit with the model type the settings name, shows a progress bar, saves the model
//! (at the end if asked, and always on Ctrl-C), and returns a summary that is not generic
//! over the model ([`FitReport`]) for the tool to print and draw.
//!
//! A tool gives the data (its own scene or a dataset on disk) and a [`SessionPlan`]; `fogray
//! fit` and `fogray-grid fit` differ only in those and in what they print.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use fogray_tape::Float;

use crate::checkpoint::{self, CheckpointError, ModelInfo};
use crate::dataset::Dataset;
use crate::dispatch::{with_field_kind, with_float, FieldWork, FloatWork};
use crate::error::FitError;
use crate::interrupt::StopFlag;
use crate::live::{snapshot, LiveHook};
use crate::metrics::{mean_psnr, view_scores, ViewScore};
use crate::model::RadianceField;
use crate::profile::ProfileTable;
use crate::render::RenderedView;
use crate::settings::FitSettings;
use crate::space::{self, SpaceDecision};
use crate::train::{training_views_psnr, LogEntry, Progress};
use crate::trainer::{run_budget, Evaluation, StepReport, Stepper, Trainer};

/// Why a session failed.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// From the fit (settings, data, ops).
    #[error(transparent)]
    Fit(#[from] FitError),
    /// From reading or writing a model file.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// From the metrics of the held-out views.
    #[error(transparent)]
    Image(#[from] crate::images::ImageError),
}

/// What a tool asks of a session.
#[derive(Debug, Clone)]
pub struct SessionPlan {
    /// The fit's settings (a resumed fit's: [`resume_settings`]).
    pub settings: FitSettings,
    /// The saved fit to continue.
    pub resume: Option<PathBuf>,
    /// Where to save the fitted model at the end; an interrupted fit is saved here too.
    pub save_model: Option<PathBuf>,
    /// Where an interrupted fit is saved when `save_model` is not given.
    pub save_on_interrupt: PathBuf,
    /// The tool's own entries in the model file (what it needs to resume or render).
    pub entries: BTreeMap<String, String>,
    /// The tool's name, at the head of each line the session writes to stderr.
    pub tool: String,
    /// Whether to show a progress bar on stderr.
    pub progress_bar: bool,
    /// Whether to say on stderr, once the first step is done, what is trained and where
    /// Ctrl-C saves it.
    pub announce: bool,
    /// A watcher of the fit as it trains, and the flag that stops it in place of Ctrl-C's
    /// ([`crate::live`]; a splat fit tells it nothing yet).
    pub live: Option<LiveHook>,
}

/// A fit's outcome as a tool reports it, whatever the model type.
#[derive(Debug, Clone)]
pub struct FitReport {
    /// The evaluations, in order.
    pub log: Vec<LogEntry>,
    /// PSNR (dB) of the held-out views' pooled squared error at the end.
    pub final_test_psnr: f64,
    /// The mean of the held-out views' own PSNRs at the end (the literature's convention).
    pub final_test_psnr_view_mean: f64,
    /// SSIM over the held-out views at the end (NaN for views smaller than its window).
    pub final_test_ssim: f64,
    /// PSNR over as many training views as held-out ones.
    pub train_views_psnr: f64,
    /// Each held-out view's PSNR and share of the squared error, in view order.
    pub view_scores: Vec<ViewScore>,
    /// The held-out views rendered at the end (colour unclamped, opacity, depth).
    pub held_out: Vec<RenderedView>,
    /// Training seconds (evaluations excluded).
    pub seconds: f64,
    /// Steps done, a resumed fit's earlier ones included.
    pub steps: usize,
    /// Mean samples per training ray over this session's steps.
    pub samples_per_ray_mean: f64,
    /// Fraction of occupied cells at the end (1 with uniform sampling).
    pub occupied_fraction: f64,
    /// Where a step's time went.
    pub profile: ProfileTable,
    /// Trainable values of the fitted model.
    pub parameters: usize,
    /// Seconds from the session's start to its first step's end (loading a checkpoint
    /// included); NaN if it took none.
    pub first_step_seconds: f64,
    /// Where the model was saved, if it was.
    pub saved: Option<PathBuf>,
    /// The space the field was fitted in, and why.
    pub space: SpaceDecision,
    /// The settings the fit ran with (its space decided).
    pub settings: FitSettings,
}

/// How a session ended.
#[derive(Debug, Clone)]
pub enum SessionOutcome {
    /// The budget was spent.
    Finished(Box<FitReport>),
    /// Ctrl-C stopped the fit after `step`; it was saved to `saved`.
    Interrupted {
        /// Steps done.
        step: usize,
        /// The model file.
        saved: PathBuf,
    },
}

/// A resumed fit's settings: `flags`' for the settings `given` names (by field name), the
/// file's for the rest, with the file's model info. `--grid` and `--precision`, if given,
/// must be the file's.
///
/// Errors: a file that cannot be read, or that another lattice or precision was asked of.
pub fn resume_settings(
    file: &Path,
    flags: &FitSettings,
    given: &dyn Fn(&str) -> bool,
) -> Result<(FitSettings, ModelInfo), SessionError> {
    let info = checkpoint::read_info(file)?;
    let settings = flags.given_over(&info.settings, given)?;
    info.check_matches(file, settings.precision, settings.grid)?;
    Ok((settings, info))
}

/// Runs a session: the fit of `data` that `plan` describes, with the model type its settings
/// name and its space decided from the data ([`SpaceDecision`]), stopped by Ctrl-C (which
/// saves it).
///
/// Errors: bad settings, a model file that cannot be read or written, the ops' errors.
pub fn run(data: &Dataset, plan: &SessionPlan) -> Result<SessionOutcome, SessionError> {
    let (settings, space) = space::resolve(&plan.settings, data)?;
    settings.check()?;
    let plan = &SessionPlan {
        settings,
        ..plan.clone()
    };
    if let Some(file) = &plan.save_model {
        checkpoint::check_destination(file)?;
    }
    let stop = match &plan.live {
        Some(live) => live.stop.clone(),
        None => StopFlag::on_ctrl_c()?,
    };
    let work = SessionWork {
        data,
        plan,
        space: &space,
        stop: &stop,
    };
    match plan.settings.model.field() {
        Some(field) => with_field_kind(plan.settings.precision, field, work),
        None => with_float(plan.settings.precision, work),
    }
}

/// A session with one model type, as the dispatch runs it.
struct SessionWork<'a> {
    data: &'a Dataset,
    plan: &'a SessionPlan,
    space: &'a SpaceDecision,
    stop: &'a StopFlag,
}

impl FieldWork for SessionWork<'_> {
    type Output = Result<SessionOutcome, SessionError>;

    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
        run_field::<F, M>(self.data, self.plan, self.space, self.stop)
    }
}

/// The splats' session ([`crate::splats::session`]).
impl FloatWork for SessionWork<'_> {
    type Output = Result<SessionOutcome, SessionError>;

    fn run<F: Float>(self) -> Self::Output {
        crate::splats::session::run::<F>(self.data, self.plan, self.space, self.stop)
    }
}

fn run_field<F: Float, M: RadianceField<F>>(
    data: &Dataset,
    plan: &SessionPlan,
    space: &SpaceDecision,
    stop: &StopFlag,
) -> Result<SessionOutcome, SessionError> {
    let mut bar = SessionBar::new(plan, data);
    let settings = &plan.settings;
    let start = match &plan.resume {
        Some(file) => Some(checkpoint::load::<F, M>(file)?.start),
        None => None,
    };
    let first_step = start.as_ref().map_or(0, |s| s.training.step);
    let save_path = plan
        .save_model
        .clone()
        .unwrap_or_else(|| plan.save_on_interrupt.clone());
    let from = match &plan.resume {
        Some(file) => format!(", from step {first_step} of {}", fogray_data::shown(file)),
        None => String::new(),
    };
    let mut trainer = Trainer::<F, M>::new(data, settings, start)?;
    let live = plan.live.as_ref();
    let mut watched = Watched {
        trainer: &mut trainer,
        live,
    };
    // A copy of the model that failed ends the fit after the loop, as a failed step would.
    let mut copy_failed = None;
    let run = run_budget(&mut watched, settings.evaluations, Some(stop.flag()), &mut |p, w| {
        bar.on_step(
            p,
            first_step,
            || (String::new(), from.clone(), save_path.clone()),
            format!("step {}", p.step),
        );
        if let Some(live) = live {
            live.sink.step(p);
            if live.sink.wants_model() && copy_failed.is_none() {
                match snapshot(w.trainer.model(), w.trainer.occupancy(), settings, p.step) {
                    Ok(copy) => live.sink.model(copy),
                    Err(e) => copy_failed = Some(e),
                }
            }
        }
    })?;
    bar.finish();
    if let Some(e) = copy_failed {
        return Err(e.into());
    }
    if let Some(live) = live {
        live.sink.model(snapshot(
            trainer.model(),
            trainer.occupancy(),
            settings,
            trainer.steps(),
        )?);
        live.sink.finished(&run.log, run.interrupted);
    }
    let training = trainer.state()?;
    if run.interrupted || plan.save_model.is_some() {
        checkpoint::save(&save_path, trainer.model(), &training, settings, &plan.entries)?;
    }
    let Some(last) = run.last else {
        return Ok(SessionOutcome::Interrupted {
            step: training.step,
            saved: save_path,
        });
    };
    let steps_taken = trainer.steps_taken();
    let samples_per_ray_mean = trainer.samples() as f64 / (steps_taken * settings.batch) as f64;
    let train_views_psnr = training_views_psnr(trainer.model(), data, settings, trainer.occupancy(), data.test.len())?;
    let profile = trainer.profile().table();
    let seconds = trainer.seconds();
    let (model, occupancy) = trainer.into_parts();
    let params = model.params();
    let fit = FitFigures {
        train_views_psnr,
        seconds,
        steps: training.step,
        samples_per_ray_mean,
        occupied_fraction: occupancy.as_ref().map_or(1.0, |g| g.occupied_fraction()),
        profile,
        parameters: params.ids().filter_map(|id| params.get(id).ok()).map(|v| v.len()).sum(),
        saved: plan.save_model.is_some().then_some(save_path),
    };
    Ok(SessionOutcome::Finished(Box::new(FitReport::of(
        data,
        plan,
        space,
        run.log,
        last,
        fit,
        bar.first_step_seconds,
    )?)))
}

/// A trainer whose evaluations a watcher sees as they are made.
struct Watched<'t, 'd, F: Float, M> {
    trainer: &'t mut Trainer<'d, F, M>,
    live: Option<&'t LiveHook>,
}

impl<F: Float, M: RadianceField<F>> Stepper for Watched<'_, '_, F, M> {
    fn step(&mut self) -> Result<StepReport, FitError> {
        self.trainer.step()
    }

    fn evaluate(&self, depth: bool) -> Result<Evaluation, FitError> {
        let evaluation = Stepper::evaluate(&*self.trainer, depth)?;
        if let Some(live) = self.live {
            live.sink.evaluated(&evaluation.entry);
        }
        Ok(evaluation)
    }

    fn fraction(&self) -> f64 {
        Stepper::fraction(&*self.trainer)
    }

    fn steps(&self) -> usize {
        Stepper::steps(&*self.trainer)
    }
}

/// What a model's session measured beside the budget loop's evaluations.
pub(crate) struct FitFigures {
    pub(crate) train_views_psnr: f64,
    pub(crate) seconds: f64,
    pub(crate) steps: usize,
    pub(crate) samples_per_ray_mean: f64,
    pub(crate) occupied_fraction: f64,
    pub(crate) profile: ProfileTable,
    pub(crate) parameters: usize,
    pub(crate) saved: Option<PathBuf>,
}

impl FitReport {
    /// The report of a finished fit of `data`: the budget loop's `log` and `last` evaluation,
    /// scored view by view, with the model's `fit` figures.
    ///
    /// Errors: renders that do not match the held-out views.
    pub(crate) fn of(
        data: &Dataset,
        plan: &SessionPlan,
        space: &SpaceDecision,
        log: Vec<LogEntry>,
        last: Evaluation,
        fit: FitFigures,
        first_step_seconds: f64,
    ) -> Result<FitReport, SessionError> {
        let scores = view_scores(
            &last.views.iter().map(|v| v.color.view()).collect::<Vec<_>>(),
            &data.test.iter().map(|t| t.image.view()).collect::<Vec<_>>(),
        )?;
        Ok(FitReport {
            final_test_psnr: last.entry.test_psnr,
            final_test_psnr_view_mean: mean_psnr(&scores),
            final_test_ssim: last.entry.test_ssim,
            train_views_psnr: fit.train_views_psnr,
            view_scores: scores,
            held_out: last.views,
            seconds: fit.seconds,
            steps: fit.steps,
            samples_per_ray_mean: fit.samples_per_ray_mean,
            occupied_fraction: fit.occupied_fraction,
            profile: fit.profile,
            parameters: fit.parameters,
            first_step_seconds,
            saved: fit.saved,
            space: space.clone(),
            settings: plan.settings,
            log,
        })
    }
}

/// A session's progress bar, and the line it writes once the first step is done.
pub(crate) struct SessionBar<'a> {
    plan: &'a SessionPlan,
    data: &'a Dataset,
    clock: Instant,
    bar: indicatif::ProgressBar,
    /// Seconds from the session's start to its first step's end; NaN until then.
    pub(crate) first_step_seconds: f64,
}

impl<'a> SessionBar<'a> {
    /// A bar for `plan`'s fit of `data` (hidden if the plan asks for none), its clock started.
    pub(crate) fn new(plan: &'a SessionPlan, data: &'a Dataset) -> Self {
        SessionBar {
            plan,
            data,
            clock: Instant::now(),
            bar: progress_bar(plan.progress_bar),
            first_step_seconds: f64::NAN,
        }
    }

    /// Shows `progress` with `message`. After the first step of the session (step
    /// `first_step + 1`), notes the time and, if the plan asks, says what is trained: `line`
    /// gives what goes before the views' count, what follows their size, and where Ctrl-C saves.
    pub(crate) fn on_step(
        &mut self,
        progress: Progress,
        first_step: usize,
        line: impl FnOnce() -> (String, String, PathBuf),
        message: String,
    ) {
        if progress.step == first_step + 1 {
            self.first_step_seconds = self.clock.elapsed().as_secs_f64();
            if self.plan.announce {
                let (before, after, saved) = line();
                let [h, w] = self.data.train[0].size();
                self.bar.suspend(|| {
                    eprintln!(
                        "{}: {before}{} training and {} held-out views of {w}x{h}{after}; Ctrl-C stops and saves the fit to {}",
                        self.plan.tool,
                        self.data.train.len(),
                        self.data.test.len(),
                        fogray_data::shown(&saved)
                    )
                });
            }
        }
        self.bar.set_position((progress.fraction * 1000.0) as u64);
        self.bar.set_message(message);
    }

    /// Clears the bar.
    pub(crate) fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

fn progress_bar(shown: bool) -> indicatif::ProgressBar {
    if !shown {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(1000);
    if let Ok(style) = indicatif::ProgressStyle::with_template("fit [{bar:40}] {msg} ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}
