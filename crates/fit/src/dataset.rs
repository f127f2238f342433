//! The data of a fit: every training pixel's ray with its colour, and the held-out views'
//! rays and images. Any source of cameras and pictures (a synthetic scene, a dataset on disk)
//! builds one from [`View`]s.
//!
//! ```
//! use fogray_fit::dataset::{Dataset, View};
//! use fogray_ops::{Intrinsics, PinholeCamera};
//! use ndarray::Array3;
//!
//! let view = |eye: [f64; 3], name: &str| -> Result<View, Box<dyn std::error::Error>> {
//!     let k = Intrinsics::from_vertical_fov(4, 3, 0.7)?;
//!     let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0])?;
//!     Ok(View::new(name, &camera, Array3::from_elem((3, 4, 3), 0.5))?)
//! };
//! let train = [view([3.0, 0.0, 0.0], "a")?, view([0.0, 3.0, 0.0], "b")?];
//! let data = Dataset::new(&train, vec![view([0.0, -3.0, 0.0], "c")?], [1.0; 3])?;
//! assert_eq!(data.colors.nrows(), 2 * 12); // every pixel of the two training views
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray_ops::PinholeCamera;
use ndarray::{Array2, Array3};

use crate::error::FitError;

/// One picture with the ray of each of its pixels.
#[derive(Debug, Clone)]
pub struct View {
    /// What the view is called in file names and reports.
    pub name: String,
    /// Origins `[H*W, 3]`, row-major over the pixels.
    pub origins: Array2<f64>,
    /// Unit directions `[H*W, 3]`.
    pub directions: Array2<f64>,
    /// The picture `[H][W][3]`, RGB in `[0, 1]`.
    pub image: Array3<f64>,
}

impl View {
    /// The view of `camera` with picture `image` (`[H][W][3]`, the camera's image size): one
    /// ray through each pixel's centre.
    ///
    /// Errors: [`FitError::Config`] if the picture's size is not the camera's.
    pub fn new(name: impl Into<String>, camera: &PinholeCamera, image: Array3<f64>) -> Result<View, FitError> {
        let k = camera.intrinsics();
        let name = name.into();
        if image.shape() != [k.height, k.width, 3] {
            return Err(FitError::Config(format!(
                "view {name}: picture {:?}, but the camera's image is [{}, {}, 3]",
                image.shape(),
                k.height,
                k.width
            )));
        }
        let pixels = k.pixels();
        let centre = camera.centre();
        let origins = Array2::from_shape_fn((pixels, 3), |(_, a)| centre[a]);
        let mut directions = Array2::zeros((pixels, 3));
        for (p, mut row) in directions.rows_mut().into_iter().enumerate() {
            let d = camera.direction(p / k.width, p % k.width);
            row.iter_mut().zip(d).for_each(|(r, d)| *r = d);
        }
        Ok(View {
            name,
            origins,
            directions,
            image,
        })
    }

    /// `[height, width]` of the picture.
    pub fn size(&self) -> [usize; 2] {
        [self.image.shape()[0], self.image.shape()[1]]
    }
}

/// The training rays with their colours, and the test views.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Origins `[P, 3]` of every training pixel's ray.
    pub origins: Array2<f64>,
    /// Unit directions `[P, 3]`.
    pub directions: Array2<f64>,
    /// Colours `[P, 3]`.
    pub colors: Array2<f64>,
    /// The held-out views, in order.
    pub test: Vec<View>,
    /// The background composited behind the model.
    pub background: [f64; 3],
}

impl Dataset {
    /// The pixels of the training views `train`, and the held-out views `test`.
    ///
    /// Errors: [`FitError::Config`] if there is no training pixel or no test view, or a view's
    /// rays do not match its picture.
    pub fn new(train: &[View], test: Vec<View>, background: [f64; 3]) -> Result<Dataset, FitError> {
        if test.is_empty() {
            return Err(FitError::Config("the fit needs at least one test view".into()));
        }
        for v in train.iter().chain(&test) {
            let [h, w] = v.size();
            if v.origins.dim() != (h * w, 3) || v.directions.dim() != (h * w, 3) {
                return Err(FitError::Config(format!(
                    "view {}: {} rays for a picture of {h} x {w}",
                    v.name,
                    v.origins.nrows()
                )));
            }
        }
        let pixels: usize = train.iter().map(|v| v.origins.nrows()).sum();
        if pixels == 0 {
            return Err(FitError::Config("the fit needs at least one training pixel".into()));
        }
        let (mut o, mut d, mut c) = (Vec::new(), Vec::new(), Vec::new());
        for v in train {
            o.extend(v.origins.iter().copied());
            d.extend(v.directions.iter().copied());
            c.extend(v.image.iter().copied());
        }
        let shape = |v| Array2::from_shape_vec((pixels, 3), v).map_err(|e| FitError::Config(e.to_string()));
        Ok(Dataset {
            origins: shape(o)?,
            directions: shape(d)?,
            colors: shape(c)?,
            test,
            background,
        })
    }
}
