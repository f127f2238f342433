//! `fogray fit`: a dataset on disk (Blender, instant-ngp or nerfstudio) fitted with the
//! recommended model and settings; the held-out views measured at intervals off the clock.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use fogray_data::{LoadOptions, SceneData};
use fogray_fit::checkpoint;
use fogray_fit::dataset::{Dataset, View};
use fogray_fit::metrics::{haze_fraction, ViewScore};
use fogray_fit::profile::ProfileTable;
use fogray_fit::session::{self, FitReport, SessionOutcome, SessionPlan};
use fogray_fit::settings::{FitSettings, SceneBox};
use fogray_fit::space::SpaceDecision;
use fogray_fit::train::LogEntry;
use serde::Serialize;

use crate::error::CliError;

/// The value of the setting `field` (its name in [`FitSettings`]) in
/// [`FitSettings::RECOMMENDED`], as a flag's default on the command line.
///
/// Panics: a name that is not a field of [`FitSettings`] (a programming error, caught by the
/// test of the flags' defaults).
pub fn recommended(field: &str) -> &'static str {
    let settings = serde_json::to_value(FitSettings::RECOMMENDED).expect("settings are plain values");
    let text = match &settings[field] {
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Null => panic!("FitSettings has no recommended {field:?}"),
        other => other.to_string(),
    };
    // Read once each at start-up, for the life of the process.
    Box::leak(text.into_boxed_str())
}

/// `fogray fit --grid`'s help, which says how its default depends on the budget.
pub const GRID_HELP: &str =
    "Nodes per axis of the grid (of its last growth stage); unless given, 128, or 192 for --seconds 150 and more";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flags_defaults_are_the_recommended_settings_and_the_help_says_the_grid_rule() {
        assert_eq!(recommended("model"), "sparse");
        assert_eq!(recommended("grid"), "128");
        assert_eq!(recommended("lr").parse::<f64>().unwrap(), FitSettings::RECOMMENDED.lr);
        assert_eq!(recommended("tv").parse::<f64>().unwrap(), 0.0);
        assert_eq!(recommended("space"), "auto");
        let said = format!(
            "unless given, {}, or {} for --seconds {} and more",
            FitSettings::RECOMMENDED.grid,
            FitSettings::RECOMMENDED_GRID_LONG,
            FitSettings::LONG_FIT_SECONDS
        );
        assert!(GRID_HELP.ends_with(&said), "{GRID_HELP:?} against {said:?}");
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
            copy_float_bytes: 0,
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
    /// nerfstudio folder (transforms.json), a COLMAP folder (sparse/0), an LLFF folder
    /// (poses_bounds.npy), or a transforms file. Resuming, the saved fit's unless given.
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
    /// Write the fitted model here: safetensors for a grid (`fogray render --model` reads it),
    /// the PLY file 3DGS viewers open for `--model splats`.
    #[arg(long, value_name = "FILE")]
    pub save_model: Option<PathBuf>,
    /// Write a report into this directory: report.md (the final figures, PSNR and SSIM
    /// against training seconds, each held-out view beside its photograph, the settings, the
    /// machine and the command), `test/<name>.png`, psnr.png, ssim.png and fit.json.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print {"final_test_psnr", "seconds", "steps", "log": [...]} on stdout instead of a
    /// table (and no progress bar).
    #[arg(long)]
    pub json: bool,
    /// Serve a page on 127.0.0.1 showing the model as it trains (turned with the mouse, as
    /// `fogray view` shows a saved one), the held-out PSNR so far and the step; its address
    /// is printed on stderr. After the fit, the page shows the final model until Ctrl-C.
    #[arg(long)]
    pub view: bool,
    /// The port of the --view page; 0 lets the system choose a free one.
    #[arg(long, value_name = "N", default_value_t = 0, requires = "view")]
    pub view_port: u16,
    #[command(flatten)]
    pub settings: FitSettings,
}

/// What `fogray fit --json` prints.
#[derive(Debug, Serialize)]
pub struct FitSummary<'a> {
    /// PSNR (dB) over all held-out views at the end: of the mean squared error over them.
    pub final_test_psnr: f64,
    /// The mean of the held-out views' own PSNRs (dB) at the end: the figure the NeRF
    /// literature and nerfstudio report; never below `final_test_psnr` for views of one size.
    pub final_test_psnr_view_mean: f64,
    /// SSIM (Gaussian window 11, sigma 1.5) over the held-out views at the end; null for views
    /// smaller than its window.
    pub final_test_ssim: f64,
    /// PSNR (dB) at the end over as many training views as there are held-out ones, spread
    /// through the training list: its gap to `final_test_psnr` is how much better the fit
    /// reproduces its own views than new ones.
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
    /// The space the field was fitted in (`box` or `contracted`, with the inner region), and
    /// why.
    pub space: &'a SpaceDecision,
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
    /// The fit ended and its output was printed then; its `--view` page served on until Ctrl-C.
    Served,
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
/// `data_args` names) and the box the dataset gives its scene; with `progress`, the pictures
/// decoded are counted on a bar on stderr ([`crate::load_bar`]).
///
/// Errors: a bad dataset, naming the file.
pub fn load_fit_data(path: &Path, data_args: &DataArgs, progress: bool) -> Result<(Dataset, SceneBox), CliError> {
    // The views widen every frame to f64 ([`views`]): counted before any frame is copied.
    let options = LoadOptions {
        copy_float_bytes: std::mem::size_of::<f64>(),
        ..data_args.options()
    };
    let scene: SceneData = crate::load_bar::load_showing_progress(path, &options, progress)?;
    if scene.skipped > 0 {
        eprintln!(
            "fogray fit: --skip-missing dropped {} frames whose image is missing",
            scene.skipped
        );
    }
    if scene.images != fogray_data::ImageSource::Listed {
        eprintln!("fogray fit: {} ({:?} format)", scene.images, scene.format);
    }
    if scene.unregistered > 0 {
        eprintln!(
            "fogray fit: {} pictures in the images folder are not in the capture's model and were left out",
            scene.unregistered
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
/// `id` was given on the command line. A fresh fit of a long budget grows to the finer lattice
/// unless `--grid` is given ([`FitSettings::recommended_grid`]); a resumed one keeps the
/// file's lattice.
///
/// Errors: a model file that cannot be read or that another lattice or precision was asked
/// of, a saved dataset entry that cannot be read (naming the file).
pub fn plan(args: &FitArgs, given: &dyn Fn(&str) -> bool) -> Result<FitPlan, CliError> {
    let Some(file) = &args.resume else {
        let data = args.data.clone().ok_or(CliError::MissingFlag {
            give: "--data PATH, or --resume FILE",
        })?;
        let mut settings = args.settings;
        if !given("grid") {
            settings.grid = FitSettings::recommended_grid(settings.budget());
        }
        return Ok(FitPlan {
            data,
            data_args: args.data_args.clone(),
            settings,
            resume: None,
        });
    };
    let (settings, info) = session::resume_settings(file, &args.settings, given)?;
    let entry = |key: &'static str| {
        info.extra.get(key).ok_or_else(|| CliError::NoSavedEntry {
            path: file.clone(),
            key,
        })
    };
    let unreadable = |key: &'static str, text: &str, reason: &dyn std::fmt::Display| CliError::SavedEntry {
        path: file.clone(),
        key,
        text: text.to_string(),
        reason: reason.to_string(),
    };
    let data = match &args.data {
        Some(path) => path.clone(),
        None => PathBuf::from(entry("data")?),
    };
    let mut data_args = args.data_args.clone();
    if !given("downscale") {
        let text = entry("downscale")?;
        data_args.downscale = text.parse().map_err(|e| unreadable("downscale", text, &e))?;
    }
    if !given("background") {
        let text = entry("background")?;
        data_args.background = serde_json::from_str(text).map_err(|e| unreadable("background", text, &e))?;
    }
    Ok(FitPlan {
        data,
        data_args,
        settings,
        resume: Some(file.clone()),
    })
}

/// Runs `fogray fit`, where `given(id)` says whether the flag of clap id `id` was given on the
/// command line ([`plan`]): the dataset loaded, a [`session`] run, the summary printed and the
/// report written.
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
    // Before anything is read or trained: no output may be an input or collide with the
    // dataset (a report's test/ folder over the dataset's own held-out pictures).
    let mut inputs = fogray_data::Inputs::new().dataset(&plan.data)?;
    if let Some(file) = &plan.resume {
        if args.save_model.as_deref() != Some(file.as_path()) {
            inputs = inputs.file(file);
        }
    }
    fogray_data::plan_fit_outputs(
        &inputs,
        args.save_model.as_deref(),
        args.out.as_deref(),
        &crate::fit_report::REPORT_FOLDERS,
    )?;
    // Before anything is read: the outputs' disks have room for the least they will take.
    crate::disk_room::check(&outputs(args, &plan.settings), crate::disk_room::room)?;
    // Before anything is read: a port in use fails at once.
    let page = if args.view {
        if plan.settings.model == fogray_fit::settings::ModelKind::Splats {
            return Err(CliError::FlagsExclude {
                first: "--view",
                second: "--model splats",
                why: "the page shows a grid as it trains (--model dense or sparse)",
            });
        }
        Some(crate::view::live::LivePage::bind(args.view_port)?)
    } else {
        None
    };
    // The same rule as the training bar's: --json asks for a quiet run.
    let (data, scene_box) = load_fit_data(&plan.data, &plan.data_args, !args.json)?;
    let settings = FitSettings {
        scene_box: Some(plan.settings.scene_box.unwrap_or(scene_box)),
        ..plan.settings
    };
    // Removed again (while empty) if the fit fails: a failed fit leaves no empty folder.
    let mut created = crate::created_dirs::CreatedDirs::new();
    if let Some(dir) = &args.out {
        created.create(dir)?;
        for sub in crate::fit_report::REPORT_FOLDERS {
            created.create(&dir.join(sub))?;
        }
    }
    let load_seconds = clock.elapsed().as_secs_f64();
    let name = "fogray-model.safetensors";
    let session_plan = SessionPlan {
        settings,
        resume: plan.resume.clone(),
        save_model: args.save_model.clone(),
        save_on_interrupt: args
            .out
            .as_ref()
            .map_or_else(|| PathBuf::from(name), |dir| dir.join(name)),
        entries: entries(&plan)?,
        tool: "fogray fit".into(),
        progress_bar: !args.json,
        announce: !args.json,
        live: None,
    };
    let Some(page) = page else {
        let outcome = session::run(&data, &session_plan)?;
        return finish(args, &plan, &data, outcome, load_seconds, created);
    };
    let entries = session_plan.entries.clone();
    page.serve(&data, &settings, &entries, |hook| {
        let live_plan = SessionPlan {
            live: Some(hook),
            ..session_plan
        };
        let outcome = session::run(&data, &live_plan)?;
        match finish(args, &plan, &data, outcome, load_seconds, created)? {
            FitOutcome::Done(text) => {
                // Printed now: the page serves on until Ctrl-C.
                let mut out = std::io::stdout().lock();
                let _ = writeln!(out, "{text}").and_then(|()| out.flush());
                eprintln!("fogray fit: the fit is done; its page shows the final model until Ctrl-C");
                Ok((FitOutcome::Served, true))
            }
            other => Ok((other, false)),
        }
    })
}

/// The output of a fit whose session ended with `outcome`: the report written, the text to
/// print; an interrupted fit's saved file.
///
/// Errors: a report that cannot be written.
fn finish(
    args: &FitArgs,
    plan: &FitPlan,
    data: &Dataset,
    outcome: SessionOutcome,
    load_seconds: f64,
    created: crate::created_dirs::CreatedDirs,
) -> Result<FitOutcome, CliError> {
    let report = match outcome {
        SessionOutcome::Interrupted { saved, .. } => {
            created.keep();
            return Ok(FitOutcome::Interrupted(saved));
        }
        SessionOutcome::Finished(report) => report,
    };
    let summary = summary(&report, data, load_seconds);
    if let Some(dir) = &args.out {
        crate::fit_report::write_out(dir, plan, &report.settings, data, &summary, &report.held_out)?;
    }
    created.keep();
    if args.json {
        return Ok(FitOutcome::Done(serde_json::to_string(&summary)?));
    }
    let mut text = format!("space: {} ({})\n", report.space.space, report.space.why);
    text += "step      seconds  train loss  test PSNR (dB)  test SSIM\n";
    for e in &report.log {
        text += &format!(
            "{:>6} {:>10.1} {:>11.3e} {:>15.2} {:>10.4}\n",
            e.step, e.seconds, e.train_loss, e.test_psnr, e.test_ssim
        );
    }
    text += &format!(
        "final test PSNR {:.2} dB (mean of the views' {:.2}), SSIM {:.4}, over {} held-out views after {:.1} s ({} steps); {:.2} dB on as many training views",
        report.final_test_psnr,
        report.final_test_psnr_view_mean,
        report.final_test_ssim,
        data.test.len(),
        report.seconds,
        report.steps,
        report.train_views_psnr
    );
    Ok(FitOutcome::Done(text))
}

/// What a fit with `args` and `settings` will write, each with the fewest bytes it takes: the
/// model file ([`FitSettings::model_file_floor`]) and the report (of one held-out view, the
/// fewest a fit has: [`crate::fit_report::report_floor`]).
pub fn outputs(args: &FitArgs, settings: &FitSettings) -> Vec<crate::disk_room::Output> {
    let model = args.save_model.iter().map(|path| crate::disk_room::Output {
        path: path.clone(),
        what: "the model file",
        floor: settings.model_file_floor(),
    });
    let report = args.out.iter().map(|dir| crate::disk_room::Output {
        path: dir.clone(),
        what: "the report",
        floor: crate::fit_report::report_floor(1),
    });
    model.chain(report).collect()
}

/// What `fogray fit --json` prints and `--out` keeps, from the session's report; `load_seconds`
/// is the time before the session started (reading and decoding).
fn summary<'a>(report: &'a FitReport, data: &Dataset, load_seconds: f64) -> FitSummary<'a> {
    let [h, w] = data.train[0].size();
    FitSummary {
        held_out_haze: haze_fraction(
            &report.held_out.iter().map(|v| v.opacity.view()).collect::<Vec<_>>(),
            0.05,
            0.95,
        ),
        peak_resident_bytes: crate::memory::peak_resident_bytes(),
        final_test_psnr_view_mean: report.final_test_psnr_view_mean,
        held_out_views: report
            .view_scores
            .iter()
            .zip(&data.test)
            .map(|(score, t)| HeldOutScore {
                name: t.name.clone(),
                score: *score,
            })
            .collect(),
        final_test_psnr: report.final_test_psnr,
        final_test_ssim: report.final_test_ssim,
        train_views_psnr: report.train_views_psnr,
        seconds: report.seconds,
        steps: report.steps,
        log: &report.log,
        views: [data.train.len(), data.test.len()],
        size: [h, w],
        load_seconds,
        profile: report.profile.clone(),
        parameters: report.parameters,
        space: &report.space,
    }
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
