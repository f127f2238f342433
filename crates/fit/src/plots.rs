//! Test PSNR (or SSIM) against training seconds (or steps), one curve per configuration, as SVG
//! and PNG, each written whole or not at all.
//!
//! ```
//! use fogray_fit::train::LogEntry;
//! use fogray_fit::plots::{metric_curves, Curve, Metric, XAxis};
//!
//! let log = [
//!     LogEntry { step: 0, seconds: 0.0, train_loss: f64::NAN, test_psnr: 10.0, test_ssim: 0.3, samples: 0 },
//!     LogEntry { step: 50, seconds: 2.0, train_loss: 0.01, test_psnr: 20.0, test_ssim: 0.8, samples: 6400 },
//! ];
//! let dir = std::env::temp_dir().join(format!("fogray-fit-plots-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let curves = [Curve { label: "fused".into(), log: &log }];
//! metric_curves(&dir.join("psnr"), &curves, XAxis::Seconds, Metric::Psnr, &[])?;
//! assert!(dir.join("psnr.png").exists() && dir.join("psnr.svg").exists());
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use fogray_data::write_atomic;

use crate::images::{canvas, not_written, save_canvas, ImageError};
use crate::train::LogEntry;

const FONT: &str = "sans-serif";
/// Twelve colours told apart on white (a report compares up to a dozen configurations); a
/// thirteenth curve repeats the first colour.
const COLORS: [RGBColor; 12] = [
    RGBColor(230, 120, 20),
    RGBColor(40, 90, 200),
    RGBColor(40, 160, 70),
    RGBColor(200, 40, 60),
    RGBColor(120, 70, 170),
    RGBColor(90, 90, 90),
    RGBColor(0, 170, 190),
    RGBColor(185, 150, 0),
    RGBColor(230, 100, 170),
    RGBColor(140, 85, 40),
    RGBColor(20, 40, 100),
    RGBColor(130, 195, 60),
];

/// The chart's size in pixels; the legend goes in a panel to its right, so that it never
/// hides a curve.
const CHART: (u32, u32) = (900, 520);
/// The legend's font size, and the pixels a character of it takes at most on average.
const LEGEND_FONT: u32 = 14;
const LEGEND_CHAR: u32 = 7;
/// Pixels from one legend entry to the next, and the sample line's length.
const LEGEND_ROW: i32 = 22;
const LEGEND_LINE: i32 = 28;

/// The legend panel's width for these labels.
fn legend_width(curves: &[Curve<'_>]) -> u32 {
    let chars = curves.iter().map(|c| c.label.chars().count()).max().unwrap_or(0) as u32;
    2 * 12 + LEGEND_LINE as u32 + 8 + LEGEND_CHAR * chars
}

/// What the horizontal axis shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XAxis {
    /// Training seconds (evaluations excluded).
    Seconds,
    /// Training seconds on a log scale (for runs of very different lengths; the evaluations at
    /// 0 s are left out).
    LogSeconds,
    /// Training steps.
    Steps,
}

impl XAxis {
    fn of(self, e: &LogEntry) -> f64 {
        match self {
            XAxis::Seconds | XAxis::LogSeconds => e.seconds,
            XAxis::Steps => e.step as f64,
        }
    }

    /// Whether the point can be drawn on this axis.
    fn shows(self, e: &LogEntry, metric: Metric) -> bool {
        metric.of(e).is_finite() && (self != XAxis::LogSeconds || e.seconds > 0.0)
    }
}

/// What the vertical axis shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Metric {
    /// Test PSNR in dB.
    Psnr,
    /// Test SSIM.
    Ssim,
}

impl Metric {
    fn of(self, e: &LogEntry) -> f64 {
        match self {
            Metric::Psnr => e.test_psnr,
            Metric::Ssim => e.test_ssim,
        }
    }

    /// The axis's range around the values `lo..hi`: whole decibels, or hundredths of SSIM.
    fn range(self, lo: f64, hi: f64) -> (f64, f64) {
        match (lo <= hi, self) {
            (false, _) => (0.0, 1.0),
            (true, Metric::Psnr) => ((lo - 1.0).floor(), (hi + 1.0).ceil()),
            (true, Metric::Ssim) => (
                ((lo - 0.02) * 100.0).floor() / 100.0,
                ((hi + 0.02) * 100.0).ceil() / 100.0,
            ),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Metric::Psnr => "test PSNR",
            Metric::Ssim => "test SSIM",
        }
    }

    fn axis(self) -> &'static str {
        match self {
            Metric::Psnr => "test PSNR (dB)",
            Metric::Ssim => "test SSIM",
        }
    }
}

/// One configuration's log, with its legend label.
#[derive(Debug, Clone)]
pub struct Curve<'a> {
    /// Shown in the legend.
    pub label: String,
    /// The evaluations, in order.
    pub log: &'a [LogEntry],
}

type DrawResult = Result<(), String>;

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curves: &[Curve<'_>],
    x: XAxis,
    metric: Metric,
    dashed: &[usize],
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let (root, legend) = root.split_horizontally(CHART.0);
    draw_legend(&legend, curves, dashed).map_err(err)?;
    let root = &root;
    let points = || curves.iter().flat_map(|c| c.log.iter()).filter(|e| x.shows(e, metric));
    let t_max = points().map(|e| x.of(e)).fold(0.0, f64::max).max(1e-3) * 1.05;
    let lo = points().map(|e| metric.of(e)).fold(f64::INFINITY, f64::min);
    let hi = points().map(|e| metric.of(e)).fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = metric.range(lo, hi);
    let mut builder = ChartBuilder::on(root);
    let against = match x {
        XAxis::Seconds | XAxis::LogSeconds => "training time",
        XAxis::Steps => "training steps",
    };
    builder
        .caption(format!("{} against {against}", metric.name()), (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56);
    if x == XAxis::LogSeconds {
        // From the decade below the first evaluation after 0 s.
        let t_min = points()
            .map(|e| e.seconds)
            .fold(f64::INFINITY, f64::min)
            .min(t_max / 10.0);
        let t_min = 10f64.powf(t_min.log10().floor());
        let chart = builder
            .build_cartesian_2d((t_min..t_max).log_scale(), lo..hi)
            .map_err(err)?;
        draw_curves(chart, curves, x, metric, dashed)
    } else {
        let chart = builder.build_cartesian_2d(0.0..t_max, lo..hi).map_err(err)?;
        draw_curves(chart, curves, x, metric, dashed)
    }
}

fn draw_curves<'a, DB, X>(
    mut chart: ChartContext<'a, DB, Cartesian2d<X, RangedCoordf64>>,
    curves: &[Curve<'_>],
    x: XAxis,
    metric: Metric,
    dashed: &[usize],
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    chart
        .configure_mesh()
        .x_desc(match x {
            XAxis::Seconds => "training seconds (evaluations excluded)",
            XAxis::LogSeconds => "training seconds (evaluations excluded), log scale",
            XAxis::Steps => "training steps",
        })
        .y_desc(metric.axis())
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    for (k, c) in curves.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let line = c
            .log
            .iter()
            .filter(|e| x.shows(e, metric))
            .map(|e| (x.of(e), metric.of(e)));
        let drawn = if dashed.contains(&k) {
            chart.draw_series(DashedLineSeries::new(line, 8, 5, color.stroke_width(2)))
        } else {
            chart.draw_series(LineSeries::new(line, color.stroke_width(2)))
        };
        drawn.map_err(err)?;
    }
    Ok(())
}

/// The legend, in its own panel: each curve's line (two dashes for a dashed one) and label,
/// top to bottom in the curves' order.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    curves: &[Curve<'_>],
    dashed: &[usize],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    // Level with the chart's plotting area (below its caption).
    let top = 50;
    for (k, c) in curves.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let y = top + LEGEND_ROW * k as i32;
        let x0 = 12;
        let segments = if dashed.contains(&k) {
            vec![(x0, x0 + 11), (x0 + 17, x0 + LEGEND_LINE)]
        } else {
            vec![(x0, x0 + LEGEND_LINE)]
        };
        for (a, b) in segments {
            area.draw(&PathElement::new(vec![(a, y), (b, y)], color.stroke_width(2)))?;
        }
        let style = TextStyle::from((FONT, LEGEND_FONT).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
        area.draw(&Text::new(c.label.clone(), (x0 + LEGEND_LINE + 8, y), style))?;
    }
    Ok(())
}

/// Writes `<stem>.svg` and `<stem>.png` with one curve of `metric` per entry of `curves`
/// against `x` (training seconds or steps), the curves whose indices are in `dashed` drawn
/// dashed (points where the metric is not finite are left out).
///
/// Errors: [`ImageError::Empty`] for no curve, [`ImageError::Write`] if a file cannot be drawn
/// or written.
pub fn metric_curves(
    stem: &Path,
    curves: &[Curve<'_>],
    x: XAxis,
    metric: Metric,
    dashed: &[usize],
) -> Result<(), ImageError> {
    if curves.is_empty() {
        return Err(ImageError::Empty);
    }
    let size = (CHART.0 + legend_width(curves), CHART.1);
    let svg = PathBuf::from(format!("{}.svg", stem.display()));
    let png = PathBuf::from(format!("{}.png", stem.display()));
    let wrap = |path: &Path| {
        let path = path.to_path_buf();
        move |message| ImageError::Write { path, message }
    };
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        draw(&root, curves, x, metric, dashed).map_err(wrap(&svg))?;
        root.present().map_err(|e| wrap(&svg)(e.to_string()))?;
    }
    write_atomic(&svg, |out| out.write_all(text.as_bytes())).map_err(|e| not_written(&svg, e))?;
    let mut pixels = canvas(size);
    {
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        draw(&root, curves, x, metric, dashed).map_err(wrap(&png))?;
        root.present().map_err(|e| wrap(&png)(e.to_string()))?;
    }
    save_canvas(&png, &pixels, size)
}
