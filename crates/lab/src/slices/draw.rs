//! Plane images drawn as one PNG: titled rows of panels, each pixel a magnified square, with a
//! colour bar (or an occupied/empty legend) on the right.

use std::path::Path;

use fogray_fit::images::{save_canvas, ImageError};
use fogray_ops::sample::GridAxis;
use plotters::prelude::*;

use super::{axis_name, in_plane_axes, PlaneImage};

const FONT: &str = "sans-serif";
const GAP: i32 = 10;
const TITLE: i32 = 24;
/// Width of the colour bar and of the space for its labels, in PNG pixels.
const BAR: i32 = 22;
const BAR_LABELS: i32 = 190;

/// How values become colours.
#[derive(Debug, Clone, PartialEq)]
pub enum Colouring {
    /// Viridis from `lo` (dark blue) to `hi` (yellow), values outside clamped; a colour bar
    /// with `label`.
    Map {
        /// The value drawn darkest.
        lo: f64,
        /// The value drawn brightest.
        hi: f64,
        /// The colour bar's caption.
        label: String,
    },
    /// 1 dark (occupied), 0 white (empty), with a two-entry legend.
    Occupied,
}

impl Colouring {
    fn color(&self, v: f64) -> RGBColor {
        match self {
            Colouring::Map { lo, hi, .. } => {
                let h = if hi > lo {
                    ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                // NaN clamps to NaN: draw it magenta so it cannot pass for a value.
                if h.is_nan() {
                    return RGBColor(255, 0, 255);
                }
                ViridisRGB.get_color(h as f32)
            }
            Colouring::Occupied if v >= 0.5 => RGBColor(40, 40, 60),
            Colouring::Occupied => WHITE,
        }
    }
}

/// One titled row of plane images.
#[derive(Debug, Clone)]
pub struct PlaneRow<'a> {
    /// Written before each panel's plane name (`"exact"`, `"fitted"`).
    pub title: &'a str,
    /// The panels, left to right; all of one size.
    pub planes: &'a [PlaneImage],
}

fn panel_title(row: &str, axis: GridAxis) -> String {
    let (across, up) = in_plane_axes(axis);
    let name = |a: usize| ["x", "y", "z"][a];
    format!(
        "{row}, {} = 0 ({} right, {} up)",
        axis_name(axis),
        name(across),
        name(up)
    )
}

/// Writes rows of plane images, each pixel magnified `scale` times, with a colour bar (or the
/// occupied/empty legend) on the right.
///
/// Errors: [`ImageError::Empty`] for no rows or an empty image, [`ImageError::Shape`] if the
/// images differ in size, [`ImageError::Write`] if the file cannot be drawn (including a
/// `scale` of 0).
pub fn write_planes_png(
    path: &Path,
    rows: &[PlaneRow<'_>],
    colouring: &Colouring,
    scale: u32,
) -> Result<(), ImageError> {
    let first = rows
        .iter()
        .flat_map(|r| r.planes.first())
        .next()
        .ok_or(ImageError::Empty)?;
    let shape = first.values.shape().to_vec();
    if shape.contains(&0) {
        return Err(ImageError::Empty);
    }
    for p in rows.iter().flat_map(|r| r.planes) {
        if p.values.shape() != shape.as_slice() {
            return Err(ImageError::Shape {
                what: format!("plane across {}", axis_name(p.axis)),
                expected: shape.clone(),
                got: p.values.shape().to_vec(),
            });
        }
    }
    let wrap = |e: String| ImageError::Write {
        path: path.to_path_buf(),
        message: e,
    };
    if scale == 0 {
        return Err(wrap("scale must be at least 1".into()));
    }
    let s = scale as i32;
    let (h, w) = (shape[0] as i32 * s, shape[1] as i32 * s);
    let columns = rows.iter().map(|r| r.planes.len()).max().unwrap_or(1) as i32;
    let width = GAP + columns * (w + GAP) + GAP + BAR + BAR_LABELS;
    let height = GAP + rows.len() as i32 * (TITLE + h + GAP);
    let size = (width as u32, height as u32);
    // An RGB buffer for plotters' bitmap backend, which `save_canvas` writes.
    let mut pixels = vec![0u8; size.0 as usize * size.1 as usize * 3];
    let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
    let e = |e: DrawingAreaErrorKind<_>| wrap(e.to_string());
    root.fill(&WHITE).map_err(e)?;
    for (i, row) in rows.iter().enumerate() {
        let y0 = GAP + i as i32 * (TITLE + h + GAP);
        for (k, plane) in row.planes.iter().enumerate() {
            let x0 = GAP + k as i32 * (w + GAP);
            root.draw(&Text::new(
                panel_title(row.title, plane.axis),
                (x0, y0 + 2),
                (FONT, 15).into_font(),
            ))
            .map_err(e)?;
            let top = y0 + TITLE;
            root.draw(&Rectangle::new(
                [(x0 - 1, top - 1), (x0 + w, top + h)],
                RGBColor(160, 160, 160),
            ))
            .map_err(e)?;
            for ((a, b), &v) in plane.values.indexed_iter() {
                let (x, y) = (x0 + b as i32 * s, top + a as i32 * s);
                root.draw(&Rectangle::new([(x, y), (x + s, y + s)], colouring.color(v).filled()))
                    .map_err(e)?;
            }
        }
    }
    let x0 = GAP + columns * (w + GAP) + GAP;
    let (top, bottom) = (GAP + TITLE, GAP + TITLE + h.max(120));
    let text = |t: String, x: i32, y: i32| Text::new(t, (x, y), (FONT, 14).into_font());
    match colouring {
        Colouring::Map { lo, hi, label } => {
            for y in top..bottom {
                let f = (bottom - 1 - y) as f64 / (bottom - 1 - top).max(1) as f64;
                let c = colouring.color(lo + f * (hi - lo));
                root.draw(&Rectangle::new([(x0, y), (x0 + BAR, y + 1)], c.filled()))
                    .map_err(e)?;
            }
            root.draw(&Rectangle::new([(x0 - 1, top - 1), (x0 + BAR, bottom)], BLACK))
                .map_err(e)?;
            for (f, v) in [(0.0, *lo), (0.5, 0.5 * (lo + hi)), (1.0, *hi)] {
                let y = bottom - 1 - (f * (bottom - 1 - top) as f64) as i32;
                root.draw(&PathElement::new(vec![(x0 + BAR, y), (x0 + BAR + 5, y)], BLACK))
                    .map_err(e)?;
                root.draw(&text(format!("{}", (v * 1000.0).round() / 1000.0), x0 + BAR + 8, y - 7))
                    .map_err(e)?;
            }
            for (j, line) in label.split('\n').enumerate() {
                root.draw(&text(line.to_string(), x0, bottom + 8 + 18 * j as i32))
                    .map_err(e)?;
            }
        }
        Colouring::Occupied => {
            for (j, (v, name)) in [(1.0, "occupied cell"), (0.0, "empty cell")].into_iter().enumerate() {
                let y = top + 26 * j as i32;
                root.draw(&Rectangle::new(
                    [(x0, y), (x0 + 16, y + 16)],
                    colouring.color(v).filled(),
                ))
                .map_err(e)?;
                root.draw(&Rectangle::new([(x0, y), (x0 + 16, y + 16)], BLACK))
                    .map_err(e)?;
                root.draw(&text(name.to_string(), x0 + 24, y + 1)).map_err(e)?;
            }
        }
    }
    root.present().map_err(e)?;
    drop(root);
    save_canvas(path, &pixels, size)
}
