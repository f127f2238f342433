//! The speed-against-error report: time per sample of each method, precision and early
//! termination threshold, against the worst error of the disc's pixels with respect to their
//! exact values, for uniform and band sampling at several samples per ray.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use fogray::ops::{twins, Background, Composite, CompositeInputs};
use fogray::tape::{Float, Tape};
use ndarray::{Array1, Array2, ArrayD};
use plotters::prelude::*;
use serde::Serialize;

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
    /// Forward and backward (gradients for sigma and colour), all threads, median of 5.
    pub ns_per_sample: f64,
    /// Worst |C - C_exact| over every pixel and channel.
    pub max_error: f64,
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

fn median_ns(mut f: impl FnMut() -> Result<(), String>, per: f64) -> Result<f64, String> {
    f()?;
    let mut t: Vec<f64> = Vec::new();
    for _ in 0..5 {
        let start = Instant::now();
        f()?;
        t.push(start.elapsed().as_secs_f64() * 1e9 / per);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[2])
}

fn measure<F: Float>(
    setup: &Setup,
    b: &Batch,
    sampling: Sampling,
    samples: usize,
    rows: &mut Vec<Row>,
) -> Result<(), String> {
    let n = b.sigma.len();
    let ch = setup.scene.channels();
    let cast = |v: &[f64]| v.iter().map(|&x| F::lit(x)).collect::<Vec<F>>();
    let sigma = Array1::from(cast(&b.sigma));
    let delta = Array1::from(cast(&b.delta));
    let colors: Vec<f64> = (0..n).flat_map(|_| setup.scene.disc_color.iter().copied()).collect();
    let color = Array2::from_shape_vec((n, ch), cast(&colors)).map_err(|e| e.to_string())?;
    let background = Array1::from(cast(&setup.scene.background));
    let rays = b.offsets.len() - 1;
    let grad = ArrayD::from_shape_vec(vec![rays, ch], cast(&vec![1.0; rays * ch])).map_err(|e| e.to_string())?;
    let error = |image: &[f64]| {
        image
            .iter()
            .zip(&b.exact)
            .map(|(a, e)| (a - e).abs())
            .fold(0.0, f64::max)
    };
    let views = [
        sigma.view().into_dyn(),
        delta.view().into_dyn(),
        color.view().into_dyn(),
        background.view().into_dyn(),
    ];
    for threshold in THRESHOLDS {
        let op = Composite::new(&b.offsets)
            .map_err(|e| e.to_string())?
            .background(Background::Shared)
            .min_transmittance(threshold)
            .map_err(|e| e.to_string())?;
        let step = || -> Result<Vec<f64>, String> {
            let (outs, res) = op.evaluate(&views).map_err(|e| e.to_string())?;
            let g = op
                .vjp(&views, &res, &[Some(grad.view()), None], &[true, false, true, false])
                .map_err(|e| e.to_string())?;
            black_box(g);
            Ok(outs[0].iter().map(|v| v.as_f64()).collect())
        };
        let ns = median_ns(|| step().map(drop), n as f64)?;
        rows.push(Row {
            method: "fused",
            precision: F::NAME,
            sampling,
            samples,
            min_transmittance: threshold,
            ns_per_sample: ns,
            max_error: error(&step()?),
        });
    }
    let op = Composite::new(&b.offsets)
        .map_err(|e| e.to_string())?
        .background(Background::Shared);
    for (method, naive) in [("taped", false), ("taped-naive", true)] {
        let step = || -> Result<Vec<f64>, String> {
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
            }
            .map_err(|e| e.to_string())?;
            black_box(tape.backward_with(out.color, grad.clone()).map_err(|e| e.to_string())?);
            Ok(tape
                .value(out.color)
                .map_err(|e| e.to_string())?
                .iter()
                .map(|v| v.as_f64())
                .collect())
        };
        let ns = median_ns(|| step().map(drop), n as f64)?;
        rows.push(Row {
            method,
            precision: F::NAME,
            sampling,
            samples,
            min_transmittance: 0.0,
            ns_per_sample: ns,
            max_error: error(&step()?),
        });
    }
    Ok(())
}

/// Measures every configuration at softness `tau`; `progress` is called once per batch.
pub fn run(setup: &Setup, tau: f64, progress: &dyn Fn()) -> Result<Vec<Row>, String> {
    let mut rows = Vec::new();
    for sampling in [Sampling::Uniform, Sampling::Band] {
        for samples in COUNTS {
            let b = batch(setup, sampling, samples, tau);
            measure::<f32>(setup, &b, sampling, samples, &mut rows)?;
            measure::<f64>(setup, &b, sampling, samples, &mut rows)?;
            progress();
        }
    }
    Ok(rows)
}

/// The markdown table.
pub fn markdown(rows: &[Row], tau: f64, command: &str) -> String {
    let mut s = format!(
        "# Speed against error: the disc's rays\n\nMeasured by `{command}` on this machine ({} threads). Each configuration composites the 288 rays of the disc scene for the model at x = {:?} (1152 rays) with softness tau = {tau} m, forward and backward (gradients for sigma and colour); time is the median of 5 runs per sample; error is the worst |C - C_exact| over every pixel and channel, against the exact pixels (the sheet's optical depth by converged quadrature).\n\n| method | precision | sampling | samples/ray | min_transmittance | ns/sample | max error |\n|---|---|---|---|---|---|---|\n",
        rayon::current_num_threads(),
        OFFSETS
    );
    for r in rows {
        s += &format!(
            "| {} | {} | {:?} | {} | {:e} | {:.1} | {:.2e} |\n",
            r.method, r.precision, r.sampling, r.samples, r.min_transmittance, r.ns_per_sample, r.max_error
        );
    }
    s
}

/// The log-log plot (`speed_vs_error.svg` and `.png` in `dir`): time per sample against
/// error, one colour per method and precision, circles for uniform sampling and triangles for
/// band sampling.
pub fn plot(dir: &Path, rows: &[Row], tau: f64) -> Result<(), String> {
    let (svg, png) = (dir.join("speed_vs_error.svg"), dir.join("speed_vs_error.png"));
    draw_plot(SVGBackend::new(&svg, (1100, 700)).into_drawing_area(), rows, tau)?;
    draw_plot(BitMapBackend::new(&png, (1100, 700)).into_drawing_area(), rows, tau)
}

fn draw_plot<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    rows: &[Row],
    tau: f64,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    // Exact results (error 0) are drawn at the floor.
    let floor = rows
        .iter()
        .map(|r| r.max_error)
        .filter(|&e| e > 0.0)
        .fold(1.0, f64::min)
        / 10.0;
    let ceiling = rows.iter().map(|r| r.max_error).fold(floor, f64::max) * 1e3;
    let tmax = rows.iter().map(|r| r.ns_per_sample).fold(1.0, f64::max) * 1.5;
    let tmin = rows.iter().map(|r| r.ns_per_sample).fold(f64::INFINITY, f64::min) / 1.5;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("disc rays, tau = {tau} m: time per sample against worst pixel error (fused: 4 early-termination thresholds each)"),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        // Empty decades on top leave room for the legend.
        .build_cartesian_2d(
            (tmin..tmax).log_scale().with_key_points(one_two_five(tmin, tmax)),
            (floor..ceiling).log_scale(),
        )
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("forward + backward time per sample (ns, log)")
        .y_desc("worst |C - C_exact| over all pixels (log)")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .x_label_formatter(&|v| format!("{v}"))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(e)?;
    let series = [
        ("fused", "f32", RGBColor(230, 120, 20)),
        ("fused", "f64", RGBColor(150, 60, 0)),
        ("taped", "f32", RGBColor(40, 90, 200)),
        ("taped", "f64", RGBColor(20, 40, 120)),
        ("taped-naive", "f32", RGBColor(150, 150, 150)),
        ("taped-naive", "f64", RGBColor(60, 60, 60)),
    ];
    for (method, precision, color) in series {
        let pick = |s: Sampling| {
            rows.iter()
                .filter(move |r| r.method == method && r.precision == precision && r.sampling == s)
        };
        let point = |r: &Row| (r.ns_per_sample, r.max_error.max(floor));
        chart
            .draw_series(pick(Sampling::Uniform).map(|r| Circle::new(point(r), 4, color.filled())))
            .map_err(e)?
            .label(format!("{method} {precision}"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
        chart
            .draw_series(pick(Sampling::Band).map(|r| TriangleMarker::new(point(r), 6, color.filled())))
            .map_err(e)?;
    }
    chart
        .draw_series(std::iter::once(TriangleMarker::new((tmin, floor), 0, WHITE)))
        .map_err(e)?
        .label("circle: uniform sampling, triangle: band sampling")
        .legend(|(x, y)| TriangleMarker::new((x + 10, y), 6, BLACK.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(e)?;
    root.present().map_err(e)?;
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
