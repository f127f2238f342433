//! The training loop: the learning rate's schedule and its checks, and the step profile.

use crate::dense::DenseGrid;
use crate::schedule::{learning_rate, ANNEAL_START};
use crate::settings::{Budget, FitSettings, Method};
use crate::train::fit;
use crate::trainer::{run_budget, Trainer};

use crate::testing::ball_dataset;

#[test]
fn the_learning_rate_anneals_geometrically_over_the_end_of_the_budget() {
    let settings = FitSettings {
        lr: 0.2,
        lr_final: 0.02,
        ..FitSettings::default()
    };
    for f in [0.0, 0.3, ANNEAL_START] {
        assert_eq!(learning_rate(&settings, f), 0.2);
    }
    // Halfway through the anneal the rate is the geometric mean, sqrt(0.2 * 0.02).
    let mid = ANNEAL_START + 0.5 * (1.0 - ANNEAL_START);
    assert!((learning_rate(&settings, mid) - 0.004f64.sqrt()).abs() < 1e-15);
    assert!((learning_rate(&settings, 1.0) - 0.02).abs() < 1e-15);
    assert!((learning_rate(&settings, 1.5) - 0.02).abs() < 1e-15);
    let constant = FitSettings {
        lr_final: 0.2,
        ..settings
    };
    assert_eq!(learning_rate(&constant, 0.9), 0.2);
    // Bad rates are refused before any step.
    let data = ball_dataset(4, 1, 4);
    for bad in [
        FitSettings {
            lr_final: 0.0,
            ..settings
        },
        FitSettings {
            lr: f64::NAN,
            ..settings
        },
    ] {
        let e = fit::<f32, DenseGrid<f32>>(&data, &bad, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains("must be finite and positive"), "{e}");
    }
}

#[test]
fn the_profile_counts_the_steps_and_names_the_ops_each_method_runs() {
    let data = ball_dataset(6, 1, 8);
    for method in [Method::Fused, Method::Taped] {
        let settings = FitSettings {
            grid: 8,
            batch: 64,
            method,
            evaluations: 1,
            ..FitSettings::default()
        }
        .with_budget(Budget::Steps(7));
        // A fit's result carries the profile as its table.
        let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
        assert!(
            result.profile.to_string().contains("mean over 7 steps"),
            "{}",
            result.profile
        );
        // The trainer's own profile, summed over the steps, as `fit` tabulates it.
        let mut trainer = Trainer::<f32, DenseGrid<f32>>::new(&data, &settings, None).unwrap();
        run_budget(&mut trainer, settings.evaluations, None, &mut |_, _| {}).unwrap();
        let seconds = trainer.seconds();
        let profile = &trainer.profile();
        assert_eq!(profile.steps, 7);
        let calls = |name: &str| profile.ops.get(name).map(|t| (t.forward_calls, t.backward_calls));
        // One render, loss and prior a step; the prior is the same op either way. The fused
        // method composites and takes the loss in one op, the taped one through `mean`.
        assert_eq!(calls("total_variation"), Some((7, 7)), "{method:?}");
        let fused_ops = [calls("grid_field"), calls("composite_mse"), calls("density_color")];
        match method {
            Method::Fused => {
                assert_eq!(fused_ops, [Some((7, 7)); 3]);
                assert_eq!((calls("mean"), calls("composite")), (None, None));
            }
            Method::Taped => {
                assert_eq!(fused_ops, [None; 3], "the twins are built of taped ops");
                assert_eq!(calls("mean"), Some((7, 7)));
            }
        }
        // The phases are parts of the training clock.
        let p = profile.phases;
        let phases = p.batch + p.sample + p.forward + p.backward + p.optimiser + p.occupancy;
        assert!(phases.as_secs_f64() <= seconds, "{phases:?} > {seconds} s");
        // The ops run inside the step's forward and backward phases.
        assert!(
            profile.ops.forward() <= p.forward,
            "{:?} > {:?}",
            profile.ops.forward(),
            p.forward
        );
        assert!(
            profile.ops.backward() <= p.backward,
            "{:?} > {:?}",
            profile.ops.backward(),
            p.backward
        );
        // The table holds the same figures as means per step, in the profile's order.
        let table = profile.table();
        let steps = profile.steps as f64;
        let ms = |d: std::time::Duration| 1e3 * d.as_secs_f64() / steps;
        let names: Vec<_> = table.phases.iter().map(|r| r.name).collect();
        assert_eq!(
            names,
            ["batch", "sample", "forward", "backward", "optimiser", "occupancy"]
        );
        assert_eq!(table.phases[2].ms, ms(p.forward));
        assert_eq!(table.ops.len(), profile.ops.iter().count());
        for (row, (name, t)) in table.ops.iter().zip(profile.ops.by_time()) {
            assert_eq!(row.name, name);
            assert_eq!(row.calls_per_step, t.forward_calls as f64 / steps, "{name}");
            assert_eq!(
                (row.forward_ms, row.backward_ms),
                (ms(t.forward), ms(t.backward)),
                "{name}"
            );
        }
    }
}

#[test]
fn a_fit_whose_densities_are_all_below_the_threshold_keeps_sampling() {
    // At a learning rate this small no density reaches the occupancy threshold by the first
    // refreshes (steps 16 and 32): an occupancy grid emptied by them would leave no sample
    // to train on, ever (the fit of a scene that slowly gains matter would end blank).
    let data = ball_dataset(6, 1, 8);
    let settings = FitSettings {
        grid: 8,
        batch: 64,
        lr: 1e-6,
        lr_final: 1e-6,
        evaluations: 1,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(40));
    let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
    assert_eq!(result.occupied_fraction, 1.0);
    assert!(result.samples_per_ray_mean > 1.0, "{}", result.samples_per_ray_mean);
}

#[test]
fn the_training_views_psnr_renders_evenly_spaced_training_views() {
    use crate::dataset::Dataset;
    use crate::train::{render_test_views, test_psnr, training_views_psnr};
    let ball = ball_dataset(6, 2, 8);
    let settings = FitSettings {
        grid: 8,
        batch: 64,
        evaluations: 1,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(20));
    let result = fit::<f64, DenseGrid<f64>>(&ball, &settings, &mut |_| {}).unwrap();
    let model = &result.model;
    let occupancy = result.occupancy.as_ref();
    // Training views 0 and 2 of 4 are the two held-out views; 1 and 3 are a training view with
    // its picture negated, which no render comes near. Two of four views are 0 and 2, so their
    // PSNR is the held-out PSNR, measured through the test views' own path.
    let (a, b) = (ball.test[0].clone(), ball.test[1].clone());
    let mut wrong = ball.train[0].clone();
    wrong.image.mapv_inplace(|v| -v);
    let data = Dataset::new(vec![a, wrong.clone(), b, wrong], ball.test.clone(), ball.background).unwrap();
    let held_out = test_psnr(&render_test_views(model, &data, &settings, occupancy).unwrap(), &data).unwrap();
    let two = training_views_psnr(model, &data, &settings, occupancy, 2).unwrap();
    assert_eq!(two, held_out);
    // All four (and a count past the list: all of them) take the negated views in, and lose
    // more than 10 dB.
    let four = training_views_psnr(model, &data, &settings, occupancy, 4).unwrap();
    assert_eq!(
        training_views_psnr(model, &data, &settings, occupancy, 9).unwrap(),
        four
    );
    assert!(four < held_out - 10.0, "{four} against {held_out}");
    // One view: the first, held-out view 0.
    let first = Dataset::new(data.train.clone(), vec![data.test[0].clone()], data.background).unwrap();
    let want = test_psnr(&render_test_views(model, &first, &settings, occupancy).unwrap(), &first).unwrap();
    assert_eq!(
        training_views_psnr(model, &data, &settings, occupancy, 1).unwrap(),
        want
    );
    assert!(training_views_psnr(model, &data, &settings, occupancy, 0).is_err());
}
