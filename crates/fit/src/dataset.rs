//! The data of a fit: the training views (a camera and its picture each) and the held-out
//! views. Any source of cameras and pictures (a synthetic scene, a dataset on disk) builds one
//! from [`View`]s.
//!
//! A view keeps its camera, not a ray per pixel: rays are built when a batch or a render asks
//! for them (a few multiplications each, and a lens's undistortion), so a dataset costs its
//! pictures' memory and no more (a ray per pixel in `f64` would triple it).
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
//! let train = vec![view([3.0, 0.0, 0.0], "a")?, view([0.0, 3.0, 0.0], "b")?];
//! let data = Dataset::new(train, vec![view([0.0, -3.0, 0.0], "c")?], [1.0; 3])?;
//! assert_eq!(data.training_pixels(), 2 * 12); // every pixel of the two training views
//! let (origins, directions) = data.test[0].rays();
//! assert_eq!((origins.nrows(), directions[[0, 1]] > 0.0), (12, true)); // the camera looks along +y
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray_ops::PinholeCamera;
use ndarray::{Array2, Array3};
use rayon::prelude::*;

use crate::error::FitError;

/// One picture and the camera that took it.
#[derive(Debug, Clone)]
pub struct View {
    /// What the view is called in file names and reports.
    pub name: String,
    /// The camera (its image size is the picture's).
    pub camera: PinholeCamera,
    /// The picture `[H][W][3]`, RGB in `[0, 1]`, composited over the dataset's background
    /// ([`Dataset::background`]) where the picture had an alpha channel.
    pub image: Array3<f64>,
    /// The picture's opacity `[H][W]` in `[0, 1]`, where it had an alpha channel (`None` for
    /// an opaque picture: a JPEG photograph, a synthetic scene's render). The picture over
    /// another background `b` is `image + (b - background) (1 - alpha)`, as a training
    /// batch composites it.
    pub alpha: Option<Array2<f64>>,
}

impl View {
    /// The view of `camera` with picture `image` (`[H][W][3]`, the camera's image size).
    ///
    /// Errors: [`FitError::ViewSize`] if the picture's size is not the camera's.
    pub fn new(name: impl Into<String>, camera: &PinholeCamera, image: Array3<f64>) -> Result<View, FitError> {
        let view = View {
            name: name.into(),
            camera: camera.clone(),
            image,
            alpha: None,
        };
        view.check_size()?;
        Ok(view)
    }

    /// The view with the picture's opacity `alpha` (`[H][W]`, each value in `[0, 1]`): its
    /// `image` is the colour composited over the dataset's background with that opacity, so
    /// that a fit can composite it over another background
    /// ([`FitSettings::random_background`](crate::settings::FitSettings::random_background)).
    ///
    /// ```
    /// use fogray_fit::dataset::View;
    /// use fogray_ops::{Intrinsics, PinholeCamera};
    /// use ndarray::{Array2, Array3};
    ///
    /// let k = Intrinsics::from_vertical_fov(2, 1, 0.7)?;
    /// let camera = PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])?;
    /// // A grey 0.5 at half opacity over white: 0.75.
    /// let view = View::new("a", &camera, Array3::from_elem((1, 2, 3), 0.75))?;
    /// assert!(view.clone().with_alpha(Array2::from_elem((1, 2), 1.5)).is_err()); // not in [0, 1]
    /// assert!(view.clone().with_alpha(Array2::from_elem((2, 1), 0.5)).is_err()); // not [H][W]
    /// let view = view.with_alpha(Array2::from_elem((1, 2), 0.5))?;
    /// // A fit drawing black behind it trains on 0.75 + (0 - 1) (1 - 0.5) = 0.25.
    /// assert_eq!(view.alpha.as_ref().map(|a| a[[0, 1]]), Some(0.5));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// Errors: [`FitError::ViewSize`] if `alpha` is not the picture's `[H][W]`,
    /// [`FitError::AlphaOutOfRange`] if a value is not in `[0, 1]` (NaN included).
    pub fn with_alpha(self, alpha: Array2<f64>) -> Result<View, FitError> {
        let outside = alpha
            .indexed_iter()
            .find(|(_, a)| !(0.0..=1.0).contains(*a))
            .map(|((row, column), &value)| (row, column, value));
        let view = View {
            alpha: Some(alpha),
            ..self
        };
        view.check_size()?;
        match outside {
            Some((row, column, value)) => Err(FitError::AlphaOutOfRange {
                view: view.name,
                row,
                column,
                value,
            }),
            None => Ok(view),
        }
    }

    /// Checks that the picture, and the alpha if there is one, are the size of the camera's
    /// image: the one check behind [`View::new`], [`View::with_alpha`] and [`Dataset::new`]
    /// (which sees views whose fields may have been changed since).
    ///
    /// Errors: [`FitError::ViewSize`] naming the view and which of the two.
    fn check_size(&self) -> Result<(), FitError> {
        let k = self.camera.intrinsics();
        let refuse = |what, got: &[usize], expected: &[usize]| FitError::ViewSize {
            view: self.name.clone(),
            what,
            got: got.to_vec(),
            expected: expected.to_vec(),
        };
        let (h, w) = (k.height, k.width);
        if self.image.shape() != [h, w, 3] {
            return Err(refuse("picture", self.image.shape(), &[h, w, 3]));
        }
        match &self.alpha {
            Some(alpha) if alpha.shape() != [h, w] => Err(refuse("alpha", alpha.shape(), &[h, w])),
            _ => Ok(()),
        }
    }

    /// `[height, width]` of the picture.
    pub fn size(&self) -> [usize; 2] {
        [self.image.shape()[0], self.image.shape()[1]]
    }

    /// The ray through each pixel's centre, row-major: origins and unit directions `[H*W, 3]`
    /// (built in parallel, a row of the picture at a time).
    pub fn rays(&self) -> (Array2<f64>, Array2<f64>) {
        camera_rays(&self.camera)
    }

    /// Pixels of the picture.
    pub(crate) fn pixels(&self) -> usize {
        let [h, w] = self.size();
        h * w
    }
}

/// The ray through each pixel's centre of `camera`'s image, row-major: origins and unit
/// directions `[H*W, 3]` in `f64`, as [`render_picture`](crate::render::render_picture) takes
/// them (built in parallel, a row of the image at a time; the same values as
/// [`PinholeCamera::rays`]).
pub fn camera_rays(camera: &PinholeCamera) -> (Array2<f64>, Array2<f64>) {
    let k = camera.intrinsics();
    let (h, w) = (k.height, k.width);
    let centre = camera.centre();
    let origins = Array2::from_shape_fn((h * w, 3), |(_, a)| centre[a]);
    let mut directions = Array2::zeros((h * w, 3));
    if let Some(values) = directions.as_slice_mut() {
        values.par_chunks_mut(3 * w.max(1)).enumerate().for_each(|(row, line)| {
            for (col, d) in line.chunks_exact_mut(3).enumerate() {
                d.copy_from_slice(&camera.direction(row, col));
            }
        });
    }
    (origins, directions)
}

/// The training views and the held-out views of a fit.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The views trained on.
    pub train: Vec<View>,
    /// The held-out views, in order.
    pub test: Vec<View>,
    /// The background the pictures with alpha were composited over, and the one the model
    /// renders over for the held-out views (and for training, unless
    /// [`FitSettings::random_background`](crate::settings::FitSettings::random_background)
    /// draws others for the views with alpha).
    pub background: [f64; 3],
}

impl Dataset {
    /// The training views `train` and the held-out views `test`.
    ///
    /// Errors: [`FitError::NoTrainingPixel`], [`FitError::NoTestView`], or
    /// [`FitError::ViewSize`] if a view's picture or alpha is not its camera's size (possible only if its fields were changed
    /// after [`View::new`] or [`View::with_alpha`]).
    pub fn new(train: Vec<View>, test: Vec<View>, background: [f64; 3]) -> Result<Dataset, FitError> {
        if test.is_empty() {
            return Err(FitError::NoTestView);
        }
        for v in train.iter().chain(&test) {
            v.check_size()?;
        }
        let data = Dataset {
            train,
            test,
            background,
        };
        if data.training_pixels() == 0 {
            return Err(FitError::NoTrainingPixel);
        }
        Ok(data)
    }

    /// Pixels of all training views.
    pub fn training_pixels(&self) -> usize {
        self.train.iter().map(View::pixels).sum()
    }

    /// Whether any training view has an alpha channel.
    pub(crate) fn training_alpha(&self) -> bool {
        self.train.iter().any(|v| v.alpha.is_some())
    }

    /// `count` of the training views (all of them if there are fewer): views `i n / count` of
    /// the `n`, for `i` in `0..count`, spread through the training list as the held-out views
    /// are through the file. What a fit's PSNR on its own views is measured on, whatever the
    /// model.
    pub(crate) fn spread_training_views(&self, count: usize) -> Vec<&View> {
        let n = self.train.len();
        let count = count.min(n);
        (0..count).map(|i| &self.train[i * n / count]).collect()
    }
}
