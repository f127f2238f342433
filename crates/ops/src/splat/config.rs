//! The fused op's configuration ([`SplatRender`]: the camera, the background, the bound on
//! the tiles' lists) and its inputs on a tape ([`SplatVars`]) and off it ([`SplatArrays`]).

use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{ArrayView1, ArrayView2};

use super::camera::SplatCamera;
use super::tiles::DEFAULT_MAX_INTERSECTIONS;
use crate::error::{At, Op, OpsError};
use crate::rays::PinholeCamera;

/// Project and rasterise 3-D Gaussians into one camera's image, as one op with a
/// hand-written backward (see the [module docs](super)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatRender {
    pub(crate) camera: SplatCamera,
    pub(crate) background: [f64; 3],
    pub(crate) max_intersections: u64,
}

/// The splats' parameters on a tape; `n` splats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SplatVars {
    /// Means `[n, 3]`, world frame.
    pub means: Var,
    /// Log standard deviations along the splat's own axes, `[n, 3]`.
    pub log_scales: Var,
    /// Rotations `[n, 4]` as quaternions `w, x, y, z`, any non-zero length.
    pub quats: Var,
    /// Opacity logits `[n]`: the opacity is their sigmoid.
    pub opacity_logits: Var,
    /// Colours `[n, 3]`.
    pub colors: Var,
}

/// The splats' parameters as arrays (for [`SplatRender::render`] and [`SplatRender::vjp`]);
/// shapes as [`SplatVars`].
#[derive(Debug, Clone)]
pub struct SplatArrays<'a, F> {
    /// Means `[n, 3]`.
    pub means: ArrayView2<'a, F>,
    /// Log-scales `[n, 3]`.
    pub log_scales: ArrayView2<'a, F>,
    /// Quaternions `[n, 4]`.
    pub quats: ArrayView2<'a, F>,
    /// Opacity logits `[n]`.
    pub opacity_logits: ArrayView1<'a, F>,
    /// Colours `[n, 3]`.
    pub colors: ArrayView2<'a, F>,
}

impl SplatRender {
    /// The op that renders into `camera` over `background` (finite), with at most
    /// [`DEFAULT_MAX_INTERSECTIONS`] (splat, tile) pairs.
    ///
    /// Errors: a camera with a lens distortion ([`OpsError::Mismatch`]), a non-positive focal
    /// length ([`OpsError::Config`]), a non-finite background ([`OpsError::Domain`]).
    pub fn new(camera: &PinholeCamera, background: [f64; 3]) -> Result<Self, OpsError> {
        if let Some(c) = background.iter().position(|v| !v.is_finite()) {
            return Err(OpsError::domain(
                Op::Splat,
                At::Value,
                format!("background[{c}]"),
                background[c],
                "must be finite",
            ));
        }
        Ok(SplatRender {
            camera: SplatCamera::new(camera)?,
            background,
            max_intersections: DEFAULT_MAX_INTERSECTIONS,
        })
    }

    /// The same op with a different bound on the total length of the tiles' lists (what the
    /// forward keeps and the backward allocates grows with it).
    pub fn with_max_intersections(self, limit: u64) -> Self {
        SplatRender {
            max_intersections: limit,
            ..self
        }
    }

    /// The image size, `(width, height)`; the op's output is `[width * height, 3]`, row-major.
    pub fn size(&self) -> (usize, usize) {
        (self.camera.width, self.camera.height)
    }

    /// The background colour.
    pub fn background(&self) -> [f64; 3] {
        self.background
    }

    /// Records the image `[height * width, 3]` of `splats` on `tape` as one op through the
    /// tape's public custom-op interface; its backward gives the gradients of all five inputs.
    ///
    /// Errors (the tape is unchanged): those of [`SplatRender::render`] (the [`OpsError`]
    /// inside [`TapeError::Op`]), or a stale handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, splats: &SplatVars) -> Result<Var, TapeError> {
        let inputs = [
            splats.means,
            splats.log_scales,
            splats.quats,
            splats.opacity_logits,
            splats.colors,
        ];
        tape.apply1(*self, &inputs)
    }
}
