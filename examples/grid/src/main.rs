//! `fogray-grid`: exact photographs of a scene of constant-density primitives, for fitting a
//! grid of density and colour to them.
//!
//! Bad input (a bad flag or scene file, a zero count) exits with status 2 and one line on
//! stderr; scripts outside this crate rely on the flags and the JSON as they are.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use serde::Serialize;

use fogray_grid::dataset::Dataset;
use fogray_grid::fit::{fit, Budget, FitConfig, FitResult, Sampling};
use fogray_grid::images::{nested, write_comparison_png, write_png};
use fogray_grid::model::Method;
use fogray_grid::photographs::photographs;
use fogray_grid::plots;
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;

#[derive(Parser)]
#[command(
    name = "fogray-grid",
    version,
    about = "Exact photographs of a scene of constant-density spheres and boxes, seen by a ring of cameras",
    long_about = "A scene of constant-density spheres and boxes inside [-1, 1]^3 (densities add where they overlap, colours mix by density) is photographed exactly: along a ray the medium is piecewise constant, so compositing its pieces is the emission-absorption integral itself. The cameras sit on a Fibonacci lattice over the sphere of radius 3, look at the origin with a 40 degree field of view, and every e-th view (e = (V + T) / T) is held out for testing."
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
#[derive(Args)]
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
    /// Fits a dense grid of density and colour to the training views' exact photographs
    /// (Adam on random batches of rays), measuring the test PSNR on the held-out views.
    Fit(FitArgs),
    /// The speed-against-error report: fits each configuration in turn for the same budget and
    /// writes test PSNR against training time (psnr-vs-seconds.svg/.png, psnr-vs-steps.svg/.png),
    /// report.md, report.json and pictures of the best configuration's model into --out. The
    /// runs are timed: run it on a quiet machine.
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
    /// Nodes per axis of the grid.
    #[arg(long, default_value_t = 64)]
    grid: usize,
    /// Training seconds (evaluations excluded); 60 unless --steps is given.
    #[arg(long, conflicts_with = "steps", allow_negative_numbers = true)]
    seconds: Option<f64>,
    /// Training steps.
    #[arg(long)]
    steps: Option<usize>,
    /// Training rays per step.
    #[arg(long, default_value_t = 8192)]
    batch: usize,
    /// Fused ops or their taped twins.
    #[arg(long, value_enum, default_value = "fused")]
    method: MethodArg,
    /// Floating-point type of the model and the render.
    #[arg(long, value_enum, default_value = "f32")]
    precision: Precision,
    /// Samples every half voxel across the box, or only in occupied cells.
    #[arg(long, value_enum, default_value = "uniform")]
    sampling: SamplingArg,
    /// Seed of the batches.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Adam's learning rate.
    #[arg(long, default_value_t = 0.1)]
    lr: f64,
    /// Train the full grid from the start instead of growing it coarse to fine (a quarter of
    /// --grid nodes per axis, doubled at 10 % and 30 % of the budget).
    #[arg(long)]
    no_grow: bool,
    /// Print one JSON object (the log and the final figures) instead of text.
    #[arg(long)]
    json: bool,
    /// Directory for the pictures: each test view's photograph, render and |error| x 4
    /// (test-view-NNN.png), and test PSNR against training seconds (psnr.svg, psnr.png).
    #[arg(long)]
    out: Option<PathBuf>,
    /// File for the final renders of the test views as {"images": [view][row][column][channel]}.
    #[arg(long)]
    save_renders: Option<PathBuf>,
}

#[derive(Args)]
struct ReportArgs {
    #[command(flatten)]
    scene: SceneArg,
    #[command(flatten)]
    ring: RingArgs,
    /// Nodes per axis of the grid.
    #[arg(long, default_value_t = 64)]
    grid: usize,
    /// Training seconds of each configuration (evaluations excluded); 60 unless --steps is given.
    #[arg(long, conflicts_with = "steps", allow_negative_numbers = true)]
    seconds: Option<f64>,
    /// Training steps of each configuration instead of seconds.
    #[arg(long)]
    steps: Option<usize>,
    /// Training rays per step.
    #[arg(long, default_value_t = 8192)]
    batch: usize,
    /// Seed of the batches (the same for every configuration).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Configurations to run, in order, comma-separated: METHOD-SAMPLING[-PRECISION] with
    /// METHOD fused|taped, SAMPLING uniform|occupancy, PRECISION f32 (default)|f64.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "fused-uniform,taped-uniform,fused-occupancy,taped-occupancy"
    )]
    configs: Vec<String>,
    /// Directory for the report (created if missing).
    #[arg(long, default_value = "reports/grid")]
    out: PathBuf,
}

fn run_report(args: ReportArgs) -> Result<()> {
    use fogray_grid::report::configuration::RunConfig;
    use fogray_grid::report::run::{run_configs, ReportOptions};
    use fogray_grid::report::write::{write_report, ReportSetup};

    let configs = args
        .configs
        .iter()
        .map(|c| c.parse::<RunConfig>())
        .collect::<Result<Vec<_>, _>>()?;
    let (scene, ring) = (args.scene.load()?, args.ring.ring()?);
    let budget = match (args.steps, args.seconds) {
        (Some(n), _) => Budget::Steps(n),
        (None, s) => Budget::Seconds(s.unwrap_or(60.0)),
    };
    let options = ReportOptions {
        fit: FitConfig {
            grid: args.grid,
            batch: args.batch,
            budget,
            seed: args.seed,
            ..FitConfig::default()
        },
        configs,
        slice_pixels: 128,
    };
    // Before training, so that a bad directory costs nothing.
    create_dir(&args.out)?;
    let given: Vec<String> = std::env::args().skip(1).collect();
    let stamp = fogray::stamp::Stamp::now(&format!("fogray-grid {}", given.join(" ")));
    let reproduce = format!("cargo run --release -p fogray-grid -- {}", given.join(" "));
    let data = Dataset::new(&ring, &photographs(&scene, &ring), scene.background)?;
    let bar = indicatif::ProgressBar::new(1000);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{prefix} [{bar:40}] {msg} ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    let names: Vec<String> = options.configs.iter().map(|c| c.to_string()).collect();
    let mut current = usize::MAX;
    let runs = run_configs(&data, &options, &mut |i, p| {
        if i != current {
            current = i;
            bar.reset();
            bar.set_prefix(format!("{} ({}/{})", names[i], i + 1, names.len()));
        }
        bar.set_position((p.fraction * 1000.0) as u64);
        bar.set_message(format!("step {}", p.step));
    })?;
    bar.finish_and_clear();
    let problem = format!(
        "A {g}^3 grid fitted from {v} exact photographs of {s} x {s} pixels of {scene}, judged on {t} held-out views; {b} rays per step, seed {seed}.",
        g = args.grid,
        v = args.ring.views,
        s = args.ring.size,
        scene = match &args.scene.scene {
            Some(path) => format!("the scene {}", path.display()),
            None => "the built-in scene".into(),
        },
        t = data.test.len(),
        b = args.batch,
        seed = args.seed,
    );
    let setup = ReportSetup {
        stamp: &stamp,
        reproduce: &reproduce,
        budget,
        batch: args.batch,
        problem: &problem,
    };
    let md = write_report(&args.out, &runs, &data, &scene, &setup)?;
    for r in &runs {
        println!(
            "{:<22} final test PSNR {:.2} dB, {} steps in {:.1} s",
            r.name, r.final_test_psnr, r.steps, r.seconds
        );
    }
    println!("written: {}", md.display());
    Ok(())
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MethodArg {
    Fused,
    Taped,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Precision {
    F32,
    F64,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum SamplingArg {
    Uniform,
    Occupancy,
}

impl MethodArg {
    fn name(self) -> &'static str {
        match self {
            MethodArg::Fused => "fused",
            MethodArg::Taped => "taped",
        }
    }
}

impl Precision {
    fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

impl SamplingArg {
    fn name(self) -> &'static str {
        match self {
            SamplingArg::Uniform => "uniform",
            SamplingArg::Occupancy => "occupancy",
        }
    }
}

#[derive(Serialize)]
struct FitSummary<'a> {
    log: &'a [fogray_grid::fit::LogEntry],
    final_test_psnr: f64,
    seconds: f64,
    samples_per_ray_mean: f64,
    occupied_fraction: f64,
}

fn run_fit(args: FitArgs) -> Result<()> {
    let (scene, ring) = (args.scene.load()?, args.ring.ring()?);
    // Before training, so that a bad directory costs nothing.
    if let Some(dir) = &args.out {
        create_dir(dir)?;
    }
    let data = Dataset::new(&ring, &photographs(&scene, &ring), scene.background)?;
    let config = FitConfig {
        grid: args.grid,
        batch: args.batch,
        budget: match (args.steps, args.seconds) {
            (Some(n), _) => Budget::Steps(n),
            (None, s) => Budget::Seconds(s.unwrap_or(60.0)),
        },
        method: match args.method {
            MethodArg::Fused => Method::Fused,
            MethodArg::Taped => Method::Taped,
        },
        sampling: match args.sampling {
            SamplingArg::Uniform => Sampling::Uniform,
            SamplingArg::Occupancy => Sampling::Occupancy,
        },
        seed: args.seed,
        lr: args.lr,
        grow: !args.no_grow,
        ..FitConfig::default()
    };
    let bar = if args.json {
        indicatif::ProgressBar::hidden()
    } else {
        let bar = indicatif::ProgressBar::new(1000);
        if let Ok(style) = indicatif::ProgressStyle::with_template("fit [{bar:40}] {msg} ({elapsed})") {
            bar.set_style(style.progress_chars("=> "));
        }
        bar
    };
    let mut progress = |p: fogray_grid::fit::Progress| {
        bar.set_position((p.fraction * 1000.0) as u64);
        bar.set_message(format!("step {}", p.step));
    };
    match args.precision {
        Precision::F32 => report_fit(&args, &data, fit::<f32>(&data, &config, &mut progress)?, &bar),
        Precision::F64 => report_fit(&args, &data, fit::<f64>(&data, &config, &mut progress)?, &bar),
    }
}

fn report_fit<F: fogray::tape::Float>(
    args: &FitArgs,
    data: &Dataset,
    result: FitResult<F>,
    bar: &indicatif::ProgressBar,
) -> Result<()> {
    bar.finish_and_clear();
    if let Some(file) = &args.save_renders {
        let images = Images {
            images: result.renders.iter().map(|im| nested(im.view())).collect(),
        };
        let text = serde_json::to_string(&images)?;
        std::fs::write(file, text).with_context(|| format!("cannot write {}", file.display()))?;
    }
    if let Some(dir) = &args.out {
        for (t, render) in data.test.iter().zip(&result.renders) {
            let path = dir.join(format!("test-view-{:03}.png", t.view));
            write_comparison_png(&path, t.photograph.view(), render.view(), 4.0, 4)?;
        }
        let label = format!(
            "{} {} {}",
            args.method.name(),
            args.precision.name(),
            args.sampling.name()
        );
        plots::psnr_curves(
            &dir.join("psnr"),
            &[plots::Curve {
                label,
                log: &result.log,
            }],
        )?;
    }
    let summary = FitSummary {
        log: &result.log,
        final_test_psnr: result.final_test_psnr,
        seconds: result.seconds,
        samples_per_ray_mean: result.samples_per_ray_mean,
        occupied_fraction: result.occupied_fraction,
    };
    if args.json {
        return write_stdout(|w| Ok(serde_json::to_writer(w, &summary)?));
    }
    for e in &result.log {
        println!(
            "step {:>6}  {:>8.2} s  train loss {:.3e}  test PSNR {:.2} dB",
            e.step, e.seconds, e.train_loss, e.test_psnr
        );
    }
    println!(
        "final test PSNR {:.2} dB after {:.1} s of training; {:.1} samples per ray; {:.1} % of cells occupied",
        result.final_test_psnr,
        result.seconds,
        result.samples_per_ray_mean,
        100.0 * result.occupied_fraction
    );
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

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Photographs { scene, ring, json, out } => {
            let (scene, ring) = (scene.load()?, ring.ring()?);
            let images = photographs(&scene, &ring);
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
        Command::Fit(args) => run_fit(args)?,
        Command::Report(args) => run_report(args)?,
        Command::Scene { out } => {
            let text = Scene::default().to_json_pretty() + "\n";
            match out {
                Some(path) => {
                    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?
                }
                None => write_stdout(|w| Ok(w.write_all(text.as_bytes())?))?,
            }
        }
    }
    Ok(())
}

/// One line on stderr and status 2.
fn fail(message: &str) -> ExitCode {
    eprintln!("fogray-grid: error: {}", message.replace('\n', " "));
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            return match e.kind() {
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                    let _ = e.print();
                    ExitCode::SUCCESS
                }
                ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand | ErrorKind::MissingSubcommand => {
                    fail("a subcommand is required (photographs, fit, report, scene); see --help")
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
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => fail(&format!("{e:#}")),
    }
}
