//! The training batches of a fit: the rays and exact colours of the pixels a step draws,
//! gathered from one table in the fit's precision.
//!
//! A step draws its pixels at random from all training views, so each one is a cache miss.
//! Kept as three `[P, 3]` tables of `f64` (as [`Dataset`] holds them), a pixel costs three
//! misses and a conversion on every step; interleaved once in `F`, its origin, direction and
//! colour share one or two cache lines.
//!
use fogray_ops::rays::RayBatch;
use fogray_tape::Float;
use ndarray::Array2;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::FitError;

/// Values of a pixel in the table: origin, direction, colour.
const ROW: usize = 9;

/// Pixels per parallel task of a gather.
const ROWS_PER_TASK: usize = 1024;

/// Every training pixel's origin, unit direction and exact colour, converted to `F` and
/// interleaved, pixel by pixel.
#[derive(Debug, Clone)]
pub struct TrainingTable<F: Float> {
    values: Vec<F>,
    pixels: usize,
}

/// The pixels one step trains on.
#[derive(Debug, Clone)]
pub struct TrainingBatch<F: Float> {
    /// Their rays.
    pub rays: RayBatch<F>,
    /// Their exact colours `[n, 3]`.
    pub colors: Array2<F>,
}

impl<F: Float> TrainingTable<F> {
    /// The table of `data`'s training pixels, each value rounded to `F` (to nearest).
    pub fn new(data: &Dataset) -> Self {
        let pixels = data.origins.nrows();
        let mut values = Vec::with_capacity(pixels * ROW);
        for p in 0..pixels {
            for table in [&data.origins, &data.directions, &data.colors] {
                values.extend(table.row(p).iter().map(|&v| F::lit(v)));
            }
        }
        TrainingTable { values, pixels }
    }

    /// Training pixels in the table.
    pub fn pixels(&self) -> usize {
        self.pixels
    }

    /// The rays and colours of pixels `rows`, in that order (a pixel may repeat).
    ///
    /// Errors: [`FitError::Config`] for a row past the last pixel (nothing is gathered), or
    /// an error of [`RayBatch::new`] (no rows at all).
    pub fn gather(&self, rows: &[usize]) -> Result<TrainingBatch<F>, FitError> {
        if let Some(&bad) = rows.iter().find(|&&r| r >= self.pixels) {
            return Err(FitError::Config(format!(
                "training pixel {bad} asked of a table of {}",
                self.pixels
            )));
        }
        let n = rows.len();
        let (mut o, mut d, mut c) = (vec![F::zero(); 3 * n], vec![F::zero(); 3 * n], vec![F::zero(); 3 * n]);
        // In parallel: each row is a cache miss into a table of megabytes.
        o.par_chunks_mut(3 * ROWS_PER_TASK)
            .zip(d.par_chunks_mut(3 * ROWS_PER_TASK))
            .zip(c.par_chunks_mut(3 * ROWS_PER_TASK))
            .zip(rows.par_chunks(ROWS_PER_TASK))
            .for_each(|(((o, d), c), rows)| {
                for (k, &r) in rows.iter().enumerate() {
                    let pixel = &self.values[r * ROW..(r + 1) * ROW];
                    o[3 * k..3 * k + 3].copy_from_slice(&pixel[0..3]);
                    d[3 * k..3 * k + 3].copy_from_slice(&pixel[3..6]);
                    c[3 * k..3 * k + 3].copy_from_slice(&pixel[6..9]);
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

    #[test]
    fn a_batch_holds_the_drawn_pixels_rounded_to_the_precision() {
        let data = small_dataset();
        // Past one parallel task's rows, and ending inside another's.
        let mut rows = vec![7, 0, 74, 7];
        rows.extend((0..2 * ROWS_PER_TASK + 3).map(|k| (k * 37 + 5) % data.origins.nrows()));
        let batch = TrainingTable::<f32>::new(&data).gather(&rows).unwrap();
        assert_eq!(batch.colors.nrows(), rows.len());
        for (k, &r) in rows.iter().enumerate() {
            for a in 0..3 {
                assert_eq!(batch.rays.origins()[[k, a]], data.origins[[r, a]] as f32);
                assert_eq!(batch.rays.directions()[[k, a]], data.directions[[r, a]] as f32);
                assert_eq!(batch.colors[[k, a]], data.colors[[r, a]] as f32);
            }
        }
        let exact = TrainingTable::<f64>::new(&data).gather(&rows).unwrap();
        assert_eq!(exact.colors[[2, 0]], data.colors[[74, 0]]);
    }

    #[test]
    fn a_row_past_the_last_pixel_is_refused() {
        let data = small_dataset();
        let table = TrainingTable::<f64>::new(&data);
        let pixels = data.origins.nrows();
        assert_eq!(table.pixels(), pixels);
        let err = table.gather(&[0, pixels]).unwrap_err();
        assert!(err.to_string().contains(&format!("training pixel {pixels}")), "{err}");
    }
}
