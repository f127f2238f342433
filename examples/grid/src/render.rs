//! Renders any camera of a [`Ring`] from a model: per pixel the colour, the opacity and the
//! expected depth along the ray, with the same samples as the fit's test renders (uniform,
//! every half voxel across the box), so a test view renders here bit for bit as in the fit.
//!
//! ```
//! use fogray_grid::model::GridModel;
//! use fogray_grid::render::render_view;
//! use fogray_grid::ring::Ring;
//!
//! let ring = Ring::new(4, 1, 8)?;
//! let model = GridModel::<f32>::new(6, -4.0)?;
//! let r = render_view(&model, &ring, 3, [1.0, 1.0, 1.0], None)?;
//! assert_eq!(r.color.shape(), &[8, 8, 3]);
//! // A fresh grid is a thin fog (opacity under 0.07 across the box): all background.
//! assert!(r.depth.iter().all(|d| d.is_nan()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray::ops::rays::{Aabb, RayBatch};
use fogray::ops::sample::{Jitter, OccupancyGrid, Spacing, Uniform};
use fogray::ops::{GeometryError, SampleError};
use fogray::tape::{Float, Tape, TapeError};
use ndarray::{Array2, Array3};
use thiserror::Error;

use crate::model::{GridModel, BOUNDS};
use crate::ring::Ring;

/// Pixels whose opacity is below this are background: their depth is NaN. The expected depth
/// divides by the opacity, which is meaningless for a ray that (almost) never stops.
pub const BACKGROUND_OPACITY: f64 = 0.1;

/// Rays rendered on one tape at a time (the fit's test renders use the same).
const CHUNK: usize = 8192;

/// Why a view could not be rendered.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RenderError {
    /// The view is not one of the ring's.
    #[error("view {view} is out of range: the ring has views 0 to {last}")]
    ViewOutOfRange {
        /// The view asked for.
        view: usize,
        /// The ring's last view.
        last: usize,
    },
    /// From the tape or an op on it.
    #[error(transparent)]
    Tape(#[from] TapeError),
    /// From the sampler.
    #[error(transparent)]
    Sample(#[from] SampleError),
    /// From the rays.
    #[error(transparent)]
    Geometry(#[from] GeometryError),
}

/// One view rendered from a model.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewRender {
    /// The view's index in the ring.
    pub view: usize,
    /// Colour `[W][W][3]` over the scene's background, unclamped.
    pub color: Array3<f64>,
    /// Opacity `1 - T_end` per pixel, `[W][W]`.
    pub opacity: Array2<f64>,
    /// Expected depth given that the ray stops, `sum_k w_k t_k / opacity` (distance from the
    /// eye along the unit ray), `[W][W]`; NaN where the opacity is below
    /// [`BACKGROUND_OPACITY`].
    pub depth: Array2<f64>,
}

/// Renders view `view` of `ring` from `model` over `background`, with samples every half voxel
/// across the box, or only in the occupied cells of `occupancy` (for a model fitted with one).
///
/// Errors: [`RenderError::ViewOutOfRange`], or an error of the ops.
pub fn render_view<F: Float>(
    model: &GridModel<F>,
    ring: &Ring,
    view: usize,
    background: [f64; 3],
    occupancy: Option<&OccupancyGrid>,
) -> Result<ViewRender, RenderError> {
    if view >= ring.len() {
        return Err(RenderError::ViewOutOfRange {
            view,
            last: ring.len().saturating_sub(1),
        });
    }
    let rays = ring.rays(view);
    let w = ring.size();
    let mut color = Array3::zeros((w, w, 3));
    let (mut opacity, mut depth) = (Array2::zeros((w, w)), Array2::zeros((w, w)));
    let bounds = Aabb::new(BOUNDS.0, BOUNDS.1)?;
    let sampler = Uniform::new(Spacing::Step(model.voxel() / 2.0))?;
    let mut tape = Tape::<F>::new();
    // No backward: the ops keep no record and no residuals.
    tape.set_grad_enabled(false);
    for start in (0..rays.len()).step_by(CHUNK) {
        let chunk = &rays[start..(start + CHUNK).min(rays.len())];
        let origins = Array2::from_shape_fn((chunk.len(), 3), |(i, k)| F::lit(chunk[i].origin[k]));
        let directions = Array2::from_shape_fn((chunk.len(), 3), |(i, k)| F::lit(chunk[i].direction[k]));
        let batch = RayBatch::new(origins, directions)?;
        let clip = bounds.clip(&batch);
        let samples = match occupancy {
            None => sampler.sample(&batch, &clip)?,
            Some(g) => g.march_midpoints(&batch, &clip, model.voxel() / 2.0, Jitter::None)?,
        };
        let out = model.render_with_depth(&mut tape, samples, background)?;
        let (c, o) = (tape.value(out.color)?, tape.value(out.opacity)?);
        let Some(d) = out.depth else {
            return Err(RenderError::Tape(TapeError::InvalidArgument {
                op: "composite",
                reason: "a composite built with depth gave none".into(),
            }));
        };
        let d = tape.value(d)?;
        for k in 0..chunk.len() {
            let (row, column) = ((start + k) / w, (start + k) % w);
            for ch in 0..3 {
                color[[row, column, ch]] = c[[k, ch]].as_f64();
            }
            let alpha = o[[k]].as_f64();
            opacity[[row, column]] = alpha;
            depth[[row, column]] = if alpha >= BACKGROUND_OPACITY {
                d[[k]].as_f64() / alpha
            } else {
                f64::NAN
            };
        }
        tape.clear();
    }
    Ok(ViewRender {
        view,
        color,
        opacity,
        depth,
    })
}
