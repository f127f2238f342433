//! `Composite::apply_mse` (the composite and its mean squared error as one op) against the
//! chain it replaces (`apply`, then the tape's `sub`, `square` and `mean`): the loss and every
//! gradient bitwise, over ragged packs, empty rays, each background, early termination and
//! both precisions; for upstream gradients other than 1 and on a second sweep; against the
//! lesson's table and finite differences; and its errors, which leave the tape unchanged.

use fogray_ops::{At, Background, Composite, CompositeInputs, Op, OpsError};
use fogray_tape::gradcheck::Domain;
use fogray_tape::{gradcheck, Float, GradcheckOptions, Gradients, Tape, TapeError, Var};
use ndarray::{arr1, arr2, ArrayD};
use rand::{Rng, SeedableRng};

/// Ray lengths with empty rays, single samples and a long ray.
const LENGTHS: [usize; 12] = [3, 0, 1, 7, 64, 2, 0, 5, 17, 1, 9, 40];

/// Random packed inputs in f64 (f32-representable), `ch` channels.
struct Case {
    offsets: Vec<usize>,
    sigma: ArrayD<f64>,
    delta: ArrayD<f64>,
    color: ArrayD<f64>,
    background: Option<ArrayD<f64>>,
    target: ArrayD<f64>,
}

fn case(ch: usize, background: Background, seed: u64) -> Case {
    let mut offsets = vec![0];
    for l in LENGTHS {
        offsets.push(offsets[offsets.len() - 1] + l);
    }
    let (n, rays) = (offsets[LENGTHS.len()], LENGTHS.len());
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut v = |len: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..len).map(|_| f64::from(rng.gen_range(lo..hi) as f32)).collect()
    };
    let mut sigma = v(n, 0.0, 6.0);
    // Empty samples, opaque ones, and tiny optical depths.
    for (i, s) in sigma.iter_mut().enumerate() {
        match i % 11 {
            0 => *s = 0.0,
            1 => *s = 300.0,
            2 => *s = 1e-6,
            _ => {}
        }
    }
    let arr = |shape: Vec<usize>, data: Vec<f64>| ArrayD::from_shape_vec(shape, data).unwrap();
    Case {
        sigma: arr(vec![n], sigma),
        delta: arr(vec![n], v(n, 0.0, 0.2)),
        color: arr(vec![n, ch], v(n * ch, -0.5, 1.5)),
        background: match background {
            Background::None => None,
            Background::Shared => Some(arr(vec![ch], v(ch, 0.0, 1.0))),
            Background::PerRay => Some(arr(vec![rays, ch], v(rays * ch, 0.0, 1.0))),
        },
        target: arr(vec![rays, ch], v(rays * ch, 0.0, 1.0)),
        offsets,
    }
}

/// Every input of a case on a tape as a parameter (so that every gradient is computed).
struct Recorded {
    inputs: CompositeInputs,
    target: Var,
}

fn record<F: Float>(tape: &mut Tape<F>, c: &Case) -> Recorded {
    let to = |a: &ArrayD<f64>| a.mapv(F::lit);
    let inputs = CompositeInputs {
        sigma: tape.param(to(&c.sigma)),
        delta: tape.param(to(&c.delta)),
        color: tape.param(to(&c.color)),
        background: c.background.as_ref().map(|b| tape.param(to(b))),
        t: None,
    };
    let target = tape.param(to(&c.target));
    Recorded { inputs, target }
}

/// The chain the op replaces.
fn chain<F: Float>(tape: &mut Tape<F>, op: &Composite, r: &Recorded) -> Var {
    let color = op.apply(tape, &r.inputs).unwrap().color;
    let error = tape.sub(color, r.target).unwrap();
    let squared = tape.square(error).unwrap();
    tape.mean(squared).unwrap()
}

/// The bits of every gradient (sigma, delta, colour, background, target).
fn gradient_bits<F: Float>(g: &Gradients<F>, r: &Recorded) -> Vec<Vec<u64>> {
    let vars = [
        Some(r.inputs.sigma),
        Some(r.inputs.delta),
        Some(r.inputs.color),
        r.inputs.background,
        Some(r.target),
    ];
    vars.iter()
        .flatten()
        .map(|&v| {
            g.get(v)
                .expect("every input is a parameter")
                .iter()
                .map(|x| x.as_f64().to_bits())
                .collect()
        })
        .collect()
}

fn value_bits<F: Float>(tape: &Tape<F>, v: Var) -> u64 {
    tape.value(v).unwrap().iter().next().unwrap().as_f64().to_bits()
}

fn ops() -> Vec<(Background, Composite)> {
    let base = Composite::new(&{
        let mut o = vec![0];
        for l in LENGTHS {
            o.push(o[o.len() - 1] + l);
        }
        o
    })
    .unwrap();
    let mut ops = Vec::new();
    for background in [Background::None, Background::Shared, Background::PerRay] {
        for threshold in [0.0, 1e-3] {
            let op = base
                .clone()
                .background(background)
                .min_transmittance(threshold)
                .unwrap();
            ops.push((background, op));
        }
    }
    ops
}

fn same_as_the_chain<F: Float>() {
    for (seed, (background, op)) in ops().into_iter().enumerate() {
        for ch in [1, 3] {
            let c = case(ch, background, seed as u64);
            assert_eq!(op.offsets(), &c.offsets[..]);
            let mut tape = Tape::<F>::new();
            let r = record(&mut tape, &c);
            let loss = op.apply_mse(&mut tape, &r.inputs, r.target).unwrap();
            let want = chain(&mut tape, &op, &r);
            assert_eq!(
                value_bits(&tape, loss),
                value_bits(&tape, want),
                "{background:?} ch {ch}"
            );
            let got = gradient_bits(&tape.backward(loss).unwrap(), &r);
            let expected = gradient_bits(&tape.backward(want).unwrap(), &r);
            assert_eq!(got.len(), expected.len());
            for (k, (g, e)) in got.iter().zip(&expected).enumerate() {
                assert_eq!(g, e, "gradient {k}, {background:?}, ch {ch}, seed {seed}");
            }
            // Not all zeros: the comparison means something.
            assert!(got[0].iter().any(|&b| f64::from_bits(b) != 0.0));
        }
    }
}

#[test]
fn the_loss_and_every_gradient_are_the_chains_bits() {
    same_as_the_chain::<f32>();
    same_as_the_chain::<f64>();
}

#[test]
fn other_upstream_gradients_and_a_second_sweep_give_the_chains_bits_too() {
    let (background, op) = ops().swap_remove(3);
    let c = case(3, background, 7);
    let mut tape = Tape::<f32>::new();
    let r = record(&mut tape, &c);
    let loss = op.apply_mse(&mut tape, &r.inputs, r.target).unwrap();
    let want = chain(&mut tape, &op, &r);
    let expected = gradient_bits(&tape.backward(want).unwrap(), &r);
    // The first sweep hands over the forward's gradients, the second recomputes them.
    let first = gradient_bits(&tape.backward(loss).unwrap(), &r);
    let second = gradient_bits(&tape.backward(loss).unwrap(), &r);
    assert_eq!(first, expected);
    assert_eq!(second, expected);
    // Weighted by 2.5 and by 1, after the sweeps above: the chain's bits in each case.
    for weight in [2.5f32, 1.0] {
        let weighted = tape.mul_scalar(loss, weight).unwrap();
        let chain_weighted = tape.mul_scalar(want, weight).unwrap();
        let got = gradient_bits(&tape.backward(weighted).unwrap(), &r);
        assert_eq!(
            got,
            gradient_bits(&tape.backward(chain_weighted).unwrap(), &r),
            "weight {weight}"
        );
    }
    // A zero upstream gradient gives zeros, as the chain's strong-zero products do.
    let zero = tape.mul_scalar(loss, 0.0).unwrap();
    let chain_zero = tape.mul_scalar(want, 0.0).unwrap();
    let got = gradient_bits(&tape.backward(zero).unwrap(), &r);
    assert_eq!(got, gradient_bits(&tape.backward(chain_zero).unwrap(), &r));

    // A weighted loss on a fresh recording: its first sweep must not hand over the gradients
    // made for a weight of 1.
    for weight in [2.5f32, 0.0] {
        let mut tape = Tape::<f32>::new();
        let r = record(&mut tape, &c);
        let loss = op.apply_mse(&mut tape, &r.inputs, r.target).unwrap();
        let weighted = tape.mul_scalar(loss, weight).unwrap();
        let got = gradient_bits(&tape.backward(weighted).unwrap(), &r);
        let want = chain(&mut tape, &op, &r);
        let chain_weighted = tape.mul_scalar(want, weight).unwrap();
        assert_eq!(
            got,
            gradient_bits(&tape.backward(chain_weighted).unwrap(), &r),
            "weight {weight}"
        );
    }
}

#[test]
fn the_lesson_example_gives_its_table_through_the_loss() {
    // delta 0.5, sigma (0, 0.5, 2, 8), c (0.9, 0.2, 0.9, 0.4), background 1: C = 0.6051 and
    // dC/dsigma = (+0.1475, -0.2025, +0.0701, -0.0016). Against a target of 0.5 the loss is
    // (C - 0.5)^2 and dL/dsigma = 2 (C - 0.5) dC/dsigma.
    let op = Composite::new(&[0, 4]).unwrap();
    let mut tape = Tape::<f64>::new();
    let sigma = tape.param(arr1(&[0.0, 0.5, 2.0, 8.0]));
    let inputs = CompositeInputs {
        sigma,
        delta: tape.constant(arr1(&[0.5; 4])),
        color: tape.constant(arr2(&[[0.9], [0.2], [0.9], [0.4]])),
        background: Some(tape.constant(arr1(&[1.0]))),
        t: None,
    };
    let target = tape.constant(arr2(&[[0.5]]));
    let loss = op.apply_mse(&mut tape, &inputs, target).unwrap();
    let c = 0.6051;
    let l = tape.value(loss).unwrap()[[]];
    assert!((l - (c - 0.5f64).powi(2)).abs() < 2e-5, "loss {l}");
    let g = tape.backward(loss).unwrap();
    let g = g.get(sigma).unwrap();
    for (k, dc) in [0.1475, -0.2025, 0.0701, -0.0016].into_iter().enumerate() {
        let want = 2.0 * (c - 0.5) * dc;
        assert!((g[k] - want).abs() < 2e-5, "dL/dsigma[{k}] = {} against {want}", g[k]);
    }
}

#[test]
fn gradients_match_finite_differences_in_f64() {
    for (background, op) in ops().into_iter().filter(|(_, op)| op.offsets().len() > 1) {
        let mut c = case(2, background, 11);
        // Finite differences need smooth functions: no opaque samples (their alpha saturates
        // to 1 in the step) and no early termination (its stop moves).
        c.sigma.mapv_inplace(|s| s.min(4.0));
        let op = op.min_transmittance(0.0).unwrap();
        let mut inputs = vec![c.sigma.clone(), c.delta.clone(), c.color.clone()];
        inputs.extend(c.background.clone());
        inputs.push(c.target.clone());
        let has_bg = c.background.is_some();
        let report = gradcheck(
            |tape, v| {
                let composite = CompositeInputs {
                    sigma: v[0],
                    delta: v[1],
                    color: v[2],
                    background: has_bg.then(|| v[3]),
                    t: None,
                };
                op.apply_mse(tape, &composite, v[v.len() - 1])
            },
            &inputs,
            &GradcheckOptions {
                domains: vec![Domain::at_least(0.0), Domain::at_least(0.0)],
                ..GradcheckOptions::default()
            },
        )
        .unwrap();
        assert!(report.passes(), "{background:?}: {report}");
    }
}

#[test]
fn without_a_record_the_loss_is_the_same_and_nothing_is_kept() {
    let (background, op) = ops().swap_remove(2);
    let c = case(3, background, 5);
    let mut tape = Tape::<f32>::new();
    let r = record(&mut tape, &c);
    let recorded = op.apply_mse(&mut tape, &r.inputs, r.target).unwrap();
    let before = tape.stats().saved_bytes;
    let unrecorded = tape.no_grad(|t| op.apply_mse(t, &r.inputs, r.target)).unwrap();
    assert_eq!(value_bits(&tape, recorded), value_bits(&tape, unrecorded));
    assert_eq!(tape.stats().saved_bytes, before);
    let g = tape.backward(unrecorded).unwrap();
    assert!(g.get(r.inputs.sigma).is_none());
}

#[test]
fn bad_input_is_a_typed_error_and_the_tape_is_unchanged() {
    let op = Composite::new(&[0, 2, 3]).unwrap();
    let mut tape = Tape::<f64>::new();
    let inputs = CompositeInputs {
        sigma: tape.param(arr1(&[0.5, 2.0, 1.0])),
        delta: tape.constant(arr1(&[0.5, 0.5, 0.5])),
        color: tape.constant(ArrayD::from_elem(vec![3, 3], 0.25)),
        background: Some(tape.constant(arr1(&[1.0, 1.0, 1.0]))),
        t: None,
    };
    let target = tape.constant(ArrayD::from_elem(vec![2, 3], 0.5));
    let wrong_target = tape.constant(ArrayD::from_elem(vec![3, 2], 0.5));
    let t = tape.constant(arr1(&[0.0, 1.0, 2.0]));
    let nan_sigma = tape.param(arr1(&[0.5, f64::NAN, 1.0]));
    let len = tape.len();
    let invalid = |e: TapeError| {
        matches!(
            e,
            TapeError::InvalidArgument {
                op: "composite_mse",
                ..
            }
        )
    };

    let with_depth = op.clone().with_depth();
    let depth_inputs = CompositeInputs { t: Some(t), ..inputs };
    assert!(invalid(
        with_depth.apply_mse(&mut tape, &depth_inputs, target).unwrap_err()
    ));
    assert!(invalid(
        op.clone()
            .with_weights()
            .apply_mse(&mut tape, &inputs, target)
            .unwrap_err()
    ));
    assert!(invalid(op.apply_mse(&mut tape, &depth_inputs, target).unwrap_err()));
    let no_bg = CompositeInputs {
        background: None,
        ..inputs
    };
    assert!(invalid(op.apply_mse(&mut tape, &no_bg, target).unwrap_err()));
    let none = op.clone().background(Background::None);
    assert!(invalid(none.apply_mse(&mut tape, &inputs, target).unwrap_err()));

    let e = op.apply_mse(&mut tape, &inputs, wrong_target).unwrap_err();
    assert!(
        matches!(
            e.downcast_ref::<OpsError>(),
            Some(OpsError::Shape {
                op: Op::CompositeMse,
                what: "target",
                ..
            })
        ),
        "{e}"
    );
    let nan = CompositeInputs {
        sigma: nan_sigma,
        ..inputs
    };
    let e = op.apply_mse(&mut tape, &nan, target).unwrap_err();
    // The composite's check, run by the fused op, names the fused op.
    let typed = e.downcast_ref::<OpsError>();
    assert!(
        matches!(
            typed,
            Some(OpsError::Domain {
                op: Op::CompositeMse,
                at: At::Sample { ray: 0, .. },
                ..
            })
        ),
        "{e}"
    );
    assert!(e.to_string().starts_with("composite_mse: ray 0"), "{e}");
    assert_eq!(tape.len(), len);

    // No colour values at all: the mean of nothing, as the tape's mean refuses it.
    let empty = Composite::new(&[0]).unwrap();
    let empty_inputs = CompositeInputs {
        sigma: tape.param(ArrayD::zeros(vec![0])),
        delta: tape.constant(ArrayD::zeros(vec![0])),
        color: tape.constant(ArrayD::zeros(vec![0, 3])),
        background: Some(tape.constant(arr1(&[1.0, 1.0, 1.0]))),
        t: None,
    };
    let empty_target = tape.constant(ArrayD::zeros(vec![0, 3]));
    let len_empty = tape.len();
    assert!(empty.apply_mse(&mut tape, &empty_inputs, empty_target).is_err());
    assert_eq!(tape.len(), len_empty);
}
