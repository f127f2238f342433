//! # fogray-fit
//!
//! The pipeline around a training step, so that a renderer is written once and every scene
//! (a synthetic one, a dataset on disk) is fitted, rendered and saved the same way:
//!
//! - [`model`]: what the pipeline asks of a radiance field ([`RadianceField`](model::RadianceField)); [`dense`]: the
//!   dense grid of density and colour, its first implementation; [`dispatch`]: work generic
//!   over the model run with the types that settings or a model file name;
//! - [`settings`]: one settings struct ([`FitSettings`](settings::FitSettings)) for the command line, the checkpoint
//!   and resume;
//! - [`dataset`], `batch`: views (a camera and its picture) to training rays and test views;
//! - [`train`]: the training loop with its schedules (`schedule`), the occupancy grid's
//!   refresh (`sampling`) and a step profile ([`profile`]); [`interrupt`]: Ctrl-C;
//! - [`render`]: any rays or views rendered in chunks without a tape's record (colour,
//!   opacity, depth);
//! - [`checkpoint`]: a fit to a safetensors file and back; [`metrics`]: PSNR;
//!   [`mesh`]: a model's surface as a coloured triangle mesh (marching cubes, PLY);
//!   [`images`], [`depth`], [`plots`]: PNGs, depth maps and PSNR curves; [`stamp`]: the
//!   date, machine and command at the top of a generated report.
//!
//! Sweeps over configurations, curves compared and slices through a model, which measure the
//! pipeline rather than run it, are the `fogray-lab` crate's.
//!
//! A user's whole fit: cameras and pictures in, a fitted model, its test PSNR, a checkpoint
//! and a render out.
//!
//! ```
//! use std::collections::BTreeMap;
//!
//! use fogray_fit::checkpoint;
//! use fogray_fit::dataset::{Dataset, View};
//! use fogray_fit::dense::DenseGrid;
//! use fogray_fit::render::{render_picture, RenderOptions};
//! use fogray_fit::settings::FitSettings;
//! use fogray_fit::train::fit;
//! use fogray_ops::{Intrinsics, PinholeCamera};
//! use ndarray::Array3;
//!
//! // Six views of a scene whose every picture is a mid grey: the model must learn a grey fog.
//! let k = Intrinsics::from_vertical_fov(16, 16, 40f64.to_radians())?;
//! let eyes = [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [-3.0, 0.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 3.0], [2.0, 2.0, 1.0]];
//! let mut views = Vec::new();
//! for (i, eye) in eyes.into_iter().enumerate() {
//!     let up = if i == 4 { [0.0, 1.0, 0.0] } else { [0.0, 0.0, 1.0] };
//!     let camera = PinholeCamera::look_at(k, eye, [0.0; 3], up)?;
//!     views.push(View::new(format!("{i}"), &camera, Array3::from_elem((16, 16, 3), 0.5))?);
//! }
//! let test = vec![views.pop().unwrap()];
//! let data = Dataset::new(views, test, [1.0; 3])?;
//!
//! let settings = FitSettings { grid: 16, batch: 1024, steps: Some(60), ..FitSettings::default() };
//! let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {})?;
//! let first = result.log[0].test_psnr;
//! assert!(result.final_test_psnr > first + 10.0, "{first} -> {}", result.final_test_psnr);
//!
//! let file = std::env::temp_dir().join(format!("fogray-fit-doc-{}.safetensors", std::process::id()));
//! checkpoint::save(&file, &result.model, &result.training, &settings, &BTreeMap::new())?;
//! let saved = checkpoint::load::<f32, DenseGrid<f32>>(&file)?;
//! let view = &data.test[0];
//! let options = RenderOptions { depth: true, ..RenderOptions::default() };
//! let occupancy = result.occupancy.as_ref();
//! let (origins, directions) = view.rays();
//! let picture = render_picture(&saved.start.model, occupancy, &origins, &directions, view.size(), &options)?;
//! assert_eq!(picture.color, result.renders[0]); // the saved model renders as the fitted one
//! # std::fs::remove_file(&file)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// A `pub` item no path outside the crate reaches is `pub(crate)`: the public surface is what the
// modules and their re-exports show, nothing more.
#![warn(unreachable_pub)]

mod backdrop;
mod batch;
pub mod checkpoint;
pub mod dataset;
pub mod dense;
pub mod depth;
pub mod dispatch;
mod environment;
mod error;
mod file_floor;
mod grid_model;
pub mod images;
pub mod interrupt;
mod kernels;
pub mod live;
pub mod mesh;
pub mod metrics;
pub mod model;
pub mod plots;
pub mod profile;
pub mod render;
mod sampling;
mod schedule;
pub mod session;
pub mod settings;
mod shading;
pub mod space;
mod space_picture;
pub mod sparse;
mod splats;
pub mod stamp;
pub mod state;
#[cfg(test)]
mod testing;
pub mod train;
pub mod trainer;

pub use error::FitError;
