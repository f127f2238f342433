//! `fogray-grid`: exact photographs of a scene of constant-density primitives, for fitting a
//! grid of density and colour to them.
//!
//! Bad input (a bad flag or scene file, a zero count) exits with status 2 and one line on
//! stderr; scripts outside this crate rely on the flags and the JSON as they are.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::parser::ValueSource;
use clap::{ArgMatches, Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use serde::Serialize;

use fogray::fit::checkpoint::{self, ModelInfo};
use fogray::fit::dataset::Dataset;
use fogray::fit::depth::write_depth_png;
use fogray::fit::dispatch::{with_field, FieldWork};
use fogray::fit::images::{nested, write_comparison_png, write_png};
use fogray::fit::metrics::psnr;
use fogray::fit::plots;
use fogray::fit::render::{render_picture, RenderOptions};
use fogray::fit::session::{self, FitReport, SessionOutcome, SessionPlan};
use fogray::fit::settings::{FitSettings, ModelKind};
use fogray::fit::train::Progress;
use fogray::fit::RadianceField;
use fogray_grid::capture::{self, CaptureSettings};
use fogray_grid::photographs::{photograph, photographs};
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_grid::views::dataset;

#[derive(Parser)]
#[command(
    name = "fogray-grid",
    version,
    about = "Exact photographs of a scene of constant-density spheres and boxes, seen by a ring of cameras",
    long_about = "A scene of constant-density spheres and boxes inside [-1, 1]^3 (densities add where they overlap, colours mix by density) is photographed exactly: along a ray the medium is piecewise constant, so compositing its pieces is the emission-absorption integral itself; each pixel is the mean of 4 x 4 such rays across its area. The cameras sit on a Fibonacci lattice over the sphere of radius 3, look at the origin with a 40 degree field of view, and every e-th view (e = (V + T) / T) is held out for testing."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Where the scene comes from.
#[derive(Args)]
struct SceneArg {
    /// Scene file (JSON); the built-in scene (see `fogray-grid scene`) if absent.
    #[arg(long)]
    scene: Option<PathBuf>,
}

impl SceneArg {
    fn load(&self) -> Result<Scene> {
        Ok(match &self.scene {
            Some(path) => Scene::read(path)?,
            None => Scene::default(),
        })
    }
}

/// The cameras.
#[derive(Args, Clone, Copy)]
struct RingArgs {
    /// Training views.
    #[arg(long, default_value_t = 32)]
    views: usize,
    /// Held-out test views (view i is one when i mod e == e / 2, e = (views + test-views) /
    /// test-views).
    #[arg(long, default_value_t = 4)]
    test_views: usize,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 64)]
    size: usize,
}

impl RingArgs {
    fn ring(&self) -> Result<Ring> {
        Ok(Ring::new(self.views, self.test_views, self.size)?)
    }

    /// The cameras as a checkpoint's entries.
    fn entries(&self) -> BTreeMap<String, String> {
        [
            ("views", self.views),
            ("test_views", self.test_views),
            ("size", self.size),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
    }

    /// The cameras saved in a checkpoint's entries.
    fn saved(extra: &BTreeMap<String, String>, path: &Path) -> Result<RingArgs> {
        let read = |key: &str| -> Result<usize> {
            extra
                .get(key)
                .and_then(|v| v.parse().ok())
                .with_context(|| format!("{} is not a fogray-grid model: no camera entry {key:?}", path.display()))
        };
        Ok(RingArgs {
            views: read("views")?,
            test_views: read("test_views")?,
            size: read("size")?,
        })
    }
}

#[derive(Subcommand)]
enum Command {
    /// The exact photographs of all views, training and test, in view order. With --json,
    /// prints {"images": [view][row][column][channel]}; with --out, writes view-NNN.png there.
    Photographs {
        #[command(flatten)]
        scene: SceneArg,
        #[command(flatten)]
        ring: RingArgs,
        /// Print the images as JSON instead of a summary.
        #[arg(long)]
        json: bool,
        /// Directory for one PNG per view (created if missing).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Writes a phone-like capture of the scene as an instant-ngp dataset in --out
    /// (transforms.json and images/frame_NNNN.png): a hand-held walk once around it through a
    /// distorted, off-centre lens, with the scene standing in a painted room beyond the box and
    /// no alpha. Each picture is exact for its lens. Fit it with `fogray fit --data DIR
    /// --learn-background`.
    Capture {
        #[command(flatten)]
        scene: SceneArg,
        #[command(flatten)]
        settings: CaptureSettings,
        /// The folder to write (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// Fits a dense grid of density and colour to the training views' exact photographs
    /// (Adam on random batches of rays), measuring the test PSNR on the held-out views.
    Fit(FitArgs),
    /// Renders views of the ring from a model saved by `fit --save-model`: per view, the exact
    /// photograph, the render and |render - exact| x 4 (view-NNN.png) and the expected depth
    /// (depth-NNN.png), and the PSNR of the render against the photograph.
    Render(RenderArgs),
    /// The speed-against-error report: fits each configuration in turn for the same budget and
    /// writes test PSNR against training time (psnr-vs-seconds.svg/.png, psnr-vs-steps.svg/.png),
    /// report.md, report.json and pictures of the best configuration's model into --out. Fused
    /// against taped is timed over the same steps: with a budget of seconds, each pair of twins
    /// trains again for the steps the taped run made. The runs are timed: run it on a quiet
    /// machine.
    Report(ReportArgs),
    /// Writes the built-in scene as JSON, to edit and pass back with --scene.
    Scene {
        /// File to write; stdout if absent.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(Args)]
struct FitArgs {
    #[command(flatten)]
    scene: SceneArg,
    #[command(flatten)]
    ring: RingArgs,
    #[command(flatten)]
    settings: FitSettings,
    /// Print one JSON object (the log and the final figures) instead of text.
    #[arg(long)]
    json: bool,
    /// Also print where the training time went, in milliseconds a step: each phase of a step
    /// and the tape's ops, forward and backward (with --json, as "profile").
    #[arg(long)]
    profile: bool,
    /// Directory for the pictures: each test view's photograph, render and |error| x 4
    /// (test-view-NNN.png), and test PSNR against training seconds (psnr.svg, psnr.png).
    #[arg(long)]
    out: Option<PathBuf>,
    /// File for the final renders of the test views as {"images": [view][row][column][channel]}.
    #[arg(long)]
    save_renders: Option<PathBuf>,
    /// Safetensors file for the model and the fit's state (Adam's moments, step, seconds, batch
    /// stream), written at the end or on Ctrl-C.
    #[arg(long, value_name = "FILE")]
    save_model: Option<PathBuf>,
    /// Continue the fit saved in FILE. --steps / --seconds are the total budget, the saved
    /// steps / seconds included (the saved budget if neither is given). --grid and --precision
    /// must match the file's; every other setting, the scene and the cameras are the file's
    /// unless given.
    #[arg(long, value_name = "FILE")]
    resume: Option<PathBuf>,
}

#[derive(Args)]
struct RenderArgs {
    /// Model file written by `fit --save-model`.
    #[arg(long, value_name = "FILE")]
    model: PathBuf,
    /// Scene file for the exact photographs; the scene saved in the model file if absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Training views of the ring; the fit's (saved in the model file) if absent.
    #[arg(long)]
    views: Option<usize>,
    /// Held-out test views of the ring; the fit's if absent.
    #[arg(long)]
    test_views: Option<usize>,
    /// Image width and height in pixels; the fit's if absent.
    #[arg(long)]
    size: Option<usize>,
    /// A view to render (repeat for several); the ring's test views if neither --view nor --all.
    #[arg(long = "view", value_name = "I")]
    view: Vec<usize>,
    /// Render every view of the ring.
    #[arg(long, conflicts_with = "view")]
    all: bool,
    /// Directory for the PNGs (created if missing).
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Print the renders as {"images": [view][row][column][channel], "views": [...], "psnr":
    /// [...]} instead of a summary.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct ReportArgs {
    #[command(flatten)]
    scene: SceneArg,
    #[command(flatten)]
    ring: RingArgs,
    /// The settings every configuration trains with (the budget is each configuration's;
    /// --evaluations is 60 unless given, so that the time to a PSNR is read between close
    /// evaluations); --configs sets the method, the sampling and the precision.
    #[command(flatten)]
    settings: FitSettings,
    /// Configurations to run, in order, comma-separated: METHOD-SAMPLING[-PRECISION] with
    /// METHOD fused|taped, SAMPLING uniform|occupancy, PRECISION f32 (default)|f64.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "fused-uniform,taped-uniform,fused-occupancy,taped-occupancy"
    )]
    configs: Vec<String>,
    /// An outside pipeline's run of the same scene, cameras and test views, measured on the same
    /// machine, to compare with: JSON {"name": .., "note": .., "log": [{"seconds": .., "test_psnr": ..}, ..]}
    /// (note optional). Its curve joins a log-scaled plot, and each configuration's time to the
    /// anchor's final PSNR is set against the anchor's.
    #[arg(long, value_name = "FILE")]
    anchor: Option<PathBuf>,
    /// Directory for the report (created if missing).
    #[arg(long, default_value = "reports/grid")]
    out: PathBuf,
}

/// Test evaluations of each run of the report unless --evaluations is given.
const REPORT_EVALUATIONS: usize = 60;

fn run_report(args: ReportArgs, given: &dyn Fn(&str) -> bool) -> Result<()> {
    use fogray_grid::report::write::{write_report, MachineBandwidth, ReportSetup};
    use fogray_lab::curves::Anchor;
    use fogray_lab::sweep::{run_configs, same_steps, RunConfig, SweepOptions};
    /// Timed passes of each bandwidth measurement (the best is kept).
    const TRIAD_PASSES: usize = 5;

    let configs = args
        .configs
        .iter()
        .map(|c| c.parse::<RunConfig>())
        .collect::<Result<Vec<_>, _>>()?;
    let (scene, ring) = (args.scene.load()?, args.ring.ring()?);
    let anchor = args.anchor.as_deref().map(Anchor::read).transpose()?;
    if let Some(flag) = ["method", "sampling", "precision"].into_iter().find(|f| given(f)) {
        anyhow::bail!("--{flag} is set by --configs in a report");
    }
    let settings = FitSettings {
        evaluations: if given("evaluations") {
            args.settings.evaluations
        } else {
            REPORT_EVALUATIONS
        },
        ..args.settings
    };
    settings.check()?;
    let budget = settings.budget();
    let options = SweepOptions {
        fit: settings,
        configs,
        slice_pixels: 128,
    };
    // Before training, so that a bad directory costs nothing.
    create_dir(&args.out)?;
    let given: Vec<String> = std::env::args().skip(1).collect();
    let stamp = fogray_lab::stamp::Stamp::now(&format!("fogray-grid {}", given.join(" ")));
    let reproduce = format!("cargo run --release -p fogray-grid -- {}", given.join(" "));
    let data = dataset(&scene, &ring)?;
    let bar = indicatif::ProgressBar::new(1000);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{prefix} [{bar:40}] {msg} ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    let names: Vec<String> = options.configs.iter().map(|c| c.to_string()).collect();
    // One bar for every fit, restarted under a new label when the fit changes.
    let show = |label: String, p: Progress| {
        if bar.prefix() != label {
            bar.reset();
            bar.set_prefix(label);
        }
        bar.set_position((p.fraction * 1000.0) as u64);
        bar.set_message(format!("step {}", p.step));
    };
    // The machine's state around the timed runs (about a second each).
    let before = fogray_lab::machine::triad(TRIAD_PASSES);
    let runs = run_configs(&data, &options, &mut |i, p| {
        show(format!("{} ({}/{})", names[i], i + 1, names.len()), p)
    })?;
    // Fused against taped to the same PSNR: over the same steps (with a budget of seconds, a
    // second pair of runs; the bar names them).
    let pairs = same_steps(&data, &options, &runs, &mut |label, p| show(label.to_string(), p))?;
    bar.finish_and_clear();
    let bandwidth = MachineBandwidth {
        before,
        after: fogray_lab::machine::triad(TRIAD_PASSES),
    };
    let problem = format!(
        "A {g}^3 grid fitted from {v} exact photographs of {s} x {s} pixels of {scene}, judged on {t} held-out views; {b} rays per step, seed {seed}.",
        g = settings.grid,
        v = args.ring.views,
        s = args.ring.size,
        scene = match &args.scene.scene {
            Some(path) => format!("the scene {}", path.display()),
            None => "the built-in scene".into(),
        },
        t = data.test.len(),
        b = settings.batch,
        seed = settings.seed,
    );
    let setup = ReportSetup {
        stamp: &stamp,
        reproduce: &reproduce,
        budget,
        batch: settings.batch,
        problem: &problem,
        evaluations: settings.evaluations,
        anchor: anchor.as_ref(),
        same_steps: &pairs,
        bandwidth: Some(bandwidth),
    };
    let md = write_report(&args.out, &runs, &data, &scene, &setup)?;
    for r in &runs {
        println!(
            "{:<22} final test PSNR {:.2} dB, {} steps in {:.1} s",
            r.name, r.final_test_psnr, r.steps, r.seconds
        );
    }
    for (name, pair) in &pairs {
        println!(
            "fused against taped, {name}, the same {} steps: {:.1} s (fused, the mean of its runs) against {:.1} s ({:.2} and {:.2} dB)",
            pair.steps,
            pair.fused_seconds(),
            pair.taped.seconds,
            pair.fused.final_test_psnr,
            pair.taped.final_test_psnr
        );
    }
    println!(
        "memory bandwidth (STREAM triad, {} threads): {:.1} GB/s before the runs, {:.1} GB/s after",
        bandwidth.before.threads,
        bandwidth.before.bytes_per_sec / 1e9,
        bandwidth.after.bytes_per_sec / 1e9
    );
    println!("written: {}", md.display());
    Ok(())
}

#[derive(Serialize)]
struct FitSummary<'a> {
    log: &'a [fogray::fit::train::LogEntry],
    final_test_psnr: f64,
    /// The mean of the held-out views' own PSNRs (the NeRF papers' convention), beside the
    /// PSNR of their pooled squared error.
    final_test_psnr_view_mean: f64,
    /// PSNR on as many training views as held-out ones (`training_views_psnr`).
    train_views_psnr: f64,
    seconds: f64,
    samples_per_ray_mean: f64,
    occupied_fraction: f64,
    /// With --profile.
    #[serde(skip_serializing_if = "Option::is_none")]
    profile: Option<fogray::fit::profile::ProfileTable>,
}

/// What a fit resumes from: the file and its metadata.
struct Resume {
    path: PathBuf,
    info: ModelInfo,
}

/// What a fit trains on, beside its settings: the scene and the cameras, as a checkpoint
/// keeps them.
struct Problem {
    scene: Scene,
    ring: RingArgs,
}

impl Problem {
    fn entries(&self) -> BTreeMap<String, String> {
        let mut m = self.ring.entries();
        m.insert("scene".into(), self.scene.to_json_pretty());
        m
    }
}

fn run_fit(args: FitArgs, given: &dyn Fn(&str) -> bool) -> Result<()> {
    let resume = match &args.resume {
        Some(path) => Some(Resume {
            path: path.clone(),
            info: checkpoint::read_info(path)?,
        }),
        None => None,
    };
    let (settings, problem) = match &resume {
        None => (
            args.settings,
            Problem {
                scene: args.scene.load()?,
                ring: args.ring,
            },
        ),
        Some(r) => resumed_settings(&args, r, given)?,
    };
    settings.check()?;
    let ring = problem.ring.ring()?;
    // Before training, so that a bad directory costs nothing.
    if let Some(dir) = &args.out {
        create_dir(dir)?;
    }
    let data = dataset(&problem.scene, &ring)?;
    let plan = SessionPlan {
        settings,
        resume: args.resume.clone(),
        save_model: args.save_model.clone(),
        save_on_interrupt: default_model_path(&args),
        entries: problem.entries(),
        tool: "fogray-grid".into(),
        progress_bar: !args.json,
        announce: true,
    };
    match session::run(&data, &plan)? {
        SessionOutcome::Interrupted { step, saved } => {
            eprintln!(
                "fogray-grid: interrupted after step {step}: the fit is saved to {} (continue it with --resume)",
                saved.display()
            );
            std::process::exit(session::INTERRUPTED_EXIT.into());
        }
        SessionOutcome::Finished(report) => report_fit(&args, &settings, &data, &report),
    }
}

/// A resumed fit's settings, scene and cameras: the file's, except those given on the command
/// line; --grid and --precision, if given, must be the file's.
fn resumed_settings(args: &FitArgs, resume: &Resume, given: &dyn Fn(&str) -> bool) -> Result<(FitSettings, Problem)> {
    let (settings, _) = session::resume_settings(&resume.path, &args.settings, given)?;
    let extra = &resume.info.extra;
    let file_ring = RingArgs::saved(extra, &resume.path)?;
    let ring = RingArgs {
        views: if given("views") {
            args.ring.views
        } else {
            file_ring.views
        },
        test_views: if given("test_views") {
            args.ring.test_views
        } else {
            file_ring.test_views
        },
        size: if given("size") { args.ring.size } else { file_ring.size },
    };
    let scene = if given("scene") {
        args.scene.load()?
    } else {
        saved_scene(extra, &resume.path)?
    };
    Ok((settings, Problem { scene, ring }))
}

/// The scene saved in a checkpoint's entries.
fn saved_scene(extra: &BTreeMap<String, String>, path: &Path) -> Result<Scene> {
    let text = extra
        .get("scene")
        .with_context(|| format!("{} is not a fogray-grid model: no scene", path.display()))?;
    Scene::from_json(text).with_context(|| format!("{}: the saved scene", path.display()))
}

/// Where an interrupted fit is saved without --save-model.
fn default_model_path(args: &FitArgs) -> PathBuf {
    let name = "fogray-grid-model.safetensors";
    match &args.out {
        Some(dir) => dir.join(name),
        None => PathBuf::from(name),
    }
}

fn report_fit(args: &FitArgs, settings: &FitSettings, data: &Dataset, report: &FitReport) -> Result<()> {
    if let Some(file) = &args.save_renders {
        let images = Images {
            images: report.held_out.iter().map(|v| nested(v.color.view())).collect(),
        };
        let text = serde_json::to_string(&images)?;
        // Whole or not at all, as every fogray writer.
        fogray_data::write_atomic(file, |w| w.write_all(text.as_bytes()))
            .with_context(|| format!("cannot write {}", file.display()))?;
    }
    if let Some(dir) = &args.out {
        for (t, render) in data.test.iter().zip(&report.held_out) {
            let path = dir.join(format!("test-view-{}.png", t.name));
            write_comparison_png(&path, t.image.view(), render.color.view(), 4.0, 4)?;
        }
        let label = format!(
            "{} {} {}",
            settings.method.name(),
            settings.precision.name(),
            settings.sampling.name()
        );
        plots::psnr_curves(
            &dir.join("psnr"),
            &[plots::Curve {
                label,
                log: &report.log,
            }],
        )?;
    }
    let summary = FitSummary {
        log: &report.log,
        final_test_psnr: report.final_test_psnr,
        final_test_psnr_view_mean: report.final_test_psnr_view_mean,
        train_views_psnr: report.train_views_psnr,
        seconds: report.seconds,
        samples_per_ray_mean: report.samples_per_ray_mean,
        occupied_fraction: report.occupied_fraction,
        profile: args.profile.then(|| report.profile.clone()),
    };
    if args.json {
        return write_stdout(|w| Ok(serde_json::to_writer(w, &summary)?));
    }
    for e in &report.log {
        // Before the first step there is no training loss (NaN in the log, null in JSON).
        let loss = if e.train_loss.is_nan() {
            "-".to_string()
        } else {
            format!("{:.3e}", e.train_loss)
        };
        println!(
            "step {:>6}  {:>8.2} s  train loss {loss:>9}  test PSNR {:.2} dB",
            e.step, e.seconds, e.test_psnr
        );
    }
    println!(
        "final test PSNR {:.2} dB (mean of the views' {:.2}; {:.2} on as many training views) after {:.1} s of training; {:.1} samples per ray; {:.1} % of cells occupied",
        report.final_test_psnr,
        summary.final_test_psnr_view_mean,
        summary.train_views_psnr,
        report.seconds,
        report.samples_per_ray_mean,
        100.0 * report.occupied_fraction
    );
    if let Some(table) = &summary.profile {
        print!("{table}");
    }
    Ok(())
}

#[derive(Serialize)]
struct Images {
    images: Vec<Vec<Vec<Vec<f64>>>>,
}

fn write_stdout(f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    f(&mut out)?;
    out.flush().context("cannot write to stdout")
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
}

fn run(cli: Cli, matches: &ArgMatches) -> Result<()> {
    match cli.command {
        Command::Photographs { scene, ring, json, out } => {
            let (scene, ring) = (scene.load()?, ring.ring()?);
            let images = photographs(&scene, &ring)?;
            let mut written = Vec::new();
            if let Some(dir) = &out {
                create_dir(dir)?;
                for (i, image) in images.iter().enumerate() {
                    let path = dir.join(format!("view-{i:03}.png"));
                    write_png(&path, image.view())?;
                    written.push(path);
                }
            }
            if json {
                let images = Images {
                    images: images.iter().map(|im| nested(im.view())).collect(),
                };
                return write_stdout(|w| Ok(serde_json::to_writer(w, &images)?));
            }
            let test: Vec<String> = ring.test_views().iter().map(|i| i.to_string()).collect();
            println!(
                "{} views of {s} x {s} pixels; test views: {}",
                ring.len(),
                if test.is_empty() {
                    "none".into()
                } else {
                    test.join(", ")
                },
                s = ring.size()
            );
            if let (Some(dir), Some(last)) = (&out, written.last()) {
                println!("written: {}/view-000.png .. {}", dir.display(), last.display());
            }
        }
        Command::Capture { scene, settings, out } => {
            let scene = scene.load()?;
            let cams = capture::cameras(&settings)?;
            let pictures: Vec<_> = cams
                .iter()
                .map(|c| capture::capture_photograph(&scene, c, settings.room_radius))
                .collect();
            let names: Vec<String> = (0..cams.len()).map(capture::frame_name).collect();
            let frames: Vec<_> = names
                .iter()
                .zip(&cams)
                .zip(&pictures)
                .map(|((n, c), p)| (n.as_str(), c, p))
                .collect();
            let transforms = fogray_data::write_instant_ngp(&out, &frames)?;
            println!(
                "{} views of {} x {} pixels written: {}",
                settings.views,
                settings.width,
                settings.height,
                transforms.display()
            );
        }
        Command::Fit(args) => {
            let fit = matches.subcommand_matches("fit");
            let given = |id: &str| fit.and_then(|m| m.value_source(id)) == Some(ValueSource::CommandLine);
            run_fit(args, &given)?
        }
        Command::Render(args) => run_render(args)?,
        Command::Report(args) => {
            let report = matches.subcommand_matches("report");
            let given = |id: &str| report.and_then(|m| m.value_source(id)) == Some(ValueSource::CommandLine);
            run_report(args, &given)?
        }
        Command::Scene { out } => {
            let text = Scene::default().to_json_pretty() + "\n";
            match out {
                Some(path) => fogray_data::write_atomic(&path, |w| w.write_all(text.as_bytes()))
                    .with_context(|| format!("cannot write {}", path.display()))?,
                None => write_stdout(|w| Ok(w.write_all(text.as_bytes())?))?,
            }
        }
    }
    Ok(())
}

#[derive(Serialize)]
struct RenderSummary {
    images: Vec<Vec<Vec<Vec<f64>>>>,
    views: Vec<usize>,
    psnr: Vec<f64>,
}

fn run_render(args: RenderArgs) -> Result<()> {
    let info = checkpoint::read_info(&args.model)?;
    let saved_ring = RingArgs::saved(&info.extra, &args.model)?;
    let ring = RingArgs {
        views: args.views.unwrap_or(saved_ring.views),
        test_views: args.test_views.unwrap_or(saved_ring.test_views),
        size: args.size.unwrap_or(saved_ring.size),
    }
    .ring()?;
    let scene = match &args.scene {
        Some(path) => Scene::read(path)?,
        None => saved_scene(&info.extra, &args.model)?,
    };
    let views = if args.all {
        (0..ring.len()).collect()
    } else if args.view.is_empty() {
        ring.test_views()
    } else {
        args.view.clone()
    };
    if let Some(&bad) = views.iter().find(|&&v| v >= ring.len()) {
        anyhow::bail!(
            "--view {bad} is out of range: the ring has views 0 to {}",
            ring.len() - 1
        );
    }
    if views.is_empty() {
        anyhow::bail!("no view to render: the ring has no test views; pass --view I or --all");
    }
    let kind = ModelKind::of_kind(&info.kind)
        .and_then(ModelKind::field)
        .with_context(|| {
            format!(
                "{}: a {:?} model, which fogray-grid does not know",
                args.model.display(),
                info.kind
            )
        })?;
    create_dir(&args.out)?;
    let work = RenderWork {
        args: &args,
        ring: &ring,
        scene: &scene,
        views: &views,
    };
    with_field(info.settings.precision, kind, work)
}

/// The views to render from the model file, as fogray-fit's dispatch runs it.
struct RenderWork<'a> {
    args: &'a RenderArgs,
    ring: &'a Ring,
    scene: &'a Scene,
    views: &'a [usize],
}

impl FieldWork for RenderWork<'_> {
    type Output = Result<()>;

    fn run<F: fogray::tape::Float, M: RadianceField<F>>(self) -> Result<()> {
        render_views::<F, M>(self.args, self.ring, self.scene, self.views)
    }
}

fn render_views<F: fogray::tape::Float, M: RadianceField<F>>(
    args: &RenderArgs,
    ring: &Ring,
    scene: &Scene,
    views: &[usize],
) -> Result<()> {
    let saved = checkpoint::load::<F, M>(&args.model)?;
    let occupancy = saved.occupancy_grid()?;
    let model = saved.start.model;
    let options = RenderOptions {
        background: scene.background,
        method: fogray::fit::settings::Method::Fused,
        depth: true,
    };
    // PNGs of about 256 pixels a side whatever the image size.
    let scale = (256 / ring.size()).clamp(1, 16) as u32;
    let mut summary = RenderSummary {
        images: Vec::new(),
        views: views.to_vec(),
        psnr: Vec::new(),
    };
    for &view in views {
        let camera = ring.camera(view)?;
        let view_data = fogray::fit::dataset::View::new(view.to_string(), &camera, photograph(scene, &camera))?;
        let (origins, directions) = view_data.rays();
        let r = render_picture(
            &model,
            occupancy.as_ref(),
            &origins,
            &directions,
            view_data.size(),
            &options,
        )?;
        let exact = view_data.image;
        let db = psnr(&[r.color.view()], &[exact.view()])?;
        let image_path = args.out.join(format!("view-{view:03}.png"));
        let depth_path = args.out.join(format!("depth-{view:03}.png"));
        write_comparison_png(&image_path, exact.view(), r.color.view(), 4.0, scale)?;
        let depth = r.depth.context("a render asked for depth gave none")?;
        let range = write_depth_png(&depth_path, depth.view(), &format!("view {view}"), scale)?;
        if !args.json {
            let depth = match range {
                Some(d) => format!("depth {:.3} to {:.3}", d.near, d.far),
                None => "no pixel opaque enough for a depth".into(),
            };
            println!(
                "view {view:>3}{}  PSNR {db:.2} dB  {}  {} ({depth})",
                if ring.is_test(view) { " (test)" } else { "       " },
                image_path.display(),
                depth_path.display()
            );
        }
        summary.images.push(nested(r.color.view()));
        summary.psnr.push(db);
    }
    if args.json {
        return write_stdout(|w| Ok(serde_json::to_writer(w, &summary)?));
    }
    Ok(())
}

/// One line on stderr and status 2.
fn fail(message: &str) -> ExitCode {
    eprintln!("fogray-grid: error: {}", message.replace('\n', " "));
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let parsed = Cli::command()
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m).map(|cli| (cli, m)));
    let (cli, matches) = match parsed {
        Ok(parsed) => parsed,
        Err(e) => {
            use clap::error::ErrorKind;
            return match e.kind() {
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                    let _ = e.print();
                    ExitCode::SUCCESS
                }
                ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand | ErrorKind::MissingSubcommand => {
                    fail("a subcommand is required (photographs, fit, render, report, scene); see --help")
                }
                _ => {
                    // clap's message is its first line; the rest is usage and a hint.
                    let text = e.render().to_string();
                    let first = text.lines().next().unwrap_or("bad arguments");
                    fail(first.strip_prefix("error: ").unwrap_or(first))
                }
            };
        }
    };
    match run(cli, &matches) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => fail(&format!("{e:#}")),
    }
}
