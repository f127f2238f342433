//! The report: a table of the runs, the PSNR-against-seconds plot with the anchor, and a
//! held-out view beside its photograph.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fogray_fit::plots::{metric_curves, Curve, Metric, XAxis};
use fogray_fit::train::LogEntry;
use fogray_lab::curves::{against_anchor, psnr_at, reach, Anchor, AnchorPoint};
use fogray_lab::stamp::Stamp;

use crate::anchors::{NERFACTO_CPU, NERFACTO_PEAK_BYTES, NERFACTO_RENDER_SECONDS};
use crate::{Args, Run};

/// The log of a run as the plotting code takes it.
fn log_entries(run: &Run) -> Vec<LogEntry> {
    run.result
        .log
        .iter()
        .map(|e| LogEntry {
            step: e.step,
            seconds: e.seconds,
            train_loss: e.train_loss.unwrap_or(f64::NAN),
            test_psnr: e.test_psnr,
            test_ssim: e.test_ssim.unwrap_or(f64::NAN),
            samples: e.samples,
        })
        .collect()
}

fn phase(run: &Run, name: &str) -> f64 {
    run.result
        .profile
        .phases
        .iter()
        .find(|p| p.name == name)
        .map_or(f64::NAN, |p| p.ms)
}

fn cell(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.2}"))
}

/// Writes report.md, report.json, psnr-vs-seconds.{png,svg} and the held-out view.
/// The stamp of a run of the configurations now, with the command that makes it.
pub fn stamp(args: &Args) -> Stamp {
    let mut command = format!("fogray-lego --data <lego> --downscale {}", args.downscale);
    if args.budget_scale != 1.0 {
        command += &format!(" --budget-scale {}", args.budget_scale);
    }
    if let Some(file) = &args.anchor {
        command += &format!(" --anchor {}", file.display());
    }
    Stamp::now(&command)
}

/// Writes report.md, report.json and the plot for `runs`, measured as `stamp` says.
pub fn report(args: &Args, runs: &[Run], outside: Option<&Anchor>, stamp: &Stamp) -> Result<()> {
    let out = &args.out;
    let nerfacto = Anchor {
        name: "nerfacto, CPU (the issue's run)".into(),
        note: None,
        log: NERFACTO_CPU
            .iter()
            .map(|&(seconds, test_psnr)| AnchorPoint {
                seconds,
                test_psnr,
                step: None,
            })
            .collect(),
    };
    let anchor = nerfacto.entries();
    let outside_log = outside.map(Anchor::entries);
    let logs: Vec<Vec<LogEntry>> = runs.iter().map(log_entries).collect();
    let mut curves: Vec<Curve<'_>> = runs
        .iter()
        .zip(&logs)
        .map(|(r, log)| Curve {
            label: format!("{} ({} s)", r.config.name, r.seconds_budget),
            log,
        })
        .collect();
    curves.push(Curve {
        label: nerfacto.name.clone(),
        log: &anchor,
    });
    if let (Some(a), Some(log)) = (outside, &outside_log) {
        curves.push(Curve {
            label: a.name.clone(),
            log,
        });
    }
    let dashed: Vec<usize> = (runs.len()..curves.len()).collect();
    metric_curves(
        &out.join("psnr-vs-seconds"),
        &curves,
        XAxis::Seconds,
        Metric::Psnr,
        &dashed,
    )
    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;

    let first = &runs[0].result;
    let mut md = String::new();
    writeln!(md, "# fogray fit on NeRF-synthetic lego\n")?;
    writeln!(md, "{}\n", stamp.markdown())?;
    if args.replot {
        writeln!(
            md,
            "Tables and plot redrawn on {} from the runs' files by `fogray-lego --replot`; the runs are the \
             stamp's.\n",
            Stamp::now("").date
        )?;
    }
    writeln!(
        md,
        "Each row is one `fogray fit --data <lego> --downscale {} --seconds S` process with the flags shown \
         beside the defaults, trained on {} views of {}x{} and judged on {} views it never saw (every 8th \
         frame of the training file: r_0 r_9 r_18 ... r_98). \"final dB\" is the PSNR of the squared error over \
         all held-out pixels; \"views' mean\" the mean of each held-out view's own PSNR, as the anchors' papers \
         report it; \"training views dB\" the PSNR on as many training views, rendered alike; SSIM the mean over \
         the held-out views (Gaussian window 11, sigma 1.5). All are measured off the training clock. Memory is the process's peak resident set; haze is the fraction of held-out \
         pixels whose opacity lies in (0.05, 0.95); ms/step are the step's phases averaged over the fit.\n",
        args.downscale, first.views[0], first.size[1], first.size[0], first.views[1]
    )?;
    writeln!(
        md,
        "| run | flags | s | steps | dB at 30 s | dB at 60 s | final dB | final dB, views' mean | training views dB | \
         final SSIM | parameters | peak memory | haze | forward + backward ms | optimiser ms | occupancy ms | \
         s to 16.4 dB |"
    )?;
    writeln!(
        md,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    )?;
    for (run, log) in runs.iter().zip(&logs) {
        let r = &run.result;
        writeln!(
            md,
            "| {} | `{}` | {:.0} | {} | {} | {} | {:.2} | {} | {} | {} | {:.1} M | {} | {:.4} | {:.1} | {:.1} | {:.1} | {} |",
            run.config.name,
            if run.config.flags.is_empty() {
                "(defaults)"
            } else {
                run.config.flags
            },
            r.seconds,
            r.steps,
            cell(psnr_at(log, 30.0)?),
            cell(psnr_at(log, 60.0)?),
            r.final_test_psnr,
            cell(r.final_test_psnr_view_mean),
            cell(r.train_views_psnr),
            r.final_test_ssim.map_or("-".into(), |v| format!("{v:.4}")),
            r.parameters as f64 / 1e6,
            r.peak_resident_bytes
                .map_or("-".into(), |b| format!("{:.2} GB", b as f64 / 1e9)),
            r.held_out_haze,
            phase(run, "forward") + phase(run, "backward"),
            phase(run, "optimiser"),
            phase(run, "occupancy"),
            cell(reach(log, NERFACTO_CPU[3].1)?.map(|r| r.seconds)),
        )?;
    }
    writeln!(
        md,
        "\nThe anchor, nerfacto on this machine's CPU (the model issue's run, not this report's): {} dB after \
         {} s, peak memory {:.1} GB, about {} s to render one view. \"s to 16.4 dB\" is when a run first \
         reaches nerfacto's 300 s PSNR, and \"dB at 30 s\" the PSNR at 30 s, each read linearly between \
         the two evaluations around it (evaluations are a twentieth of the budget apart).\n",
        NERFACTO_CPU[3].1,
        NERFACTO_CPU[3].0,
        NERFACTO_PEAK_BYTES / 1e9,
        NERFACTO_RENDER_SECONDS
    )?;
    if let (Some(a), Some(log)) = (outside, &outside_log) {
        against_outside(&mut md, a, log, runs, &logs)?;
    }
    writeln!(md, "![held-out PSNR against training seconds](psnr-vs-seconds.png)\n")?;
    // The held-out view of the defaults' run, as fogray fit --out wrote it.
    if let Some(run) = runs.iter().rev().find(|r| r.config.flags.is_empty()) {
        if let Some(name) = held_out_view(out, run.config.name)? {
            writeln!(
                md,
                "A held-out view after the {} s run `{}`: photograph, render, error (x4):\n\n![held-out view]({name})\n",
                run.seconds_budget, run.config.name
            )?;
        }
    }
    // Whole or not at all, as every fogray writer: a full disk or Ctrl-C never leaves a
    // truncated report in place of the last one.
    fogray_data::write_atomic(&out.join("report.md"), |w| w.write_all(md.as_bytes()))?;
    let json = serde_json::to_string_pretty(&serde_json::json!({ "stamp": stamp, "runs": runs, "anchor": outside }))?;
    fogray_data::write_atomic(&out.join("report.json"), |w| w.write_all(json.as_bytes()))?;
    Ok(())
}

/// Each run against an outside pipeline's run: when each first reached the PSNR the outside
/// run ends at, and how many times sooner than it.
fn against_outside(
    md: &mut String,
    anchor: &Anchor,
    log: &[LogEntry],
    runs: &[Run],
    logs: &[Vec<LogEntry>],
) -> Result<()> {
    // Each comparison carries the anchor's target and when the anchor reached it.
    let against: Vec<_> = logs
        .iter()
        .map(|own| against_anchor(own, log))
        .collect::<Result<_, _>>()?;
    let Some(first) = against.first() else {
        return Ok(());
    };
    let target = first.target_psnr;
    writeln!(
        md,
        "Against {}: {:.2} dB after {:.0} s (first reached at {:.1} s). {}\n",
        anchor.name,
        target,
        log.last().map_or(f64::NAN, |e| e.seconds),
        first.anchor.seconds,
        anchor.note.as_deref().unwrap_or("")
    )?;
    writeln!(md, "| run | s to {target:.2} dB | times sooner |")?;
    writeln!(md, "|---|---|---|")?;
    for (run, versus) in runs.iter().zip(&against) {
        writeln!(
            md,
            "| {} | {} | {} |",
            run.config.name,
            cell(versus.run.map(|r| r.seconds)),
            versus.speedup.map_or("-".into(), |x| format!("{x:.0}x")),
        )?;
    }
    writeln!(md)?;
    Ok(())
}

/// The held-out view the report shows, as a file under `out`: the first of the run's views
/// (copied there), or, where the run's folder is gone (a `--replot` elsewhere), the view an
/// earlier report copied.
fn held_out_view(out: &Path, run: &str) -> Result<Option<String>> {
    let dir = out.join("runs").join(run).join("test");
    let pngs = |dir: &Path, keep: &dyn Fn(&str) -> bool| -> Result<Vec<PathBuf>> {
        let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("{}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.file_name().is_some_and(|n| keep(&n.to_string_lossy())))
            .collect();
        found.sort();
        Ok(found)
    };
    if !dir.is_dir() {
        let earlier = pngs(out, &|n| n.starts_with("held-out-") && n.ends_with(".png"))?;
        return Ok(earlier
            .first()
            .and_then(|p| p.file_name())
            .map(|n| n.to_string_lossy().into_owned()));
    }
    // The view itself, not its depth map.
    let views = pngs(&dir, &|n| n.ends_with(".png") && !n.ends_with("-depth.png"))?;
    let Some(view) = views.first() else {
        return Ok(None);
    };
    let name = format!(
        "held-out-{}",
        view.file_name().map_or("view".into(), |n| n.to_string_lossy())
    );
    std::fs::copy(view, out.join(&name))?;
    Ok(Some(name))
}
