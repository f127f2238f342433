//! The speed-against-error report: the time of one frame (forward and backward over the
//! disc's 288 rays for each of 4 model offsets) for each method, precision, early termination
//! threshold, sampling and number of samples per ray, against the worst error of the frame's
//! pixels with respect to their exact values; the configurations that no other beats in both
//! time and error (the Pareto front), and the recommendation read off that front.
//!
//! The time axis is per frame, not per sample: a configuration is chosen by what a whole job
//! costs, and 16 band samples beat 256 uniform ones only when the samples are counted.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use fogray::ops::{twins, Background, Composite, CompositeArrays, CompositeInputs, CompositeUpstream, CompositeWanted};
use fogray::tape::{Float, Tape};
use fogray_lab::stamp::Stamp;
use ndarray::{Array1, Array2, ArrayD};
use plotters::prelude::*;
use serde::Serialize;

use crate::error::DiscError;
use crate::sampling::{self, Sampling};
use crate::setup::Setup;
use crate::soft::Samples;

/// One configuration's speed and error.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub method: &'static str,
    pub precision: &'static str,
    pub sampling: Sampling,
    pub samples: usize,
    pub min_transmittance: f64,
    /// One frame's forward and backward (gradients for sigma and colour), all threads: the
    /// median of the runs [`Timing`] asks for, in microseconds.
    pub us_per_frame: f64,
    /// Interquartile range of those runs over their median.
    pub spread: f64,
    /// Worst |C - C_exact| over every pixel and channel.
    pub max_error: f64,
    /// No other configuration is at once faster and at least as accurate.
    pub pareto: bool,
}

/// How long each configuration is timed: until its runs add up to `min_seconds` and there are
/// at least `min_runs` of them, after one warm-up run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// The least total time of the timed runs.
    pub min_seconds: f64,
    /// The fewest timed runs.
    pub min_runs: usize,
}

impl Timing {
    /// What the report uses: long enough for stable medians.
    pub const STABLE: Timing = Timing {
        min_seconds: 0.2,
        min_runs: 5,
    };
    /// One timed run (for tests, which check errors and never speed).
    pub const ONCE: Timing = Timing {
        min_seconds: 0.0,
        min_runs: 1,
    };
}

/// The model offsets whose rays are rendered together (288 rays each).
pub const OFFSETS: [f64; 4] = [-1.5, -0.5, 0.0, 0.7];
/// Samples per ray.
pub const COUNTS: [usize; 5] = [16, 32, 64, 128, 256];
/// Early termination thresholds of the fused op.
pub const THRESHOLDS: [f64; 4] = [0.0, 1e-6, 1e-4, 1e-2];

struct Batch {
    offsets: Vec<usize>,
    sigma: Vec<f64>,
    delta: Vec<f64>,
    exact: Vec<f64>,
}

fn batch(setup: &Setup, sampling: Sampling, samples: usize, tau: f64) -> Batch {
    let scene = crate::scene::Scene {
        samples,
        sampling,
        ..setup.scene.clone()
    };
    let mut b = Batch {
        offsets: vec![0],
        sigma: Vec::new(),
        delta: Vec::new(),
        exact: Vec::new(),
    };
    for &x in &OFFSETS {
        let s: Samples = match sampling {
            Sampling::Uniform => Samples::uniform(&scene, &setup.rays),
            Sampling::Band => sampling::band(&scene, &setup.rays, x, tau, scene.band_k),
        };
        let base = b.sigma.len();
        b.sigma.extend(
            s.x.iter()
                .zip(&s.z)
                .map(|(px, pz)| scene.density(((px - x).powi(2) + pz * pz).sqrt(), tau)),
        );
        b.delta.extend(&s.delta);
        b.offsets.extend(s.offsets[1..].iter().map(|o| o + base));
        b.exact.extend(sampling::exact_pixels(&scene, &setup.rays, x, tau));
    }
    b
}

/// The median run time of `f` in microseconds and the runs' interquartile range over it,
/// after a warm-up run.
fn time_frame(timing: Timing, mut f: impl FnMut() -> Result<(), DiscError>) -> Result<(f64, f64), DiscError> {
    f()?;
    let mut t: Vec<f64> = Vec::new();
    let mut total = 0.0;
    while t.len() < timing.min_runs.max(1) || total < timing.min_seconds {
        let start = Instant::now();
        f()?;
        let secs = start.elapsed().as_secs_f64();
        total += secs;
        t.push(secs * 1e6);
    }
    t.sort_by(f64::total_cmp);
    let at = |q: f64| t[((t.len() - 1) as f64 * q).round() as usize];
    let median = at(0.5);
    Ok((median, (at(0.75) - at(0.25)) / median))
}

fn measure<F: Float>(
    setup: &Setup,
    timing: Timing,
    b: &Batch,
    sampling: Sampling,
    samples: usize,
    rows: &mut Vec<Row>,
) -> Result<(), DiscError> {
    let n = b.sigma.len();
    let ch = setup.scene.channels();
    let cast = |v: &[f64]| v.iter().map(|&x| F::lit(x)).collect::<Vec<F>>();
    let sigma = Array1::from(cast(&b.sigma));
    let delta = Array1::from(cast(&b.delta));
    let colors: Vec<f64> = (0..n).flat_map(|_| setup.scene.disc_color.iter().copied()).collect();
    let color = Array2::from_shape_vec((n, ch), cast(&colors))?;
    let background = Array1::from(cast(&setup.scene.background));
    let rays = b.offsets.len() - 1;
    let grad = ArrayD::from_shape_vec(vec![rays, ch], cast(&vec![1.0; rays * ch]))?;
    let error = |image: &[f64]| {
        image
            .iter()
            .zip(&b.exact)
            .map(|(a, e)| (a - e).abs())
            .fold(0.0, f64::max)
    };
    let views = CompositeArrays::new(
        sigma.view().into_dyn(),
        delta.view().into_dyn(),
        color.view().into_dyn(),
    )
    .with_background(background.view().into_dyn());
    let upstream = CompositeUpstream::color(grad.view());
    let wanted = CompositeWanted {
        sigma: true,
        color: true,
        ..Default::default()
    };
    for threshold in THRESHOLDS {
        let op = Composite::new(&b.offsets)?
            .background(Background::Shared)
            .min_transmittance(threshold)?;
        let step = || -> Result<Vec<f64>, DiscError> {
            let (outs, res) = op.evaluate(&views)?;
            let g = op.vjp(&views, &res, &upstream, wanted)?;
            black_box(g);
            Ok(outs.color.iter().map(|v| v.as_f64()).collect())
        };
        let (us_per_frame, spread) = time_frame(timing, || step().map(drop))?;
        rows.push(Row {
            method: "fused",
            precision: F::NAME,
            sampling,
            samples,
            min_transmittance: threshold,
            us_per_frame,
            spread,
            max_error: error(&step()?),
            pareto: false,
        });
    }
    let op = Composite::new(&b.offsets)?.background(Background::Shared);
    for (method, naive) in [("taped", false), ("taped-naive", true)] {
        let step = || -> Result<Vec<f64>, DiscError> {
            let mut tape = Tape::<F>::new();
            let inputs = CompositeInputs {
                sigma: tape.param(sigma.clone()),
                delta: tape.constant(delta.clone()),
                color: tape.param(color.clone()),
                background: Some(tape.constant(background.clone())),
                t: None,
            };
            let out = if naive {
                twins::naive(&mut tape, &op, &inputs)
            } else {
                twins::stable(&mut tape, &op, &inputs)
            }?;
            black_box(tape.backward_with(out.color, grad.clone())?);
            Ok(tape.value(out.color)?.iter().map(|v| v.as_f64()).collect())
        };
        let (us_per_frame, spread) = time_frame(timing, || step().map(drop))?;
        rows.push(Row {
            method,
            precision: F::NAME,
            sampling,
            samples,
            min_transmittance: 0.0,
            us_per_frame,
            spread,
            max_error: error(&step()?),
            pareto: false,
        });
    }
    Ok(())
}

/// Measures every configuration at softness `tau`; `progress` is called once per batch.
pub fn run(setup: &Setup, tau: f64, timing: Timing, progress: &dyn Fn()) -> Result<Vec<Row>, DiscError> {
    let mut rows = Vec::new();
    for sampling in [Sampling::Uniform, Sampling::Band] {
        for samples in COUNTS {
            let b = batch(setup, sampling, samples, tau);
            measure::<f32>(setup, timing, &b, sampling, samples, &mut rows)?;
            measure::<f64>(setup, timing, &b, sampling, samples, &mut rows)?;
            progress();
        }
    }
    mark_pareto_front(&mut rows);
    Ok(rows)
}

/// Marks the rows that no other row dominates (faster and at least as accurate, or as fast
/// and more accurate).
pub fn mark_pareto_front(rows: &mut [Row]) {
    let dominated: Vec<bool> = rows
        .iter()
        .map(|r| {
            rows.iter().any(|o| {
                o.us_per_frame <= r.us_per_frame
                    && o.max_error <= r.max_error
                    && (o.us_per_frame < r.us_per_frame || o.max_error < r.max_error)
            })
        })
        .collect();
    for (r, d) in rows.iter_mut().zip(dominated) {
        r.pareto = !d;
    }
}

/// The front's rows by increasing time (and so decreasing error).
pub fn front(rows: &[Row]) -> Vec<&Row> {
    let mut f: Vec<&Row> = rows.iter().filter(|r| r.pareto).collect();
    f.sort_by(|a, b| a.us_per_frame.total_cmp(&b.us_per_frame));
    f
}

fn describe(r: &Row) -> String {
    let stop = if r.min_transmittance > 0.0 {
        format!(", early termination at {:e}", r.min_transmittance)
    } else {
        String::new()
    };
    format!(
        "{} {} with {} {} samples per ray{stop}",
        r.method,
        r.precision,
        r.samples,
        format!("{:?}", r.sampling).to_lowercase()
    )
}

/// For each error budget, the fastest configuration whose error is within it (the first row
/// of the front, by time, that reaches it).
pub fn recommendations(rows: &[Row]) -> Vec<(f64, Option<&Row>)> {
    let front = front(rows);
    [1e-2, 1e-3, 1e-4, 1e-5, 1e-6]
        .into_iter()
        .map(|budget| (budget, front.iter().copied().find(|r| r.max_error <= budget)))
        .collect()
}

/// The markdown report: provenance, what is measured, the recommendation read off the Pareto
/// front, the front, then every row.
pub fn markdown(rows: &[Row], tau: f64, timing: Timing, stamp: &Stamp) -> String {
    let mut s = format!(
        "# Speed against error: the disc's rays\n\n{}\n\nA frame is the 288 rays of the disc scene for each of the model offsets x = {:?} (1152 rays) at softness tau = {tau} m, composited forward and backward (gradients for density and colour). Time is the median over runs repeated for at least {} s (and at least {} runs), with their interquartile range over the median as the spread; error is the worst |C - C_exact| over every pixel and channel of the frame, against the exact pixels (the sheet's optical depth by converged quadrature).\n\n## What to pick\n\nRead off the Pareto front (the configurations that no other beats in both time and error): the fastest one within each error budget.\n\n| error budget | fastest configuration | time per frame (us) | its error |\n|---|---|---|---|\n",
        stamp.markdown(),
        OFFSETS,
        timing.min_seconds,
        timing.min_runs
    );
    for (budget, pick) in recommendations(rows) {
        s += &match pick {
            Some(r) => format!(
                "| {budget:e} | {} | {:.0} | {:.2e} |\n",
                describe(r),
                r.us_per_frame,
                r.max_error
            ),
            None => format!("| {budget:e} | none measured reaches it | - | - |\n"),
        };
    }
    s += "\n## The Pareto front\n\n| configuration | time per frame (us) | spread | max error |\n|---|---|---|---|\n";
    for r in front(rows) {
        s += &format!(
            "| {} | {:.0} | {:.0}% | {:.2e} |\n",
            describe(r),
            r.us_per_frame,
            r.spread * 100.0,
            r.max_error
        );
    }
    s += "\n## Every configuration\n\n| method | precision | sampling | samples/ray | min_transmittance | time per frame (us) | spread | max error | on the front |\n|---|---|---|---|---|---|---|---|---|\n";
    for r in rows {
        s += &format!(
            "| {} | {} | {:?} | {} | {:e} | {:.0} | {:.0}% | {:.2e} | {} |\n",
            r.method,
            r.precision,
            r.sampling,
            r.samples,
            r.min_transmittance,
            r.us_per_frame,
            r.spread * 100.0,
            r.max_error,
            if r.pareto { "yes" } else { "" }
        );
    }
    s
}

/// The log-log plot (`speed_vs_error.svg` and `.png` in `dir`): time per frame against
/// error, one colour per method and precision, circles for uniform sampling and triangles for
/// band sampling, the Pareto front as a line; the legend beside the chart, off the data.
pub fn plot(dir: &Path, rows: &[Row], tau: f64) -> Result<(), DiscError> {
    let (svg, png) = (dir.join("speed_vs_error.svg"), dir.join("speed_vs_error.png"));
    let size = (1200, 700);
    let mut text = String::new();
    draw_plot(SVGBackend::with_string(&mut text, size).into_drawing_area(), rows, tau)?;
    let mut pixels = crate::plots::canvas(size);
    draw_plot(
        BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area(),
        rows,
        tau,
    )?;
    crate::plots::save(&svg, &text, &png, &pixels, size)
}

const SERIES: [(&str, &str, RGBColor); 6] = [
    ("fused", "f32", RGBColor(230, 120, 20)),
    ("fused", "f64", RGBColor(150, 60, 0)),
    ("taped", "f32", RGBColor(40, 90, 200)),
    ("taped", "f64", RGBColor(20, 40, 120)),
    ("taped-naive", "f32", RGBColor(150, 150, 150)),
    ("taped-naive", "f64", RGBColor(60, 60, 60)),
];

fn draw_plot<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    rows: &[Row],
    tau: f64,
) -> Result<(), DiscError>
where
    DB::ErrorType: 'static,
{
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| DiscError::plot(x);
    root.fill(&WHITE).map_err(e)?;
    let (left, right) = root.split_horizontally(930);
    // Exact results (error 0) are drawn at the floor.
    let floor = rows
        .iter()
        .map(|r| r.max_error)
        .filter(|&e| e > 0.0)
        .fold(1.0, f64::min)
        / 3.0;
    let ceiling = rows.iter().map(|r| r.max_error).fold(floor, f64::max) * 3.0;
    let tmax = rows.iter().map(|r| r.us_per_frame).fold(1.0, f64::max) * 1.3;
    let tmin = rows.iter().map(|r| r.us_per_frame).fold(f64::INFINITY, f64::min) / 1.3;
    let mut chart = ChartBuilder::on(&left)
        .caption(
            format!("disc, tau = {tau} m: time per frame (1152 rays) against worst pixel error"),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (tmin..tmax).log_scale().with_key_points(one_two_five(tmin, tmax)),
            (floor..ceiling).log_scale(),
        )
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("forward + backward time per frame (us, log)")
        .y_desc("worst |C - C_exact| over the frame's pixels (log)")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .x_label_formatter(&|v| format!("{v}"))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(e)?;
    let point = |r: &Row| (r.us_per_frame, r.max_error.max(floor));
    // The front as a staircase: each step holds its error until the next, faster-converging point.
    let front = front(rows);
    let mut stairs = Vec::new();
    for (k, r) in front.iter().enumerate() {
        stairs.push(point(r));
        if let Some(next) = front.get(k + 1) {
            stairs.push((next.us_per_frame, r.max_error.max(floor)));
        }
    }
    chart
        .draw_series(LineSeries::new(stairs, BLACK.stroke_width(1)))
        .map_err(e)?;
    for (method, precision, color) in SERIES {
        let pick = |s: Sampling| {
            rows.iter()
                .filter(move |r| r.method == method && r.precision == precision && r.sampling == s)
        };
        chart
            .draw_series(pick(Sampling::Uniform).map(|r| Circle::new(point(r), 4, color.filled())))
            .map_err(e)?;
        chart
            .draw_series(pick(Sampling::Band).map(|r| TriangleMarker::new(point(r), 6, color.filled())))
            .map_err(e)?;
    }
    chart
        .draw_series(front.iter().map(|r| Circle::new(point(r), 8, BLACK.stroke_width(1))))
        .map_err(e)?;
    draw_legend(&right).map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

/// The legend in its own panel, so that it covers no data.
fn draw_legend<DB: DrawingBackend>(
    panel: &DrawingArea<DB, plotters::coord::Shift>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let font = ("sans-serif", 15).into_font();
    let mut y = 60;
    for (method, precision, color) in SERIES {
        panel.draw(&Circle::new((20, y), 5, color.filled()))?;
        panel.draw(&Text::new(format!("{method} {precision}"), (34, y - 8), font.clone()))?;
        y += 26;
    }
    y += 14;
    panel.draw(&Circle::new((20, y), 5, BLACK.filled()))?;
    panel.draw(&Text::new("uniform sampling", (34, y - 8), font.clone()))?;
    y += 26;
    panel.draw(&TriangleMarker::new((20, y), 6, BLACK.filled()))?;
    panel.draw(&Text::new("band sampling", (34, y - 8), font.clone()))?;
    y += 26;
    panel.draw(&Circle::new((20, y), 8, BLACK.stroke_width(1)))?;
    panel.draw(&Text::new("on the Pareto front", (34, y - 8), font.clone()))?;
    y += 40;
    for line in [
        "fused: early termination",
        "at 0, 1e-6, 1e-4, 1e-2",
        "samples per ray:",
        "16, 32, 64, 128, 256",
    ] {
        panel.draw(&Text::new(line, (12, y), font.clone()))?;
        y += 22;
    }
    Ok(())
}

/// 1, 2, 5 times the powers of ten within `lo..=hi` (tick labels for a log axis that spans
/// little more than a decade, where powers of ten alone give one or two labels).
fn one_two_five(lo: f64, hi: f64) -> Vec<f64> {
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    (first..=last)
        .flat_map(|e| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(e)))
        .filter(|&v| (lo..=hi).contains(&v))
        .collect()
}
