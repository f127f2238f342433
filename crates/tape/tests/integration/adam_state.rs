//! Adam's state export and import: k steps, export, import into a fresh optimiser over a
//! fresh copy of the parameters, k more steps equals 2k steps bit for bit; and the refusals
//! of `restore`, which leave the optimiser as it was.

use fogray_tape::optim::{Adam, AdamConfig, AdamState};
use fogray_tape::params::{ParamError, ParamId, Params};
use fogray_tape::{Float, Tape};
use ndarray::{Array1, Array2, ArrayD, IxDyn};

/// Two parameters, a matrix large enough for Adam's parallel chunks and a vector.
fn store<F: Float>() -> (Params<F>, ParamId, ParamId) {
    let mut params = Params::new();
    let w = params
        .add(
            "w",
            Array2::from_shape_fn((130, 160), |(i, j)| F::lit(((i * 7 + j) as f64 * 0.13).sin())),
        )
        .unwrap();
    let b = params
        .add("b", Array1::from_shape_fn(160, |j| F::lit(j as f64 * 0.01)))
        .unwrap();
    (params, w, b)
}

/// A copy of `params`'s values in a new store (new identity), as a reload would make.
fn copy<F: Float>(params: &Params<F>) -> (Params<F>, ParamId, ParamId) {
    let mut fresh = Params::new();
    let mut ids = params.ids().map(|id| {
        fresh
            .add(params.name(id).unwrap(), params.get(id).unwrap().to_owned())
            .unwrap()
    });
    let (w, b) = (ids.next().unwrap(), ids.next().unwrap());
    (fresh, w, b)
}

/// `n` Adam steps on `mean((sin(w) + b - target)^2)` with a target that changes every step
/// (a stochastic loss, so the moments differ from one step to the next).
fn steps<F: Float>(params: &mut Params<F>, w: ParamId, b: ParamId, adam: &mut Adam<F>, first: usize, n: usize) {
    let mut tape = Tape::<F>::new();
    for s in first..first + n {
        let wv = tape.param_from(params, w).unwrap();
        let bv = tape.param_from(params, b).unwrap();
        let target = tape.constant(Array2::from_shape_fn((130, 160), |(i, j)| {
            F::lit(((i + 3 * j + 11 * s) as f64 * 0.071).cos())
        }));
        let sw = tape.sin(wv).unwrap();
        let pred = tape.add(sw, bv).unwrap();
        let r = tape.sub(pred, target).unwrap();
        let sq = tape.square(r).unwrap();
        let loss = tape.mean(sq).unwrap();
        let grads = tape.backward(loss).unwrap();
        tape.clear();
        adam.step(params, &grads).unwrap();
        tape.recycle(grads);
    }
}

fn bits<F: Float>(params: &Params<F>, id: ParamId) -> Vec<u64> {
    params.get(id).unwrap().iter().map(|v| v.as_f64().to_bits()).collect()
}

fn split_equals_whole<F: Float>() {
    let config = AdamConfig {
        lr: 0.05,
        ..AdamConfig::default()
    };
    let k = 6;
    let (mut whole, w, b) = store::<F>();
    let mut adam = Adam::new(config).unwrap();
    steps(&mut whole, w, b, &mut adam, 0, 2 * k);

    let (mut first, w1, b1) = store::<F>();
    let mut adam1 = Adam::new(config).unwrap();
    steps(&mut first, w1, b1, &mut adam1, 0, k);
    let saved_w = adam1.state(&first, w1).unwrap().unwrap();
    let saved_b = adam1.state(&first, b1).unwrap().unwrap();
    assert_eq!(saved_w.updates, k);
    assert_eq!(saved_w.first_moment.shape(), &[130, 160]);
    assert!(saved_w.second_moment.iter().all(|v| *v > F::zero()));

    let (mut second, w2, b2) = copy(&first);
    drop((first, adam1));
    let mut adam2 = Adam::new(config).unwrap();
    adam2.restore(&second, w2, saved_w.clone()).unwrap();
    adam2.restore(&second, b2, saved_b).unwrap();
    assert_eq!(adam2.state(&second, w2).unwrap().unwrap(), saved_w);
    steps(&mut second, w2, b2, &mut adam2, k, k);

    assert_eq!(bits(&second, w2), bits(&whole, w));
    assert_eq!(bits(&second, b2), bits(&whole, b));
    assert_eq!(adam2.updates(w2), 2 * k);
    assert_eq!(adam2.state(&second, w2).unwrap(), adam.state(&whole, w).unwrap());

    // Without the state the continuation differs: the test can fail.
    let (mut third, w3, b3) = store::<F>();
    let mut adam3 = Adam::new(config).unwrap();
    steps(&mut third, w3, b3, &mut adam3, 0, k);
    let mut fresh = Adam::new(config).unwrap();
    steps(&mut third, w3, b3, &mut fresh, k, k);
    assert_ne!(bits(&third, w3), bits(&whole, w));
}

#[test]
fn k_steps_exported_and_imported_then_k_more_equal_2k_steps_bitwise() {
    split_equals_whole::<f32>();
    split_equals_whole::<f64>();
}

#[test]
fn state_is_none_before_the_first_update_and_is_bound_to_the_store() {
    let (params, w, _) = store::<f64>();
    let adam = Adam::<f64>::new(AdamConfig::default()).unwrap();
    assert_eq!(adam.state(&params, w).unwrap(), None);
    let (other, w_other, _) = store::<f64>();
    assert_eq!(
        adam.state(&params, w_other).unwrap_err(),
        ParamError::ForeignParam { index: 0 }
    );
    let mut bound = Adam::<f64>::new(AdamConfig::default()).unwrap();
    let good = AdamState {
        first_moment: ArrayD::zeros(IxDyn(&[130, 160])),
        second_moment: ArrayD::zeros(IxDyn(&[130, 160])),
        updates: 3,
    };
    bound.restore(&params, w, good.clone()).unwrap();
    assert_eq!(bound.updates(w), 3);
    assert_eq!(bound.state(&other, w_other).unwrap_err(), ParamError::ForeignStore);
    assert_eq!(
        bound.restore(&other, w_other, good).unwrap_err(),
        ParamError::ForeignStore
    );
}

#[test]
fn a_bad_state_is_refused_and_changes_nothing() {
    let (mut params, w, b) = store::<f32>();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    steps(&mut params, w, b, &mut adam, 0, 2);
    let before = adam.state(&params, w).unwrap().unwrap();
    let with = |f: &dyn Fn(&mut AdamState<f32>)| {
        let mut s = before.clone();
        f(&mut s);
        s
    };
    let cases: Vec<(AdamState<f32>, ParamError)> = vec![
        (
            with(&|s| s.second_moment = ArrayD::zeros(IxDyn(&[160, 130]))),
            ParamError::StateShape {
                name: "w".into(),
                what: "second moment",
                expected: vec![130, 160],
                got: vec![160, 130],
            },
        ),
        (
            with(&|s| s.first_moment[[4, 5]] = f32::NAN),
            ParamError::InvalidState {
                name: "w".into(),
                what: "first moment",
                index: 4 * 160 + 5,
                value: f64::NAN,
                range: "finite",
            },
        ),
        (
            with(&|s| s.second_moment[[0, 7]] = -1e-30),
            ParamError::InvalidState {
                name: "w".into(),
                what: "second moment",
                index: 7,
                value: -1e-30f32 as f64,
                range: "at least 0",
            },
        ),
        (
            with(&|s| s.updates = 1 << 31),
            ParamError::InvalidState {
                name: "w".into(),
                what: "updates",
                index: 0,
                value: 2147483648.0,
                range: "at most 2^31 - 1",
            },
        ),
    ];
    for (state, want) in cases {
        let got = adam.restore(&params, w, state).unwrap_err();
        // NaN != NaN: compare the NaN case through its message.
        assert_eq!(got.to_string(), want.to_string());
        assert_eq!(adam.state(&params, w).unwrap().unwrap(), before);
        assert_eq!(adam.updates(w), 2);
    }
}
