//! The ring's exact photographs as the pipeline's data: every training view's pixels and the
//! held-out views, each named by its index in the ring (`004`).
//!
//! ```
//! use fogray_grid::views::dataset;
//! use fogray_grid::{ring::Ring, scene::Scene};
//!
//! let ring = Ring::new(4, 1, 6)?;
//! let data = dataset(&Scene::default(), &ring)?;
//! assert_eq!(data.training_pixels(), 4 * 36); // every pixel of the four training views
//! assert_eq!(data.test[0].name, "002"); // e = 5 / 1 = 5, so view 2 is held out
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray::fit::dataset::{Dataset, View};
use fogray::fit::FitError;

use crate::photographs::photograph;
use crate::ring::Ring;
use crate::scene::Scene;

/// The name of view `i` in file names and reports.
pub fn view_name(i: usize) -> String {
    format!("{i:03}")
}

/// View `i` of `ring` with its exact photograph of `scene`.
///
/// Errors: as [`Ring::camera`], as a [`FitError::Config`].
pub fn view(scene: &Scene, ring: &Ring, i: usize) -> Result<View, FitError> {
    let camera = ring.camera(i).map_err(|e| FitError::Config(e.to_string()))?;
    View::new(view_name(i), &camera, photograph(scene, &camera))
}

/// The data of a fit of `scene` seen by `ring`: its training views' pixels, its test views,
/// and the scene's background.
///
/// Errors: a ring without test views, as [`Dataset::new`].
pub fn dataset(scene: &Scene, ring: &Ring) -> Result<Dataset, FitError> {
    let train = ring
        .train_views()
        .into_iter()
        .map(|i| view(scene, ring, i))
        .collect::<Result<Vec<_>, _>>()?;
    let test = ring
        .test_views()
        .into_iter()
        .map(|i| view(scene, ring, i))
        .collect::<Result<Vec<_>, _>>()?;
    Dataset::new(train, test, scene.background)
}
