//! Helpers of the tests: a synthetic dataset, temporary files, bit patterns.
#![allow(dead_code)] // each test module uses the helpers it needs

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::dataset::{Dataset, View};
use crate::dense::DenseGrid;
use crate::model::RadianceField;
use crate::settings::FitSettings;
use crate::state::Start;
use crate::train::{fit_from, FitResult, Progress};
use fogray_ops::{Intrinsics, PinholeCamera};
use fogray_tape::Float;
use ndarray::{Array2, Array3};

/// The colour of the ball of [`ball_dataset`].
pub(crate) const BALL: [f64; 3] = [0.8, 0.3, 0.1];

/// Radius of the ball of [`ball_dataset`], centred at the origin.
pub(crate) const RADIUS: f64 = 0.5;

/// The white background of [`ball_dataset`].
pub(crate) const BACKGROUND: [f64; 3] = [1.0; 3];

/// View `i` of `size x size` pixels from `eye`, looking at the origin (40 degree field of
/// view), of an opaque ball of colour [`BALL`] and radius [`RADIUS`] at the origin in front of
/// a white background: a pixel is the ball's colour where its ray passes within the radius of
/// the origin.
pub(crate) fn ball_view(i: usize, eye: [f64; 3], size: usize) -> View {
    let k = Intrinsics::from_vertical_fov(size, size, 40f64.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let mut view = View::new(format!("{i:03}"), &camera, Array3::zeros((size, size, 3))).unwrap();
    let rays = view.rays();
    for p in 0..size * size {
        let (o, d) = (rays.0.row(p), rays.1.row(p));
        // The distance of the line o + t d (unit d) from the origin.
        let along = o.dot(&d);
        let miss: f64 = (0..3).map(|a| (o[a] - along * d[a]).powi(2)).sum::<f64>().sqrt();
        let color = if miss < RADIUS { BALL } else { BACKGROUND };
        for (c, v) in color.into_iter().enumerate() {
            view.image[[p / size, p % size, c]] = v;
        }
    }
    view
}

/// `train + test` views of the ball of [`ball_view`] from eyes at distance 3 around it,
/// alternately above and below its equator; view `i` is held out when `i mod e == e / 2`,
/// `e = (train + test) / test`.
pub(crate) fn ball_dataset(train: usize, test: usize, size: usize) -> Dataset {
    let n = train + test;
    let e = n / test;
    let (mut training, mut held_out) = (Vec::new(), Vec::new());
    for i in 0..n {
        let azimuth = std::f64::consts::TAU * (i as f64 + 0.25) / n as f64;
        let elevation: f64 = if i % 2 == 0 { 0.4 } else { -0.3 };
        let eye = [
            3.0 * elevation.cos() * azimuth.cos(),
            3.0 * elevation.cos() * azimuth.sin(),
            3.0 * elevation.sin(),
        ];
        let view = ball_view(i, eye, size);
        if i % e == e / 2 {
            held_out.push(view);
        } else {
            training.push(view);
        }
    }
    Dataset::new(training, held_out, BACKGROUND).unwrap()
}

/// [`ball_dataset`]'s views as pictures with alpha: the ball opaque (alpha 1), the rest
/// transparent (alpha 0) and composited over `background`, the dataset's background.
pub(crate) fn alpha_ball_dataset(train: usize, test: usize, size: usize, background: [f64; 3]) -> Dataset {
    let with_alpha = |view: View| {
        let alpha = Array2::from_shape_fn((size, size), |(r, c)| {
            if view.image[[r, c, 0]] == BACKGROUND[0] {
                0.0
            } else {
                1.0
            }
        });
        let mut view = view.with_alpha(alpha).unwrap();
        for ((r, c, ch), v) in view.image.indexed_iter_mut() {
            if view.alpha.as_ref().unwrap()[[r, c]] == 0.0 {
                *v = background[ch];
            }
        }
        view
    };
    let data = ball_dataset(train, test, size);
    let train = data.train.into_iter().map(with_alpha).collect();
    let test = data.test.into_iter().map(with_alpha).collect();
    Dataset::new(train, test, background).unwrap()
}

/// A fresh path `name` in this process's temporary directory: the tests share one process and
/// run in parallel, so two calls never share a path, whatever their `name`.
pub(crate) fn temp(name: &str) -> PathBuf {
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("fogray-fit-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{call}-{name}"))
}

/// The raw grid's values, as bits.
pub(crate) fn grid_bits<F: Float>(model: &DenseGrid<F>) -> Vec<u64> {
    let grid = model.params().get(model.grid_id()).unwrap();
    grid.iter().map(|v| v.as_f64().to_bits()).collect()
}

/// Every value of `images`, as bits.
pub(crate) fn image_bits(images: &[Array3<f64>]) -> Vec<u64> {
    images.iter().flat_map(|im| im.iter().map(|v| v.to_bits())).collect()
}

/// A fit of `settings` from `start`, its stop flag raised after step `stop_after`.
pub(crate) fn run<F: Float>(
    data: &Dataset,
    settings: &FitSettings,
    start: Option<Start<F, DenseGrid<F>>>,
    stop_after: Option<usize>,
) -> FitResult<F, DenseGrid<F>> {
    let stop = AtomicBool::new(false);
    let mut progress = |p: Progress| {
        if Some(p.step) == stop_after {
            stop.store(true, Ordering::Relaxed);
        }
    };
    fit_from(data, settings, start, Some(&stop), &mut progress).unwrap()
}
