//! Structural similarity (SSIM) as the field computes it: Wang, Bovik, Sheikh and Simoncelli
//! (2004) with their constants, an 11-tap Gaussian window of sigma 1.5, on values in `[0, 1]`,
//! averaged over the window positions that lie wholly inside the image ("valid" filtering, as
//! the authors' MATLAB code, mip-NeRF's `compute_ssim` and scikit-image's
//! `structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
//! data_range=1)` do), per channel, then over channels.

use ndarray::{s, Array2, ArrayView2, ArrayView3, Axis};
use rayon::prelude::*;

use crate::images::ImageError;

/// Taps of the Gaussian window (its radius is 5).
pub(crate) const SSIM_WINDOW: usize = 11;
/// Standard deviation of the Gaussian window, in pixels.
pub(crate) const SSIM_SIGMA: f64 = 1.5;
/// The luminance constant's factor: `C1 = (K1 L)^2` with `L = 1`.
const K1: f64 = 0.01;
/// The contrast constant's factor: `C2 = (K2 L)^2`.
const K2: f64 = 0.03;

/// Mean SSIM over `renders` against their photographs, each render clamped to `[0, 1]` as
/// [`psnr`](super::psnr) does; each image's SSIM is the mean over its channels and its valid
/// window positions, and images count equally.
///
/// Errors: [`ImageError::Empty`] for no images, [`ImageError::Shape`] if the counts or any
/// pair's shapes differ or an image is smaller than the window (11 x 11).
pub(crate) fn ssim(renders: &[ArrayView3<'_, f64>], exacts: &[ArrayView3<'_, f64>]) -> Result<f64, ImageError> {
    super::check_pairs(renders, exacts)?;
    for (i, r) in renders.iter().enumerate() {
        let (h, w, _) = r.dim();
        if h < SSIM_WINDOW || w < SSIM_WINDOW {
            return Err(ImageError::Shape {
                what: format!("render {i} (SSIM needs at least its 11 x 11 window)"),
                expected: vec![SSIM_WINDOW, SSIM_WINDOW, 3],
                got: r.shape().to_vec(),
            });
        }
    }
    let window = gaussian_window();
    let per_image: Vec<f64> = renders
        .par_iter()
        .zip(exacts.par_iter())
        .map(|(r, e)| {
            let channels = r.dim().2;
            let sum: f64 = (0..channels)
                .map(|c| {
                    let render = r.index_axis(Axis(2), c).mapv(|v| v.clamp(0.0, 1.0));
                    channel_ssim(render.view(), e.index_axis(Axis(2), c), &window)
                })
                .sum();
            sum / channels as f64
        })
        .collect();
    Ok(per_image.iter().sum::<f64>() / per_image.len() as f64)
}

/// The normalised window `exp(-(i - 5)^2 / (2 sigma^2))`, `i = 0..11`.
fn gaussian_window() -> [f64; SSIM_WINDOW] {
    let r = (SSIM_WINDOW / 2) as f64;
    let mut w = [0.0; SSIM_WINDOW];
    for (i, v) in w.iter_mut().enumerate() {
        *v = (-(i as f64 - r).powi(2) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let total: f64 = w.iter().sum();
    w.map(|v| v / total)
}

/// The window's weighted mean at every valid position: rows, then columns (the window is the
/// outer product of `window` with itself).
fn filter_valid(image: ArrayView2<'_, f64>, window: &[f64; SSIM_WINDOW]) -> Array2<f64> {
    let (h, w) = image.dim();
    let (oh, ow) = (h + 1 - SSIM_WINDOW, w + 1 - SSIM_WINDOW);
    let mut rows = Array2::zeros((oh, w));
    for (k, &wk) in window.iter().enumerate() {
        rows.scaled_add(wk, &image.slice(s![k..k + oh, ..]));
    }
    let mut out = Array2::zeros((oh, ow));
    for (k, &wk) in window.iter().enumerate() {
        out.scaled_add(wk, &rows.slice(s![.., k..k + ow]));
    }
    out
}

/// The mean of the SSIM map of one channel.
fn channel_ssim(x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>, window: &[f64; SSIM_WINDOW]) -> f64 {
    let (c1, c2) = (K1 * K1, K2 * K2);
    let mu_x = filter_valid(x, window);
    let mu_y = filter_valid(y, window);
    let xx = filter_valid((&x * &x).view(), window);
    let yy = filter_valid((&y * &y).view(), window);
    let xy = filter_valid((&x * &y).view(), window);
    let mut total = 0.0;
    ndarray::Zip::from(&mu_x)
        .and(&mu_y)
        .and(&xx)
        .and(&yy)
        .and(&xy)
        .for_each(|&mx, &my, &xx, &yy, &xy| {
            // Second moments less squared means: in f64 their cancellation costs ~1e-16 against
            // C2 = 9e-4, far below what SSIM resolves.
            let (vx, vy, cov) = (xx - mx * mx, yy - my * my, xy - mx * my);
            total += ((2.0 * mx * my + c1) * (2.0 * cov + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
        });
    total / mu_x.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_is_the_normalised_gaussian_of_sigma_one_and_a_half() {
        let w = gaussian_window();
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // Closed form of neighbouring taps' ratio: exp(-(1 - 0) / (2 * 2.25)).
        assert!((w[6] / w[5] - (-1.0f64 / 4.5).exp()).abs() < 1e-15);
        assert_eq!(w[0], w[10]);
    }

    #[test]
    fn filtering_keeps_only_whole_windows() {
        let image = Array2::from_shape_fn((13, 20), |(i, j)| (i * 20 + j) as f64);
        let out = filter_valid(image.view(), &gaussian_window());
        assert_eq!(out.dim(), (3, 10));
        // A linear image's symmetric weighted mean is its centre value.
        assert!((out[[0, 0]] - image[[5, 5]]).abs() < 1e-9);
        assert!((out[[2, 9]] - image[[7, 14]]).abs() < 1e-9);
    }
}
