//! The whole pipeline: its gradient against central differences, the fused ops against their
//! taped twins, and a tiny fit that must learn.

use crate::common::default_scene_data;
use fogray::ops::rays::{Aabb, RayBatch};
use fogray::ops::sample::{Spacing, Uniform};
use fogray::tape::{gradcheck, GradcheckOptions, Tape, Var};
use fogray_grid::fit::{fit, Budget, FitConfig, Sampling};
use fogray_grid::model::{GridModel, Method};
use fogray_grid::ring::Ring;
use ndarray::{arr2, Array2, Array4, ArrayD};

/// Three rays crossing a 3^3 grid, sampled every 0.4, and a target colour per ray.
fn setup() -> (GridModel<f64>, fogray::ops::sample::PackedSamples<f64>, Array2<f64>) {
    let model = GridModel::<f64>::new(3, -1.0).unwrap();
    let origins = arr2(&[[0.1, -3.0, 0.2], [-2.5, 0.3, -0.4], [0.5, 0.6, 3.0]]);
    let directions = arr2(&[[0.05, 1.0, -0.1], [1.0, -0.2, 0.1], [-0.1, -0.2, -1.0]]);
    let rays = RayBatch::new(origins, directions).unwrap();
    let clip = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&rays);
    let samples = Uniform::new(Spacing::Step(0.4)).unwrap().sample(&rays, &clip).unwrap();
    let target = arr2(&[[0.9, 0.2, 0.1], [0.3, 0.3, 0.8], [0.5, 0.9, 0.4]]);
    (model, samples, target)
}

/// A raw grid with every value different, densities around the shift.
fn raw_grid() -> ArrayD<f64> {
    Array4::from_shape_fn((3, 3, 3, 4), |(i, j, k, c)| {
        ((i * 36 + j * 12 + k * 4 + c) as f64 * 0.37).sin() * 1.5
    })
    .into_dyn()
}

fn loss(tape: &mut Tape<f64>, grid: Var, method: Method) -> Result<Var, fogray::tape::TapeError> {
    let (model, samples, target) = setup();
    let target = tape.constant(target);
    model.photometric_loss(tape, grid, samples, [1.0, 0.95, 0.9], target, method)
}

#[test]
fn the_whole_pipeline_passes_gradcheck_fused_and_taped() {
    let (_, samples, _) = setup();
    assert!(
        samples.len() > 12,
        "the rays must cross the grid: {} samples",
        samples.len()
    );
    for method in [Method::Fused, Method::Taped] {
        let report = gradcheck(
            |t, v| loss(t, v[0], method),
            &[raw_grid()],
            &GradcheckOptions::default(),
        )
        .unwrap();
        assert!(report.passes(), "{method:?}: {report}");
    }
}

#[test]
fn fused_and_taped_give_the_same_loss_and_gradient() {
    let mut results = Vec::new();
    for method in [Method::Fused, Method::Taped] {
        let mut tape = Tape::<f64>::new();
        let grid = tape.param(raw_grid());
        let l = loss(&mut tape, grid, method).unwrap();
        let value = tape.value(l).unwrap()[[]];
        let g = tape.backward(l).unwrap().get(grid).unwrap().to_owned();
        results.push((value, g));
    }
    let ((l0, g0), (l1, g1)) = (&results[0], &results[1]);
    assert!((l0 - l1).abs() < 1e-14, "{l0} {l1}");
    assert!(g0.iter().any(|v| v.abs() > 1e-3), "a gradient that can fail");
    for (a, b) in g0.iter().zip(g1.iter()) {
        assert!((a - b).abs() < 1e-13, "{a} {b}");
    }
}

#[test]
fn a_tiny_fit_raises_the_test_psnr_by_5_db() {
    let ring = Ring::new(12, 2, 12).unwrap();
    let data = default_scene_data(&ring);
    for sampling in [Sampling::Uniform, Sampling::Occupancy] {
        let config = FitConfig {
            grid: 12,
            batch: 512,
            budget: Budget::Steps(80),
            sampling,
            lr: 0.3,
            ..FitConfig::default()
        };
        let result = fit::<f32>(&data, &config, &mut |_| {}).unwrap();
        let first = result.log[0].test_psnr;
        assert!(
            result.final_test_psnr > first + 5.0,
            "{sampling:?}: {first} -> {}",
            result.final_test_psnr
        );
        assert_eq!(result.renders.len(), ring.test_views().len());
    }
}

#[test]
fn resampling_keeps_a_linear_field_exactly() {
    // Trilinear interpolation reproduces a linear field, so the 5^3 grid grown from a 3^3 one
    // holding f(x, y, z) = 1 + x - 2y + 3z (channel c scaled by c + 1) holds it at its nodes.
    let f = |x: f64, y: f64, z: f64, c: usize| (1.0 + x - 2.0 * y + 3.0 * z) * (c + 1) as f64;
    let at = |i: usize, n: usize| -1.0 + 2.0 * i as f64 / (n - 1) as f64;
    let mut model = GridModel::<f64>::new(3, -1.0).unwrap();
    let id = model.grid_id();
    model
        .params_mut()
        .get_mut(id)
        .unwrap()
        .assign(&Array4::from_shape_fn((3, 3, 3, 4), |(i, j, k, c)| {
            f(at(i, 3), at(j, 3), at(k, 3), c)
        }));
    let grown = model.resampled(5).unwrap();
    assert_eq!(grown.nodes(), 5);
    let values = grown.params().get(grown.grid_id()).unwrap();
    for ((i, j, k, c), v) in values.into_dimensionality::<ndarray::Ix4>().unwrap().indexed_iter() {
        let want = f(at(i, 5), at(j, 5), at(k, 5), c);
        assert!((v - want).abs() < 1e-12, "({i}, {j}, {k}, {c}): {v} vs {want}");
    }
}

#[test]
fn densities_are_the_softplus_of_the_shifted_raw_density() {
    // Raw densities from -30 to 30 at the nodes of a 3^3 grid; the model reads them at the
    // nodes, so its densities are ln(1 + exp(raw - 2)), computed here through the C library.
    let mut model = GridModel::<f64>::new(3, -2.0).unwrap();
    let id = model.grid_id();
    let raw = |i: usize, j: usize, k: usize| (i * 9 + j * 3 + k) as f64 * (60.0 / 26.0) - 30.0;
    model
        .params_mut()
        .get_mut(id)
        .unwrap()
        .assign(&Array4::from_shape_fn((3, 3, 3, 4), |(i, j, k, c)| {
            if c == 0 {
                raw(i, j, k)
            } else {
                7.0
            }
        }));
    let positions = Array2::from_shape_fn((27, 3), |(p, axis)| [p / 9, p / 3 % 3, p % 3][axis] as f64 - 1.0);
    let sigma = model.densities(positions.view()).unwrap();
    for (p, s) in sigma.iter().enumerate() {
        let x = raw(p / 9, p / 3 % 3, p % 3) - 2.0;
        let want = if x > 0.0 {
            x + (-x).exp().ln_1p()
        } else {
            x.exp().ln_1p()
        };
        assert!((s - want).abs() <= 5e-16 * want, "node {p}: {s:e} vs {want:e}");
    }
    // Outside the box the raw value is 0: softplus(-2).
    let outside = model.densities(arr2(&[[2.0, 0.0, 0.0]]).view()).unwrap();
    assert!((outside[0] - (-2f64).exp().ln_1p()).abs() < 1e-16);
    assert!(GridModel::<f32>::new(3, f64::NAN).is_err());
}

#[test]
fn the_learning_rate_anneals_geometrically_over_the_end_of_the_budget() {
    use fogray_grid::fit::{learning_rate, ANNEAL_START};
    let config = FitConfig {
        lr: 0.2,
        lr_final: 0.02,
        ..FitConfig::default()
    };
    for f in [0.0, 0.3, ANNEAL_START] {
        assert_eq!(learning_rate(&config, f), 0.2);
    }
    // Halfway through the anneal the rate is the geometric mean, sqrt(0.2 * 0.02).
    let mid = ANNEAL_START + 0.5 * (1.0 - ANNEAL_START);
    assert!((learning_rate(&config, mid) - 0.004f64.sqrt()).abs() < 1e-15);
    assert!((learning_rate(&config, 1.0) - 0.02).abs() < 1e-15);
    assert!((learning_rate(&config, 1.5) - 0.02).abs() < 1e-15);
    let constant = FitConfig {
        lr_final: 0.2,
        ..config
    };
    assert_eq!(learning_rate(&constant, 0.9), 0.2);
    // Bad rates are refused before any step.
    let data = default_scene_data(&Ring::new(4, 1, 4).unwrap());
    for bad in [
        FitConfig {
            lr_final: 0.0,
            ..config
        },
        FitConfig { lr: f64::NAN, ..config },
    ] {
        let e = fit::<f32>(&data, &bad, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains("must be finite and positive"), "{e}");
    }
}

#[test]
fn the_profile_counts_the_steps_and_names_the_ops_each_method_runs() {
    let data = default_scene_data(&Ring::new(6, 1, 8).unwrap());
    for method in [Method::Fused, Method::Taped] {
        let config = FitConfig {
            grid: 8,
            batch: 64,
            budget: Budget::Steps(7),
            method,
            evaluations: 1,
            ..FitConfig::default()
        };
        let result = fit::<f32>(&data, &config, &mut |_| {}).unwrap();
        let profile = &result.profile;
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
        assert!(
            phases.as_secs_f64() <= result.seconds,
            "{phases:?} > {} s",
            result.seconds
        );
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
