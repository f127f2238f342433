//! The training batches of a fit: the rays and exact colours of the pixels a step draws from
//! all training views, numbered one after another (view 0's pixels first, row-major).
//!
//! A drawn pixel's ray is built from its view's camera when the batch is gathered (a few
//! multiplications, beside the cache miss of reading its colour), so that no table of a ray
//! per training pixel is kept: for 90 views of 800 x 800 it would take 2.8 GB in `f64`.
//!
use fogray_ops::rays::RayBatch;
use fogray_tape::Float;
use ndarray::{Array1, Array2, ArrayView2};
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::FitError;

/// Pixels per parallel task of a gather.
const ROWS_PER_TASK: usize = 1024;

/// Every training pixel of a dataset, numbered across its views.
#[derive(Debug, Clone)]
pub(crate) struct TrainingTable<'a> {
    data: &'a Dataset,
    /// `starts[v]` is the number of view `v`'s first pixel; the last entry is the total.
    starts: Vec<usize>,
}

/// The pixels one step trains on.
#[derive(Debug, Clone)]
pub(crate) struct TrainingBatch<F: Float> {
    /// Their rays.
    pub rays: RayBatch<F>,
    /// Their exact colours `[n, 3]`, composited over the dataset's background where their
    /// picture had alpha.
    pub colors: Array2<F>,
    /// Their opacities `[n]`, when a training view has an alpha channel (a pixel of a view
    /// without one is opaque: 1); `None` when no training view has one.
    pub alpha: Option<Array1<F>>,
}

impl<F: Float> TrainingBatch<F> {
    /// The pixels' colours over `backgrounds` (`[n, 3]`, one per pixel) instead of `from`,
    /// the background they were composited over: `color + (b - from) (1 - alpha)` in `f64`,
    /// rounded to `F`; the colours themselves without alpha.
    ///
    /// Errors: [`FitError::BackgroundsShape`] if `backgrounds` is not `[n, 3]`.
    pub(crate) fn colors_over(&self, from: [f64; 3], backgrounds: ArrayView2<'_, F>) -> Result<Array2<F>, FitError> {
        if backgrounds.dim() != self.colors.dim() {
            return Err(FitError::BackgroundsShape {
                got: backgrounds.shape().to_vec(),
                pixels: self.colors.nrows(),
            });
        }
        let Some(alpha) = &self.alpha else {
            return Ok(self.colors.clone());
        };
        Ok(Array2::from_shape_fn(self.colors.dim(), |(k, c)| {
            let seen = 1.0 - alpha[k].as_f64();
            F::lit(self.colors[[k, c]].as_f64() + (backgrounds[[k, c]].as_f64() - from[c]) * seen)
        }))
    }
}

impl<'a> TrainingTable<'a> {
    /// The training pixels of `data`.
    pub(crate) fn new(data: &'a Dataset) -> Self {
        let mut starts = vec![0];
        for v in &data.train {
            starts.push(starts[starts.len() - 1] + v.pixels());
        }
        TrainingTable { data, starts }
    }

    /// Training pixels in the table.
    pub(crate) fn pixels(&self) -> usize {
        self.starts[self.starts.len() - 1]
    }

    /// The rays, colours and (when a training view has alpha) opacities of pixels `rows`, in
    /// that order (a pixel may repeat), each value rounded to `F` (to nearest) from the view's
    /// `f64`.
    ///
    /// Errors: [`FitError::PixelOutOfRange`] for a row past the last pixel (nothing is gathered), or
    /// an error of [`RayBatch::new`] (no rows at all).
    pub(crate) fn gather<F: Float>(&self, rows: &[usize]) -> Result<TrainingBatch<F>, FitError> {
        if let Some(&bad) = rows.iter().find(|&&r| r >= self.pixels()) {
            return Err(FitError::PixelOutOfRange {
                pixel: bad,
                pixels: self.pixels(),
            });
        }
        let n = rows.len();
        let (mut o, mut d, mut c) = (vec![F::zero(); 3 * n], vec![F::zero(); 3 * n], vec![F::zero(); 3 * n]);
        let with_alpha = self.data.training_alpha();
        let mut alpha = vec![F::one(); if with_alpha { n } else { 0 }];
        // Each task's opacities; without alpha, every task gets an empty slice.
        let mut alpha_chunks: Vec<&mut [F]> = alpha.chunks_mut(ROWS_PER_TASK).collect();
        alpha_chunks.resize_with(n.div_ceil(ROWS_PER_TASK), Default::default);
        o.par_chunks_mut(3 * ROWS_PER_TASK)
            .zip(d.par_chunks_mut(3 * ROWS_PER_TASK))
            .zip(c.par_chunks_mut(3 * ROWS_PER_TASK))
            .zip(alpha_chunks.into_par_iter())
            .zip(rows.par_chunks(ROWS_PER_TASK))
            .for_each(|((((o, d), c), opacity), rows)| {
                for (k, &r) in rows.iter().enumerate() {
                    // The view holding pixel r: the last start at or before it.
                    let v = self.starts.partition_point(|&s| s <= r) - 1;
                    let view = &self.data.train[v];
                    let pixel = r - self.starts[v];
                    let width = view.size()[1];
                    let (row, col) = (pixel / width, pixel % width);
                    let origin = view.camera.centre();
                    let direction = view.camera.direction(row, col);
                    for a in 0..3 {
                        o[3 * k + a] = F::lit(origin[a]);
                        d[3 * k + a] = F::lit(direction[a]);
                        c[3 * k + a] = F::lit(view.image[[row, col, a]]);
                    }
                    if let (Some(slot), Some(alpha)) = (opacity.get_mut(k), &view.alpha) {
                        *slot = F::lit(alpha[[row, col]]);
                    }
                }
            });
        let shape = |v| Array2::from_shape_vec((n, 3), v).map_err(|e| FitError::Config(e.to_string()));
        Ok(TrainingBatch {
            rays: RayBatch::new(shape(o)?, shape(d)?)?,
            colors: shape(c)?,
            alpha: with_alpha.then(|| Array1::from(alpha)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::small_dataset;

    /// Pixel numbers across views against the views' own rays and pictures.
    #[test]
    fn a_batch_holds_the_drawn_pixels_rounded_to_the_precision() {
        let data = small_dataset();
        let table = TrainingTable::new(&data);
        let per_view = data.train[0].pixels();
        // Past one parallel task's rows, and ending inside another's; every view.
        let mut rows = vec![7, 0, per_view + 10, 7, 3 * per_view - 1];
        rows.extend((0..2 * ROWS_PER_TASK + 3).map(|k| (k * 37 + 5) % table.pixels()));
        let batch = table.gather::<f32>(&rows).unwrap();
        assert_eq!(batch.colors.nrows(), rows.len());
        let rays: Vec<_> = data.train.iter().map(|v| v.rays()).collect();
        for (k, &r) in rows.iter().enumerate() {
            let (v, p) = (r / per_view, r % per_view);
            let (origins, directions) = &rays[v];
            let image = &data.train[v].image;
            for a in 0..3 {
                assert_eq!(batch.rays.origins()[[k, a]], origins[[p, a]] as f32);
                assert_eq!(batch.rays.directions()[[k, a]], directions[[p, a]] as f32);
                assert_eq!(batch.colors[[k, a]], image[[p / 8, p % 8, a]] as f32);
            }
        }
        let exact = table.gather::<f64>(&rows).unwrap();
        assert_eq!(exact.colors[[2, 0]], data.train[1].image[[1, 2, 0]]);
    }

    /// The picture over another background against a pixel computed by hand: colour
    /// (0.8, 0.3, 0.1) at opacity 0.25 over white is (0.95, 0.825, 0.775); over
    /// (0.2, 0.4, 0.6) it is 0.25 (0.8, 0.3, 0.1) + 0.75 (0.2, 0.4, 0.6) = (0.35, 0.375, 0.475).
    #[test]
    fn a_pixel_with_alpha_over_another_background_is_the_colour_composited_over_it() {
        let mut data = small_dataset();
        let over_white = [0.95, 0.825, 0.775];
        for (c, v) in over_white.into_iter().enumerate() {
            data.train[1].image[[2, 5, c]] = v;
            data.train[1].image[[0, 0, c]] = 1.0; // transparent over white
        }
        let mut alpha = Array2::from_elem((8, 8), 1.0);
        alpha[[2, 5]] = 0.25;
        alpha[[0, 0]] = 0.0;
        let view = data.train[1].clone().with_alpha(alpha).unwrap();
        let want = [0.35, 0.375, 0.475];
        data.train[1] = view;
        // In a batch: view 1's pixel (2, 5), its transparent (0, 0), and a pixel of view 0,
        // which has no alpha and is opaque.
        let table = TrainingTable::new(&data);
        let rows = [64 + 2 * 8 + 5, 64, 3];
        let batch = table.gather::<f64>(&rows).unwrap();
        assert_eq!(batch.alpha, Some(ndarray::arr1(&[0.25, 0.0, 1.0])));
        let backgrounds = ndarray::arr2(&[[0.2, 0.4, 0.6], [0.0, 0.5, 1.0], [0.0, 0.0, 0.0]]);
        let targets = batch.colors_over([1.0; 3], backgrounds.view()).unwrap();
        for c in 0..3 {
            assert!((targets[[0, c]] - want[c]).abs() < 1e-15, "{targets}");
            // Transparent: the background itself; opaque: the picture whatever the background.
            assert!((targets[[1, c]] - backgrounds[[1, c]]).abs() < 1e-15, "{targets}");
            assert_eq!(targets[[2, c]], data.train[0].image[[0, 3, c]]);
        }
        let e = batch
            .colors_over([1.0; 3], backgrounds.slice(ndarray::s![..2, ..]))
            .unwrap_err();
        assert_eq!(e.to_string(), "backgrounds [2, 3] for a batch of 3 pixels");
        // Without alpha anywhere the batch carries none.
        assert_eq!(
            TrainingTable::new(&small_dataset()).gather::<f32>(&rows).unwrap().alpha,
            None
        );
    }

    #[test]
    fn a_view_refuses_an_alpha_of_the_wrong_shape_or_range() {
        let view = small_dataset().train[0].clone();
        for (alpha, size, says) in [
            (
                Array2::from_elem((8, 7), 0.5),
                true,
                "view 000: alpha [8, 7], but the camera's image is [8, 8]",
            ),
            (
                Array2::from_elem((8, 8), -0.1),
                false,
                "view 000: alpha -0.1 at row 0, column 0 (must be in [0, 1])",
            ),
            (
                Array2::from_elem((8, 8), f64::NAN),
                false,
                "view 000: alpha NaN at row 0, column 0 (must be in [0, 1])",
            ),
        ] {
            let e = view.clone().with_alpha(alpha).unwrap_err();
            let typed = if size {
                matches!(e, FitError::ViewSize { what: "alpha", .. })
            } else {
                matches!(e, FitError::AlphaOutOfRange { row: 0, column: 0, .. })
            };
            assert!(typed, "{e:?}");
            assert_eq!(e.to_string(), says);
        }
    }

    #[test]
    fn a_row_past_the_last_pixel_is_refused() {
        let data = small_dataset();
        let table = TrainingTable::new(&data);
        let pixels = data.training_pixels();
        assert_eq!(table.pixels(), pixels);
        let err = table.gather::<f64>(&[0, pixels]).unwrap_err();
        assert_eq!(err, FitError::PixelOutOfRange { pixel: pixels, pixels });
        assert_eq!(
            err.to_string(),
            format!("training pixel {pixels} asked of a table of {pixels}")
        );
    }
}
