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
use fogray::fit::dispatch::{with_field_kind, FieldKind, FieldWork};
use fogray::fit::images::{write_comparison_png, write_png};
use fogray::fit::metrics::psnr;
use fogray::fit::model::RadianceField;
use fogray::fit::plots;
use fogray::fit::render::{render_picture, RenderOptions};
use fogray::fit::session::{self, FitReport, SessionOutcome, SessionPlan};
use fogray::fit::settings::FitSettings;
use fogray::fit::train::Progress;
use fogray_grid::capture::{self, CaptureSettings};
use fogray_grid::photographs::{photograph, photographs};
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_grid::views::dataset;

mod command_fit;
mod command_render;
mod command_report;

use command_fit::run_fit;
use command_render::run_render;
use command_report::run_report;

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
        Command::Fit(args) => run_fit(args, &|id| given(matches, "fit", id))?,
        Command::Render(args) => run_render(args)?,
        Command::Report(args) => run_report(args, &|id| given(matches, "report", id))?,
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

/// Whether the flag of clap id `id` was given on the command line of subcommand `sub`.
fn given(matches: &ArgMatches, sub: &str, id: &str) -> bool {
    matches.subcommand_matches(sub).and_then(|m| m.value_source(id)) == Some(ValueSource::CommandLine)
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

/// The image as nested vectors `[row][column][channel]`, the layout of the JSON outputs.
fn nested(image: ndarray::ArrayView3<'_, f64>) -> Vec<Vec<Vec<f64>>> {
    image
        .outer_iter()
        .map(|row| row.outer_iter().map(|px| px.to_vec()).collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use ndarray::Array3;

    use super::nested;

    #[test]
    fn nested_keeps_row_column_channel_order() {
        let card = Array3::from_shape_fn((3, 5, 3), |(a, b, c)| (a * 15 + b * 3 + c) as f64 / 44.0);
        let n = nested(card.view());
        assert_eq!((n.len(), n[0].len(), n[0][0].len()), (3, 5, 3));
        // Value (a, b, c) of the card is (15 a + 3 b + c) / 44.
        assert_eq!(n[2][1][0], 33.0 / 44.0);
        assert_eq!(n[0][4][2], 14.0 / 44.0);
    }
}
