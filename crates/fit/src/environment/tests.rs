//! The learned background of captures without alpha: its colour model against a closed form,
//! and a fit of a ball in front of a sky (no alpha) that learns the sky instead of painting it
//! into the box.

use crate::dataset::{Dataset, View};
use crate::environment::{Environment, ENVIRONMENT};
use crate::model::RadianceField;
use crate::settings::{FitSettings, SceneBox};
use fogray_ops::sh::basis::{C0, C1};
use ndarray::{Array2, ArrayView1};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;

use crate::testing::{alpha_ball_dataset, ball_dataset, run, BACKGROUND};

/// The sky's colour logits at the horizon, per channel, and how much brighter it gets upwards.
const LOGITS: [f64; 3] = [-0.5, 0.2, 1.0];
const UPWARDS: f64 = 1.5;

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// The sky seen along unit direction `d`: `sigmoid(L_c + 1.5 d_z)`.
fn sky(d: ArrayView1<'_, f64>) -> [f64; 3] {
    LOGITS.map(|l| sigmoid(l + UPWARDS * d[2]))
}

/// [`ball_dataset`]'s views with the sky behind the ball instead of white, and no alpha: a
/// photograph of a ball outdoors.
fn sky_ball_dataset(train: usize, test: usize, size: usize) -> Dataset {
    let outdoors = |mut view: View| {
        let (_, directions) = view.rays();
        for p in 0..size * size {
            let (r, c) = (p / size, p % size);
            if (0..3).all(|ch| view.image[[r, c, ch]] == BACKGROUND[ch]) {
                for (ch, v) in sky(directions.row(p)).into_iter().enumerate() {
                    view.image[[r, c, ch]] = v;
                }
            }
        }
        view
    };
    let data = ball_dataset(train, test, size);
    let train = data.train.into_iter().map(outdoors).collect();
    let test = data.test.into_iter().map(outdoors).collect();
    Dataset::new(train, test, BACKGROUND).unwrap()
}

#[test]
fn the_environment_is_the_sigmoid_of_the_harmonics_in_the_ray_direction() {
    let environment = Environment::new(2).unwrap();
    let b = 9;
    assert_eq!(environment.coefficient_count(), 3 * b);
    // The sky in closed form: Y_0 = C0 and Y_2 = C1 z, so channel c's coefficients are
    // L_c / C0 and 1.5 / C1, every other one 0.
    let mut coefficients = Array2::<f64>::zeros((1, 3 * b));
    for (c, l) in LOGITS.into_iter().enumerate() {
        coefficients[[0, c * b]] = l / C0;
        coefficients[[0, c * b + 2]] = UPWARDS / C1;
    }
    let mut rng = ChaCha12Rng::seed_from_u64(3);
    let directions = Array2::from_shape_fn((200, 3), |_| rng.gen_range(-1.0..1.0f64));
    let norms = directions.map_axis(ndarray::Axis(1), |d| d.dot(&d).sqrt());
    let directions = &directions / &norms.insert_axis(ndarray::Axis(1));
    let colors = environment.colors(coefficients.view(), directions.view()).unwrap();
    for (d, got) in directions.outer_iter().zip(colors.outer_iter()) {
        for (g, want) in got.iter().zip(sky(d)) {
            assert!((g - want).abs() < 1e-12, "{d}: {g} against {want}");
        }
    }
    let wrong = Array2::<f64>::zeros((2, 3 * b));
    assert!(environment.colors(wrong.view(), directions.view()).is_err());
}

/// Over a fixed white background the sky cannot be explained; with the learned background the
/// held-out views fit far better and the learned colours are the sky's.
#[test]
fn a_fit_with_a_learned_background_learns_the_sky() {
    let data = sky_ball_dataset(12, 4, 16);
    let settings = FitSettings {
        grid: 12,
        batch: 512,
        steps: Some(300),
        scene_box: Some(SceneBox::cube(1.0)),
        ..FitSettings::default()
    };
    let fixed = run::<f64>(&data, &settings, None, None);
    let learned_settings = FitSettings {
        learn_background: true,
        ..settings
    };
    let learned = run::<f64>(&data, &learned_settings, None, None);
    let (a, b) = (fixed.final_test_psnr, learned.final_test_psnr);
    assert!(b > a + 6.0, "fixed {a} dB, learned {b} dB");
    let id = learned.model.params().id(ENVIRONMENT).unwrap();
    let coefficients = learned.model.params().get(id).unwrap().to_owned();
    let coefficients = coefficients.into_dimensionality::<ndarray::Ix2>().unwrap();
    // The settings' degree (3 by default): 3 channels of 16 coefficients.
    assert_eq!(coefficients.dim(), (1, 48));
    let mut rng = ChaCha12Rng::seed_from_u64(5);
    // Directions the training views saw beside the ball: from the cameras' elevations.
    for _ in 0..50 {
        let (azimuth, z) = (rng.gen_range(0.0..std::f64::consts::TAU), rng.gen_range(-0.4..0.4f64));
        let r = (1.0 - z * z).sqrt();
        let d = ndarray::arr2(&[[r * azimuth.cos(), r * azimuth.sin(), z]]);
        let got = Environment::new(learned_settings.background_degree)
            .unwrap()
            .colors(coefficients.view(), d.view())
            .unwrap();
        for (g, want) in got.row(0).iter().zip(sky(d.row(0))) {
            assert!((g - want).abs() < 0.05, "{d}: {g} against {want}");
        }
    }
    assert!(fixed.model.params().id(ENVIRONMENT).is_none());
}

#[test]
fn the_degree_sets_the_coefficients_and_above_3_is_refused() {
    for (degree, count) in [(0, 3), (1, 12), (2, 27), (3, 48)] {
        assert_eq!(Environment::new(degree).unwrap().coefficient_count(), count);
    }
    let e = Environment::new(4).unwrap_err().to_string();
    assert!(e.contains("--background-degree"), "{e}");
    // Degree 0 is one colour from every direction: sigmoid(C0 k) per channel.
    let zero = Environment::new(0).unwrap();
    let k = ndarray::arr2(&[[1.0, -2.0, 0.5]]);
    let d = ndarray::arr2(&[[0.0, 0.0, 1.0], [0.6, -0.8, 0.0]]);
    let colors = zero.colors(k.view(), d.view()).unwrap();
    for row in colors.outer_iter() {
        for (c, k) in row.iter().zip(k.row(0)) {
            let want = 1.0 / (1.0 + (-C0 * k).exp());
            assert!((c - want).abs() < 1e-15, "{c} against {want}");
        }
    }
}

#[test]
fn a_learned_background_is_refused_for_views_with_alpha() {
    let data = alpha_ball_dataset(4, 1, 8, [1.0; 3]);
    let settings = FitSettings {
        grid: 6,
        batch: 16,
        steps: Some(2),
        learn_background: true,
        ..FitSettings::default()
    };
    let e = crate::train::fit::<f64, crate::dense::DenseGrid<f64>>(&data, &settings, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("--learn-background"), "{e}");
}

#[test]
fn fresh_coefficients_are_grey_from_every_direction() -> Result<(), Box<dyn std::error::Error>> {
    use ndarray::arr2;

    let environment = Environment::new(2)?;
    assert_eq!(environment.coefficient_count(), 27);
    let coefficients = Array2::<f64>::zeros((1, environment.coefficient_count()));
    let directions = arr2(&[[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]]);
    // Fresh coefficients are 0: grey (sigmoid 0) from every direction.
    let colors = environment.colors(coefficients.view(), directions.view())?;
    assert!(colors.iter().all(|&c| c == 0.5));
    Ok(())
}
