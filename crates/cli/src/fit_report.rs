//! What `fogray fit --out DIR` leaves: a report a person reads without running anything
//! (`report.md`: the final figures, PSNR and SSIM against training seconds, every held-out view
//! beside its photograph, the settings, the machine and the command), and the same as data
//! (`fit.json`).

use std::fmt::Write as _;
use std::path::Path;

use fogray_fit::dataset::Dataset;
use fogray_fit::depth::write_depth_png;
use fogray_fit::images::write_comparison_png;
use fogray_fit::plots::{self, Curve, Metric, XAxis};
use fogray_fit::render::RenderedView;
use fogray_fit::settings::FitSettings;
use fogray_fit::stamp::Stamp;

use crate::error::CliError;
use crate::fit::{FitPlan, FitSummary};

/// The narrowest a held-out view's panel is drawn, in pixels: its title ("|render - exact| x 4"
/// in an 18-pixel font) takes about 180, and a narrower view's titles run into each other.
const MIN_PANEL_WIDTH: usize = 200;

/// The report's folders under `--out` (each checked before the fit trains: a link there into
/// the dataset, or a file in its place, is refused before any work).
pub const REPORT_FOLDERS: [&str; 1] = ["test"];

/// The fewest bytes a PNG file takes: its signature (8) and the frames of its header chunk
/// (25 with the header's 13 bytes), of one data chunk (12) and of its end chunk (12).
pub const PNG_FLOOR: u64 = 8 + 25 + 12 + 12;

/// The report's files besides the held-out views' pictures: the two plots as PNG and SVG,
/// fit.json and report.md.
const FIXED_PNGS: u64 = 2;
const FIXED_TEXTS: u64 = 4;

/// The fewest bytes the report of a fit with `held_out` views takes on its disk: a
/// comparison PNG for each view and the two plots' PNGs at [`PNG_FLOOR`], the plots' SVGs,
/// fit.json and report.md at a byte each (what [`crate::disk_room`] checks before a fit trains).
pub fn report_floor(held_out: usize) -> u64 {
    (held_out as u64)
        .saturating_add(FIXED_PNGS)
        .saturating_mul(PNG_FLOOR)
        .saturating_add(FIXED_TEXTS)
}

/// How many times a view `width` pixels wide is magnified in its panels: the least whole
/// factor that makes it [`MIN_PANEL_WIDTH`] wide (1 for views at least that wide).
fn panel_scale(width: usize) -> u32 {
    MIN_PANEL_WIDTH.div_ceil(width.max(1)) as u32
}

/// Writes `DIR/test/<name>.png` (photograph | render | error x4) and `DIR/test/<name>-depth.png`
/// for each held-out view (`held_out`: its render with depth), `DIR/psnr.{png,svg}`,
/// `DIR/ssim.{png,svg}`, `DIR/fit.json` (the summary) and `DIR/report.md`.
///
/// Errors: a file that cannot be written, naming it.
pub fn write_out(
    dir: &Path,
    plan: &FitPlan,
    settings: &FitSettings,
    data: &Dataset,
    summary: &FitSummary,
    held_out: &[RenderedView],
) -> Result<(), CliError> {
    let views = dir.join(REPORT_FOLDERS[0]);
    std::fs::create_dir_all(&views).map_err(CliError::file("create", &views))?;
    for (t, view) in data.test.iter().zip(held_out) {
        let render = &view.color;
        let scale = panel_scale(t.size()[1]);
        write_comparison_png(
            &views.join(format!("{}.png", t.name)),
            t.image.view(),
            render.view(),
            4.0,
            scale,
        )?;
        if let Some(depth) = &view.depth {
            write_depth_png(
                &views.join(format!("{}-depth.png", t.name)),
                depth.view(),
                &t.name,
                scale,
            )?;
        }
    }
    if let Some(framing) = &summary.space.framing {
        framing.write_png(&dir.join("framing.png"), data)?;
    }
    let curve = [Curve {
        label: "fogray fit".into(),
        log: summary.log,
    }];
    plots::metric_curves(&dir.join("psnr"), &curve, XAxis::Seconds, Metric::Psnr, &[])?;
    plots::metric_curves(&dir.join("ssim"), &curve, XAxis::Seconds, Metric::Ssim, &[])?;
    let path = dir.join("fit.json");
    let json = serde_json::to_string_pretty(summary)?;
    fogray_data::write_atomic(&path, |out| out.write_all(json.as_bytes()))?;
    let stamp = Stamp::now(&command_line());
    let names: Vec<&str> = data.test.iter().map(|t| t.name.as_str()).collect();
    let text = markdown(plan, settings, summary, &stamp, &names)?;
    let path = dir.join("report.md");
    Ok(fogray_data::write_atomic(&path, |out| out.write_all(text.as_bytes()))?)
}

/// The command as it was typed, each argument quoted where a shell would need it.
fn command_line() -> String {
    std::env::args()
        .map(|a| {
            let plain = !a.is_empty() && a.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=,:+@%".contains(c));
            if plain {
                a
            } else {
                format!("'{}'", a.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// `show(v)`, or "-" for a value that was not measured (NaN).
fn number(v: f64, show: impl Fn(f64) -> String) -> String {
    if v.is_nan() {
        "-".into()
    } else {
        show(v)
    }
}

/// report.md's text; `names` are the held-out views' names, in order.
fn markdown(
    plan: &FitPlan,
    settings: &FitSettings,
    s: &FitSummary,
    stamp: &Stamp,
    names: &[&str],
) -> Result<String, CliError> {
    let mut md = String::new();
    let [h, w] = s.size;
    let w_ = CliError::Report;
    writeln!(md, "# fogray fit of {}\n", plan.data.display()).map_err(w_)?;
    writeln!(md, "{}\n", stamp.markdown()).map_err(w_)?;
    writeln!(
        md,
        "Trained on {} views of {w}x{h}, judged on {} held-out views it never saw, measured off the \
         training clock.\n",
        s.views[0], s.views[1]
    )
    .map_err(w_)?;
    let framing = match &s.space.framing {
        Some(f) => format!(
            ", inner region centred at ({:.3}, {:.3}, {:.3}) with half-side {:.3}",
            f.centre[0], f.centre[1], f.centre[2], f.radius
        ),
        None => String::new(),
    };
    writeln!(md, "Space: **{}**{framing}: {}.\n", s.space.space, s.space.why).map_err(w_)?;
    if s.space.framing.is_some() {
        writeln!(
            md,
            "![the cameras (training blue, held-out orange) and the inner region (green), seen from above](framing.png)\n"
        )
        .map_err(w_)?;
    }
    writeln!(md, "| figure | value |\n|---|---|").map_err(w_)?;
    let rows = [
        (
            "held-out PSNR (of the mean squared error over the views)",
            format!("{:.2} dB", s.final_test_psnr),
        ),
        (
            "held-out PSNR, the mean of the views' (the NeRF literature's and nerfstudio's figure)",
            format!("{:.2} dB", s.final_test_psnr_view_mean),
        ),
        ("held-out SSIM", number(s.final_test_ssim, |v| format!("{v:.4}"))),
        (
            "PSNR on as many training views (the gap to held-out: how much the fit learnt its own views)",
            format!("{:.2} dB", s.train_views_psnr),
        ),
        ("training seconds (evaluations excluded)", format!("{:.1}", s.seconds)),
        ("steps", s.steps.to_string()),
        (
            "steps a second",
            format!("{:.1}", s.steps as f64 / s.seconds.max(f64::MIN_POSITIVE)),
        ),
        ("trainable values", s.parameters.to_string()),
        (
            "peak resident memory",
            s.peak_resident_bytes
                .map_or("not known".into(), |b| format!("{:.2} GB", b as f64 / 1e9)),
        ),
        (
            "held-out pixels with opacity in (0.05, 0.95)",
            format!("{:.4}", s.held_out_haze),
        ),
        ("seconds to load the data", format!("{:.1}", s.load_seconds)),
    ];
    for (name, value) in rows {
        writeln!(md, "| {name} | {value} |").map_err(w_)?;
    }
    writeln!(md, "\n## Against training time\n").map_err(w_)?;
    writeln!(md, "![held-out PSNR against training seconds](psnr.png)\n").map_err(w_)?;
    writeln!(md, "![held-out SSIM against training seconds](ssim.png)\n").map_err(w_)?;
    writeln!(
        md,
        "| step | seconds | train loss | PSNR (dB) | SSIM |\n|---|---|---|---|---|"
    )
    .map_err(w_)?;
    for e in s.log {
        writeln!(
            md,
            "| {} | {:.1} | {} | {:.2} | {} |",
            e.step,
            e.seconds,
            number(e.train_loss, |v| format!("{v:.3e}")),
            e.test_psnr,
            number(e.test_ssim, |v| format!("{v:.4}"))
        )
        .map_err(w_)?;
    }
    writeln!(md, "\n## Held-out views\n").map_err(w_)?;
    writeln!(
        md,
        "The held-out PSNR is set by the mean squared error over all views, so a view's share of the \
         squared error says how much of the loss it carries; the mean of the views' PSNRs weighs each \
         view by its decibels instead.\n"
    )
    .map_err(w_)?;
    writeln!(md, "| view | PSNR (dB) | share of the squared error |\n|---|---|---|").map_err(w_)?;
    for v in &s.held_out_views {
        writeln!(
            md,
            "| {} | {:.2} | {:.3} |",
            v.name, v.score.psnr, v.score.share_of_error
        )
        .map_err(w_)?;
    }
    writeln!(
        md,
        "\nEach row: the photograph, the render, the absolute error times 4, and the render's expected \
         depth (scene units; grey where the opacity is below 0.1).\n"
    )
    .map_err(w_)?;
    for name in names {
        writeln!(
            md,
            "![{name}](test/{name}.png) ![{name}: depth](test/{name}-depth.png)\n"
        )
        .map_err(w_)?;
    }
    writeln!(md, "## Where a step went\n\n```\n{}```\n", s.profile).map_err(w_)?;
    writeln!(md, "## Settings\n").map_err(w_)?;
    writeln!(
        md,
        "Data: `{}`, downscale {}, background {:?}.\n",
        plan.data.display(),
        plan.data_args.downscale,
        plan.data_args.background
    )
    .map_err(w_)?;
    writeln!(md, "```json\n{}\n```", serde_json::to_string_pretty(settings)?).map_err(w_)?;
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn narrow_views_are_magnified_until_their_titles_fit() {
        // Lego at --downscale 4 stays as it is; the capture's 120-pixel views double.
        assert_eq!(panel_scale(200), 1);
        assert_eq!(panel_scale(800), 1);
        assert_eq!(panel_scale(120), 2);
        assert_eq!(panel_scale(199), 2);
        assert_eq!(panel_scale(50), 4);
    }
}
