//! The lesson's pictures, as SVG and PNG: loss landscapes, the ray panel, the image strips and
//! the annealed fits.

use std::path::Path;

use fogray_data::PngChannels;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::error::DiscError;
use crate::experiments::{Fit, Landscape, RayProfile};

const GREY: RGBColor = RGBColor(150, 150, 150);
const ORANGE: RGBColor = RGBColor(230, 120, 20);
const BLUE: RGBColor = RGBColor(40, 90, 200);
const FONT: &str = "sans-serif";

type Res = Result<(), DiscError>;

fn err<E: std::fmt::Display>(e: E) -> DiscError {
    DiscError::plot(e)
}

/// Writes a drawing to `svg` (its SVG text) and `png` (its RGB pixels, `size` as plotters'
/// bitmap backend lays them out), each whole or not at all: a full disk or Ctrl-C leaves the
/// previous file or none under either name, never a truncated picture.
///
/// Errors: [`DiscError::Output`] naming the file that could not be written.
pub(crate) fn save(svg: &Path, text: &str, png: &Path, pixels: &[u8], size: (u32, u32)) -> Res {
    fogray_data::write_atomic(svg, |out| out.write_all(text.as_bytes()))?;
    fogray_data::write_png8(png, pixels, size.0, size.1, PngChannels::Rgb)?;
    Ok(())
}

/// A black canvas of `size` RGB pixels, as plotters' bitmap backend starts one.
pub(crate) fn canvas(size: (u32, u32)) -> Vec<u8> {
    vec![0; size.0 as usize * size.1 as usize * 3]
}

/// Draws with `$draw` into `$stem.svg` and `$stem.png` (drawn in memory, then [`save`]d).
macro_rules! both {
    ($stem:expr, $size:expr, $draw:ident, $($arg:expr),*) => {{
        // Not with_extension: a name like "landscape-tau0.45" already has a dot.
        let svg = std::path::PathBuf::from(format!("{}.svg", $stem.display()));
        let png = std::path::PathBuf::from(format!("{}.png", $stem.display()));
        let size: (u32, u32) = $size;
        let mut text = String::new();
        {
            let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
            $draw(&root, $($arg),*)?;
            root.present().map_err(err)?;
        }
        let mut pixels = canvas(size);
        {
            let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
            $draw(&root, $($arg),*)?;
            root.present().map_err(err)?;
        }
        save(&svg, &text, &png, &pixels, size)
    }};
}

fn legend_line(color: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
}

fn draw_landscapes<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, panels: &[(Landscape, Vec<Fit>)]) -> Res
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let cols = panels.len().clamp(1, 2);
    let areas = root.split_evenly((panels.len().div_ceil(cols), cols));
    for (area, (l, fits)) in areas.iter().zip(panels) {
        let top = l.hard_loss.iter().chain(&l.soft_loss).fold(0.0f64, |m, &v| m.max(v)) * 1.08;
        let (x0, x1) = (l.x[0], l.x[l.x.len() - 1]);
        let mut chart = ChartBuilder::on(area)
            .caption(format!("loss landscape, tau = {} m", l.tau), (FONT, 20))
            .margin(12)
            .x_label_area_size(38)
            .y_label_area_size(58)
            .build_cartesian_2d(x0..x1, 0.0..top)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("model offset x (m); truth at 0")
            .y_desc("loss E")
            .light_line_style(WHITE)
            .draw()
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(
                l.x.iter().copied().zip(l.hard_loss.iter().copied()),
                GREY.stroke_width(2),
            ))
            .map_err(err)?
            .label("hard")
            .legend(legend_line(GREY));
        chart
            .draw_series(LineSeries::new(
                l.x.iter().copied().zip(l.soft_loss.iter().copied()),
                ORANGE.stroke_width(2),
            ))
            .map_err(err)?
            .label("soft")
            .legend(legend_line(ORANGE));
        let loss_at = |x: f64| {
            let i = ((x - x0) / (x1 - x0) * (l.x.len() - 1) as f64)
                .round()
                .clamp(0.0, (l.x.len() - 1) as f64) as usize;
            l.soft_loss[i]
        };
        for (i, fit) in fits.iter().enumerate() {
            let dots = chart
                .draw_series(fit.path.iter().map(|&x| Circle::new((x, loss_at(x)), 2, BLUE.filled())))
                .map_err(err)?;
            if i == 0 {
                dots.label("Adam path (soft), end = triangle")
                    .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
            }
            let end = fit.end;
            chart
                .draw_series(std::iter::once(TriangleMarker::new(
                    (end, loss_at(end)),
                    7,
                    BLACK.filled(),
                )))
                .map_err(err)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 14))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// The loss landscapes (hard grey, soft orange), one panel per softness (two per row), with
/// the descents, into `<dir>/<name>.svg` and `.png`.
pub fn landscapes(dir: &Path, name: &str, panels: &[(Landscape, Vec<Fit>)]) -> Res {
    let size = if panels.len() > 1 {
        (1200, 430 * panels.len().div_ceil(2) as u32)
    } else {
        (900, 480)
    };
    both!(dir.join(name), size, draw_landscapes, panels)
}

fn draw_ray<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &RayProfile) -> Res
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let (root, strip) = root.split_vertically(root.dim_in_pixel().1 - 40);
    let root = &root;
    let (t0, t1) = (p.t[0], p.t[p.t.len() - 1]);
    let smax = p.sigma.iter().fold(0.0f64, |m, &v| m.max(v)) * 1.1;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "camera {} pixel {} at x = {} m, tau = {} m: T after the first crossing {:.4}, back-half weight {:.2} %",
                p.camera,
                p.pixel,
                p.x,
                p.tau,
                p.t_after_first_crossing,
                100.0 * p.back_half_weight
            ),
            (FONT, 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .right_y_label_area_size(60)
        .build_cartesian_2d(t0..t1, 0.0..smax.max(1e-9))
        .map_err(err)?
        .set_secondary_coord(t0..t1, 0.0..1.05);
    chart
        .configure_mesh()
        .x_desc("depth along the ray t (m)")
        .y_desc("density sigma (1/m)")
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    chart
        .configure_secondary_axes()
        .y_desc("transmittance T, weight w")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(
            p.t.iter().copied().zip(p.sigma.iter().copied()),
            GREY.stroke_width(2),
        ))
        .map_err(err)?;
    chart
        .draw_secondary_series(LineSeries::new(
            p.t.iter().copied().zip(p.transmittance.iter().copied()),
            BLUE.stroke_width(2),
        ))
        .map_err(err)?;
    chart
        .draw_secondary_series(
            p.t.iter()
                .zip(&p.weights)
                .map(|(&t, &w)| Circle::new((t, w), 3, ORANGE.filled())),
        )
        .map_err(err)?;
    // The legend in a strip under the chart, where it covers no curve.
    let font = (FONT, 14).into_font();
    let mut x = 80;
    for (label, color) in [
        ("sigma (left axis)", GREY),
        ("T before each sample (right axis)", BLUE),
        ("stopping weight w (right axis)", ORANGE),
    ] {
        if color == ORANGE {
            strip
                .draw(&Circle::new((x + 10, 20), 3, ORANGE.filled()))
                .map_err(err)?;
        } else {
            strip
                .draw(&PathElement::new(vec![(x, 20), (x + 20, 20)], color.stroke_width(2)))
                .map_err(err)?;
        }
        strip.draw(&Text::new(label, (x + 28, 12), font.clone())).map_err(err)?;
        x += 330;
    }
    Ok(())
}

/// The ray panel of the lesson: sigma (grey), T (blue) and w (orange) along one ray.
pub fn ray(dir: &Path, p: &RayProfile) -> Res {
    both!(dir.join("ray"), (1100, 560), draw_ray, p)
}

/// One camera's photograph, soft render and hard render, one coloured cell per pixel.
pub struct Strips<'a> {
    pub camera: usize,
    pub x: f64,
    pub tau: f64,
    /// The three rows, each `[pixels * ch]` (first three channels drawn as RGB).
    pub rows: [(&'a str, &'a [f64]); 3],
    pub ch: usize,
    /// A pixel to mark with a vertical line (the ray panel's), if any.
    pub marked: Option<usize>,
}

fn draw_strips<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, s: &Strips<'_>) -> Res
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let pixels = s.rows[0].1.len() / s.ch;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("camera {}: model at x = {} m, tau = {} m", s.camera, s.x, s.tau),
            (FONT, 20),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(20)
        .build_cartesian_2d(0.0..pixels as f64, 0.0..3.0)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_y_axis()
        .x_desc("pixel (blue line: the ray of the ray panel)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(err)?;
    let to_u8 = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    for (row, (_, values)) in s.rows.iter().enumerate() {
        let y = 2.0 - row as f64;
        chart
            .draw_series((0..pixels).map(|j| {
                let c = &values[j * s.ch..(j + 1) * s.ch];
                let g = |k: usize| to_u8(c[k.min(s.ch - 1)]);
                Rectangle::new(
                    [(j as f64, y + 0.08), (j as f64 + 1.0, y + 0.78)],
                    RGBColor(g(0), g(1), g(2)).filled(),
                )
            }))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(Text::new(
                s.rows[row].0.to_string(),
                (0.0, y + 0.97),
                (FONT, 15).into_font(),
            )))
            .map_err(err)?;
    }
    if let Some(j) = s.marked {
        let x = j as f64 + 0.5;
        chart
            .draw_series(LineSeries::new(vec![(x, 0.0), (x, 3.0)], BLUE.stroke_width(2)))
            .map_err(err)?;
    }
    Ok(())
}

/// The photograph, soft and hard strips of one camera.
pub fn strips(dir: &Path, s: &Strips<'_>) -> Res {
    both!(dir.join("strips"), (1100, 330), draw_strips, s)
}

fn draw_fits<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, annealed: &[Fit], fixed: &[Fit]) -> Res
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let (left, right) = root.split_horizontally(640);
    let steps = annealed.iter().chain(fixed).map(|f| f.path.len()).max().unwrap_or(1) as f64;
    let mut chart = ChartBuilder::on(&left)
        .caption("descents from 25 starts in [-3, 3]", (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..steps, -3.2..3.2)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("Adam step")
        .y_desc("model offset x (m)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    for (i, f) in fixed.iter().enumerate() {
        let s = chart
            .draw_series(LineSeries::new(
                f.path.iter().enumerate().map(|(k, &x)| (k as f64, x)),
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(err)?;
        if i == 0 {
            s.label("fixed tau = 0.15 (lesson), 80 steps")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.5).stroke_width(2)));
        }
    }
    for (i, f) in annealed.iter().enumerate() {
        let s = chart
            .draw_series(LineSeries::new(
                f.path.iter().enumerate().map(|(k, &x)| (k as f64, x)),
                ORANGE.stroke_width(1),
            ))
            .map_err(err)?;
        if i == 0 {
            s.label("annealed tau 0.3 -> 0.1, 200 steps")
                .legend(legend_line(ORANGE));
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 14))
        .draw()
        .map_err(err)?;
    draw_fit_ends(&right, annealed, fixed, steps)
}

/// The same descents as |x| on a log axis, where their end states are told apart: how close to
/// the truth each one settles.
fn draw_fit_ends<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, annealed: &[Fit], fixed: &[Fit], steps: f64) -> Res
where
    DB::ErrorType: 'static,
{
    const FLOOR: f64 = 1e-4;
    let mut chart = ChartBuilder::on(root)
        .caption("distance from the truth |x| (log)", (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..steps, (FLOOR..4.0).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("Adam step")
        .y_desc("|x| (m)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    for (paths, style) in [
        (fixed, BLACK.mix(0.5).stroke_width(1)),
        (annealed, ORANGE.stroke_width(1)),
    ] {
        for f in paths {
            chart
                .draw_series(LineSeries::new(
                    f.path.iter().enumerate().map(|(k, &x)| (k as f64, x.abs().max(FLOOR))),
                    style,
                ))
                .map_err(err)?;
        }
    }
    Ok(())
}

/// Annealed fits (orange) beside the lesson's fixed-softness fits (grey), from many starts.
pub fn fits(dir: &Path, annealed: &[Fit], fixed: &[Fit]) -> Res {
    both!(dir.join("fits"), (1280, 600), draw_fits, annealed, fixed)
}
