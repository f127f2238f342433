//! Random backgrounds for pictures with alpha: the per-ray background reaches the composite of
//! the training loss (fused and taped alike), and a fit with them clears fog of the
//! background's colour that a fit over the fixed background cannot see.

use crate::dataset::Dataset;
use crate::dense::DenseGrid;
use crate::model::{RadianceField, TrainingBackground};
use crate::render::{render_picture, RenderOptions};
use crate::settings::{Budget, FitSettings, Method, Sampling, SceneBox};
use crate::state::{Start, TrainingState};
use crate::train::fit_from;
use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{Spacing, Uniform};
use fogray_tape::Tape;
use ndarray::{arr2, s, Array2, Array4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;

use crate::testing::alpha_ball_dataset;

/// The grey of the fog below and of the background it hides in: a fresh grid's colour.
const GREY: [f64; 3] = [0.5; 3];

/// A 3^3 grid (shift -1, no prior) of grey fog: raw density `raw_density`, raw colour 0
/// (exactly 0.5 after the sigmoid).
fn grey_fog(raw_density: f64) -> DenseGrid<f64> {
    let mut model = DenseGrid::<f64>::new(SceneBox::UNIT, 3, -1.0, 0.0).unwrap();
    let id = model.grid_id();
    let raw = Array4::from_shape_fn((3, 3, 3, 4), |(_, _, _, c)| if c == 0 { raw_density } else { 0.0 });
    model.params_mut().get_mut(id).unwrap().assign(&raw.into_dyn());
    model
}

/// The gradient of the photometric loss with respect to the raw densities `[3, 3, 3]` for
/// three rays through the fog, each against `target` over `background`.
fn density_gradient(
    model: &DenseGrid<f64>,
    background: TrainingBackground<f64>,
    target: Array2<f64>,
    method: Method,
) -> Array4<f64> {
    let origins = arr2(&[[0.1, -3.0, 0.2], [-2.5, 0.3, -0.4], [0.5, 0.6, 3.0]]);
    let directions = arr2(&[[0.05, 1.0, -0.1], [1.0, -0.2, 0.1], [-0.1, -0.2, -1.0]]);
    let rays = RayBatch::new(origins, directions).unwrap();
    let clip = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&rays);
    let samples = Uniform::new(Spacing::Step(0.2)).unwrap().sample(&rays, &clip).unwrap();
    let mut tape = Tape::<f64>::new();
    let target = tape.constant(target);
    let loss = model
        .training_loss(&mut tape, &rays, samples, background, target, method)
        .unwrap();
    let grads = tape.backward(loss.photometric).unwrap();
    let g = grads.param(model.grid_id()).unwrap().to_owned();
    let g = g.into_dimensionality::<ndarray::Ix4>().unwrap();
    g.slice(s![.., .., .., 0..1]).to_owned()
}

/// A ray through empty space (alpha 0) has the background as its target. Over the fixed grey
/// background, grey fog renders exactly the target and nothing moves it; over a random colour
/// per ray, whatever colours are drawn, the loss's gradient with respect to every raw density
/// is non-negative (descent lowers the density) and not all zero.
#[test]
fn over_random_backgrounds_fog_in_empty_space_is_pushed_down() {
    let model = grey_fog(1.0);
    for method in [Method::Fused, Method::Taped] {
        let fixed = density_gradient(
            &model,
            TrainingBackground::Shared(GREY),
            Array2::from_elem((3, 3), 0.5),
            method,
        );
        assert!(fixed.iter().all(|g| g.abs() < 1e-15), "{method:?}: {fixed}");
        let mut rng = ChaCha12Rng::seed_from_u64(7);
        for draw in 0..20 {
            let drawn = Array2::from_shape_simple_fn((3, 3), || rng.gen::<f64>());
            // Alpha 0: the picture over the drawn colour is the drawn colour.
            let g = density_gradient(&model, TrainingBackground::PerRay(drawn.clone()), drawn, method);
            assert!(g.iter().all(|&v| v >= -1e-15), "{method:?}, draw {draw}: {g}");
            assert!(g.sum() > 1e-4, "{method:?}, draw {draw}: {g}");
        }
    }
}

/// A fit's settings for the fog-clearing fits: an 8^3 grid, no growth, no prior, uniform
/// sampling, a constant rate.
fn fog_settings(random_background: bool) -> FitSettings {
    FitSettings {
        grid: 8,
        batch: 256,
        grow: false,
        tv: 0.0,
        sampling: Sampling::Uniform,
        lr: 0.1,
        lr_final: 0.1,
        evaluations: 1,
        precision: crate::settings::Precision::F64,
        random_background,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(150))
}

/// The mean rendered opacity of the held-out pixels with alpha 0 (empty space).
fn empty_space_opacity(model: &DenseGrid<f64>, data: &Dataset) -> f64 {
    let options = RenderOptions {
        background: data.background,
        ..RenderOptions::default()
    };
    let (mut sum, mut count) = (0.0, 0usize);
    for view in &data.test {
        let (origins, directions) = view.rays();
        let picture = render_picture(model, None, &origins, &directions, view.size(), &options).unwrap();
        for (o, a) in picture.opacity.iter().zip(view.alpha.as_ref().unwrap()) {
            if *a == 0.0 {
                sum += o;
                count += 1;
            }
        }
    }
    assert!(count > 50, "{count} empty-space pixels");
    sum / count as f64
}

/// The ball over a grey background, fitted from a grid full of grey fog (mean opacity 0.87
/// over the held-out empty-space pixels): over the fixed grey background the fog off the ball renders the target
/// exactly and stays; over random backgrounds the training loss sees it and clears it.
#[test]
fn a_fit_over_random_backgrounds_clears_fog_of_the_background_colour() {
    let data = alpha_ball_dataset(8, 2, 10, GREY);
    let foggy = || {
        let settings = fog_settings(true);
        let mut model = DenseGrid::<f64>::fresh(&settings, settings.grid).unwrap();
        let id = model.grid_id();
        let mut grid = model.params_mut().get_mut(id).unwrap();
        grid.slice_each_axis_mut(|a| {
            if a.axis.index() == 3 {
                ndarray::Slice::from(0..1)
            } else {
                ndarray::Slice::from(..)
            }
        })
        .fill(5.0);
        model
    };
    let before = empty_space_opacity(&foggy(), &data);
    let mut after = Vec::new();
    for random in [false, true] {
        let start = Start {
            model: foggy(),
            training: TrainingState::default(),
        };
        let result = fit_from(&data, &fog_settings(random), Some(start), None, &mut |_| {}).unwrap();
        after.push(empty_space_opacity(&result.model, &data));
    }
    let [fixed, random] = [after[0], after[1]];
    assert!(before > 0.8, "{before}");
    // 0.87 -> 0.52 over the fixed background (the rays that hit the ball clear the fog in
    // front of it), 0.87 -> 0.08 over random ones.
    assert!(
        fixed > 0.4,
        "over the fixed background the fog stays: {before} -> {fixed}"
    );
    assert!(random < 0.15, "over random backgrounds it clears: {before} -> {random}");
}
