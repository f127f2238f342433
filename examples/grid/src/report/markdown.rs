//! The report's tables, as numbers ([`checkpoints`], [`config_rows`]; the pairs of
//! configurations are fogray-lab's [`sweep::pairs`](fogray_lab::sweep::pairs)) and as markdown
//! ([`report`]).

use fogray::fit::settings::Budget;
use fogray_lab::curves::{psnr_at, AgainstAnchor, Anchor, FusedVsTaped, OccupancyVsUniform};
use fogray_lab::stamp::Stamp;
use fogray_lab::sweep::{ConfigRun, SameSteps};

use super::write::MachineBandwidth;
use super::ReportError;

/// The training times the table reads the PSNR at: a quarter, half and all of a budget of
/// seconds; for a budget of steps (whose runs stop at different times), of the shortest run's
/// training time.
pub fn checkpoints(budget: Budget, runs: &[ConfigRun]) -> Vec<f64> {
    let total = match budget {
        Budget::Seconds(s) => s,
        Budget::Steps(_) => runs.iter().map(|r| r.seconds).fold(f64::INFINITY, f64::min),
    };
    if total.is_finite() {
        vec![total / 4.0, total / 2.0, total]
    } else {
        Vec::new()
    }
}

/// One configuration's row of the main table.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigRow {
    /// The configuration's name.
    pub name: String,
    /// Test PSNR at each checkpoint (`None` where the run stopped before it).
    pub psnr_at: Vec<Option<f64>>,
    /// Test PSNR at the end.
    pub final_psnr: f64,
    /// Steps done.
    pub steps: usize,
    /// Training seconds.
    pub seconds: f64,
    /// Steps per training second.
    pub steps_per_second: f64,
    /// Mean samples per training ray.
    pub samples_per_ray: f64,
    /// Fraction of occupied cells at the end.
    pub occupied_fraction: f64,
}

/// The main table's rows. Errors: [`ReportError::Curve`] for a log that is not a curve.
pub fn config_rows(runs: &[ConfigRun], checkpoints: &[f64]) -> Result<Vec<ConfigRow>, ReportError> {
    runs.iter()
        .map(|r| {
            Ok(ConfigRow {
                name: r.name.clone(),
                psnr_at: checkpoints
                    .iter()
                    .map(|&t| psnr_at(&r.log, t))
                    .collect::<Result<_, _>>()?,
                final_psnr: r.final_test_psnr,
                steps: r.steps,
                seconds: r.seconds,
                steps_per_second: r.steps as f64 / r.seconds,
                samples_per_ray: r.samples_per_ray_mean,
                occupied_fraction: r.occupied_fraction,
            })
        })
        .collect()
}

fn num(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.decimals$}"),
        Some(v) => format!("{v}"),
        None => "-".into(),
    }
}

/// What the markdown needs besides the runs.
#[derive(Debug, Clone)]
pub struct ReportContext<'a> {
    /// Date, machine and command.
    pub stamp: &'a Stamp,
    /// The command that reproduces the report, shown at the top.
    pub reproduce: &'a str,
    /// The budget every run had.
    pub budget: Budget,
    /// A sentence on the problem (grid, views, image size).
    pub problem: &'a str,
    /// Test evaluations each run makes over its budget (besides the one at the start).
    pub evaluations: usize,
    /// An outside pipeline's run to compare with, if given, and every configuration against
    /// it (as [`anchor_rows`](fogray_lab::sweep::pairs::anchor_rows) gives them).
    pub anchor: Option<(&'a Anchor, &'a [(String, AgainstAnchor)])>,
    /// Markdown for the pictures section (images and captions), or empty.
    pub pictures: &'a str,
    /// Fused against taped over the same steps, as
    /// [`same_steps`](fn@fogray_lab::sweep::same_steps) gives them.
    pub same_steps: &'a [(String, SameSteps)],
    /// Fused against taped at the first crossing, as
    /// [`fused_vs_taped_rows`](fogray_lab::sweep::pairs::fused_vs_taped_rows) gives them.
    pub fused_vs_taped: &'a [(String, FusedVsTaped)],
    /// Occupancy against uniform, as
    /// [`occupancy_vs_uniform_rows`](fogray_lab::sweep::pairs::occupancy_vs_uniform_rows) gives
    /// them.
    pub occupancy_vs_uniform: &'a [(String, OccupancyVsUniform)],
    /// The machine's memory bandwidth before and after the runs, if measured.
    pub bandwidth: Option<MachineBandwidth>,
}

/// One sentence on the machine's bandwidth around the runs, in GB/s (10^9 bytes a second).
pub fn bandwidth_sentence(b: &MachineBandwidth) -> String {
    format!(
        "The machine's memory bandwidth (a STREAM triad, {} threads) was {:.1} GB/s just before the \
         first run and {:.1} GB/s just after the last; on a shared machine it moves from hour to hour, \
         and the timed figures with it: compare reports measured at about the same bandwidth.",
        b.before.threads,
        b.before.bytes_per_sec / 1e9,
        b.after.bytes_per_sec / 1e9
    )
}

fn same_steps_section(pairs: &[(String, SameSteps)]) -> String {
    let mut md = String::from("## Fused against taped: time to the same PSNR\n\n");
    md += "| sampling | steps | taped s | fused s | taped final PSNR (dB) | fused final PSNR (dB) | fused speed-up |\n|---|---|---|---|---|---|---|\n";
    for (name, c) in pairs {
        md += &format!(
            "| {name} | {} | {} | {} | {} | {} | {} |\n",
            c.steps,
            num(Some(c.taped.seconds), 2),
            match c.fused_again {
                Some(again) => format!("{} / {}", num(Some(c.fused.seconds), 2), num(Some(again.seconds), 2)),
                None => num(Some(c.fused.seconds), 2),
            },
            num(Some(c.taped.final_test_psnr), 2),
            num(Some(c.fused.final_test_psnr), 2),
            c.speedup.map_or("-".into(), |x| format!("{x:.2} x"))
        );
    }
    let extra = pairs.iter().any(|(_, c)| c.extra_runs);
    md += if extra {
        "\nEach pair trained again, after the runs above, for the steps the taped run made in the \
         budget, each with its schedule (growth, annealing) over those steps and one test \
         evaluation at the end: fused, taped, then fused again (the fused s column gives both), \
         so that the long taped run lies between two short fused ones and a change of the \
         machine's speed during it moves both sides; the speed-up is the taped seconds over the \
         mean of the fused ones."
    } else {
        "\nEach pair is the two runs above, which made the same steps."
    };
    md += " The fused ops and their taped twins do the same arithmetic, so the two end at the \
           same PSNR up to rounding, and the ratio of their training seconds is the speed-up to \
           that PSNR. It is not read off the curves: a run's schedule is a fraction of its budget, \
           so partway through its run the faster method is still on a coarser grid at a higher \
           learning rate than a run of that length would be, and where the curves flatten, the \
           time at which one run first passes the other's final PSNR (below) says more about the \
           schedule than about the ops.\n\n";
    md
}

fn anchor_section(anchor: &Anchor, rows: &[(String, AgainstAnchor)]) -> String {
    // Every row has the anchor's own target and time.
    let Some((_, first)) = rows.first() else {
        return String::new();
    };
    let mut md = format!("## Against an outside pipeline: {}\n\n", anchor.name);
    if let Some(note) = &anchor.note {
        md += &format!("{note}\n\n");
    }
    md += "![test PSNR against training seconds, log scale, with the outside pipeline](psnr-vs-seconds-log.png)\n\n";
    md += &format!(
        "The outside pipeline ends at {} dB after {} s of training, first reaching it at {} s.\n\n",
        num(Some(first.target_psnr), 2),
        num(anchor.log.last().map(|p| p.seconds), 1),
        num(Some(first.anchor.seconds), 1)
    );
    md += "| configuration | s to reach the outside pipeline's final PSNR | speed-up |\n|---|---|---|\n";
    for (name, c) in rows {
        md += &format!(
            "| {name} | {} | {} |\n",
            num(c.run.map(|r| r.seconds), 2),
            c.speedup.map_or("-".into(), |x| format!("{x:.1} x"))
        );
    }
    md += "\nThe seconds are read as in the tables above (the first crossing, interpolated between \
           evaluations); `-` where a configuration never reached it. Both runs' seconds are \
           training seconds, evaluations excluded; the outside pipeline's come from its own log.\n\n";
    md
}

/// The whole of `report.md`. Errors: as [`config_rows`].
pub fn report(runs: &[ConfigRun], ctx: &ReportContext<'_>) -> Result<String, ReportError> {
    let points = checkpoints(ctx.budget, runs);
    let mut md = String::from("# fogray-grid: test PSNR against training time\n\n");
    md += &format!(
        "Reproduce with `{}` (on a quiet machine: the runs are timed).\n\n",
        ctx.reproduce
    );
    md += &format!("{}\n\n", ctx.stamp.markdown());
    if let Some(b) = &ctx.bandwidth {
        md += &format!("{}\n\n", bandwidth_sentence(b));
    }
    let budget = match ctx.budget {
        Budget::Seconds(s) => format!("{s} training seconds"),
        Budget::Steps(n) => format!("{n} steps"),
    };
    md += &format!(
        "{} Each configuration trains for {budget} (test evaluations excluded from the clock), one after another in one process.\n\n",
        ctx.problem
    );
    md += "![test PSNR against training seconds](psnr-vs-seconds.png)\n\n";
    md += "![test PSNR against training steps](psnr-vs-steps.png)\n\n";
    md += "## Configurations\n\n| configuration |";
    for t in &points {
        md += &format!(" PSNR at {} s (dB) |", (t * 1000.0).round() / 1000.0);
    }
    md += " final PSNR (dB) | steps | training s | steps/s | samples per ray | occupied fraction |\n|---|";
    md += &"---|".repeat(points.len() + 6);
    md += "\n";
    for row in config_rows(runs, &points)? {
        md += &format!("| {} |", row.name);
        for p in &row.psnr_at {
            md += &format!(" {} |", num(*p, 2));
        }
        md += &format!(
            " {} | {} | {} | {} | {} | {} |\n",
            num(Some(row.final_psnr), 2),
            row.steps,
            num(Some(row.seconds), 2),
            num(Some(row.steps_per_second), 2),
            num(Some(row.samples_per_ray), 1),
            num(Some(row.occupied_fraction), 3)
        );
    }
    md += &format!(
        "\nThe PSNR at a time is interpolated linearly between the two test evaluations around it \
         ({} per run, evenly spaced over the budget); `-` where the run stopped before that time. \
         Samples per ray are the mean over all training steps; the occupied fraction is the \
         occupancy grid's at the end (1 with uniform sampling).\n\n",
        ctx.evaluations
    );
    if !ctx.same_steps.is_empty() {
        md += &same_steps_section(ctx.same_steps);
    }
    let fvt = ctx.fused_vs_taped;
    if !fvt.is_empty() {
        md += "## Fused against taped within the timed runs: the first crossing\n\n";
        md += "| sampling | target PSNR (dB, the taped final) | taped s to reach it | fused s to reach it | fused speed-up |\n|---|---|---|---|---|\n";
        for (name, c) in fvt {
            md += &format!(
                "| {name} | {} | {} | {} | {} |\n",
                num(Some(c.target_psnr), 2),
                num(Some(c.taped.seconds), 2),
                num(Some(c.fused.seconds), 2),
                c.speedup.map_or("-".into(), |x| format!("{x:.2} x"))
            );
        }
        md += "\nThe target is the taped run's final PSNR, or the fused run's where that is lower \
               (with the same steps they differ only by rounding). The seconds to reach it are \
               interpolated linearly between the last evaluation below it and the first at or \
               above it (the first crossing).\n\n";
    }
    let ovu = ctx.occupancy_vs_uniform;
    if !ovu.is_empty() {
        md += "## Occupancy against uniform sampling at the same PSNR\n\n";
        md += "| method | target PSNR (dB, the lower final) | uniform samples per ray | occupancy samples per ray | occupancy / uniform | uniform s | occupancy s | occupancy speed-up |\n|---|---|---|---|---|---|---|---|\n";
        for (name, c) in ovu {
            md += &format!(
                "| {name} | {} | {} | {} | {} | {} | {} | {} |\n",
                num(Some(c.target_psnr), 2),
                num(c.uniform_samples_per_ray, 1),
                num(c.occupancy_samples_per_ray, 1),
                num(c.samples_per_ray_ratio, 3),
                num(Some(c.uniform.seconds), 2),
                num(Some(c.occupancy.seconds), 2),
                num(c.speedup, 2)
            );
        }
        md += "\nSamples per ray: the training samples drawn until the run first reached the target \
               PSNR, over the rays of those steps (both interpolated between evaluations).\n\n";
    }
    if let Some((anchor, rows)) = ctx.anchor {
        md += &anchor_section(anchor, rows);
    }
    md += ctx.pictures;
    Ok(md)
}
