use fogray_tape::Offsets;
use ndarray::{arr1, Array1, Array2};

use super::PackedSamples;
use crate::error::{At, Op, OpsError};

/// Packed samples with the given per-ray `delta`s (positions and t are the sample index, so
/// a test can see which samples were kept).
fn packed<F: fogray_tape::Float>(rays: &[Vec<f64>]) -> PackedSamples<F> {
    let n: usize = rays.iter().map(Vec::len).sum();
    PackedSamples {
        positions: Array2::from_shape_fn((n, 3), |(k, _)| F::lit(k as f64)),
        t: Array1::from_iter((0..n).map(|k| F::lit(k as f64))),
        delta: Array1::from_iter(rays.iter().flatten().map(|&d| F::lit(d))),
        offsets: Offsets::from_lengths(rays.iter().map(Vec::len)),
        ray: rays
            .iter()
            .enumerate()
            .flat_map(|(r, v)| std::iter::repeat_n(r, v.len()))
            .collect(),
    }
}

#[test]
fn keeps_each_ray_until_its_transmittance_falls_below_the_threshold() {
    // Ray 0: optical depth 1 per sample, so T on arrival is 1, e^-1, e^-2, e^-3; with a
    // threshold of 0.2 (ln 5 = 1.61) samples 0 and 1 remain. Ray 1 is empty; ray 2 has no
    // density and keeps everything.
    let s = packed::<f64>(&[vec![1.0; 4], vec![], vec![0.5; 3]]);
    let sigma = arr1(&[1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
    let v = s.visible(sigma.view(), 0.2).unwrap();
    assert_eq!(v.offsets.as_slice(), &[0, 2, 2, 5]);
    assert_eq!(v.t.to_vec(), vec![0.0, 1.0, 4.0, 5.0, 6.0]);
    assert_eq!(v.ray, vec![0, 0, 2, 2, 2]);
    assert_eq!(v.positions.column(1).to_vec(), vec![0.0, 1.0, 4.0, 5.0, 6.0]);
    assert_eq!(v.delta.to_vec(), vec![1.0, 1.0, 0.5, 0.5, 0.5]);
    // A threshold of 0 keeps every sample.
    assert_eq!(s.visible(sigma.view(), 0.0).unwrap(), s);
}

/// The colour of one ray by the textbook sum, in f64: an independent reference.
fn colour(sigma: &[f64], delta: &[f64], color: &[f64], background: f64) -> f64 {
    let (mut t, mut c) = (1.0, 0.0);
    for k in 0..sigma.len() {
        let a = 1.0 - (-sigma[k] * delta[k]).exp();
        c += t * a * color[k];
        t *= 1.0 - a;
    }
    c + t * background
}

#[test]
fn the_kept_samples_render_within_the_threshold_of_the_full_ray() {
    // Rays through a slab of rising density: the full render and the render of the kept
    // samples differ by at most the threshold (colours and background in [0, 1]), and the
    // truncation does drop samples.
    let n = 200;
    let delta: Vec<f64> = vec![0.01; n];
    let sigma: Vec<f64> = (0..n)
        .map(|k| if k < 50 { 0.0 } else { 3.0 * (k - 50) as f64 })
        .collect();
    let color: Vec<f64> = (0..n).map(|k| (k as f64 * 0.37).sin().abs()).collect();
    let s = packed::<f64>(std::slice::from_ref(&delta));
    for min_t in [1e-2, 1e-3, 1e-4] {
        let v = s.visible(Array1::from(sigma.clone()).view(), min_t).unwrap();
        let m = v.len();
        assert!(m < n, "nothing dropped at {min_t}");
        let full = colour(&sigma, &delta, &color, 1.0);
        let cut = colour(&sigma[..m], &delta[..m], &color[..m], 1.0);
        // The render of the kept samples sees the background through what is left.
        let left: f64 = sigma[..m].iter().zip(&delta).map(|(s, d)| s * d).sum();
        assert!((-left).exp() < min_t, "the last kept sample ends below the threshold");
        assert!((full - cut).abs() <= min_t, "{min_t}: {full} vs {cut}");
    }
}

#[test]
fn optical_depth_is_accumulated_in_f64() {
    // Depth 1 then 100 samples of 2^-25 each: in f32, 1 + 2^-25 rounds back to 1, so a
    // running f32 sum would never pass 1 + 1e-6 and keep all 101 samples. The true depth
    // before sample k >= 1 is 1 + (k - 1) 2^-25, past 1 + 1e-6 from k = 35 on.
    let tiny = 2f64.powi(-25);
    let mut f32_sum = 0f32;
    for d in std::iter::once(1.0).chain(std::iter::repeat_n(tiny, 100)) {
        f32_sum += d as f32;
    }
    assert_eq!(f32_sum, 1.0, "the naive sum loses every small term");
    let s = packed::<f32>(&[vec![1.0; 101]]);
    let sigma = Array1::from_iter(std::iter::once(1.0f32).chain(std::iter::repeat_n(tiny as f32, 100)));
    let v = s.visible(sigma.view(), (-(1.0 + 1e-6f64)).exp()).unwrap();
    assert_eq!(v.len(), 35);
}

#[test]
fn bad_input_is_refused() {
    let s = packed::<f64>(&[vec![1.0; 2], vec![1.0]]);
    let ok = arr1(&[0.0, 1.0, 2.0]);
    for min_t in [1.0, -0.1, f64::NAN, 2.0] {
        assert!(
            matches!(
                s.visible(ok.view(), min_t),
                Err(OpsError::Config { op: Op::Sample, .. })
            ),
            "{min_t}"
        );
    }
    assert!(matches!(
        s.visible(arr1(&[0.0, 1.0]).view(), 0.1),
        Err(OpsError::Shape { op: Op::Sample, .. })
    ));
    for bad in [f64::NAN, -1.0, f64::INFINITY] {
        let sigma = arr1(&[0.0, 1.0, bad]);
        match s.visible(sigma.view(), 0.1) {
            Err(OpsError::Domain {
                op: Op::Sample,
                at: At::Sample { ray, sample },
                value,
                ..
            }) => {
                assert_eq!((ray, sample), (1, 0));
                assert!(value == bad || (value.is_nan() && bad.is_nan()));
            }
            other => panic!("{bad}: {other:?}"),
        }
    }
}
