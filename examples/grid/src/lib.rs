//! # fogray-grid
//!
//! A scene with no known shape: a density and a colour at every point of space, which
//! gradient descent on photographs must find. This crate holds the parts of that experiment
//! that are particular to its scene; the model, the fit, the render and the checkpoints are
//! fogray-fit's (`fogray::fit`), the sweep over configurations, the curves it compares and the
//! density slices fogray-lab's (`fogray_lab`):
//!
//! - [`scene`]: constant-density spheres and boxes in front of a background, from JSON;
//! - [`exact`]: the exact emission-absorption render of such a scene along a ray (the medium
//!   is piecewise constant, so compositing its pieces has no quadrature error);
//! - [`ring`]: the cameras, `V + T` views over a sphere of radius 3 looking at the origin, and
//!   which of them are held out for testing;
//! - [`photographs`]: the exact photographs of every view;
//! - [`views`]: the ring's photographs as the pipeline's data (fogray-fit's `Dataset`);
//! - [`report`]: the speed-against-error report over configurations.
//!
//! ```
//! use fogray::fit::metrics::psnr;
//! use fogray_grid::{photographs::photographs, ring::Ring, scene::Scene};
//!
//! let ring = Ring::new(4, 1, 8)?;
//! let exact = photographs(&Scene::default(), &ring)?;
//! let db = psnr(&[exact[0].view()], &[exact[0].view()])?;
//! assert_eq!(db, f64::INFINITY); // a photograph is its own perfect render
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A fit of the scene is the pipeline's, on this crate's data (`fogray-grid fit` is this with
//! a command line, pictures and checkpoints; here a small grid for 40 steps):
//!
//! ```
//! use fogray::fit::{dense::DenseGrid, settings::FitSettings, train::fit};
//! use fogray_grid::{ring::Ring, scene::Scene, views::dataset};
//!
//! let data = dataset(&Scene::default(), &Ring::new(16, 2, 24)?)?;
//! let settings = FitSettings { grid: 24, batch: 2048, steps: Some(40), ..FitSettings::default() };
//! let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {})?;
//! assert!(result.final_test_psnr > result.log[0].test_psnr + 3.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod capture;
pub mod exact;
pub mod photographs;
pub mod report;
pub mod ring;
pub mod scene;
pub mod views;
