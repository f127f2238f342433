//! The data of a fit: every training pixel's ray with its exact colour, and the held-out
//! views' rays and photographs.
//!
//! ```
//! use fogray_grid::dataset::Dataset;
//! use fogray_grid::{photographs::photographs, ring::Ring, scene::Scene};
//!
//! let ring = Ring::new(4, 1, 6)?;
//! let data = Dataset::new(&ring, &photographs(&Scene::default(), &ring), [1.0; 3])?;
//! assert_eq!(data.colors.nrows(), 4 * 36); // every pixel of the four training views
//! assert_eq!(data.test[0].view, 2); // e = 5 / 1 = 5, so view 2 is held out
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use ndarray::{Array2, Array3};

use crate::fit::FitError;
use crate::ring::Ring;

/// The training rays with their exact colours, and the test views' rays and photographs.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Origins `[P, 3]` of every training pixel's ray.
    pub origins: Array2<f64>,
    /// Unit directions `[P, 3]`.
    pub directions: Array2<f64>,
    /// Exact colours `[P, 3]`.
    pub colors: Array2<f64>,
    /// Per test view (in view order): its index, rays (origins, directions) and photograph.
    pub test: Vec<TestView>,
    /// The scene's background, composited behind the model.
    pub background: [f64; 3],
}

/// One held-out view.
#[derive(Debug, Clone)]
pub struct TestView {
    /// The view's index in the ring.
    pub view: usize,
    /// Origins `[W*W, 3]`.
    pub origins: Array2<f64>,
    /// Unit directions `[W*W, 3]`.
    pub directions: Array2<f64>,
    /// The exact photograph `[W][W][3]`.
    pub photograph: Array3<f64>,
}

fn rays_of(ring: &Ring, view: usize) -> (Array2<f64>, Array2<f64>) {
    let rays = ring.rays(view);
    let o = Array2::from_shape_fn((rays.len(), 3), |(i, k)| rays[i].origin[k]);
    let d = Array2::from_shape_fn((rays.len(), 3), |(i, k)| rays[i].direction[k]);
    (o, d)
}

impl Dataset {
    /// The training pixels of `ring`'s training views and its test views, from `photographs`
    /// (one per view, `[W][W][3]`, in view order).
    ///
    /// Errors: [`FitError::Config`] if the photographs do not match the ring or there is no
    /// test view.
    pub fn new(ring: &Ring, photographs: &[Array3<f64>], background: [f64; 3]) -> Result<Dataset, FitError> {
        let w = ring.size();
        if photographs.len() != ring.len() || photographs.iter().any(|p| p.shape() != [w, w, 3]) {
            return Err(FitError::Config(format!(
                "need {} photographs of {w} x {w} x 3",
                ring.len()
            )));
        }
        if ring.test_views().is_empty() {
            return Err(FitError::Config("the fit needs at least one test view".into()));
        }
        let (mut o, mut d, mut c) = (Vec::new(), Vec::new(), Vec::new());
        for view in ring.train_views() {
            let (vo, vd) = rays_of(ring, view);
            o.extend(vo);
            d.extend(vd);
            c.extend(photographs[view].iter().copied());
        }
        let p = o.len() / 3;
        let shape = |v| Array2::from_shape_vec((p, 3), v).map_err(|e| FitError::Config(e.to_string()));
        let test = ring
            .test_views()
            .into_iter()
            .map(|view| {
                let (origins, directions) = rays_of(ring, view);
                TestView {
                    view,
                    origins,
                    directions,
                    photograph: photographs[view].clone(),
                }
            })
            .collect();
        Ok(Dataset {
            origins: shape(o)?,
            directions: shape(d)?,
            colors: shape(c)?,
            test,
            background,
        })
    }
}
