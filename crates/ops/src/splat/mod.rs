//! 3D Gaussian splatting on the CPU: 3-D Gaussians projected into a pinhole camera and
//! composited front to back into an image, with hand-written backwards, as one fused op on the
//! tape ([`SplatRender`]) or stage by stage without one.
//!
//! The stages, each a function of its own:
//!
//! 1. [`project`] ([`project_vjp`]): means, log-scales and quaternions to 2-D means, depths,
//!    conics (inverse screen covariances, by the EWA approximation with a 0.3 px² low-pass
//!    dilation) and screen radii; splats behind the near plane or with a degenerate
//!    covariance are culled.
//! 2. [`bin`]: every visible splat listed in each 16x16 tile its radius touches, each tile's
//!    list front to back (depth, then index); the total is bounded before it is allocated.
//! 3. [`rasterize`] ([`rasterize_vjp`]): per pixel, `alpha = min(0.99, o exp(-d^T K d / 2))`,
//!    splats below `1/255` skipped, stopping before the transmittance would fall below
//!    `1e-4`; the backward reads the same splats and carries the colour behind each one back
//!    to front, never dividing by `1 - alpha`.
//!
//! Every stage computes in f64 whatever the input precision (`f32` or `f64`), is parallel
//! (rayon) over splats or tiles, and gives bitwise the same result for any number of threads.
//! The fused op takes opacity logits (opacity = sigmoid); the stages take the opacity itself.
//!
//! ```
//! use fogray_ops::splat::{SplatArrays, SplatRender};
//! use fogray_ops::{Intrinsics, PinholeCamera};
//! use fogray_tape::Tape;
//! use ndarray::{arr1, arr2};
//!
//! // One round Gaussian (standard deviation 0.1) 2 units in front of a 16x16 camera.
//! let k = Intrinsics { fx: 20.0, fy: 20.0, cx: 8.0, cy: 8.0, width: 16, height: 16 };
//! let camera = PinholeCamera::look_at(k, [0.0, 0.0, -2.0], [0.0; 3], [0.0, -1.0, 0.0])?;
//! let op = SplatRender::new(&camera, [1.0, 1.0, 1.0])?;
//! let mut tape = Tape::<f64>::new();
//! let means = tape.param(arr2(&[[0.0, 0.0, 0.0]]));
//! let log_scales = tape.param(arr2(&[[0.1f64.ln(); 3]]));
//! let quats = tape.param(arr2(&[[1.0, 0.0, 0.0, 0.0]]));
//! let opacity_logits = tape.param(arr1(&[0.0])); // opacity 0.5
//! let colors = tape.param(arr2(&[[1.0, 0.0, 0.0]]));
//! let splats = fogray_ops::splat::SplatVars { means, log_scales, quats, opacity_logits, colors };
//! let image = op.apply(&mut tape, &splats)?;
//! // The pixel at the splat's centre (8, 8) is 0.5 red over 0.5 white, nearly: the centre is
//! // half a pixel from the pixel's.
//! let centre = tape.value(image)?.to_owned();
//! assert!((centre[[8 * 16 + 8, 0]] - 1.0).abs() < 1e-12);
//! assert!((centre[[8 * 16 + 8, 1]] - 0.5).abs() < 0.1);
//! let loss = tape.sum(image)?;
//! let grads = tape.backward(loss)?;
//! assert!(grads.get(means).is_some());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod camera;
mod check;
mod config;
mod linalg;
mod op;
mod project;
mod project_backward;
mod quat;
mod raster;
mod raster_backward;
mod tiles;
pub mod twin;

pub use config::{SplatArrays, SplatRender, SplatVars};
pub use op::SplatGradients;
pub use project::{project, Projection, DILATION, NEAR};
pub use project_backward::{project_vjp, ProjectionGradients};
pub use raster::{rasterize, Raster, ALPHA_MAX, ALPHA_MIN, T_MIN};
pub use raster_backward::{rasterize_vjp, RasterGradients};
pub use tiles::{bin, TileLists, DEFAULT_MAX_INTERSECTIONS, TILE};
