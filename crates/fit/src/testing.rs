//! Test data shared by the crate's unit tests: a few cameras around the origin and pictures
//! whose every pixel differs.

use ndarray::Array3;

mod scenes;

pub(crate) use scenes::*;

use crate::dataset::{Dataset, View};
use fogray_ops::{Intrinsics, PinholeCamera};

/// View `i` of 8 x 8 pixels from `eye`, looking at the origin, its picture a ramp.
pub(crate) fn view(i: usize, eye: [f64; 3]) -> View {
    let k = Intrinsics::from_vertical_fov(8, 8, 40f64.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let image = Array3::from_shape_fn((8, 8, 3), |(a, b, c)| ((a * 8 + b) * 3 + c + i) as f64 / 200.0);
    View::new(format!("{i:03}"), &camera, image).unwrap()
}

/// Three training views and one test view on a circle of radius 3, white background.
pub(crate) fn small_dataset() -> Dataset {
    let eyes = [[3.0, 0.0, 0.5], [0.0, 3.0, 0.5], [-3.0, 0.0, 0.5], [0.0, -3.0, 0.5]];
    let mut views: Vec<View> = eyes.iter().enumerate().map(|(i, &e)| view(i, e)).collect();
    let test = views.split_off(3);
    Dataset::new(views, test, [1.0; 3]).unwrap()
}
