//! `fogray fit`: a dataset on disk (Blender, instant-ngp or nerfstudio) fitted with the
//! recommended model and settings; the held-out views measured at intervals off the clock.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use fogray_data::{load, LoadOptions, SceneData};
use fogray_fit::checkpoint;
use fogray_fit::dataset::{Dataset, View};
use fogray_fit::dispatch::{with_model, ModelWork};
use fogray_fit::interrupt::StopFlag;
use fogray_fit::metrics::{haze_fraction, mean_psnr, view_scores, ViewScore};
use fogray_fit::profile::ProfileTable;
use fogray_fit::render::{render_picture, RenderOptions, RenderedView};
use fogray_fit::settings::{Budget, FitSettings, SceneBox};
use fogray_fit::train::{fit_from, FitResult, LogEntry, Progress};
use fogray_fit::RadianceField;
use fogray_tape::Float;
use serde::Serialize;

use crate::error::CliError;

/// The degree of spherical harmonics `fogray fit` uses unless `--sh-degree` is given: real
/// objects shine, and degree 1 buys more on held-out views than its cost per step takes.
pub const RECOMMENDED_SH_DEGREE: &str = "1";

/// The model `fogray fit` trains unless `--model` is given: a real scene fills a small part of
/// its box, and the sparse grid keeps only that part.
pub const RECOMMENDED_MODEL: &str = "sparse";

/// The total-variation weight `fogray fit` uses unless `--tv` is given: none. Tens of views
/// constrain a scene enough, and the prior costs a step as much as the lookup's backward
/// without buying held-out PSNR (the lego comparison in reports/lego/report.md).
pub const RECOMMENDED_TV: &str = "0";

/// Adam's learning rate `fogray fit` uses unless `--lr` is given, and where it anneals to
/// unless `--lr-final` is: twice the library's. The grid example's few hundred rays a pixel
/// settle at the library's rate; tens of photographs seen through a sparse grid with
/// view-dependent colour gain held-out PSNR step for step at this one, and no more above it
/// (lego, fits of a fixed number of steps).
pub const RECOMMENDED_LR: &str = "0.4";
/// See [`RECOMMENDED_LR`].
pub const RECOMMENDED_LR_FINAL: &str = "0.04";

/// The distortion-loss weight `fogray fit` uses unless `--distortion` is given: a little of
/// mip-NeRF 360's loss pulls each ray's weights onto its surface, which clears the haze a
/// photograph cannot tell from a sheet and gains held-out PSNR at short and long budgets
/// alike; ten times more costs PSNR (lego, reports/lego/report.md).
pub const RECOMMENDED_DISTORTION: &str = "0.01";

/// The lattice `fogray fit` grows to unless `--grid` is given: 128 nodes per axis (32, 64,
/// then 128), the finest that a minute's fit on two cores still trains well; from
/// [`LONG_FIT_SECONDS`] of training on, [`RECOMMENDED_GRID_LONG`] ([`long_fit_grid`]).
pub const RECOMMENDED_GRID: &str = "128";

/// The lattice of a long fit unless `--grid` is given (48, 96, then 192): its finer nodes
/// cost a step twice as much, which a long budget pays back in held-out PSNR and a short one
/// does not (lego, reports/lego/report.md).
pub const RECOMMENDED_GRID_LONG: usize = 192;

/// The training seconds from which [`RECOMMENDED_GRID_LONG`] is the recommended lattice.
pub const LONG_FIT_SECONDS: f64 = 150.0;

/// `fogray fit --grid`'s help, which says how its default depends on the budget.
pub const GRID_HELP: &str =
    "Nodes per axis of the grid (of its last growth stage); unless given, 128, or 192 for --seconds 150 and more";

/// The lattice a fit of `budget` grows to when `--grid` is not given, where it is not
/// [`RECOMMENDED_GRID`]: [`RECOMMENDED_GRID_LONG`] for a budget of [`LONG_FIT_SECONDS`] or
/// more; `None` for shorter ones and for a budget of steps, which says nothing of time.
pub fn long_fit_grid(budget: Budget) -> Option<usize> {
    match budget {
        Budget::Seconds(s) if s >= LONG_FIT_SECONDS => Some(RECOMMENDED_GRID_LONG),
        _ => None,
    }
}

/// Where the data comes from and how it is read (shared by `fogray fit` and `fogray render`).
#[derive(Debug, Clone, clap::Args)]
pub struct DataArgs {
    /// Average each KxK block of pixels (after compositing over the background) and divide
    /// the focal lengths and principal point by K.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub downscale: usize,
    /// The colour behind the scene, r,g,b in [0, 1]: transparent pixels are composited over
    /// it and the model renders over it.
    #[arg(long, default_value = "1,1,1", value_parser = parse_colour, value_name = "R,G,B")]
    pub background: [f64; 3],
    /// Drop the frames whose image file is missing (and say how many) instead of failing.
    #[arg(long)]
    pub skip_missing: bool,
}

impl DataArgs {
    /// The loader's options.
    pub fn options(&self) -> LoadOptions {
        LoadOptions {
            downscale: self.downscale,
            background: self.background,
            skip_missing: self.skip_missing,
        }
    }
}

/// `r,g,b`, each finite in [0, 1].
pub fn parse_colour(text: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match values[..] {
        [r, g, b] if values.iter().all(|v| (0.0..=1.0).contains(v)) => Ok([r, g, b]),
        _ => Err(format!("{text:?}: give r,g,b, each in [0, 1]")),
    }
}

/// The flags of `fogray fit`.
#[derive(Debug, Clone, clap::Args)]
pub struct FitArgs {
    /// A Blender / NeRF-synthetic folder (transforms_train.json ...), an instant-ngp or
    /// nerfstudio folder (transforms.json), or a transforms file. Resuming, the saved fit's
    /// unless given.
    #[arg(long, value_name = "PATH", required_unless_present = "resume")]
    pub data: Option<PathBuf>,
    /// Continue the fit saved in FILE (by --save-model, or by Ctrl-C) up to its budget, or to
    /// the --steps or --seconds given (counting the steps and seconds it has done): its
    /// settings, dataset, --downscale and --background are the file's except where given;
    /// --grid and --precision, if given, must be the file's.
    #[arg(long, value_name = "FILE")]
    pub resume: Option<PathBuf>,
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Write the fitted model here (safetensors; `fogray render --model` reads it).
    #[arg(long, value_name = "FILE")]
    pub save_model: Option<PathBuf>,
    /// Write a report into this directory: report.md (the final figures, PSNR and SSIM
    /// against training seconds, each held-out view beside its photograph, the settings, the
    /// machine and the command), test/<name>.png, psnr.png, ssim.png and fit.json.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print {"final_test_psnr", "seconds", "steps", "log": [...]} on stdout instead of a
    /// table (and no progress bar).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub settings: FitSettings,
}

/// What `fogray fit --json` prints.
#[derive(Debug, Serialize)]
pub struct FitSummary<'a> {
    /// PSNR (dB) over all held-out views at the end: of the mean squared error over them.
    pub final_test_psnr: f64,
    /// The mean of the held-out views' own PSNRs (dB) at the end ([`mean_psnr`]): the
    /// figure the NeRF literature and nerfstudio report; never below `final_test_psnr` for views of one size.
    pub final_test_psnr_view_mean: f64,
    /// SSIM (Gaussian window 11, sigma 1.5) over the held-out views at the end; null for views
    /// smaller than its window.
    pub final_test_ssim: f64,
    /// PSNR (dB) at the end over as many training views as there are held-out ones, spread
    /// through the training list ([`FitResult::training_views_psnr`]): its gap to `final_test_psnr` is
    /// how much better the fit reproduces its own views than new ones.
    pub train_views_psnr: f64,
    /// Training seconds (evaluations and loading excluded).
    pub seconds: f64,
    /// Training steps.
    pub steps: usize,
    /// The evaluations, in order (`train_loss` is null before the first step).
    pub log: &'a [LogEntry],
    /// Training and held-out views.
    pub views: [usize; 2],
    /// `[height, width]` of the first training view.
    pub size: [usize; 2],
    /// Seconds from the command's start to the first training step (reading and decoding).
    pub load_seconds: f64,
    /// Trainable values of the fitted model (a sparse grid's follow the nodes it kept).
    pub parameters: usize,
    /// Where a training step's time went, milliseconds a step averaged over the fit.
    pub profile: ProfileTable,
    /// The fraction of held-out pixels whose rendered opacity lies in (0.05, 0.95) at the end:
    /// the haze around an object that should be opaque or empty.
    pub held_out_haze: f64,
    /// The process's peak resident memory in bytes (null where the system does not say).
    pub peak_resident_bytes: Option<u64>,
    /// Each held-out view's PSNR and share of the held-out squared error, in view order.
    pub held_out_views: Vec<HeldOutScore>,
}

/// One held-out view's PSNR and its share of the squared error over all of them.
#[derive(Debug, Serialize)]
pub struct HeldOutScore {
    /// The view's name.
    pub name: String,
    /// Its PSNR and share of the error.
    #[serde(flatten)]
    pub score: ViewScore,
}

/// How a fit ended: its output for stdout, or an interruption (saved).
pub enum FitOutcome {
    /// The text to print.
    Done(String),
    /// Ctrl-C stopped the fit; it was saved to this file.
    Interrupted(PathBuf),
}

/// The dataset's views as the pipeline's: each picture (and its alpha, where the file had
/// one, for `--random-background`) widened to `f64` and its `f32` dropped as it goes, so that
/// the peak is one copy plus one picture.
pub fn views(frames: Vec<fogray_data::Frame>) -> Result<Vec<View>, CliError> {
    frames
        .into_iter()
        .map(|f| {
            let view = View::new(f.name, &f.camera, f.picture.color.mapv(f64::from))?;
            Ok(match f.picture.alpha {
                Some(alpha) => view.with_alpha(alpha.mapv(f64::from))?,
                None => view,
            })
        })
        .collect()
}

/// A dataset on disk as a fit's data (its training and held-out views over the background
/// `data_args` names) and the box the dataset gives its scene.
///
/// Errors: a bad dataset, naming the file.
pub fn load_fit_data(path: &Path, data_args: &DataArgs) -> Result<(Dataset, SceneBox), CliError> {
    let scene: SceneData = load(path, &data_args.options())?;
    if scene.skipped > 0 {
        eprintln!(
            "fogray fit: --skip-missing dropped {} frames whose image is missing",
            scene.skipped
        );
    }
    let (min, max) = scene.scene_box;
    let data = Dataset::new(views(scene.train)?, views(scene.test)?, data_args.background)?;
    Ok((data, SceneBox { min, max }))
}

/// What a fit reads and how it trains: the flags, or, resuming, the saved fit's choices under
/// the flags given.
#[derive(Debug, Clone)]
pub struct FitPlan {
    /// The dataset.
    pub data: PathBuf,
    /// How its pictures are read.
    pub data_args: DataArgs,
    /// The fit's settings (the scene box is the dataset's unless they name one).
    pub settings: FitSettings,
    /// The saved fit to continue.
    pub resume: Option<PathBuf>,
}

/// The plan of `fogray fit` with `args`, where `given(id)` says whether the flag of clap id
/// `id` was given on the command line. A fresh fit of a long budget grows to
/// [`RECOMMENDED_GRID_LONG`] unless `--grid` is given ([`long_fit_grid`]); a resumed one keeps
/// the file's lattice.
///
/// Errors: a model file that cannot be read or that another lattice or precision was asked
/// of, a saved dataset entry that cannot be read (naming the file).
pub fn plan(args: &FitArgs, given: &dyn Fn(&str) -> bool) -> Result<FitPlan, CliError> {
    let Some(file) = &args.resume else {
        let data = args
            .data
            .clone()
            .ok_or_else(|| CliError::Option("give --data PATH, or --resume FILE".into()))?;
        let mut settings = args.settings;
        if let (false, Some(n)) = (given("grid"), long_fit_grid(settings.budget())) {
            settings.grid = n;
        }
        return Ok(FitPlan {
            data,
            data_args: args.data_args.clone(),
            settings,
            resume: None,
        });
    };
    let info = checkpoint::read_info(file)?;
    let settings = args.settings.given_over(&info.settings, given)?;
    info.check_matches(file, settings.precision, settings.grid)?;
    let entry = |key: &str| {
        info.extra.get(key).ok_or_else(|| {
            CliError::Option(format!(
                "{} has no saved {key} (it was not written by fogray fit): give --{key}",
                file.display()
            ))
        })
    };
    let unreadable = |key: &str, text: &str| {
        CliError::Option(format!("{}: its saved {key} {text:?} cannot be read", file.display()))
    };
    let data = match &args.data {
        Some(path) => path.clone(),
        None => PathBuf::from(entry("data")?),
    };
    let mut data_args = args.data_args.clone();
    if !given("downscale") {
        let text = entry("downscale")?;
        data_args.downscale = text.parse().map_err(|_| unreadable("downscale", text))?;
    }
    if !given("background") {
        let text = entry("background")?;
        data_args.background = serde_json::from_str(text).map_err(|_| unreadable("background", text))?;
    }
    Ok(FitPlan {
        data,
        data_args,
        settings,
        resume: Some(file.clone()),
    })
}

/// Runs `fogray fit`, where `given(id)` says whether the flag of clap id `id` was given on the
/// command line ([`plan`]).
///
/// Errors: a bad dataset or model file (naming the file), bad settings, a file that cannot be
/// written.
pub fn run(args: &FitArgs, given: &dyn Fn(&str) -> bool) -> Result<FitOutcome, CliError> {
    let clock = Instant::now();
    if let Some(file) = &args.save_model {
        checkpoint::check_destination(file)?;
    }
    let plan = plan(args, given)?;
    plan.settings.check()?;
    let (data, scene_box) = load_fit_data(&plan.data, &plan.data_args)?;
    let settings = FitSettings {
        scene_box: Some(plan.settings.scene_box.unwrap_or(scene_box)),
        ..plan.settings
    };
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).map_err(CliError::file("create", dir))?;
    }
    let stop = StopFlag::on_ctrl_c()?;
    let work = FitWork {
        args,
        plan: &plan,
        settings: &settings,
        data: &data,
        stop: &stop,
        clock,
    };
    with_model(settings.precision, settings.model, work)
}

fn progress_bar(hidden: bool) -> indicatif::ProgressBar {
    if hidden {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(1000);
    if let Ok(style) = indicatif::ProgressStyle::with_template("fit [{bar:40}] {msg} ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// The checkpoint's own entries: what `fogray render` and `fogray fit --resume` need beside
/// the model.
fn entries(plan: &FitPlan) -> Result<BTreeMap<String, String>, CliError> {
    Ok(BTreeMap::from([
        (
            "background".to_string(),
            serde_json::to_string(&plan.data_args.background)?,
        ),
        // Absolute (the fit has just read it), so that a render from another folder finds it.
        (
            "data".to_string(),
            std::fs::canonicalize(&plan.data)
                .unwrap_or_else(|_| plan.data.clone())
                .display()
                .to_string(),
        ),
        ("downscale".to_string(), plan.data_args.downscale.to_string()),
    ]))
}

/// A fit of one model type, as fogray-fit's dispatch runs it.
struct FitWork<'a> {
    args: &'a FitArgs,
    plan: &'a FitPlan,
    settings: &'a FitSettings,
    data: &'a Dataset,
    stop: &'a StopFlag,
    clock: Instant,
}

impl ModelWork for FitWork<'_> {
    type Output = Result<FitOutcome, CliError>;

    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
        fit_and_report::<F, M>(self.args, self.plan, self.settings, self.data, self.stop, self.clock)
    }
}

fn fit_and_report<F: Float, M: RadianceField<F>>(
    args: &FitArgs,
    plan: &FitPlan,
    settings: &FitSettings,
    data: &Dataset,
    stop: &StopFlag,
    clock: Instant,
) -> Result<FitOutcome, CliError> {
    let bar = progress_bar(args.json);
    let mut load_seconds = f64::NAN;
    let mut progress = |p: Progress| {
        if load_seconds.is_nan() {
            load_seconds = clock.elapsed().as_secs_f64();
        }
        bar.set_position((p.fraction * 1000.0) as u64);
        bar.set_message(format!("step {}", p.step));
    };
    let [h, w] = data.train[0].size();
    let start = match &plan.resume {
        Some(file) => Some(checkpoint::load::<F, M>(file)?.start),
        None => None,
    };
    if !args.json {
        let from = match (&plan.resume, &start) {
            (Some(file), Some(s)) => format!(", from step {} of {}", s.training.step, file.display()),
            _ => String::new(),
        };
        eprintln!(
            "fogray fit: {} training and {} held-out views of {w}x{h}{from}; Ctrl-C stops and saves",
            data.train.len(),
            data.test.len()
        );
    }
    let result = fit_from::<F, M>(data, settings, start, Some(stop.flag()), &mut progress)?;
    bar.finish_and_clear();
    let save_path = match (&args.save_model, result.interrupted) {
        (Some(p), _) => Some(p.clone()),
        (None, true) => Some(match &args.out {
            Some(dir) => dir.join("fogray-model.safetensors"),
            None => PathBuf::from("fogray-model.safetensors"),
        }),
        (None, false) => None,
    };
    if let Some(path) = &save_path {
        checkpoint::save(path, &result.model, &result.training, settings, &entries(plan)?)?;
    }
    if let (true, Some(path)) = (result.interrupted, save_path) {
        return Ok(FitOutcome::Interrupted(path));
    }
    let held_out = held_out_views(&result, data, settings)?;
    // Each held-out view scored once: its row, and the mean of the views' PSNRs.
    let scores = view_scores(
        &result.renders.iter().map(|r| r.view()).collect::<Vec<_>>(),
        &data.test.iter().map(|t| t.image.view()).collect::<Vec<_>>(),
    )?;
    let summary = FitSummary {
        held_out_haze: haze_fraction(
            &held_out.iter().map(|v| v.opacity.view()).collect::<Vec<_>>(),
            0.05,
            0.95,
        ),
        peak_resident_bytes: crate::memory::peak_resident_bytes(),
        final_test_psnr_view_mean: mean_psnr(&scores),
        held_out_views: scores
            .into_iter()
            .zip(&data.test)
            .map(|(score, t)| HeldOutScore {
                name: t.name.clone(),
                score,
            })
            .collect(),
        final_test_psnr: result.final_test_psnr,
        final_test_ssim: result.final_test_ssim,
        train_views_psnr: result.training_views_psnr(data, settings)?,
        seconds: result.seconds,
        steps: result.training.step,
        log: &result.log,
        views: [data.train.len(), data.test.len()],
        size: [h, w],
        load_seconds,
        profile: result.profile.table(),
        parameters: result
            .model
            .params()
            .ids()
            .filter_map(|id| result.model.params().get(id).ok())
            .map(|v| v.len())
            .sum(),
    };
    if let Some(dir) = &args.out {
        crate::fit_report::write_out(dir, plan, settings, data, &result, &held_out, &summary)?;
    }
    if args.json {
        return Ok(FitOutcome::Done(serde_json::to_string(&summary)?));
    }
    let mut text = String::from("step      seconds  train loss  test PSNR (dB)  test SSIM\n");
    for e in &result.log {
        text += &format!(
            "{:>6} {:>10.1} {:>11.3e} {:>15.2} {:>10.4}\n",
            e.step, e.seconds, e.train_loss, e.test_psnr, e.test_ssim
        );
    }
    text += &format!(
        "final test PSNR {:.2} dB (mean of the views' {:.2}), SSIM {:.4}, over {} held-out views after {:.1} s ({} steps); {:.2} dB on as many training views",
        result.final_test_psnr,
        summary.final_test_psnr_view_mean,
        result.final_test_ssim,
        data.test.len(),
        result.seconds,
        result.training.step,
        summary.train_views_psnr
    );
    Ok(FitOutcome::Done(text))
}

/// The fitted model's held-out views rendered with their opacity and depth (off the clock).
fn held_out_views<F: Float, M: RadianceField<F>>(
    result: &FitResult<F, M>,
    data: &Dataset,
    settings: &FitSettings,
) -> Result<Vec<RenderedView>, CliError> {
    let options = RenderOptions {
        background: data.background,
        method: settings.method,
        depth: true,
    };
    let mut views = Vec::new();
    for t in &data.test {
        let (origins, directions) = t.rays();
        let view = render_picture(
            &result.model,
            result.occupancy.as_ref(),
            &origins,
            &directions,
            t.size(),
            &options,
        )?;
        views.push(view);
    }
    Ok(views)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_budget_of_seconds_grows_to_the_finer_lattice() {
        assert_eq!(long_fit_grid(Budget::Seconds(60.0)), None);
        assert_eq!(long_fit_grid(Budget::Seconds(LONG_FIT_SECONDS - 1e-9)), None);
        assert_eq!(long_fit_grid(Budget::Seconds(LONG_FIT_SECONDS)), Some(192));
        assert_eq!(long_fit_grid(Budget::Seconds(300.0)), Some(192));
        // Steps say nothing of time.
        assert_eq!(long_fit_grid(Budget::Steps(1_000_000)), None);
        // The help states the same three numbers.
        let said = format!(
            "unless given, {RECOMMENDED_GRID}, or {RECOMMENDED_GRID_LONG} for --seconds {LONG_FIT_SECONDS} and more"
        );
        assert!(GRID_HELP.ends_with(&said), "{GRID_HELP:?} against {said:?}");
    }
}
