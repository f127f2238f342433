//! # fogray-grid
//!
//! A scene with no known shape: a density and a colour at every point of space, which
//! gradient descent on photographs must find. This crate holds the parts of that experiment
//! that do not depend on the model:
//!
//! - [`scene`]: constant-density spheres and boxes in front of a background, from JSON;
//! - [`exact`]: the exact emission-absorption render of such a scene along a ray (the medium
//!   is piecewise constant, so compositing its pieces has no quadrature error);
//! - [`ring`]: the cameras, `V + T` views over a sphere of radius 3 looking at the origin, and
//!   which of them are held out for testing;
//! - [`photographs`]: the exact photographs of every view;
//! - [`images`]: PNG files and the test PSNR;
//! - [`model`]: the dense grid of raw density and colour, rendered with fogray's grid field,
//!   density/colour activation and composite (fused, or their taped twins);
//! - [`dataset`]: the training rays and colours, the test views;
//! - [`batch`]: the training pixels a step draws, gathered from one table in the fit's
//!   precision;
//! - [`fit`]: Adam on random batches of training rays, test PSNR on the held-out views;
//! - [`state`], [`checkpoint`]: where a fit stands, saved to a safetensors file and read back
//!   to continue it or render from it;
//! - [`render`], [`depth`]: any camera of the ring rendered from a model, with its expected
//!   depth drawn as a PNG;
//! - [`plots`]: test PSNR against training seconds;
//! - [`slices`]: the density and the occupancy grid on planes through the box;
//! - [`report`]: the speed-against-error report over configurations.
//!
//! ```
//! use fogray_grid::{images, photographs::photographs, ring::Ring, scene::Scene};
//!
//! let ring = Ring::new(4, 1, 8)?;
//! let exact = photographs(&Scene::default(), &ring);
//! let db = images::psnr(&[exact[0].view()], &[exact[0].view()])?;
//! assert_eq!(db, f64::INFINITY); // a photograph is its own perfect render
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod batch;
pub mod checkpoint;
pub mod dataset;
pub mod depth;
pub mod exact;
pub mod fit;
pub mod images;
pub mod model;
pub mod photographs;
pub mod plots;
pub mod profile;
pub mod render;
pub mod report;
pub mod ring;
pub mod scene;
pub mod slices;
pub mod state;
