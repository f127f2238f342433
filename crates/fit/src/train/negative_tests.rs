//! Nothing in a fit's defaults favours a white background over a dark one: a scene and its
//! colour negative (every picture `1 - picture`, over `1 - background`) fit alike. The
//! composite is affine in the colours with weights and transmittance summing to one, so the
//! negative's render is `1 - render` and its loss the same; a sigmoid colour starting at its
//! centre (raw 0) and a sign-symmetric optimiser then take the mirror image of every step.
//! An initial colour, a learned background or a threshold that leaned towards white would
//! set the two fits apart.

use crate::dataset::{Dataset, View};
use crate::dense::DenseGrid;
use crate::model::RadianceField;
use crate::settings::{FitSettings, ModelKind};
use crate::sparse::SparseGrid;
use crate::train::{fit, FitResult};

use crate::testing::ball_dataset;

fn negative(data: &Dataset) -> Dataset {
    let flip = |views: &[View]| -> Vec<View> {
        views
            .iter()
            .map(|v| View::new(v.name.clone(), &v.camera, v.image.mapv(|x| 1.0 - x)).unwrap())
            .collect()
    };
    Dataset::new(flip(&data.train), flip(&data.test), data.background.map(|b| 1.0 - b)).unwrap()
}

/// The held-out PSNR at each evaluation.
fn curve<M>(result: &FitResult<f64, M>) -> Vec<f64> {
    result.log.iter().map(|e| e.test_psnr).collect()
}

fn assert_alike<M: RadianceField<f64>>(settings: &FitSettings, what: &str) {
    let scene = ball_dataset(10, 2, 16);
    let dark = negative(&scene);
    let (light, dark) = (
        fit::<f64, M>(&scene, settings, &mut |_| {}).unwrap(),
        fit::<f64, M>(&dark, settings, &mut |_| {}).unwrap(),
    );
    let (a, b) = (curve(&light), curve(&dark));
    assert_eq!(a.len(), b.len());
    // The fits learn: the comparison is not of two untouched grids.
    assert!(a[a.len() - 1] > a[0] + 5.0, "{what}: {a:?}");
    for (x, y) in a.iter().zip(&b) {
        // Only rounding sets them apart (sigmoid(-x) is 1 - sigmoid(x) to the last bit or
        // two): measured, 0 to 1.2e-13 dB. An initial colour of 0.501 instead of 0.5 sets
        // them 8e-4 dB apart.
        assert!((x - y).abs() < 1e-9, "{what}: white {a:?} against dark {b:?}");
    }
}

fn steps(settings: FitSettings) -> FitSettings {
    FitSettings {
        grid: 16,
        batch: 512,
        steps: Some(120),
        evaluations: 4,
        ..settings
    }
}

#[test]
fn a_scene_and_its_colour_negative_fit_alike_with_the_librarys_defaults() {
    assert_alike::<DenseGrid<f64>>(&steps(FitSettings::DEFAULT), "the library's defaults");
}

#[test]
fn a_scene_and_its_colour_negative_fit_alike_with_the_recommended_model() {
    // fogray fit's recommended model: sparse, view-dependent colour, the distortion loss, no
    // prior, twice the rate.
    let recommended = FitSettings {
        model: ModelKind::Sparse,
        sh_degree: 1,
        distortion: 0.01,
        tv: 0.0,
        lr: 0.4,
        lr_final: 0.04,
        ..FitSettings::DEFAULT
    };
    assert_alike::<SparseGrid<f64>>(&steps(recommended), "the recommended model");
}

#[test]
fn a_capture_and_its_colour_negative_fit_alike_with_a_learned_background() {
    let learned = FitSettings {
        learn_background: true,
        ..FitSettings::DEFAULT
    };
    assert_alike::<DenseGrid<f64>>(&steps(learned), "a learned background");
}
