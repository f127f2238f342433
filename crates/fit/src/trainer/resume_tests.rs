//! A fit stopped at step k, saved, reloaded and continued takes the same steps, bit for bit,
//! as one never stopped: with a constant rate or through growth and the anneal, stopped by its
//! budget or by its flag, in f32 and f64, with uniform or occupancy sampling, over the
//! dataset's background or random ones.

use std::collections::BTreeMap;

use crate::checkpoint::{load, save};
use crate::dataset::Dataset;
use crate::dense::DenseGrid;
use crate::model::RadianceField;
use crate::sampling::FIT_REFRESH;
use crate::settings::{Budget, FitSettings, Precision, Sampling};
use fogray_tape::Float;

use crate::testing::{alpha_ball_dataset, ball_dataset, grid_bits, image_bits, run, temp};

fn data() -> Dataset {
    ball_dataset(8, 2, 10)
}

/// A fit of `total` steps against one of `k` steps saved to a file, reloaded and continued
/// to `total`: the first part is a fit with a budget of `k` steps, or (`stopped`) a fit to
/// `total` stopped by its flag after step `k`.
fn split_equals_whole<F: Float>(settings: FitSettings, total: usize, k: usize, stopped: bool, name: &str) {
    split_equals_whole_of::<F>(&data(), settings, total, k, stopped, name);
}

/// [`split_equals_whole`] on `data`.
fn split_equals_whole_of<F: Float>(
    data: &Dataset,
    settings: FitSettings,
    total: usize,
    k: usize,
    stopped: bool,
    name: &str,
) {
    let settings = FitSettings {
        precision: Precision::of::<F>(),
        ..settings
    };
    let whole_settings = settings.with_budget(Budget::Steps(total));
    let whole = run::<F>(data, &whole_settings, None, None);
    let first_settings = if stopped {
        whole_settings
    } else {
        settings.with_budget(Budget::Steps(k))
    };
    let first = run::<F>(data, &first_settings, None, stopped.then_some(k));
    assert_eq!(first.training.step, k);
    assert_eq!(first.interrupted, stopped);
    let file = temp(name);
    save(&file, &first.model, &first.training, &first_settings, &BTreeMap::new()).unwrap();
    let back = load::<F, DenseGrid<F>>(&file).unwrap();
    assert_eq!(back.start.training, first.training);
    assert_eq!(back.settings, first_settings);
    let second = run::<F>(data, &whole_settings, Some(back.start), None);
    assert_eq!(second.training.step, total);
    assert_eq!(second.model.nodes(), whole.model.nodes());
    assert_eq!(grid_bits(&second.model), grid_bits(&whole.model), "{name}");
    // Everything but the training seconds, which are the clock's.
    let (a, b) = (&second.training, &whole.training);
    assert_eq!(
        (a.step, a.stage, a.batch_stream),
        (b.step, b.stage, b.batch_stream),
        "{name}"
    );
    assert_eq!(a.adam, b.adam, "{name}");
    assert_eq!(a.occupancy, b.occupancy, "{name}");
    assert!(a.seconds > first.training.seconds);
    assert_eq!(image_bits(&second.renders), image_bits(&whole.renders));
    assert_eq!(second.log[0].step, k);
    assert_eq!(
        second.log.last().unwrap().test_psnr.to_bits(),
        whole.log.last().unwrap().test_psnr.to_bits()
    );
    // A fresh Adam and the stream restarted would differ: the comparison can fail.
    let mut forgetful = load::<F, DenseGrid<F>>(&file).unwrap().start;
    assert!(!forgetful.training.adam.is_empty());
    forgetful.training.adam = Vec::new();
    forgetful.training.batch_stream = 0;
    let differs = run::<F>(data, &whole_settings, Some(forgetful), None);
    assert_ne!(grid_bits(&differs.model), grid_bits(&whole.model));
    let _ = std::fs::remove_file(&file);
}

#[test]
fn k_steps_saved_and_continued_equal_2k_steps_bitwise() {
    // A constant rate and no growth: the first part's budget of k steps does what the first k
    // steps of the whole's do.
    let base = FitSettings {
        grid: 6,
        batch: 128,
        lr: 0.2,
        lr_final: 0.2,
        grow: false,
        sampling: Sampling::Uniform,
        ..FitSettings::default()
    };
    split_equals_whole::<f32>(base, 12, 6, false, "split-f32.safetensors");
    split_equals_whole::<f64>(base, 12, 6, false, "split-f64.safetensors");
    // A growing grid (3, 5 then 10 nodes from steps 2 and 6 of 20) with an annealed rate,
    // stopped between stages after step 4 and continued through the growth and the anneal.
    let growing = FitSettings {
        grid: 10,
        grow: true,
        lr_final: 0.02,
        ..base
    };
    split_equals_whole::<f32>(growing, 20, 4, true, "split-grow.safetensors");
    split_equals_whole::<f32>(base, 8, 3, true, "split-stop.safetensors");
}

#[test]
fn a_fit_with_a_learned_background_saved_and_continued_equals_the_whole_bitwise() {
    // The background's coefficients and their Adam moments are in the file, and it grows
    // with the grid (3, 5 then 10 nodes): the renders compared below are over it.
    let learned = FitSettings {
        grid: 10,
        batch: 128,
        lr: 0.2,
        lr_final: 0.02,
        sampling: Sampling::Uniform,
        learn_background: true,
        ..FitSettings::default()
    };
    split_equals_whole::<f32>(learned, 20, 4, true, "split-environment.safetensors");
    let file = temp("environment.safetensors");
    let first = run::<f32>(&data(), &learned.with_budget(Budget::Steps(5)), None, None);
    save(&file, &first.model, &first.training, &learned, &BTreeMap::new()).unwrap();
    let back = load::<f32, DenseGrid<f32>>(&file).unwrap().start.model;
    let id = |m: &DenseGrid<f32>| m.params().id(crate::environment::ENVIRONMENT).unwrap();
    let (saved, read) = (
        first.model.params().get(id(&first.model)).unwrap(),
        back.params().get(id(&back)).unwrap(),
    );
    assert!(saved.iter().any(|&v| v != 0.0), "the fit moved the background");
    assert_eq!(saved, read);
    let _ = std::fs::remove_file(&file);
}

#[test]
fn a_fit_over_random_backgrounds_saved_and_continued_equals_the_whole_bitwise() {
    // Pictures with alpha: each step draws its rows, then a colour per ray, from the one
    // stream; the file's position in it continues both.
    let alpha = alpha_ball_dataset(8, 2, 10, [1.0; 3]);
    let base = FitSettings {
        grid: 6,
        batch: 128,
        lr: 0.2,
        lr_final: 0.2,
        grow: false,
        sampling: Sampling::Uniform,
        random_background: true,
        ..FitSettings::default()
    };
    split_equals_whole_of::<f32>(&alpha, base, 12, 6, false, "split-random-f32.safetensors");
    split_equals_whole_of::<f64>(&alpha, base, 12, 5, true, "split-random-f64.safetensors");
    // The backgrounds are drawn: the same fit over the dataset's background differs, and so
    // does the stream's position (a colour per ray more a step).
    let steps = base.with_budget(Budget::Steps(4));
    let random = run::<f32>(&alpha, &steps, None, None);
    let fixed = run::<f32>(
        &alpha,
        &FitSettings {
            random_background: false,
            ..steps
        },
        None,
        None,
    );
    assert_ne!(grid_bits(&random.model), grid_bits(&fixed.model));
    assert!(random.training.batch_stream > fixed.training.batch_stream);
    // Without alpha the setting draws nothing: the fit is the one over the fixed background.
    let opaque = data();
    let on = run::<f32>(&opaque, &steps, None, None);
    let off = run::<f32>(
        &opaque,
        &FitSettings {
            random_background: false,
            ..steps
        },
        None,
        None,
    );
    assert_eq!(grid_bits(&on.model), grid_bits(&off.model));
    assert_eq!(on.training.batch_stream, off.training.batch_stream);
}

#[test]
fn an_occupancy_fit_saved_and_continued_equals_the_whole_bitwise() {
    // The fit's occupancy grid is first refreshed at step 16, then every 16 steps: saved at
    // step 24 (one refresh in), continued through the refreshes at 32 and 48.
    let occupancy = FitSettings {
        grid: 6,
        batch: 64,
        lr: 0.2,
        lr_final: 0.2,
        grow: false,
        sampling: Sampling::Occupancy,
        ..FitSettings::default()
    };
    let refresh = FIT_REFRESH;
    assert!(refresh.warmup < 24 && 24 < refresh.warmup + refresh.every);
    split_equals_whole::<f32>(occupancy, 52, 24, false, "split-occupancy.safetensors");
    // The grid in the file is the one the fit had, and it is not the fresh grid a file
    // without one would give.
    let data = data();
    let first_settings = occupancy.with_budget(Budget::Steps(24));
    let first = run::<f32>(&data, &first_settings, None, None);
    let fraction = first.occupancy.as_ref().unwrap().occupied_fraction();
    assert!(fraction < 1.0, "{fraction}");
    let file = temp("occupancy.safetensors");
    save(&file, &first.model, &first.training, &first_settings, &BTreeMap::new()).unwrap();
    let back = load::<f32, DenseGrid<f32>>(&file)
        .unwrap()
        .start
        .training
        .occupancy
        .unwrap();
    assert_eq!(Some(back), first.occupancy.map(|g| g.state()));
    let _ = std::fs::remove_file(&file);
}
