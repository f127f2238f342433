//! # fogray-ops
//!
//! Volume-rendering ops on packed rays for [`fogray_tape`]:
//!
//! - [`Composite`]: the emission-absorption composite (`docs/volume-rendering.md` in the
//!   repository restates the model and its derivative) as one fused op with a
//!   hand-written backward (colour, opacity, depth, weights and transmittance out; gradients
//!   for density, step, colour, background and depth values), plugged into the tape through
//!   its public [`CustomOp`](fogray_tape::CustomOp) interface;
//! - [`twins`]: the same composite written with tape primitives only, in the stable form
//!   (exclusive cumsum of optical depth, `exp`, `expm1`) and the naive form (cumulative
//!   product of `1 - alpha`), to check the fused op against and to measure what fusing buys;
//! - [`hard`]: the hard "first hit" renderer that the soft one generalises, and the exact
//!   ray / ball hit test of a scene whose surface is a ball;
//! - [`rays`]: pinhole cameras, batches of rays, and ray / box clipping;
//! - [`sample`]: samplers that turn clipped rays into packed samples for the composite
//!   (uniform, stratified, importance resampling), an occupancy grid that skips empty space,
//!   and a sampler of unbounded scenes in contracted space ([`sample::ContractedSampler`]);
//! - [`space`]: the scene contraction of unbounded captures into `[-2, 2]^3`
//!   ([`Contraction`]) and the framing of its inner region from cameras;
//! - [`grid`]: a dense grid field over a box, looked up bilinearly (2-D) or trilinearly (3-D)
//!   at packed positions, as a fused op ([`GridField`]) with a deterministic parallel backward
//!   into the grid values and the positions, and its taped twin;
//! - [`activation`]: the activations of a grid renderer's raw values, density
//!   `softplus(raw_0 + shift)` and colour `sigmoid(raw_1..)`, as a fused op
//!   ([`DensityColor`]) with a hand-written backward, and its taped twin;
//! - [`sh`]: view-dependent colour from spherical-harmonics coefficients (degree 0 to 3, the
//!   Plenoxels / 3D Gaussian splatting basis) through a sigmoid, as a fused op ([`ShColor`])
//!   with a hand-written backward, and its taped twin;
//! - [`distortion`]: the mip-NeRF 360 distortion loss of packed rays' weights, as a fused op
//!   ([`DistortionLoss`]) with a hand-written O(n) backward into the densities, and its
//!   taped (pairwise) twin;
//! - [`splat`]: 3D Gaussian splatting: projection of 3-D Gaussians into a camera, binning
//!   into tiles and front-to-back rasterisation, each with a hand-written backward, and the
//!   fused op ([`splat::SplatRender`]) that records them as one node of the tape;
//! - [`prior`]: priors on a grid's values for a fit's loss ([`prior::TotalVariation`]);
//! - [`limits`]: what a grid, a training batch, a render and a loaded frame will allocate,
//!   checked against the machine's memory before anything is allocated.
//!
//! ```
//! use fogray_ops::{Composite, CompositeInputs};
//! use fogray_tape::Tape;
//! use ndarray::{arr1, arr2};
//!
//! // The four-sample worked example of the volume-rendering lesson: C = 0.605.
//! let mut tape = Tape::<f64>::new();
//! let sigma = tape.param(arr1(&[0.0, 0.5, 2.0, 8.0]));
//! let delta = tape.constant(arr1(&[0.5; 4]));
//! let color = tape.constant(arr2(&[[0.9], [0.2], [0.9], [0.4]]));
//! let background = Some(tape.constant(arr1(&[1.0])));
//! let op = Composite::new(&[0, 4]).unwrap();
//! let out = op.apply(&mut tape, &CompositeInputs { sigma, delta, color, background, t: None })?;
//! let c = tape.value(out.color)?[[0, 0]];
//! assert!((c - 0.605).abs() < 5e-4);
//! let grads = tape.backward(out.color)?;          // dC/dsigma: what it adds minus what it hides
//! assert!((grads.get(sigma).unwrap()[0] - 0.147).abs() < 5e-4);
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

#![warn(missing_docs)]

pub mod activation;
pub mod composite;
pub mod distortion;
mod error;
pub mod grid;
pub mod hard;
pub mod limits;
mod math;
mod prefetch;
pub mod prior;
pub mod rays;
pub mod sample;
pub mod sh;
pub mod space;
pub mod splat;
pub mod twins;

pub use activation::{Activated, ActivatedGrads, ActivatedMut, ActivatedVars, DensityColor};
pub use composite::{
    Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeGradients, CompositeInputs,
    CompositeOutputBuffers, CompositeOutputs, CompositeUpstream, CompositeVars, CompositeWanted,
};
pub use distortion::DistortionLoss;
pub use error::{At, Op, OpsError};
pub use grid::{GridBox, GridField, GridGradientBuffers, GridGradients, GridWanted, NodeIndex, SparseGridField};
pub use rays::{
    rays_for_camera_pixels, Aabb, CameraPixel, Intrinsics, LensDistortion, Orbit, PinholeCamera, RayBatch, RayIntervals,
};
pub use sh::ShColor;
pub use space::{framing_from_cameras, Contraction, InnerRegion};
