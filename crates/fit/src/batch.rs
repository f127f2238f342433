//! The training batches of a fit: the rays and exact colours of the pixels a step draws from
//! all training views, numbered one after another (view 0's pixels first, row-major).
//!
//! A drawn pixel's ray is built from its view's camera when the batch is gathered (a few
//! multiplications, beside the cache miss of reading its colour), so that no table of a ray
//! per training pixel is kept: for 90 views of 800 x 800 it would take 2.8 GB in `f64`.
//!
use fogray_ops::rays::RayBatch;
use fogray_tape::Float;
use ndarray::Array2;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::FitError;

/// Pixels per parallel task of a gather.
const ROWS_PER_TASK: usize = 1024;

/// Every training pixel of a dataset, numbered across its views.
#[derive(Debug, Clone)]
pub struct TrainingTable<'a> {
    data: &'a Dataset,
    /// `starts[v]` is the number of view `v`'s first pixel; the last entry is the total.
    starts: Vec<usize>,
}

/// The pixels one step trains on.
#[derive(Debug, Clone)]
pub struct TrainingBatch<F: Float> {
    /// Their rays.
    pub rays: RayBatch<F>,
    /// Their exact colours `[n, 3]`.
    pub colors: Array2<F>,
}

impl<'a> TrainingTable<'a> {
    /// The training pixels of `data`.
    pub fn new(data: &'a Dataset) -> Self {
        let mut starts = vec![0];
        for v in &data.train {
            starts.push(starts[starts.len() - 1] + v.pixels());
        }
        TrainingTable { data, starts }
    }

    /// Training pixels in the table.
    pub fn pixels(&self) -> usize {
        self.starts[self.starts.len() - 1]
    }

    /// The rays and colours of pixels `rows`, in that order (a pixel may repeat), each value
    /// rounded to `F` (to nearest) from the view's `f64`.
    ///
    /// Errors: [`FitError::Config`] for a row past the last pixel (nothing is gathered), or
    /// an error of [`RayBatch::new`] (no rows at all).
    pub fn gather<F: Float>(&self, rows: &[usize]) -> Result<TrainingBatch<F>, FitError> {
        if let Some(&bad) = rows.iter().find(|&&r| r >= self.pixels()) {
            return Err(FitError::Config(format!(
                "training pixel {bad} asked of a table of {}",
                self.pixels()
            )));
        }
        let n = rows.len();
        let (mut o, mut d, mut c) = (vec![F::zero(); 3 * n], vec![F::zero(); 3 * n], vec![F::zero(); 3 * n]);
        o.par_chunks_mut(3 * ROWS_PER_TASK)
            .zip(d.par_chunks_mut(3 * ROWS_PER_TASK))
            .zip(c.par_chunks_mut(3 * ROWS_PER_TASK))
            .zip(rows.par_chunks(ROWS_PER_TASK))
            .for_each(|(((o, d), c), rows)| {
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
                }
            });
        let shape = |v| Array2::from_shape_vec((n, 3), v).map_err(|e| FitError::Config(e.to_string()));
        Ok(TrainingBatch {
            rays: RayBatch::new(shape(o)?, shape(d)?)?,
            colors: shape(c)?,
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

    #[test]
    fn a_row_past_the_last_pixel_is_refused() {
        let data = small_dataset();
        let table = TrainingTable::new(&data);
        let pixels = data.training_pixels();
        assert_eq!(table.pixels(), pixels);
        let err = table.gather::<f64>(&[0, pixels]).unwrap_err();
        assert!(err.to_string().contains(&format!("training pixel {pixels}")), "{err}");
    }
}
