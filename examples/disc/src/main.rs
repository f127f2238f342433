//! `fogray-disc`: the disc experiment on the command line (`docs/disc.md`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use fogray_disc::adam::Adam;
use fogray_disc::anneal::{fit_annealed, Schedule};
use fogray_disc::error::DiscError;
use fogray_disc::experiments::{self, grid, Renderer};
use fogray_disc::scene::Scene;
use fogray_disc::setup::Setup;
use fogray_disc::{plots, reproduce};

#[derive(Parser)]
#[command(
    name = "fogray-disc",
    version,
    about = "The disc experiment of the volume-rendering lesson: a hard renderer's staircase against a soft renderer's landscape",
    long_about = "The disc experiment of the lesson 'Making visibility soft: volume rendering'. A disc of radius 1 m is photographed by six cameras on a ring of radius 5 m; a model disc offset by x is rendered hard (first hit) and soft (a Gaussian fog sheet of softness tau, composited by fogray's fused op, with dE/dx from the tape's backward). Without a subcommand it runs `reproduce`: every figure of the lesson beside ours, and all plots (SVG and PNG in --out)."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    common: Common,
}

#[derive(Args, Clone)]
struct Common {
    #[command(flatten)]
    scene: Scene,
    /// Print machine-readable JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Directory for plots.
    #[arg(long, default_value = "out")]
    out: PathBuf,
}

#[derive(Subcommand)]
enum Command {
    /// The hard loss over x in [-1.6, 1.6] in 1 mm steps: how many distinct values, and how
    /// many steps change nothing.
    Staircase {
        #[command(flatten)]
        common: Common,
    },
    /// Soft and hard loss and slope over a range of x at softness --tau; minima and false
    /// valleys (minima more than 0.25 m from the truth). Plots landscape.svg/png.
    Landscape {
        #[command(flatten)]
        common: Common,
        /// First offset (m).
        #[arg(long, default_value_t = -3.0, allow_negative_numbers = true)]
        from: f64,
        /// Last offset (m).
        #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
        to: f64,
        /// Step (m).
        #[arg(long, default_value_t = 0.01)]
        step: f64,
    },
    /// Adam on x from --start with the soft or hard renderer at softness --tau; with
    /// --anneal, tau and the learning rate follow the schedule (--tau-start .. --anneal-steps)
    /// instead of --tau, --lr and --steps.
    Fit {
        #[command(flatten)]
        common: Common,
        /// Which renderer's exact derivative to descend.
        #[arg(long, value_enum, default_value = "soft")]
        renderer: Renderer,
        /// Starting offset (m).
        #[arg(long, allow_negative_numbers = true)]
        start: f64,
        /// Anneal the softness from large to small while descending (soft renderer only).
        #[arg(long)]
        anneal: bool,
        #[command(flatten)]
        adam: Adam,
        #[command(flatten)]
        schedule: Schedule,
    },
    /// Density, transmittance and weights along one pixel's ray. Plots ray.svg/png.
    Ray {
        #[command(flatten)]
        common: Common,
        /// Camera index.
        #[arg(long, default_value_t = 0)]
        camera: usize,
        /// Pixel index.
        #[arg(long, default_value_t = 36)]
        pixel: usize,
        /// Model offset (m).
        #[arg(long, default_value_t = -1.5, allow_negative_numbers = true)]
        x: f64,
    },
    /// Uniform against band sampling: the soft pixels' error against the exact pixels
    /// (optical depth by converged quadrature) at equal sample counts.
    Sampling {
        #[command(flatten)]
        common: Common,
        /// Model offsets to measure at (m).
        #[arg(long, value_delimiter = ',', default_values_t = [-1.5, 0.0], allow_negative_numbers = true)]
        at: Vec<f64>,
        /// Samples per ray to compare.
        #[arg(long, value_delimiter = ',', default_values_t = [16, 32, 64, 128, 256])]
        counts: Vec<usize>,
    },
    /// The speed-against-error report: time per frame (288 rays x 4 model offsets, forward and
    /// backward) of the fused op (with early termination thresholds 0, 1e-6, 1e-4, 1e-2) and of
    /// the taped twins, in f32 and f64, against the worst error of the frame's pixels, for
    /// uniform and band sampling at 16..256 samples per ray; the Pareto front and what to pick
    /// for each error budget. Writes speed_vs_error.md, .json, .svg and .png into --dir.
    Report {
        #[command(flatten)]
        common: Common,
        /// Directory for the report.
        #[arg(long, default_value = "reports")]
        dir: PathBuf,
    },
    /// Every figure of the lesson beside ours, and all plots (the default).
    Reproduce {
        #[command(flatten)]
        common: Common,
    },
}

fn bar(len: u64, json: bool) -> ProgressBar {
    if json {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})") {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

fn print_json(v: &impl serde::Serialize) -> Result<(), DiscError> {
    println!("{}", serde_json::to_string_pretty(v)?);
    Ok(())
}

fn run(cli: Cli) -> Result<(), DiscError> {
    match cli.command.unwrap_or(Command::Reproduce { common: cli.common }) {
        Command::Staircase { common } => {
            let setup = Setup::new(common.scene)?;
            let s = experiments::staircase(&setup);
            if common.json {
                return print_json(&json!({
                    "distinct_values": s.distinct_values,
                    "distinct_values_plain": s.distinct_values_plain,
                    "unchanged_fraction": s.unchanged_fraction,
                    "tie_offsets": s.tie_offsets,
                }));
            }
            println!("hard loss over x in [-1.6, 1.6], {} steps of 1 mm:", s.x.len() - 1);
            println!(
                "  distinct values: {} (tangent rays counted consistently as hits)",
                s.distinct_values
            );
            println!(
                "  distinct values with the textbook test |w|^2 - (w.d)^2 <= R^2: {} (it rounds one ray of an exactly tangent pair in and the other out at x = {:?}, giving an odd mismatch count no other offset has)",
                s.distinct_values_plain, s.tie_offsets
            );
            println!("  steps that change nothing: {:.2} %", 100.0 * s.unchanged_fraction);
        }
        Command::Landscape { common, from, to, step } => {
            let setup = Setup::new(common.scene.clone())?;
            if !(step > 0.0 && from < to) {
                return Err(DiscError::Range { from, to, step });
            }
            let n = ((to - from) / step).round() as i64;
            let xs = grid(
                (from * 1000.0).round() as i64,
                (from * 1000.0).round() as i64 + n * (step * 1000.0).round() as i64,
                (step * 1000.0).round().max(1.0) as i64,
            );
            let pb = bar(xs.len() as u64, common.json);
            pb.set_message(format!("landscape tau = {}", common.scene.tau));
            let l = experiments::landscape(&setup, common.scene.tau, &xs, &|| pb.inc(1))?;
            pb.finish_and_clear();
            std::fs::create_dir_all(&common.out).map_err(DiscError::file("create", &common.out))?;
            let name = format!("landscape-tau{}", l.tau);
            plots::landscapes(&common.out, &name, &[(l.clone(), Vec::new())])?;
            if common.json {
                return print_json(&json!({
                    "tau": l.tau, "minima": l.minima, "false_valleys": l.false_valleys,
                    "truth_is_local_max": l.truth_is_local_max,
                    "x": l.x, "soft_loss": l.soft_loss, "soft_slope": l.soft_slope, "hard_loss": l.hard_loss,
                }));
            }
            println!("tau = {} m: minima at {:?}", l.tau, l.minima);
            println!(
                "  false valleys (more than 0.25 m from the truth): {:?}",
                l.false_valleys
            );
            println!("  the truth is a local maximum: {}", l.truth_is_local_max);
            println!("  plot: {}/{name}.svg and .png", common.out.display());
        }
        Command::Fit {
            common,
            renderer,
            start,
            anneal,
            adam,
            schedule,
        } => {
            let setup = Setup::new(common.scene.clone())?;
            let f = if anneal {
                if renderer == Renderer::Hard {
                    return Err(DiscError::Usage(
                        "--anneal needs the soft renderer (the hard one has no softness)",
                    ));
                }
                schedule.validate()?;
                fit_annealed(&setup, start, &schedule, &adam)?
            } else {
                experiments::fit(&setup, renderer, start, common.scene.tau, &adam)?
            };
            if common.json {
                return print_json(
                    &json!({"end": f.end, "path": f.path, "tau": f.tau, "pixels_wrong": f.pixels_wrong}),
                );
            }
            println!(
                "{:?} descent from {start} ({} steps{}): ends at {:.4} m, {:.4} m from the truth; {} of {} pixels of the hard render differ from the photographs",
                renderer,
                f.path.len() - 1,
                if anneal { format!(", tau {} -> {}", schedule.tau_start, schedule.tau_end) } else { format!(", tau {}", common.scene.tau) },
                f.end,
                f.end.abs(),
                f.pixels_wrong,
                setup.rays.len()
            );
        }
        Command::Ray {
            common,
            camera,
            pixel,
            x,
        } => {
            let setup = Setup::new(common.scene.clone())?;
            let p = experiments::ray_profile(&setup, camera, pixel, x, common.scene.tau)?;
            std::fs::create_dir_all(&common.out).map_err(DiscError::file("create", &common.out))?;
            plots::ray(&common.out, &p)?;
            if common.json {
                return print_json(&p);
            }
            println!(
                "camera {camera} pixel {pixel}, model at x = {x} m, tau = {} m",
                common.scene.tau
            );
            println!("  T after the first crossing: {:.7}", p.t_after_first_crossing);
            println!(
                "  share of the stopping probability in the back half: {:.4} %",
                100.0 * p.back_half_weight
            );
            println!("  plot: {}/ray.svg and ray.png", common.out.display());
        }
        Command::Sampling { common, at, counts } => {
            let setup = Setup::new(common.scene.clone())?;
            if counts.contains(&0) {
                return Err(DiscError::Usage("--counts must be positive"));
            }
            let mut rows = Vec::new();
            for &x in &at {
                rows.extend(fogray_disc::sampling::compare(
                    &setup.scene,
                    &setup.rays,
                    x,
                    common.scene.tau,
                    &counts,
                )?);
            }
            if common.json {
                return print_json(&json!({ "results": rows }));
            }
            println!("soft pixels against the exact ones (tau = {} m, band = {} tau), worst |C - C_exact| over {} pixels x {} channels:", common.scene.tau, common.scene.band_k, setup.rays.len(), setup.scene.channels());
            println!("{:>8} {:>8} {:>14} {:>14}", "x", "samples", "uniform", "band");
            for pair in rows.chunks(2) {
                println!(
                    "{:>8} {:>8} {:>14.3e} {:>14.3e}",
                    pair[0].x, pair[0].samples, pair[0].max_abs_error, pair[1].max_abs_error
                );
            }
        }
        Command::Report { common, dir } => {
            let setup = Setup::new(common.scene.clone())?;
            let pb = bar(10, common.json);
            pb.set_message("report");
            let timing = fogray_disc::report::Timing::STABLE;
            let rows = fogray_disc::report::run(&setup, common.scene.tau, timing, &|| pb.inc(1))?;
            pb.finish_and_clear();
            std::fs::create_dir_all(&dir).map_err(DiscError::file("create", &dir))?;
            let stamp = fogray_lab::stamp::Stamp::now("cargo run --release -p fogray-disc -- report");
            let md = fogray_disc::report::markdown(&rows, common.scene.tau, timing, &stamp);
            let md_path = dir.join("speed_vs_error.md");
            // Whole or not at all, as every fogray writer: never a truncated report.
            fogray_data::write_atomic(&md_path, |out| out.write_all(md.as_bytes()))?;
            let js = serde_json::to_string_pretty(&json!({ "stamp": stamp, "results": rows }))?;
            let js_path = dir.join("speed_vs_error.json");
            fogray_data::write_atomic(&js_path, |out| out.write_all(js.as_bytes()))?;
            fogray_disc::report::plot(&dir, &rows, common.scene.tau)?;
            if common.json {
                println!("{js}");
            } else {
                println!("{md}");
                println!("written: {0}/speed_vs_error.md, .json, .svg, .png", dir.display());
            }
        }
        Command::Reproduce { common } => {
            let setup = Setup::new(common.scene.clone())?;
            let (adam, schedule) = (Adam::default(), Schedule::default());
            let pb = bar(reproduce::work(&adam, &schedule), common.json);
            pb.set_message("reproducing");
            let (r, panels) = reproduce::run(&setup, &adam, &schedule, &|n| pb.inc(n))?;
            pb.finish_and_clear();
            let files = reproduce::plot_all(&setup, &common.out, &r, &panels)?;
            if common.json {
                return print_json(&json!({
                    "figures": r.figures,
                    "staircase_distinct_plain": r.staircase_distinct_plain,
                    "annealed": r.annealed.iter().map(|f| json!({"start": f.start, "end": f.end, "pixels_wrong": f.pixels_wrong})).collect::<Vec<_>>(),
                    "fixed_tau_0.15": r.fixed.iter().map(|f| json!({"start": f.start, "end": f.end, "pixels_wrong": f.pixels_wrong})).collect::<Vec<_>>(),
                    "plots": files,
                }));
            }
            print_table(&r);
            println!("plots: {}", files.join(", "));
        }
    }
    Ok(())
}

fn print_table(r: &reproduce::Reproduction) {
    println!("{:<32} {:>8} {:>12}  {:<6} what", "figure", "lesson", "ours", "agrees");
    for f in &r.figures {
        let ours = match &f.ours {
            serde_json::Value::Number(n) if n.is_f64() => format!("{:.4}", n.as_f64().unwrap_or(f64::NAN)),
            v => v.to_string(),
        };
        let agrees = match (f.agrees(), f.id) {
            (true, _) => "yes",
            (false, "staircase_distinct") => "note",
            _ => "NO",
        };
        println!("{:<32} {:>8} {:>12}  {:<6} {}", f.id, f.printed, ours, agrees, f.what);
    }
    println!(
        "note: exact arithmetic gives 58 distinct values; the lesson's 59 comes from rounding: at x = {1:?} two rays are exactly tangent, and the textbook test |w|^2 - (w.d)^2 <= R^2 rounds one in and one out, an odd count no other offset has ({0} distinct values with that test)",
        r.staircase_distinct_plain, r.staircase_tie_offsets
    );
    let ok = r.annealed.iter().filter(|f| f.pixels_wrong == 0).count();
    let worst = r.annealed.iter().map(|f| f.end.abs()).fold(0.0, f64::max);
    let fixed_worst = r.fixed.iter().map(|f| f.end.abs()).fold(0.0, f64::max);
    let fixed_ok = r.fixed.iter().filter(|f| f.pixels_wrong == 0).count();
    println!(
        "annealed fits (tau 0.3 -> 0.1) from the 25 starts -3, -2.75, ..., 3: {ok} of 25 end pixel-exact, worst |x| = {worst:.4} m; fixed tau = 0.15 (80 steps): {fixed_ok} of 25 pixel-exact, worst |x| = {fixed_worst:.4} m"
    );
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fogray-disc: error: {e}");
            ExitCode::from(2)
        }
    }
}
