//! Writing the report's files into one directory: the curves, `report.md`, `report.json` and
//! the pictures of the best configuration.

use std::path::{Path, PathBuf};

use fogray_lab::machine::Bandwidth;
use fogray_lab::stamp::Stamp;
use serde::Serialize;

use crate::scene::Scene;
use fogray::fit::dataset::Dataset;
use fogray::fit::images::write_comparison_png;
use fogray::fit::plots::{metric_curves, Curve, Metric, XAxis};
use fogray::fit::settings::Budget;
use fogray_lab::curves::{AgainstAnchor, Anchor, FusedVsTaped, OccupancyVsUniform};
use fogray_lab::slices::{planes, write_planes_png, Colouring, PlaneImage, PlaneRow};
use fogray_lab::sweep::{best, ConfigRun, SameSteps};

use fogray_lab::sweep::pairs::{anchor_rows, fused_vs_taped_rows, occupancy_vs_uniform_rows};

use super::markdown::{report, ReportContext};
use super::ReportError;

/// Magnification of the test views in their PNGs.
const SCALE: u32 = 4;
/// The density slices' colour range (extinction per unit length), on a log scale.
const LOWEST_DENSITY: f64 = 0.01;
const HIGHEST_DENSITY: f64 = 100.0;

/// What the report says about how it was made.
#[derive(Debug, Clone)]
pub struct ReportSetup<'a> {
    /// Date, machine and the command that ran.
    pub stamp: &'a Stamp,
    /// The command that reproduces the report.
    pub reproduce: &'a str,
    /// Every run's budget.
    pub budget: Budget,
    /// Rays per step.
    pub batch: usize,
    /// One sentence on the problem.
    pub problem: &'a str,
    /// Test evaluations each run made over its budget.
    pub evaluations: usize,
    /// An outside pipeline's run to set beside the configurations, if given.
    pub anchor: Option<&'a Anchor>,
    /// Fused against taped over the same steps, as
    /// [`same_steps`](fn@fogray_lab::sweep::same_steps) gives them (empty for none).
    pub same_steps: &'a [(String, SameSteps)],
    /// The machine's memory bandwidth before and after the runs, if measured.
    pub bandwidth: Option<MachineBandwidth>,
}

/// The machine's memory bandwidth ([`fogray_lab::machine::triad`]) measured just before the first
/// run and just after the last: on a shared machine it moves from hour to hour, and the
/// timed figures with it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MachineBandwidth {
    /// Before the first run.
    pub before: Bandwidth,
    /// After the last run.
    pub after: Bandwidth,
}

#[derive(Serialize)]
struct AnchorJson<'a> {
    #[serde(flatten)]
    anchor: &'a Anchor,
    against: Vec<Named<AgainstAnchor>>,
}

#[derive(Serialize)]
struct ReportJson<'a> {
    stamp: &'a Stamp,
    reproduce: &'a str,
    budget_seconds: Option<f64>,
    budget_steps: Option<usize>,
    batch: usize,
    configurations: &'a [ConfigRun],
    fused_vs_taped_same_steps: Vec<Named<SameSteps>>,
    fused_vs_taped: Vec<Named<FusedVsTaped>>,
    occupancy_vs_uniform: Vec<Named<OccupancyVsUniform>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    anchor: Option<AnchorJson<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    machine_bandwidth: Option<MachineBandwidth>,
}

#[derive(Serialize)]
struct Named<T> {
    name: String,
    #[serde(flatten)]
    comparison: T,
}

fn named<T: Copy>(rows: &[(String, T)]) -> Vec<Named<T>> {
    rows.iter()
        .map(|(name, comparison)| Named {
            name: name.clone(),
            comparison: *comparison,
        })
        .collect()
}

/// Writes `text` to `path` whole or not at all (through [`fogray_data::write_atomic`]), so
/// that a full disk or Ctrl-C never leaves a truncated report in place of the last one.
fn write_text(path: &Path, text: &str) -> Result<(), ReportError> {
    fogray_data::write_atomic(path, |out| out.write_all(text.as_bytes())).map_err(|e| ReportError::Write {
        path: path.to_path_buf(),
        // The path is said once, by this error.
        message: match e {
            fogray_data::DataError::Io { message, .. } => message,
            other => other.to_string(),
        },
    })
}

fn remove_if_present(path: &Path) -> Result<(), ReportError> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(ReportError::Write {
            path: path.to_path_buf(),
            message: e.to_string(),
        }),
        _ => Ok(()),
    }
}

/// The pictures of the best run (and of the best occupancy run's grid); returns their markdown.
fn pictures(dir: &Path, runs: &[ConfigRun], data: &Dataset, scene: &Scene) -> Result<String, ReportError> {
    let Some(top) = best(runs) else {
        return Ok(String::new());
    };
    let mut md = format!(
        "## The best configuration: {} ({:.2} dB)\n\nEach test view: the exact photograph, the final render and |render - exact| x 4.\n\n",
        top.name, top.final_test_psnr
    );
    for (t, render) in data.test.iter().zip(&top.pictures.renders) {
        let name = format!("test-view-{}.png", t.name);
        write_comparison_png(&dir.join(&name), t.image.view(), render.view(), 4.0, SCALE)?;
        md += &format!("![test view {}]({name})\n\n", t.name);
    }
    if let Some(n) = top.pictures.density.first().map(|p| p.values.nrows()) {
        // Decades: the fitted density spans empty space (softplus of the shift, about 0.02)
        // to the hundreds inside opaque matter, which a linear scale shows as one colour.
        let log = |planes: &[PlaneImage]| -> Vec<PlaneImage> {
            planes
                .iter()
                .map(|p| PlaneImage {
                    axis: p.axis,
                    values: p.values.mapv(|v| v.max(LOWEST_DENSITY).log10()),
                })
                .collect()
        };
        let exact = log(&planes(&top.pictures.density_box, n, |p| scene.density_at(p)));
        let fitted = log(&top.pictures.density);
        let colouring = Colouring::Map {
            lo: LOWEST_DENSITY.log10(),
            hi: HIGHEST_DENSITY.log10(),
            label: format!(
                "log10 density (extinction\nper unit length), clamped\nto [{}, {}]",
                LOWEST_DENSITY.log10(),
                HIGHEST_DENSITY.log10()
            ),
        };
        let rows = [
            PlaneRow {
                title: "exact",
                planes: &exact,
            },
            PlaneRow {
                title: "fitted",
                planes: &fitted,
            },
        ];
        write_planes_png(
            &dir.join("density-slices.png"),
            &rows,
            &colouring,
            (384 / n as u32).max(1),
        )?;
        md += "The density on the planes through the centre of the box, log scale: the scene's (top) and the fitted model's (bottom).\n\n![density slices](density-slices.png)\n\n";
    }
    let occupancy_runs = runs.iter().filter(|r| r.pictures.occupancy.is_some());
    if let Some(occ) = occupancy_runs.reduce(|a, b| if b.final_test_psnr > a.final_test_psnr { b } else { a }) {
        if let Some(planes) = &occ.pictures.occupancy {
            let r = planes.first().map_or(1, |p| p.values.nrows()) as u32;
            let rows = [PlaneRow {
                title: &format!("{} occupancy", occ.name),
                planes,
            }];
            write_planes_png(
                &dir.join("occupancy-slices.png"),
                &rows,
                &Colouring::Occupied,
                (384 / r).max(1),
            )?;
            md += &format!(
                "The final occupancy grid of {} ({:.1} % of cells occupied), its middle plane of cells across each axis.\n\n![occupancy slices](occupancy-slices.png)\n\n",
                occ.name,
                100.0 * occ.occupied_fraction
            );
        }
    }
    Ok(md)
}

/// Writes into `dir` (created if missing): `psnr-vs-seconds.svg/.png` and
/// `psnr-vs-steps.svg/.png` (one curve per run), with an anchor `psnr-vs-seconds-log.svg/.png`
/// (the runs and the anchor, log-scaled seconds; without one, an earlier report's such plot is
/// removed), `report.md`, `report.json` (every run's log and figures, the comparisons, the
/// stamp and the machine's bandwidth), and pictures of the best run: each test view's photograph, render and error
/// (`test-view-NNN.png`), `density-slices.png` and, where a run sampled with an occupancy
/// grid, `occupancy-slices.png`. Returns `report.md`'s path.
///
/// Errors: [`ReportError::Write`] or [`ReportError::Image`] for a file that cannot be written,
/// [`ReportError::Curve`] for a log that is not a curve, [`ReportError::Config`] for no runs.
pub fn write_report(
    dir: &Path,
    runs: &[ConfigRun],
    data: &Dataset,
    scene: &Scene,
    setup: &ReportSetup<'_>,
) -> Result<PathBuf, ReportError> {
    if runs.is_empty() {
        return Err(ReportError::Config("no runs to report".into()));
    }
    std::fs::create_dir_all(dir).map_err(|e| ReportError::Write {
        path: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let curves: Vec<Curve<'_>> = runs
        .iter()
        .map(|r| Curve {
            label: r.name.clone(),
            log: &r.log,
        })
        .collect();
    // Taped dashed: against steps it follows its fused twin (the same arithmetic).
    let taped: Vec<usize> = (0..runs.len()).filter(|&i| runs[i].method == "taped").collect();
    metric_curves(
        &dir.join("psnr-vs-seconds"),
        &curves,
        XAxis::Seconds,
        Metric::Psnr,
        &taped,
    )?;
    metric_curves(&dir.join("psnr-vs-steps"), &curves, XAxis::Steps, Metric::Psnr, &taped)?;
    let anchor_plot = dir.join("psnr-vs-seconds-log");
    match setup.anchor {
        Some(anchor) => {
            let log = anchor.entries();
            let mut with_anchor = curves.clone();
            with_anchor.push(Curve {
                label: anchor.name.clone(),
                log: &log,
            });
            metric_curves(&anchor_plot, &with_anchor, XAxis::LogSeconds, Metric::Psnr, &taped)?;
        }
        // An earlier report's plot with an anchor would stand beside curves it does not show.
        None => {
            for ext in ["png", "svg"] {
                remove_if_present(&anchor_plot.with_extension(ext))?;
            }
        }
    }
    let pictures = pictures(dir, runs, data, scene)?;
    let against_anchor = setup.anchor.map(|a| anchor_rows(runs, a)).transpose()?;
    let fused_vs_taped = fused_vs_taped_rows(runs)?;
    let occupancy_vs_uniform = occupancy_vs_uniform_rows(runs, setup.batch)?;
    let ctx = ReportContext {
        stamp: setup.stamp,
        reproduce: setup.reproduce,
        budget: setup.budget,
        problem: setup.problem,
        evaluations: setup.evaluations,
        anchor: setup.anchor.zip(against_anchor.as_deref()),
        pictures: &pictures,
        same_steps: setup.same_steps,
        bandwidth: setup.bandwidth,
        fused_vs_taped: &fused_vs_taped,
        occupancy_vs_uniform: &occupancy_vs_uniform,
    };
    let md_path = dir.join("report.md");
    write_text(&md_path, &report(runs, &ctx)?)?;
    let (budget_seconds, budget_steps) = match setup.budget {
        Budget::Seconds(s) => (Some(s), None),
        Budget::Steps(n) => (None, Some(n)),
    };
    let json = ReportJson {
        stamp: setup.stamp,
        reproduce: setup.reproduce,
        budget_seconds,
        budget_steps,
        batch: setup.batch,
        configurations: runs,
        fused_vs_taped_same_steps: named(setup.same_steps),
        fused_vs_taped: named(&fused_vs_taped),
        occupancy_vs_uniform: named(&occupancy_vs_uniform),
        anchor: setup.anchor.zip(against_anchor).map(|(anchor, rows)| AnchorJson {
            anchor,
            against: named(&rows),
        }),
        machine_bandwidth: setup.bandwidth,
    };
    let text = serde_json::to_string_pretty(&json).map_err(|e| ReportError::Write {
        path: dir.join("report.json"),
        message: e.to_string(),
    })?;
    write_text(&dir.join("report.json"), &(text + "\n"))?;
    Ok(md_path)
}
