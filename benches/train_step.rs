//! Criterion benches: a whole training step of `fogray fit`'s model class with the fused ops
//! against the same step with their taped twins (`--method fused|taped`): the batch of rays,
//! the samples, the grid lookup, the activation, the composite and its loss on a tape, the
//! backward, Adam's update and the occupancy refresh, through `Trainer::step`.
//!
//! The scene: exact 64 x 64 pictures of an opaque ball from twelve cameras around it; a dense
//! 64^3 grid (no coarse-to-fine growth, so that every measured step has the same lattice),
//! 4096 rays a step, f32. Each method's trainer takes 50 steps before it is timed, so that
//! the occupancy grid has left the empty space and the steps measured are a fit's steady ones.
//!
//! `cargo bench -p fogray-benches --bench train_step` runs both; `cargo bench -p fogray-benches
//! --bench train_step -- fused` selects.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fogray_fit::dataset::{camera_rays, Dataset, View};
use fogray_fit::dense::DenseGrid;
use fogray_fit::settings::{FitSettings, Method, MAX_STEPS};
use fogray_fit::trainer::Trainer;
use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::Array3;

const SIZE: usize = 64;
const BATCH: usize = 4096;
const WARM_STEPS: usize = 50;

/// A picture of a ball of radius 0.5 and colour (0.8, 0.3, 0.1) at the origin, over white,
/// from `eye` at distance 3 (40 degree field of view).
fn ball_view(i: usize, eye: [f64; 3]) -> View {
    let k = Intrinsics::from_vertical_fov(SIZE, SIZE, 40f64.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let (origins, directions) = camera_rays(&camera);
    let image = Array3::from_shape_fn((SIZE, SIZE, 3), |(y, x, c)| {
        let (o, d) = (origins.row(y * SIZE + x), directions.row(y * SIZE + x));
        let along = o.dot(&d);
        let miss = (0..3).map(|a| (o[a] - along * d[a]).powi(2)).sum::<f64>().sqrt();
        if miss < 0.5 {
            [0.8, 0.3, 0.1][c]
        } else {
            1.0
        }
    });
    View::new(format!("{i:02}"), &camera, image).unwrap()
}

fn ball_dataset() -> Dataset {
    let mut views: Vec<View> = (0..13)
        .map(|i| {
            let azimuth = std::f64::consts::TAU * i as f64 / 13.0;
            let elevation: f64 = if i % 2 == 0 { 0.4 } else { -0.3 };
            let eye = [
                3.0 * elevation.cos() * azimuth.cos(),
                3.0 * elevation.cos() * azimuth.sin(),
                3.0 * elevation.sin(),
            ];
            ball_view(i, eye)
        })
        .collect();
    let test = vec![views.pop().unwrap()];
    Dataset::new(views, test, [1.0; 3]).unwrap()
}

fn benches(c: &mut Criterion) {
    let data = ball_dataset();
    let mut group = c.benchmark_group("train-step/f32/dense-64^3");
    group.throughput(Throughput::Elements(BATCH as u64));
    group.sample_size(10);
    for method in [Method::Fused, Method::Taped] {
        let settings = FitSettings {
            batch: BATCH,
            grow: false,
            method,
            steps: Some(MAX_STEPS),
            ..FitSettings::default()
        };
        let mut trainer = Trainer::<f32, DenseGrid<f32>>::new(&data, &settings, None).unwrap();
        for _ in 0..WARM_STEPS {
            trainer.step().unwrap();
        }
        group.bench_function(method.name(), |b| b.iter(|| trainer.step().unwrap()));
    }
    group.finish();
}

criterion_group!(train_step, benches);
criterion_main!(train_step);
