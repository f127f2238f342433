//! The optimisers against steps computed by hand, and their refusals: wrong shapes, NaNs,
//! stale gradients, parameters still lent, other stores, bad settings.

use fogray_tape::optim::{Adam, AdamConfig, ParamGradients, Sgd, SgdConfig, StepSummary};
use fogray_tape::params::{ParamError, ParamId, Params};
use fogray_tape::Tape;
use ndarray::{arr0, arr1, Array1};

fn explicit(params: &Params<f64>, grads: &[(ParamId, &[f64])]) -> ParamGradients<f64> {
    let mut pg = ParamGradients::new();
    for (id, g) in grads {
        pg.insert(params, *id, arr1(g)).unwrap();
    }
    pg
}

fn values(params: &Params<f64>, id: ParamId) -> Vec<f64> {
    params.get(id).unwrap().iter().copied().collect()
}

fn assert_near(got: &[f64], want: &[f64], tol: f64) {
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= tol, "[{k}]: got {g}, want {w}");
    }
}

#[test]
fn adam_matches_two_steps_computed_by_hand() {
    // lr 0.1, beta1 0.9, beta2 0.999, eps 1e-8; x = [1, -2, 0.5]; g1 = [3, -0.5, 0],
    // g2 = [1, 1, 2]. Step 1: m = 0.1 g, v = 0.001 g^2, m^ = g, v^ = g^2, so each element
    // moves by 0.1 g / (|g| + 1e-8): 0.9 + 0.1 * 1e-8 / 3, -1.9 - 0.1 * 1e-8 / 0.5, and the
    // zero gradient does not move (0 / eps).
    // Step 2 (t = 2 for the whole parameter): bias corrections 1 - 0.81 = 0.19 and
    // 1 - 0.998001 = 0.001999.
    //   x0: m = 0.27 + 0.1 = 0.37, v = 0.008991 + 0.001 = 0.009991,
    //       0.1 * (0.37/0.19) / (sqrt(0.009991/0.001999) + 1e-8) = 0.0871063946828040
    //   x1: m = -0.045 + 0.1 = 0.055, v = 0.00024975 + 0.001 = 0.00124975,
    //       0.1 * (0.055/0.19) / sqrt(0.00124975/0.001999) = 0.0366103522405655
    //   x2: m = 0.2, v = 0.004, 0.1 * (0.2/0.19) / sqrt(0.004/0.001999) = 0.0744136818306456
    let mut params = Params::<f64>::new();
    let x = params.add("x", arr1(&[1.0, -2.0, 0.5])).unwrap();
    let mut adam = Adam::new(AdamConfig {
        lr: 0.1,
        ..AdamConfig::default()
    })
    .unwrap();
    let s = {
        let pg = explicit(&params, &[(x, &[3.0, -0.5, 0.0])]);
        adam.step(&mut params, &pg)
    }
    .unwrap();
    assert_eq!(
        s,
        StepSummary {
            updated: 1,
            without_gradient: 0
        }
    );
    assert_near(&values(&params, x), &[0.9 + 1e-9 / 3.0, -1.9 - 2e-9, 0.5], 1e-15);
    {
        let pg = explicit(&params, &[(x, &[1.0, 1.0, 2.0])]);
        adam.step(&mut params, &pg)
    }
    .unwrap();
    let after_1 = [0.9 + 1e-9 / 3.0, -1.9 - 2e-9, 0.5];
    let moves = [
        0.087_106_394_682_804_0,
        0.036_610_352_240_565_5,
        0.074_413_681_830_645_6,
    ];
    let want: Vec<f64> = after_1.iter().zip(moves).map(|(a, d)| a - d).collect();
    assert_near(&values(&params, x), &want, 1e-12);
    assert_eq!(adam.updates(x), 2);
}

#[test]
fn adam_in_f32_moves_every_element_of_a_large_grid_by_the_rate_on_its_first_step() {
    // 100 000 elements: the parallel path. With bias correction the first step is
    // lr * g / (|g| + eps) = lr * sign(g) * (1 - eps / |g|) to first order; |g| >= 5e-4.
    let n = 100_000;
    let g = Array1::from_shape_fn(n, |i| (i as f32 - 50_000.0) * 1e-3 + 5e-4);
    let mut params = Params::<f32>::new();
    let x = params.add("grid", Array1::<f32>::from_elem(n, 1.0)).unwrap();
    let mut adam = Adam::new(AdamConfig {
        lr: 0.01,
        ..AdamConfig::default()
    })
    .unwrap();
    let mut pg = ParamGradients::new();
    pg.insert(&params, x, g.clone()).unwrap();
    adam.step(&mut params, &pg).unwrap();
    for (i, (&v, &g)) in params.get(x).unwrap().iter().zip(&g).enumerate() {
        let want = 1.0 - 0.01 * g.signum();
        // The eps term moves it back by up to 0.01 * 1e-8 / |g|; f32 rounds 1 +- 0.01 to
        // within an ulp of 1 (1.2e-7), plus an ulp of arithmetic.
        let tol = 0.01 * 1e-8 / g.abs() + 2.4e-7;
        assert!((v - want).abs() <= tol, "[{i}]: got {v}, want {want}");
    }
}

#[test]
fn adam_does_not_depend_on_the_number_of_threads() {
    let n = 70_000; // several chunks
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut params = Params::<f32>::new();
            let x = params.add("x", Array1::from_shape_fn(n, |i| (i % 13) as f32)).unwrap();
            let mut adam = Adam::new(AdamConfig::default()).unwrap();
            for k in 0..3 {
                let mut pg = ParamGradients::new();
                pg.insert(
                    &params,
                    x,
                    Array1::from_shape_fn(n, |i| ((i * 7 + k) % 11) as f32 - 5.0),
                )
                .unwrap();
                adam.step(&mut params, &pg).unwrap();
            }
            params.get(x).unwrap().to_owned()
        })
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn sgd_with_momentum_matches_steps_computed_by_hand() {
    // lr 0.1, momentum 0.9, x = 1, gradients 2, 2, -1:
    // u = 2, x = 0.8; u = 1.8 + 2 = 3.8, x = 0.42; u = 3.42 - 1 = 2.42, x = 0.178.
    let mut params = Params::<f64>::new();
    let x = params.add("x", arr1(&[1.0])).unwrap();
    let mut sgd = Sgd::new(SgdConfig { lr: 0.1, momentum: 0.9 }).unwrap();
    for (g, want) in [(2.0, 0.8), (2.0, 0.42), (-1.0, 0.178)] {
        {
            let pg = explicit(&params, &[(x, &[g])]);
            sgd.step(&mut params, &pg)
        }
        .unwrap();
        assert_near(&values(&params, x), &[want], 1e-15);
    }
    // Without momentum: x -= lr g, and a rate scale of 2 doubles the step: 1 - 2 * 0.1 * 3.
    let mut plain = Sgd::new(SgdConfig { lr: 0.1, momentum: 0.0 }).unwrap();
    let mut params = Params::<f64>::new();
    let y = params.add("y", arr1(&[1.0, 1.0])).unwrap();
    plain.set_lr_scale(y, 2.0).unwrap();
    {
        let pg = explicit(&params, &[(y, &[3.0, -1.0])]);
        plain.step(&mut params, &pg)
    }
    .unwrap();
    assert_near(&values(&params, y), &[0.4, 1.2], 1e-15);
}

#[test]
fn a_wrong_shape_or_a_nan_anywhere_changes_nothing() {
    let mut params = Params::<f64>::new();
    let a = params.add("a", arr1(&[1.0, 2.0])).unwrap();
    let b = params.add("b", arr1(&[3.0, 4.0, 5.0])).unwrap();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    let mut pg = ParamGradients::new();
    pg.insert(&params, a, arr1(&[1.0, 1.0])).unwrap();
    pg.insert(&params, b, arr1(&[1.0, 1.0])).unwrap();
    assert_eq!(
        adam.step(&mut params, &pg).unwrap_err(),
        ParamError::GradientShape {
            name: "b".into(),
            expected: vec![3],
            got: vec![2]
        }
    );
    pg.insert(&params, b, arr1(&[1.0, f64::NAN, 1.0])).unwrap();
    let err = adam.step(&mut params, &pg).unwrap_err();
    assert!(
        matches!(&err, ParamError::NonFiniteGradient { name, index: 1, .. } if name == "b"),
        "{err}"
    );
    assert_eq!(values(&params, a), vec![1.0, 2.0]);
    assert_eq!(values(&params, b), vec![3.0, 4.0, 5.0]);
    assert_eq!((adam.updates(a), adam.updates(b)), (0, 0));
    // Mended, the same gradients apply (they are not stale: nothing changed).
    pg.insert(&params, b, arr1(&[1.0, 1.0, 1.0])).unwrap();
    adam.step(&mut params, &pg).unwrap();
    assert_eq!((adam.updates(a), adam.updates(b)), (1, 1));
}

#[test]
fn gradients_from_a_tape_update_each_parameter_once_and_then_go_stale() {
    // loss = sum(w^2) with w = [1, -1] and an unused parameter u: SGD lr 0.25 gives
    // w - 0.25 * 2w = w / 2; u has no gradient and is skipped.
    let mut params = Params::<f64>::new();
    let w = params.add("w", arr1(&[1.0, -1.0])).unwrap();
    let u = params.add("u", arr0(7.0)).unwrap();
    let mut sgd = Sgd::new(SgdConfig {
        lr: 0.25,
        momentum: 0.0,
    })
    .unwrap();
    let mut tape = Tape::new();
    let wv = tape.param_from(&params, w).unwrap();
    tape.param_from(&params, u).unwrap();
    let sq = tape.square(wv).unwrap();
    let loss = tape.sum(sq).unwrap();
    let grads = tape.backward(loss).unwrap();
    // The tape still holds the arrays: no update, and no silent copy.
    assert_eq!(
        sgd.step(&mut params, &grads).unwrap_err(),
        ParamError::InUse { name: "w".into() }
    );
    assert_eq!(values(&params, w), vec![1.0, -1.0]);
    tape.clear();
    let s = sgd.step(&mut params, &grads).unwrap();
    assert_eq!(
        s,
        StepSummary {
            updated: 1,
            without_gradient: 1
        }
    );
    assert_eq!(values(&params, w), vec![0.5, -0.5]);
    assert_eq!(values(&params, u), vec![7.0]);
    // Applying them again would use a gradient of the old w.
    assert_eq!(
        sgd.step(&mut params, &grads).unwrap_err(),
        ParamError::StaleGradient { name: "w".into() }
    );
    assert_eq!(values(&params, w), vec![0.5, -0.5]);
}

#[test]
fn an_optimiser_keeps_to_one_store_and_to_valid_settings() {
    let mut first = Params::<f64>::new();
    let mut second = Params::<f64>::new();
    let a = first.add("a", arr0(1.0)).unwrap();
    let b = second.add("b", arr0(1.0)).unwrap();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    let mut pg = ParamGradients::new();
    pg.insert(&first, a, arr0(1.0)).unwrap();
    adam.step(&mut first, &pg).unwrap();
    let mut pg = ParamGradients::new();
    pg.insert(&second, b, arr0(1.0)).unwrap();
    assert_eq!(adam.step(&mut second, &pg).unwrap_err(), ParamError::ForeignStore);
    assert_eq!(second.get(b).unwrap()[[]], 1.0);
    assert_eq!(adam.set_lr_scale(b, 1.0).unwrap_err(), ParamError::ForeignStore);
    // Gradients of another store's parameters are not this store's: nothing to update.
    assert_eq!(
        adam.step(&mut first, &pg).unwrap(),
        StepSummary {
            updated: 0,
            without_gradient: 1
        }
    );

    for bad in [
        AdamConfig {
            beta1: 1.0,
            ..AdamConfig::default()
        },
        AdamConfig {
            beta2: -0.1,
            ..AdamConfig::default()
        },
        AdamConfig {
            eps: 0.0,
            ..AdamConfig::default()
        },
        AdamConfig {
            lr: f64::NAN,
            ..AdamConfig::default()
        },
    ] {
        assert!(matches!(Adam::<f64>::new(bad), Err(ParamError::InvalidSetting { .. })));
    }
    assert!(Sgd::<f32>::new(SgdConfig { lr: 0.1, momentum: 1.0 }).is_err());
    assert!(adam.set_lr(-1.0).is_err());
    assert_eq!(adam.config().lr, AdamConfig::default().lr);
    assert!(adam.set_lr_scale(a, f64::INFINITY).is_err());
    // A rate scale of 0 freezes a parameter.
    adam.set_lr_scale(a, 0.0).unwrap();
    let before = first.get(a).unwrap()[[]];
    let mut pg = ParamGradients::new();
    pg.insert(&first, a, arr0(5.0)).unwrap();
    adam.step(&mut first, &pg).unwrap();
    assert_eq!(first.get(a).unwrap()[[]], before);
}
