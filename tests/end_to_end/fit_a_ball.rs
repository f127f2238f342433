//! A whole fit of a known scene through `fogray::fit`: exact pictures of an opaque ball in front
//! of a white background, a dense grid fitted to the training views, scored on the views it
//! holds out against a bar computed from those pictures.

use fogray::fit::dataset::{Dataset, View};
use fogray::fit::dense::DenseGrid;
use fogray::fit::metrics::psnr;
use fogray::fit::settings::{Budget, FitSettings};
use fogray::fit::train::fit;
use fogray::ops::{Intrinsics, PinholeCamera};
use ndarray::{Array3, Axis};

/// The ball's colour; it is centred at the origin with radius [`RADIUS`].
const BALL: [f64; 3] = [0.8, 0.3, 0.1];
const RADIUS: f64 = 0.5;
const BACKGROUND: [f64; 3] = [1.0; 3];

/// A `size x size` picture from `eye`, looking at the origin (40 degree field of view): a pixel
/// is the ball's colour where its ray passes within [`RADIUS`] of the origin, else white.
fn ball_view(name: String, eye: [f64; 3], size: usize) -> View {
    let k = Intrinsics::from_vertical_fov(size, size, 40f64.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let mut view = View::new(name, &camera, Array3::zeros((size, size, 3))).unwrap();
    let (origins, directions) = view.rays();
    for p in 0..size * size {
        let (o, d) = (origins.row(p), directions.row(p));
        // The distance of the line o + t d (unit d) from the origin.
        let along = o.dot(&d);
        let miss = (0..3).map(|a| (o[a] - along * d[a]).powi(2)).sum::<f64>().sqrt();
        let color = if miss < RADIUS { BALL } else { BACKGROUND };
        for (c, v) in color.into_iter().enumerate() {
            view.image[[p / size, p % size, c]] = v;
        }
    }
    view
}

/// Twelve views from distance 3, around the ball and alternately above and below its
/// equator; every sixth is held out.
fn ball_dataset(size: usize) -> Dataset {
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for i in 0..12 {
        let azimuth = std::f64::consts::TAU * (i as f64 + 0.25) / 12.0;
        let elevation: f64 = if i % 2 == 0 { 0.4 } else { -0.3 };
        let eye = [
            3.0 * elevation.cos() * azimuth.cos(),
            3.0 * elevation.cos() * azimuth.sin(),
            3.0 * elevation.sin(),
        ];
        let view = ball_view(format!("{i:02}"), eye, size);
        if i % 6 == 3 {
            test.push(view);
        } else {
            train.push(view);
        }
    }
    Dataset::new(train, test, BACKGROUND).unwrap()
}

#[test]
fn a_dense_grid_fitted_to_a_ball_renders_the_held_out_views() {
    let data = ball_dataset(16);
    // The bar: the best a picture that knows the colours but not the ball's place can do, each
    // channel the mean of the held-out pictures (its squared error is the pictures' variance).
    // A fit that has found the ball's shape must have a tenth of that error: 10 dB more.
    let exacts: Vec<_> = data.test.iter().map(|v| v.image.view()).collect();
    let pixels = ndarray::concatenate(Axis(0), &exacts).unwrap();
    let mean = pixels.mean_axis(Axis(0)).unwrap().mean_axis(Axis(0)).unwrap();
    let flat: Vec<Array3<f64>> = exacts
        .iter()
        .map(|e| Array3::from_shape_fn(e.dim(), |(_, _, c)| mean[c]))
        .collect();
    let flat: Vec<_> = flat.iter().map(|f| f.view()).collect();
    let bar = psnr(&flat, &exacts).unwrap() + 10.0;

    let settings = FitSettings {
        grid: 24,
        batch: 512,
        evaluations: 1,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(150));
    let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
    let (first, last) = (result.log[0].test_psnr, result.final_test_psnr);
    eprintln!("held-out PSNR {first:.2} dB -> {last:.2} dB; the bar {bar:.2} dB");
    assert!(last > bar, "held-out PSNR {last:.2} dB, under the bar {bar:.2} dB");
}
