//! Pictures of what a fit learnt inside its box: a model's density (or any function of the
//! point) on the three planes through the centre of the box, and the occupancy grid's occupied
//! cells on the same planes, drawn as PNGs with a colour bar ([`draw`]).
//!
//! ```
//! use fogray_fit::settings::SceneBox;
//! use fogray_lab::slices::{planes, AXES};
//! use fogray_ops::sample::GridAxis;
//!
//! // A ball of density 40 and radius 0.5 at the centre of the unit box.
//! let ball = |p: [f64; 3]| if p.iter().map(|x| x * x).sum::<f64>() < 0.25 { 40.0 } else { 0.0 };
//! let images = planes(&SceneBox::UNIT, 32, ball);
//! assert_eq!(images.iter().map(|p| p.axis).collect::<Vec<_>>(), AXES);
//! let z = images.iter().find(|p| p.axis == GridAxis::Z).unwrap();
//! assert_eq!((z.values[[16, 16]], z.values[[0, 0]]), (40.0, 0.0)); // the centre, a corner
//! ```

use fogray_fit::model::RadianceField;
use fogray_fit::settings::SceneBox;
use fogray_fit::FitError;
use fogray_ops::sample::{GridAxis, OccupancyGrid};
use fogray_ops::OpsError;
use fogray_tape::Float;
use ndarray::Array2;

pub mod draw;

pub use draw::{write_planes_png, Colouring, PlaneRow};

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
/// `axis` through the centre of `bounds` (the image spans the box's two other sides).
pub fn pixel_point(bounds: &SceneBox, axis: GridAxis, n: usize, row: usize, column: usize) -> [f64; 3] {
    let SceneBox { min: lo, max: hi } = *bounds;
    let (across, up) = in_plane_axes(axis);
    let mut p = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    p[across] = lo[across] + (column as f64 + 0.5) / n as f64 * (hi[across] - lo[across]);
    p[up] = hi[up] - (row as f64 + 0.5) / n as f64 * (hi[up] - lo[up]);
    p
}

/// `value` at each pixel's centre on the three planes through the centre of `bounds`, `n x n`
/// pixels each (0 gives empty images): a scene's exact density, say, to set beside a model's.
pub fn planes(bounds: &SceneBox, n: usize, value: impl Fn([f64; 3]) -> f64) -> Vec<PlaneImage> {
    AXES.iter()
        .map(|&axis| PlaneImage {
            axis,
            values: Array2::from_shape_fn((n, n), |(a, b)| value(pixel_point(bounds, axis, n, a, b))),
        })
        .collect()
}

/// The model's density on the three planes through the centre of `bounds`, `n x n` pixels
/// each.
///
/// Errors: as [`RadianceField::densities`].
pub fn model_density_planes<F: Float, M: RadianceField<F>>(
    model: &M,
    bounds: &SceneBox,
    n: usize,
) -> Result<Vec<PlaneImage>, FitError> {
    AXES.iter()
        .map(|&axis| {
            let points = Array2::from_shape_fn((n * n, 3), |(k, a)| {
                F::lit(pixel_point(bounds, axis, n, k / n, k % n)[a])
            });
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

#[cfg(test)]
mod tests;
