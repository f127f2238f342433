//! SSIM against an independent implementation (scikit-image 0.26's `structural_similarity`
//! with `gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0,
//! channel_axis=-1`, the field's settings) on fixed images that both sides build from the same
//! formulas, and against closed forms.

use crate::images::ImageError;
use crate::metrics::ssim;
use ndarray::Array3;

const H: usize = 24;
const W: usize = 31;

/// `0.5 + 0.4 sin(0.3 i + 0.7 j + 1.1 c)`: smooth structure in [0.1, 0.9].
fn smooth() -> Array3<f64> {
    Array3::from_shape_fn((H, W, 3), |(i, j, c)| {
        0.5 + 0.4 * (0.3 * i as f64 + 0.7 * j as f64 + 1.1 * c as f64).sin()
    })
}

/// `smooth + 0.1 cos(1.3 i - 0.4 j + 2 c)`: the same structure, slightly changed.
fn perturbed() -> Array3<f64> {
    let x = smooth();
    Array3::from_shape_fn((H, W, 3), |(i, j, c)| {
        x[[i, j, c]] + 0.1 * (1.3 * i as f64 - 0.4 * j as f64 + 2.0 * c as f64).cos()
    })
}

/// An integer hash in [0, 1]: structure unrelated to [`smooth`].
fn noise() -> Array3<f64> {
    Array3::from_shape_fn((H, W, 3), |(i, j, c)| {
        (((i * 73856093) ^ (j * 19349663) ^ (c * 83492791)) % 1000) as f64 / 999.0
    })
}

#[test]
fn ssim_matches_scikit_image_on_fixed_images() {
    let x = smooth();
    for (render, expected) in [(perturbed(), 0.9581692085795915), (noise(), -0.010560046067742109)] {
        let got = ssim(&[render.view()], &[x.view()]).unwrap();
        assert!((got - expected).abs() < 1e-12, "{got} vs scikit-image's {expected}");
    }
}

#[test]
fn ssim_averages_images_and_clamps_renders_as_psnr_does() {
    let (x, y) = (smooth(), perturbed());
    let two = ssim(&[y.view(), x.view()], &[x.view(), x.view()]).unwrap();
    assert!((two - (0.9581692085795915 + 1.0) / 2.0).abs() < 1e-12);
    // A render above 1 where the photograph is 1 is as good as 1.
    let white = Array3::from_elem((H, W, 3), 1.0);
    let over = Array3::from_elem((H, W, 3), 1.7);
    assert_eq!(ssim(&[over.view()], &[white.view()]).unwrap(), 1.0);
}

#[test]
fn ssim_refuses_what_it_cannot_measure() {
    let x = smooth();
    assert_eq!(ssim(&[], &[]), Err(ImageError::Empty));
    assert!(matches!(ssim(&[x.view()], &[]), Err(ImageError::Shape { .. })));
    let small = Array3::from_elem((10, 40, 3), 0.5);
    let e = ssim(&[small.view()], &[small.view()]).unwrap_err().to_string();
    assert!(e.contains("11 x 11"), "{e}");
    let other = Array3::from_elem((H, W + 1, 3), 0.5);
    assert!(matches!(
        ssim(&[other.view()], &[x.view()]),
        Err(ImageError::Shape { .. })
    ));
}

#[test]
fn view_scores_split_the_psnr_of_all_views_by_their_squared_error() {
    use crate::metrics::{psnr, view_scores};
    let (exact, a, b) = (smooth(), perturbed(), noise());
    // Clamped as psnr clamps: a render above 1 where the picture is 1 costs nothing.
    let mut over = exact.clone();
    over.mapv_inplace(|v| if v > 0.8 { 1.0 } else { v });
    let bright = over.mapv(|v| if v == 1.0 { 7.0 } else { v + 0.05 });
    let renders = [a.view(), b.view(), bright.view()];
    let exacts = [exact.view(), exact.view(), over.view()];
    let scores = view_scores(&renders, &exacts).unwrap();
    for (i, s) in scores.iter().enumerate() {
        assert_eq!(s.psnr, psnr(&renders[i..=i], &exacts[i..=i]).unwrap());
    }
    // Same-sized views: the mean of their squared errors is the PSNR of all of them, and the
    // shares are each view's squared error over the sum.
    let mse: Vec<f64> = scores.iter().map(|s| 10f64.powf(-s.psnr / 10.0)).collect();
    let all = psnr(&renders, &exacts).unwrap();
    assert!((-10.0 * (mse.iter().sum::<f64>() / 3.0).log10() - all).abs() < 1e-9);
    for (s, m) in scores.iter().zip(&mse) {
        assert!((s.share_of_error - m / mse.iter().sum::<f64>()).abs() < 1e-12);
    }
    // The clamped view's error is the 0.05 off the values below 1 alone.
    let below = over.iter().filter(|&&v| v < 1.0).count() as f64;
    let want = -10.0 * (below * 0.05f64.powi(2) / over.len() as f64).log10();
    assert!(
        (scores[2].psnr - want).abs() < 1e-9,
        "{} against {want}",
        scores[2].psnr
    );
    assert!(view_scores(&[], &[]).is_err());
}

#[test]
fn the_mean_of_view_psnrs_is_not_the_psnr_of_all_views() -> Result<(), ImageError> {
    use crate::metrics::{mean_psnr, psnr, view_scores};
    // Errors of 0.1 and 0.001 everywhere: 20 dB and 60 dB, a mean of 40 dB; the MSE over both,
    // (0.01 + 1e-6) / 2, is 23.01 dB.
    let exact = Array3::from_elem((2, 2, 3), 0.5);
    let (a, b) = (Array3::from_elem((2, 2, 3), 0.6), Array3::from_elem((2, 2, 3), 0.501));
    let (r, e) = ([a.view(), b.view()], [exact.view(), exact.view()]);
    assert!((mean_psnr(&view_scores(&r, &e)?) - 40.0).abs() < 1e-9);
    assert!((psnr(&r, &e)? - 23.0099).abs() < 1e-4);
    assert!(view_scores(&[], &[]).is_err() && view_scores(&r[..1], &e).is_err());
    Ok(())
}

#[test]
fn view_scores_are_each_pairs_psnr_and_share_of_the_squared_error() -> Result<(), ImageError> {
    use crate::metrics::view_scores;
    // Errors of 0.1 and 0.2 everywhere: MSE 0.01 and 0.04, 20 dB and 13.98 dB, a fifth and
    // four fifths of the squared error.
    let exact = Array3::from_elem((2, 2, 3), 0.5);
    let (a, b) = (Array3::from_elem((2, 2, 3), 0.6), Array3::from_elem((2, 2, 3), 0.3));
    let s = view_scores(&[a.view(), b.view()], &[exact.view(), exact.view()])?;
    assert!((s[0].psnr - 20.0).abs() < 1e-9 && (s[1].psnr - 13.979400086720377).abs() < 1e-9);
    assert!((s[0].share_of_error - 0.2).abs() < 1e-12 && (s[1].share_of_error - 0.8).abs() < 1e-12);
    Ok(())
}

#[test]
fn ssim_of_flat_images_is_the_luminance_term() -> Result<(), ImageError> {
    // Two flat images: only the luminance term is left, (2ab + C1) / (a^2 + b^2 + C1).
    let a = Array3::from_elem((16, 16, 3), 0.2);
    let b = Array3::from_elem((16, 16, 3), 0.6);
    let c1 = 0.01f64.powi(2);
    let expected = (2.0 * 0.2 * 0.6 + c1) / (0.2f64.powi(2) + 0.6f64.powi(2) + c1);
    assert!((ssim(&[a.view()], &[b.view()])? - expected).abs() < 1e-12);
    assert_eq!(ssim(&[a.view()], &[a.view()])?, 1.0);
    Ok(())
}
