//! `fogray-grid report`: a sweep of the scene's configurations, timed, written as a report.

use super::*;

/// Test evaluations of each run of the report unless --evaluations is given.
const REPORT_EVALUATIONS: usize = 60;

pub(crate) fn run_report(args: ReportArgs, given: &dyn Fn(&str) -> bool) -> Result<()> {
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
