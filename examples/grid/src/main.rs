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

use fogray_grid::images::{nested, write_png};
use fogray_grid::photographs::photographs;
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
    /// Writes the built-in scene as JSON, to edit and pass back with --scene.
    Scene {
        /// File to write; stdout if absent.
        #[arg(long)]
        out: Option<PathBuf>,
    },
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
                    fail("a subcommand is required (photographs, scene); see --help")
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
