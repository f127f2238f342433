//! Pictures of what a fit learnt inside the box: the density on the three planes through the
//! centre of `[-1, 1]^3` (the scene's exact density beside the model's), and the occupancy
//! grid's occupied cells on the same planes, drawn as PNGs with a colour bar.
//!
//! ```
//! use fogray::ops::sample::GridAxis;
//! use fogray_grid::scene::Scene;
//! use fogray_grid::slices::scene_density_planes;
//!
//! let planes = scene_density_planes(&Scene::default(), 32);
//! assert_eq!(planes.len(), 3);
//! // The red sphere (density 40) fills the centre of the plane z = 0.
//! let z = planes.iter().find(|p| p.axis == GridAxis::Z).unwrap();
//! assert_eq!(z.values[[16, 16]], 40.0);
//! ```

use std::path::Path;

use fogray::fit::dense::DenseGrid;
use fogray::fit::images::ImageError;
use fogray::fit::settings::SceneBox;
use fogray::fit::{FitError, RadianceField};
use fogray::ops::sample::{GridAxis, OccupancyGrid};
use fogray::ops::OpsError;
use fogray::tape::Float;
use ndarray::Array2;
use plotters::prelude::*;

use crate::scene::Scene;

const FONT: &str = "sans-serif";
const GAP: i32 = 10;
const TITLE: i32 = 24;
/// Width of the colour bar and of the space for its labels, in PNG pixels.
const BAR: i32 = 22;
const BAR_LABELS: i32 = 190;

/// The three planes, in the order they are drawn.
pub const AXES: [GridAxis; 3] = [GridAxis::X, GridAxis::Y, GridAxis::Z];

/// Values on one plane through the centre of the box, as an image: `values[[row, column]]`,
/// row 0 at the top. Across x the columns run along y and the rows down z; across y, along x
/// and down z; across z, along x and down y.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneImage {
    /// The axis the plane is across (the plane is that coordinate = 0).
    pub axis: GridAxis,
    /// `[rows][columns]`.
    pub values: Array2<f64>,
}

/// `"x"`, `"y"` or `"z"`.
pub fn axis_name(axis: GridAxis) -> &'static str {
    match axis {
        GridAxis::X => "x",
        GridAxis::Y => "y",
        GridAxis::Z => "z",
    }
}

/// The axes along an image's columns and up its rows.
pub fn in_plane_axes(axis: GridAxis) -> (usize, usize) {
    match axis {
        GridAxis::X => (1, 2),
        GridAxis::Y => (0, 2),
        GridAxis::Z => (0, 1),
    }
}

/// The point at the centre of pixel `(row, column)` of an `n x n` image of the plane across
/// `axis` through the box's centre.
pub fn pixel_point(axis: GridAxis, n: usize, row: usize, column: usize) -> [f64; 3] {
    // The grid example's models cover the unit box.
    let SceneBox { min: lo, max: hi } = SceneBox::UNIT;
    let (across, up) = in_plane_axes(axis);
    let mut p = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    p[across] = lo[across] + (column as f64 + 0.5) / n as f64 * (hi[across] - lo[across]);
    p[up] = hi[up] - (row as f64 + 0.5) / n as f64 * (hi[up] - lo[up]);
    p
}

fn plane_of(axis: GridAxis, n: usize, value: impl Fn([f64; 3]) -> f64) -> PlaneImage {
    PlaneImage {
        axis,
        values: Array2::from_shape_fn((n, n), |(a, b)| value(pixel_point(axis, n, a, b))),
    }
}

/// The scene's exact density on the three planes, `n x n` pixels each (n >= 1; 0 gives empty
/// images).
pub fn scene_density_planes(scene: &Scene, n: usize) -> Vec<PlaneImage> {
    AXES.iter()
        .map(|&axis| plane_of(axis, n, |p| scene.density_at(p)))
        .collect()
}

/// The model's density on the three planes, `n x n` pixels each.
///
/// Errors: as [`RadianceField::densities`].
pub fn model_density_planes<F: Float>(model: &DenseGrid<F>, n: usize) -> Result<Vec<PlaneImage>, FitError> {
    AXES.iter()
        .map(|&axis| {
            let points = Array2::from_shape_fn((n * n, 3), |(k, a)| F::lit(pixel_point(axis, n, k / n, k % n)[a]));
            let density = model.densities(points.view())?;
            Ok(PlaneImage {
                axis,
                values: Array2::from_shape_fn((n, n), |(a, b)| density[a * n + b].as_f64()),
            })
        })
        .collect()
}

/// The occupancy grid's middle plane of cells across each axis (index `resolution / 2`), as
/// images of one pixel per cell: 1 occupied, 0 empty.
///
/// Errors: none for a grid from [`OccupancyGrid::new`]; [`OpsError`] passed on.
pub fn occupancy_planes(grid: &OccupancyGrid) -> Result<Vec<PlaneImage>, OpsError> {
    let r = grid.resolution();
    AXES.iter()
        .map(|&axis| {
            // The slice is indexed by the two other axes in order: [across, up].
            let slice = grid.slice(axis, r / 2)?;
            Ok(PlaneImage {
                axis,
                values: Array2::from_shape_fn((r, r), |(a, b)| f64::from(u8::from(slice.occupied[[b, r - 1 - a]]))),
            })
        })
        .collect()
}

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
    let root = BitMapBackend::new(path, (width as u32, height as u32)).into_drawing_area();
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
    root.present().map_err(e)
}

#[cfg(test)]
mod tests;
