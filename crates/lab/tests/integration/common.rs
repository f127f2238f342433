//! Helpers of the lab's tests: a synthetic dataset (the ball of fogray-fit's own tests).

use fogray_fit::dataset::{Dataset, View};
use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::Array3;

/// The colour of the ball of [`ball_dataset`].
pub const BALL: [f64; 3] = [0.8, 0.3, 0.1];

/// Radius of the ball of [`ball_dataset`], centred at the origin.
pub const RADIUS: f64 = 0.5;

/// The white background of [`ball_dataset`].
pub const BACKGROUND: [f64; 3] = [1.0; 3];

/// View `i` of `size x size` pixels from `eye`, looking at the origin (40 degree field of
/// view), of an opaque ball of colour [`BALL`] and radius [`RADIUS`] at the origin in front of
/// a white background: a pixel is the ball's colour where its ray passes within the radius of
/// the origin.
pub fn ball_view(i: usize, eye: [f64; 3], size: usize) -> View {
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
pub fn ball_dataset(train: usize, test: usize, size: usize) -> Dataset {
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
