//! How close renders are to their pictures: PSNR, SSIM, and the haze of their opacity.
//!
//! ```
//! use fogray_fit::metrics::psnr;
//! use ndarray::Array3;
//!
//! // Every value off by 0.1: MSE 0.01, PSNR = -10 log10(0.01) = 20 dB.
//! let exact = Array3::from_elem((4, 4, 3), 0.5);
//! let render = Array3::from_elem((4, 4, 3), 0.6);
//! let db = psnr(&[render.view()], &[exact.view()])?;
//! assert!((db - 20.0).abs() < 1e-9);
//! # Ok::<(), fogray_fit::images::ImageError>(())
//! ```

use ndarray::{ArrayView3, Zip};

mod ssim;
pub(crate) use ssim::ssim;
pub(crate) use ssim::SSIM_WINDOW;

use crate::images::{check_same, ImageError};

/// Test PSNR in dB: `-10 log10` of the mean over all pixels and channels of all image pairs of
/// `(clamp(render, 0, 1) - exact)^2`. Infinite when every clamped render equals its photograph.
///
/// Errors: [`ImageError::Empty`] for no images, [`ImageError::Shape`] if the counts or any
/// pair's shapes differ.
pub fn psnr(renders: &[ArrayView3<'_, f64>], exacts: &[ArrayView3<'_, f64>]) -> Result<f64, ImageError> {
    check_pairs(renders, exacts)?;
    let (mut sum, mut count) = (0.0, 0usize);
    for (r, e) in renders.iter().zip(exacts) {
        sum += squared_error(r, e);
        count += r.len();
    }
    Ok(-10.0 * (sum / count as f64).log10())
}

/// One view's part in a PSNR over several.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ViewScore {
    /// The view's own PSNR (dB), as [`psnr`] of it alone.
    pub psnr: f64,
    /// Its squared error over the summed squared error of all the views (0 to 1; NaN when
    /// every view is exact): where the PSNR over all of them loses its decibels, since the
    /// mean squared error, not the mean PSNR, sets it.
    pub share_of_error: f64,
}

/// Each image pair's PSNR and share of the squared error, with [`psnr`]'s clamping.
///
/// Errors: as [`psnr`]'s.
pub(crate) fn view_scores(
    renders: &[ArrayView3<'_, f64>],
    exacts: &[ArrayView3<'_, f64>],
) -> Result<Vec<ViewScore>, ImageError> {
    check_pairs(renders, exacts)?;
    let errors: Vec<f64> = renders.iter().zip(exacts).map(|(r, e)| squared_error(r, e)).collect();
    let total: f64 = errors.iter().sum();
    Ok(errors
        .iter()
        .zip(renders)
        .map(|(&sse, r)| ViewScore {
            psnr: -10.0 * (sse / r.len() as f64).log10(),
            share_of_error: sse / total,
        })
        .collect())
}

/// The mean of `scores`' PSNRs (dB), scores from [`view_scores`] (NaN for no scores): the mean
/// of the image pairs' own PSNRs, with [`psnr`]'s clamping, the convention of the NeRF
/// literature and its tools (nerfstudio's evaluation, instant-ngp, DVGO, Plenoxels), where
/// [`psnr`] takes the mean squared error over all pairs first. By the concavity of the
/// logarithm it is never below [`psnr`] for views of one size; a hard view weighs in by its
/// decibels here, by its squared error there. Infinite when a pair is exact.
pub(crate) fn mean_psnr(scores: &[ViewScore]) -> f64 {
    scores.iter().map(|s| s.psnr).sum::<f64>() / scores.len() as f64
}

/// The sum over a pair's values of `(clamp(render, 0, 1) - exact)^2`.
fn squared_error(render: &ArrayView3<'_, f64>, exact: &ArrayView3<'_, f64>) -> f64 {
    Zip::from(render)
        .and(exact)
        .fold(0.0, |acc, r, e| acc + (r.clamp(0.0, 1.0) - e).powi(2))
}

/// The fraction of pixels whose opacity lies strictly between `lo` and `hi`, over all
/// `opacities`: with `(0.05, 0.95)`, the haze of a model that should be opaque or empty
/// everywhere (an object in front of a background). NaN when there is no pixel.
///
/// ```
/// use fogray_fit::metrics::haze_fraction;
/// use ndarray::arr2;
///
/// let opacity = arr2(&[[0.0, 0.5], [0.97, 0.05]]);
/// assert_eq!(haze_fraction(&[opacity.view()], 0.05, 0.95), 0.25); // only 0.5
/// ```
pub fn haze_fraction(opacities: &[ndarray::ArrayView2<'_, f64>], lo: f64, hi: f64) -> f64 {
    let pixels: usize = opacities.iter().map(|o| o.len()).sum();
    let hazy: usize = opacities
        .iter()
        .map(|o| o.iter().filter(|&&a| lo < a && a < hi).count())
        .sum();
    hazy as f64 / pixels as f64
}

/// Errors: [`ImageError::Empty`] for no renders, [`ImageError::Shape`] if the counts or any
/// pair's shapes differ.
fn check_pairs(renders: &[ArrayView3<'_, f64>], exacts: &[ArrayView3<'_, f64>]) -> Result<(), ImageError> {
    if renders.is_empty() {
        return Err(ImageError::Empty);
    }
    if renders.len() != exacts.len() {
        return Err(ImageError::Shape {
            what: "number of renders".into(),
            expected: vec![exacts.len()],
            got: vec![renders.len()],
        });
    }
    for (i, (r, e)) in renders.iter().zip(exacts).enumerate() {
        check_same(&format!("render {i}"), r, e)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
