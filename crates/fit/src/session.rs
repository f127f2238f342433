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
use crate::dispatch::{with_model, ModelWork};
use crate::error::FitError;
use crate::interrupt::StopFlag;
use crate::metrics::{mean_psnr, view_scores, ViewScore};
use crate::model::RadianceField;
use crate::profile::ProfileTable;
use crate::render::RenderedView;
use crate::settings::FitSettings;
use crate::space::{self, SpaceDecision};
use crate::train::{fit_from, LogEntry, Progress};

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
    /// PSNR over as many training views as held-out ones
    /// ([`training_views_psnr`](crate::train::training_views_psnr)).
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

/// The exit status of a tool whose fit Ctrl-C stopped (after saving it): 128 + SIGINT, as a
/// shell reports a command stopped by Ctrl-C.
pub const INTERRUPTED_EXIT: u8 = 130;

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
/// name and its space decided from the data ([`space::resolve`]), stopped by Ctrl-C (which
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
    let stop = StopFlag::on_ctrl_c()?;
    let work = SessionWork {
        data,
        plan,
        space: &space,
        stop: &stop,
    };
    with_model(plan.settings.precision, plan.settings.model, work)
}

/// A session with one model type, as the dispatch runs it.
struct SessionWork<'a> {
    data: &'a Dataset,
    plan: &'a SessionPlan,
    space: &'a SpaceDecision,
    stop: &'a StopFlag,
}

impl ModelWork for SessionWork<'_> {
    type Output = Result<SessionOutcome, SessionError>;

    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
        run_typed::<F, M>(self.data, self.plan, self.space, self.stop)
    }

    fn run_splats<F: Float>(self) -> Self::Output {
        crate::splats::session::run::<F>(self.data, self.plan, self.space, self.stop)
    }
}

fn run_typed<F: Float, M: RadianceField<F>>(
    data: &Dataset,
    plan: &SessionPlan,
    space: &SpaceDecision,
    stop: &StopFlag,
) -> Result<SessionOutcome, SessionError> {
    let clock = Instant::now();
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
    let bar = progress_bar(plan.progress_bar);
    let mut first_step_seconds = f64::NAN;
    let mut progress = |p: Progress| {
        if p.step == first_step + 1 {
            first_step_seconds = clock.elapsed().as_secs_f64();
            if plan.announce {
                let [h, w] = data.train[0].size();
                let from = match &plan.resume {
                    Some(file) => format!(", from step {first_step} of {}", file.display()),
                    None => String::new(),
                };
                bar.suspend(|| {
                    eprintln!(
                        "{}: {} training and {} held-out views of {w}x{h}{from}; Ctrl-C stops and saves the fit to {}",
                        plan.tool,
                        data.train.len(),
                        data.test.len(),
                        save_path.display()
                    )
                });
            }
        }
        bar.set_position((p.fraction * 1000.0) as u64);
        bar.set_message(format!("step {}", p.step));
    };
    let result = fit_from::<F, M>(data, settings, start, Some(stop.flag()), &mut progress)?;
    bar.finish_and_clear();
    let saved = if plan.save_model.is_some() || result.interrupted {
        checkpoint::save(&save_path, &result.model, &result.training, settings, &plan.entries)?;
        Some(save_path)
    } else {
        None
    };
    if let (true, Some(saved)) = (result.interrupted, &saved) {
        return Ok(SessionOutcome::Interrupted {
            step: result.training.step,
            saved: saved.clone(),
        });
    }
    let scores = view_scores(
        &result.renders.iter().map(|r| r.view()).collect::<Vec<_>>(),
        &data.test.iter().map(|t| t.image.view()).collect::<Vec<_>>(),
    )?;
    let params = result.model.params();
    Ok(SessionOutcome::Finished(Box::new(FitReport {
        final_test_psnr_view_mean: mean_psnr(&scores),
        view_scores: scores,
        train_views_psnr: result.training_views_psnr(data, settings)?,
        final_test_psnr: result.final_test_psnr,
        final_test_ssim: result.final_test_ssim,
        seconds: result.seconds,
        steps: result.training.step,
        samples_per_ray_mean: result.samples_per_ray_mean,
        occupied_fraction: result.occupied_fraction,
        profile: result.profile.table(),
        parameters: params.ids().filter_map(|id| params.get(id).ok()).map(|v| v.len()).sum(),
        first_step_seconds,
        saved,
        space: space.clone(),
        settings: *settings,
        held_out: result.held_out,
        log: result.log,
    })))
}

pub(crate) fn progress_bar(shown: bool) -> indicatif::ProgressBar {
    if !shown {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(1000);
    if let Ok(style) = indicatif::ProgressStyle::with_template("fit [{bar:40}] {msg} ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}
