//! `fogray-lego`: runs `fogray fit` on NeRF-synthetic lego in the configurations the model
//! issue compares (dense or sparse grid, spherical-harmonics degree, prior, budget), one
//! process each so that each run's peak memory is its own, and writes `report.md`,
//! `report.json`, the PSNR-against-seconds plot beside the anchors' runs and a held-out view
//! beside its photograph. The runs are timed: run it on a quiet machine.
//!
//! ```text
//! cargo build --release -p fogray-cli -p fogray-lego
//! target/release/fogray-lego --data $FOGRAY_DATA/nerf_synthetic/lego --out reports/lego
//! ```
//!
//! `--replot` redraws the report from the runs its `report.json` keeps (with the measuring
//! run's stamp), running nothing.

mod anchors;
mod configs;
mod write;

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use clap::Parser;
use serde::{Deserialize, Serialize};

use configs::Config;
use fogray_lab::curves::Anchor;
use fogray_lab::stamp::Stamp;

/// Runs the configurations and writes the report.
#[derive(Parser)]
struct Args {
    /// The lego folder (transforms_train.json and its images).
    #[arg(long, required_unless_present = "replot")]
    data: Option<PathBuf>,
    /// Redraw the report from the runs --out/report.json keeps (with the stamp of the run that
    /// measured them), running nothing.
    #[arg(long)]
    replot: bool,
    /// Where the report goes (each run's own output under runs/).
    #[arg(long, default_value = "reports/lego")]
    out: PathBuf,
    /// The `fogray` binary (default: beside this one).
    #[arg(long)]
    fogray: Option<PathBuf>,
    /// Pixels averaged per side.
    #[arg(long, default_value_t = 4)]
    downscale: usize,
    /// Run only the configurations with these names (all when none is given).
    #[arg(long)]
    only: Vec<String>,
    /// Scale every budget by this factor (a quick check of the pipeline, not a measurement).
    #[arg(long, default_value_t = 1.0)]
    budget_scale: f64,
    /// An outside pipeline's run on the same views and machine (a PyTorch fit, say), as
    /// fogray_lab::curves::Anchor JSON: its curve joins the plot, and each run's time to the
    /// PSNR it ends at is set against its own.
    #[arg(long, value_name = "FILE")]
    anchor: Option<PathBuf>,
}

/// One evaluation of a run's log, as `fogray fit --json` writes it.
#[derive(Debug, Clone, Deserialize, Serialize)]
struct Evaluation {
    step: usize,
    seconds: f64,
    train_loss: Option<f64>,
    test_psnr: f64,
    /// Null before SSIM was logged, and for views smaller than its window.
    #[serde(default)]
    test_ssim: Option<f64>,
    samples: usize,
}

/// A phase of the step profile.
#[derive(Debug, Clone, Deserialize, Serialize)]
struct Phase {
    name: String,
    ms: f64,
}

/// The step profile.
#[derive(Debug, Clone, Deserialize, Serialize)]
struct Profile {
    steps: usize,
    phases: Vec<Phase>,
}

/// What `fogray fit --json` prints, the fields the report reads.
#[derive(Debug, Clone, Deserialize, Serialize)]
struct FitJson {
    final_test_psnr: f64,
    /// The mean of the held-out views' own PSNRs (the anchors' convention); null in runs
    /// from before `fogray fit` printed it.
    #[serde(default)]
    final_test_psnr_view_mean: Option<f64>,
    /// The PSNR on as many training views as held-out ones; null in runs from before.
    #[serde(default)]
    train_views_psnr: Option<f64>,
    #[serde(default)]
    final_test_ssim: Option<f64>,
    seconds: f64,
    steps: usize,
    log: Vec<Evaluation>,
    views: [usize; 2],
    size: [usize; 2],
    load_seconds: f64,
    parameters: usize,
    profile: Profile,
    held_out_haze: f64,
    peak_resident_bytes: Option<u64>,
}

/// A configuration and what its run gave.
#[derive(Debug, Clone, Serialize)]
struct Run {
    config: Config,
    seconds_budget: f64,
    result: FitJson,
}

fn fogray_binary(args: &Args) -> Result<PathBuf> {
    if let Some(p) = &args.fogray {
        return Ok(p.clone());
    }
    let me = std::env::current_exe()?;
    let beside = me.with_file_name(format!("fogray{}", std::env::consts::EXE_SUFFIX));
    if !beside.is_file() {
        bail!("no fogray binary at {} (build it, or give --fogray)", beside.display());
    }
    Ok(beside)
}

fn run_one(fogray: &Path, data: &Path, args: &Args, config: &Config, out: &Path) -> Result<Run> {
    let seconds = config.seconds * args.budget_scale;
    let mut command = Command::new(fogray);
    command
        .arg("fit")
        .arg("--data")
        .arg(data)
        .args(["--downscale", &args.downscale.to_string()])
        .args(["--seconds", &seconds.to_string()])
        .arg("--json")
        .arg("--out")
        .arg(out)
        .args(config.flags.split_whitespace());
    eprintln!("fogray-lego: {} ({seconds} s): {}", config.name, config.flags);
    let output = command
        .output()
        .with_context(|| format!("running {}", fogray.display()))?;
    if !output.status.success() {
        bail!(
            "{}: fogray fit failed: {}",
            config.name,
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let result: FitJson =
        serde_json::from_slice(&output.stdout).with_context(|| format!("{}: its JSON", config.name))?;
    Ok(Run {
        config: config.clone(),
        seconds_budget: seconds,
        result,
    })
}

/// A run as `report.json` keeps it.
#[derive(Deserialize)]
struct SavedRun {
    config: SavedConfig,
    seconds_budget: f64,
    result: FitJson,
}

#[derive(Deserialize)]
struct SavedConfig {
    name: String,
    flags: String,
}

#[derive(Deserialize)]
struct Saved {
    stamp: Stamp,
    runs: Vec<SavedRun>,
}

/// The runs `report.json` under `out` keeps, each with its configuration (which must still
/// have the flags it ran with), and the stamp of the run that measured them.
fn saved_runs(out: &Path, only: &[String]) -> Result<(Stamp, Vec<Run>)> {
    let file = out.join("report.json");
    let text = std::fs::read(&file).with_context(|| format!("--replot: reading {}", file.display()))?;
    let saved: Saved = serde_json::from_slice(&text).with_context(|| format!("--replot: {}", file.display()))?;
    let configs = configs::all();
    let mut runs = Vec::new();
    for run in saved.runs {
        if !(only.is_empty() || only.contains(&run.config.name)) {
            continue;
        }
        let Some(config) = configs.iter().find(|c| c.name == run.config.name) else {
            bail!(
                "{}: run {} is no configuration of configs.rs",
                file.display(),
                run.config.name
            );
        };
        if config.flags != run.config.flags {
            bail!(
                "{}: {} ran with `{}`, configs.rs now gives `{}`: run it again",
                file.display(),
                config.name,
                run.config.flags,
                config.flags
            );
        }
        runs.push(Run {
            config: config.clone(),
            seconds_budget: run.seconds_budget,
            result: run.result,
        });
    }
    if runs.is_empty() {
        bail!("{}: no run to redraw", file.display());
    }
    Ok((saved.stamp, runs))
}

fn main() -> Result<()> {
    let args = Args::parse();
    // Read before the runs, so that a bad file costs seconds, not the report's half hour.
    let anchor = args.anchor.as_deref().map(Anchor::read).transpose()?;
    let configs: Vec<Config> = configs::all()
        .into_iter()
        .filter(|c| args.only.is_empty() || args.only.iter().any(|o| o == c.name))
        .collect();
    if configs.is_empty() {
        bail!("--only names no configuration (see configs.rs)");
    }
    if args.replot {
        let (stamp, runs) = saved_runs(&args.out, &args.only)?;
        write::report(&args, &runs, anchor.as_ref(), &stamp)?;
        eprintln!("fogray-lego: redrew {}", args.out.join("report.md").display());
        return Ok(());
    }
    let Some(data) = args.data.as_deref() else {
        bail!("--data is needed unless --replot");
    };
    let fogray = fogray_binary(&args)?;
    std::fs::create_dir_all(&args.out)?;
    let mut runs = Vec::new();
    for config in &configs {
        let dir = args.out.join("runs").join(config.name);
        runs.push(run_one(&fogray, data, &args, config, &dir)?);
    }
    write::report(&args, &runs, anchor.as_ref(), &write::stamp(&args))?;
    eprintln!("fogray-lego: wrote {}", args.out.join("report.md").display());
    Ok(())
}
