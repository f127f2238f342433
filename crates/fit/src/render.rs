//! Rendering without a tape's record: any batch of rays, in chunks, to colour, opacity and
//! expected depth; and whole views to pictures.
//!
//! A model fitted with an occupancy grid is rendered with it, as it was trained: its empty
//! cells got no samples, so whatever density they hold was never fitted.
//!
//! ```
//! use fogray_fit::dense::DenseGrid;
//! use fogray_fit::model::RadianceField;
//! use fogray_fit::render::{render_rays, RenderOptions};
//! use fogray_fit::settings::FitSettings;
//! use ndarray::arr2;
//!
//! let model = DenseGrid::<f32>::fresh(&FitSettings::default(), 6)?;
//! let (origins, directions) = (arr2(&[[0.0, -3.0, 0.0]]), arr2(&[[0.0, 1.0, 0.0]]));
//! let options = RenderOptions { depth: true, ..RenderOptions::default() };
//! let out = render_rays(&model, None, &origins, &directions, &options)?;
//! // A fresh grid is a thin fog (opacity under 0.07 across the box): background, no depth.
//! assert!(out.opacity[0] < 0.07 && out.depth.unwrap()[0].is_nan());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray_ops::rays::RayBatch;
use fogray_ops::sample::OccupancyGrid;
use fogray_tape::{Float, Tape, TapeError};
use ndarray::{Array1, Array2, Array3};

use crate::error::FitError;
use crate::model::{RadianceField, RenderWanted};
use crate::settings::Method;

/// Pixels whose opacity is below this are background: their depth is NaN. The expected depth
/// divides by the opacity, which is meaningless for a ray that (almost) never stops.
pub const BACKGROUND_OPACITY: f64 = 0.1;

/// Rays rendered on one tape at a time.
pub const CHUNK: usize = 8192;

/// How to render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// The background behind the model.
    pub background: [f64; 3],
    /// Fused ops or their taped twins.
    pub method: Method,
    /// Also the expected depth of each ray.
    pub depth: bool,
}

impl Default for RenderOptions {
    /// White background, fused ops, no depth.
    fn default() -> Self {
        RenderOptions {
            background: [1.0; 3],
            method: Method::Fused,
            depth: false,
        }
    }
}

/// A batch of rays rendered.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedRays {
    /// Colour `[R, 3]` over the background, unclamped.
    pub color: Array2<f64>,
    /// Opacity `1 - T_end`, `[R]`.
    pub opacity: Array1<f64>,
    /// Expected depth given that the ray stops, `sum_k w_k t_k / opacity` (distance from the
    /// origin along the unit ray), `[R]`; NaN where the opacity is below
    /// [`BACKGROUND_OPACITY`]. With [`RenderOptions::depth`] only.
    pub depth: Option<Array1<f64>>,
}

/// One view rendered, as pictures.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedView {
    /// Colour `[H][W][3]`.
    pub color: Array3<f64>,
    /// Opacity `[H][W]`.
    pub opacity: Array2<f64>,
    /// Expected depth `[H][W]` (NaN for background), with [`RenderOptions::depth`] only.
    pub depth: Option<Array2<f64>>,
}

fn rows_of<F: Float>(a: &Array2<f64>, start: usize, end: usize) -> Array2<F> {
    Array2::from_shape_fn((end - start, a.ncols()), |(k, c)| F::lit(a[[start + k, c]]))
}

/// Renders rays `origins`, `directions` (`[R, 3]` each, unit directions) from `model`, in
/// chunks of [`CHUNK`] on a tape that records nothing, sampled every
/// [`RadianceField::sample_step`] across its box or in the occupied cells of `occupancy`.
///
/// Errors: tables of different shapes or not `[R, 3]`, and the ops' errors.
pub fn render_rays<F: Float, M: RadianceField<F>>(
    model: &M,
    occupancy: Option<&OccupancyGrid>,
    origins: &Array2<f64>,
    directions: &Array2<f64>,
    options: &RenderOptions,
) -> Result<RenderedRays, FitError> {
    if origins.ncols() != 3 || origins.dim() != directions.dim() {
        return Err(FitError::Config(format!(
            "rays: origins {:?} and directions {:?}, expected [R, 3] each",
            origins.dim(),
            directions.dim()
        )));
    }
    let n = origins.nrows();
    let mut color = Array2::zeros((n, 3));
    let mut opacity = Array1::zeros(n);
    let mut depth = options.depth.then(|| Array1::zeros(n));
    let space = model.space();
    let mut tape = Tape::<F>::new();
    // No backward: the ops keep no record and no residuals.
    tape.set_grad_enabled(false);
    let wanted = RenderWanted { depth: options.depth };
    for start in (0..n).step_by(CHUNK) {
        let end = (start + CHUNK).min(n);
        let rays = RayBatch::new(rows_of::<F>(origins, start, end), rows_of::<F>(directions, start, end))?;
        let samples = space.sample(occupancy, &rays, model.sample_step())?;
        let out = model.render(&mut tape, &rays, samples, options.background, options.method, wanted)?;
        let (c, o) = (tape.value(out.color)?, tape.value(out.opacity)?);
        for k in 0..end - start {
            for ch in 0..3 {
                color[[start + k, ch]] = c[[k, ch]].as_f64();
            }
            opacity[start + k] = o[[k]].as_f64();
        }
        if let Some(depth) = depth.as_mut() {
            let d = out.depth.ok_or(TapeError::InvalidArgument {
                op: "composite",
                reason: "a composite built with depth gave none".into(),
            })?;
            let d = tape.value(d)?;
            for k in 0..end - start {
                let alpha = opacity[start + k];
                depth[start + k] = if alpha >= BACKGROUND_OPACITY {
                    d[[k]].as_f64() / alpha
                } else {
                    f64::NAN
                };
            }
        }
        tape.clear();
    }
    Ok(RenderedRays { color, opacity, depth })
}

/// Renders the `height x width` picture whose row-major pixels are the rays `origins`,
/// `directions`, as [`render_rays`] does.
///
/// Errors: as [`render_rays`], and a count of rays that is not `height * width`.
pub fn render_picture<F: Float, M: RadianceField<F>>(
    model: &M,
    occupancy: Option<&OccupancyGrid>,
    origins: &Array2<f64>,
    directions: &Array2<f64>,
    [height, width]: [usize; 2],
    options: &RenderOptions,
) -> Result<RenderedView, FitError> {
    if origins.nrows() != height * width {
        return Err(FitError::Config(format!(
            "{} rays for a picture of {height} x {width}",
            origins.nrows()
        )));
    }
    let r = render_rays(model, occupancy, origins, directions, options)?;
    let shape_error = |e: ndarray::ShapeError| FitError::Config(e.to_string());
    Ok(RenderedView {
        color: r.color.into_shape_with_order((height, width, 3)).map_err(shape_error)?,
        opacity: r.opacity.into_shape_with_order((height, width)).map_err(shape_error)?,
        depth: r
            .depth
            .map(|d| d.into_shape_with_order((height, width)))
            .transpose()
            .map_err(shape_error)?,
    })
}
