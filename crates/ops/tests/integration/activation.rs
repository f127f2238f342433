//! The fused density/colour activation against its taped twin (f64, to 1e-12), f64 finite
//! differences, hand-computed values at the extremes, its own f64 run (for f32 data), and
//! itself on other thread counts; its errors and their leaving everything unchanged.

use fogray_ops::activation::{twin, DensityColor};
use fogray_ops::{ActivatedGrads, ActivatedMut, At, Op, OpsError};
use fogray_tape::{gradcheck, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{arr2, Array1, Array2, ArrayD, Axis};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};

/// `n x k` raw values ~ U[-scale, scale].
fn raw(seed: u64, n: usize, k: usize, scale: f64) -> Array2<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    Array2::from_shape_fn((n, k), |_| rng.gen_range(-scale..=scale))
}

/// A loss that weights every output differently: `sum(ws sigma) + sum(wc color^2)`.
fn weighted_loss(
    tape: &mut Tape<f64>,
    sigma: Var,
    color: Var,
    ws: &Array1<f64>,
    wc: &Array2<f64>,
) -> Result<Var, TapeError> {
    let ws = tape.constant(ws.clone());
    let wc = tape.constant(wc.clone());
    let s = tape.mul(sigma, ws)?;
    let s = tape.sum(s)?;
    let c = tape.square(color)?;
    let c = tape.mul(c, wc)?;
    let c = tape.sum(c)?;
    tape.add(s, c)
}

fn close(a: &ArrayD<f64>, b: &ArrayD<f64>, tol: f64) -> Result<(), String> {
    if a.shape() != b.shape() {
        return Err(format!("shapes {:?} and {:?}", a.shape(), b.shape()));
    }
    for (i, (x, y)) in a.iter().zip(b.iter()).enumerate() {
        if (x - y).abs() > tol * y.abs().max(1e-300) && (x - y).abs() > 1e-300 {
            return Err(format!("element {i}: {x:e} against {y:e}"));
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn fused_matches_the_taped_twin_in_f64(
        seed in 0u64..1_000_000,
        n in 1usize..300,
        k in 2usize..6,
        shift in -5.0f64..5.0,
        scale in prop::sample::select(vec![0.5, 4.0, 30.0, 700.0]),
    ) {
        let op = DensityColor::new(shift).unwrap();
        let x = raw(seed, n, k, scale);
        let ws = raw(seed + 1, n, 1, 1.0).index_axis(Axis(1), 0).to_owned();
        let wc = raw(seed + 2, n, k - 1, 1.0);
        let mut values = Vec::new();
        for fused in [true, false] {
            let mut tape = Tape::<f64>::new();
            let r = tape.param(x.clone());
            let out = if fused { op.apply(&mut tape, r).unwrap() } else { twin::density_color(&mut tape, &op, r).unwrap() };
            let loss = weighted_loss(&mut tape, out.sigma, out.color, &ws, &wc).unwrap();
            let grads = tape.backward(loss).unwrap();
            values.push([
                tape.value(out.sigma).unwrap().to_owned(),
                tape.value(out.color).unwrap().to_owned(),
                grads.get(r).unwrap().to_owned(),
            ]);
        }
        for (what, (a, b)) in ["sigma", "color", "d raw"].iter().zip(values[0].iter().zip(&values[1])) {
            prop_assert!(close(a, b, 1e-12).is_ok(), "{}: {:?}", what, close(a, b, 1e-12));
        }
    }
}

#[test]
fn the_fused_op_and_its_twin_pass_gradcheck_in_f64() {
    let op = DensityColor::new(-1.5).unwrap();
    for (k, scale) in [(4, 3.0), (2, 0.5), (5, 12.0)] {
        let x = raw(7 + k as u64, 6, k, scale).into_dyn();
        let ws = raw(8, 6, 1, 1.0).index_axis(Axis(1), 0).to_owned();
        let wc = raw(9, 6, k - 1, 1.0);
        for fused in [true, false] {
            let f = |t: &mut Tape<f64>, v: &[Var]| {
                let out = if fused {
                    op.apply(t, v[0])?
                } else {
                    twin::density_color(t, &op, v[0])?
                };
                weighted_loss(t, out.sigma, out.color, &ws, &wc)
            };
            let report = gradcheck(f, std::slice::from_ref(&x), &GradcheckOptions::default()).unwrap();
            assert!(report.passes(), "k {k}, fused {fused}: {report}");
        }
    }
}

#[test]
fn values_and_slopes_at_the_extremes_are_those_computed_by_hand() {
    let op = DensityColor::new(0.0).unwrap();
    let x = arr2(&[
        [0.0, 0.0, 40.0, -40.0],
        [1e4, 1e4, -1e4, f64::MIN_POSITIVE],
        [-1e4, f64::INFINITY, f64::NEG_INFINITY, -745.0],
        [-40.0, 1e-300, -0.0, 710.0],
    ]);
    let out = op.evaluate(x.view()).unwrap();
    let e40 = (-40f64).exp();
    let ln2 = std::f64::consts::LN_2;
    assert!((out.sigma[0] - ln2).abs() <= f64::EPSILON * ln2);
    assert_eq!(out.sigma[1], 1e4);
    assert_eq!(out.sigma[2], 0.0);
    // softplus(-40) = ln(1 + e^-40) = e^-40 (1 - e^-40 / 2), where ln(1 + exp(x)) gives 0.
    assert!((out.sigma[3] / e40 - 1.0).abs() < 4e-16);
    assert_eq!((1.0 + e40).ln(), 0.0);
    assert_eq!(out.color.row(0).to_vec(), [0.5, 1.0 / (1.0 + e40), e40 / (1.0 + e40)]);
    assert_eq!(out.color.row(1).to_vec(), [1.0, 0.0, 0.5]);
    assert_eq!(out.color[[2, 0]], 1.0);
    assert_eq!(out.color[[2, 1]], 0.0);
    assert!(out.color[[2, 2]] > 0.0 && (out.color[[2, 2]] / (-745f64).exp() - 1.0).abs() < 0.3); // subnormal
    assert_eq!(out.color.row(3).to_vec()[1..], [0.5, 1.0]);
    assert!(out.iter_finite());

    // The slopes: softplus'(0) = 1/2, sigmoid'(0) = 1/4, sigmoid'(+-40) = e^-40 / (1 + e^-40)^2
    // where y (1 - y) with y = sigmoid(40) = 1.0 (rounded) is 0.
    let ones = Array1::ones(4);
    let ones_c = Array2::ones((4, 3));
    let upstream = ActivatedGrads {
        sigma: Some(ones.view()),
        color: Some(ones_c.view()),
    };
    let g = op.vjp(x.view(), &upstream).unwrap();
    assert_eq!(g.row(0).to_vec()[..2], [0.5, 0.25]);
    let slope40 = e40 / ((1.0 + e40) * (1.0 + e40));
    assert!((g[[0, 2]] / slope40 - 1.0).abs() < 1e-15 && g[[0, 2]] == g[[0, 3]]);
    let y = out.color[[0, 1]];
    assert_eq!(y * (1.0 - y), 0.0);
    assert_eq!(g.row(1).to_vec(), [1.0, 0.0, 0.0, 0.25]);
    assert_eq!(g.row(2).to_vec()[..3], [0.0, 0.0, 0.0]);
    assert_eq!(g[[3, 0]], out.color[[0, 2]]); // softplus'(-40) = sigmoid(-40)
                                              // sigmoid'(710) = e^-710, a subnormal, not 0.
    assert!((g[[3, 3]] / (-710f64).exp() - 1.0).abs() < 1e-6);
}

/// Whether every output is finite or an exact saturation.
trait Finite {
    fn iter_finite(&self) -> bool;
}
impl Finite for fogray_ops::Activated<f64> {
    fn iter_finite(&self) -> bool {
        self.sigma.iter().all(|v| !v.is_nan()) && self.color.iter().all(|v| v.is_finite())
    }
}

#[test]
fn f32_data_give_their_f64_values_rounded_to_within_one_ulp() {
    let op = DensityColor::new(0.75).unwrap();
    let mut x64 = raw(3, 4000, 4, 25.0);
    x64.row_mut(0).assign(&Array1::from(vec![-150.0, 20.0, -100.0, 90.0]));
    let x32 = x64.mapv(|v| v as f32);
    let x64 = x32.mapv(f64::from);
    let (o32, o64) = (op.evaluate(x32.view()).unwrap(), op.evaluate(x64.view()).unwrap());
    let g32 = raw(4, 4000, 1, 2.0).index_axis(Axis(1), 0).mapv(|v| v as f32);
    let gc32 = raw(5, 4000, 3, 2.0).mapv(|v| v as f32);
    let (g64, gc64) = (g32.mapv(f64::from), gc32.mapv(f64::from));
    let d32 = op
        .vjp(
            x32.view(),
            &ActivatedGrads {
                sigma: Some(g32.view()),
                color: Some(gc32.view()),
            },
        )
        .unwrap();
    let d64 = op
        .vjp(
            x64.view(),
            &ActivatedGrads {
                sigma: Some(g64.view()),
                color: Some(gc64.view()),
            },
        )
        .unwrap();
    let within_ulp = |a: f32, b: f64| {
        let r = b as f32;
        a == r || a == f32::from_bits(r.to_bits() + 1) || a == f32::from_bits(r.to_bits().wrapping_sub(1))
    };
    let pairs = o32
        .sigma
        .iter()
        .zip(o64.sigma.iter())
        .chain(o32.color.iter().zip(o64.color.iter()))
        .chain(d32.iter().zip(d64.iter()));
    for (i, (&a, &b)) in pairs.enumerate() {
        assert!(within_ulp(a, b), "value {i}: {a:e} against {b:e}");
    }
    // The f32 slope at 20 is 2.06e-9, where y (1 - y) from y = sigmoid(20) rounded to f32 is 0.
    assert!(d32[[0, 1]] != 0.0 && (d32[[0, 1]] / gc32[[0, 0]] / 2.06e-9 - 1.0).abs() < 1e-3);
    let y = o32.color[[0, 0]];
    assert_eq!(y * (1.0 - y), 0.0);
    // softplus(90 + 0.75) in f32 without the stable form: ln(1 + exp(90.75)) overflows.
    assert!((1.0 + 90.75f32.exp()).ln().is_infinite());
    assert_eq!(op.evaluate(arr2(&[[90.0f32, 0.0]]).view()).unwrap().sigma[0], 90.75);
}

#[test]
fn results_are_bitwise_the_same_on_1_2_and_3_threads() {
    let op = DensityColor::new(-2.0).unwrap();
    let x = raw(11, 3 * 2048 + 17, 4, 20.0).mapv(|v| v as f32);
    let gs = raw(12, x.nrows(), 1, 1.0).index_axis(Axis(1), 0).mapv(|v| v as f32);
    let gc = raw(13, x.nrows(), 3, 1.0).mapv(|v| v as f32);
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let out = op.evaluate(x.view()).unwrap();
            let g = op
                .vjp(
                    x.view(),
                    &ActivatedGrads {
                        sigma: Some(gs.view()),
                        color: Some(gc.view()),
                    },
                )
                .unwrap();
            let bits = |a: &mut dyn Iterator<Item = f32>| a.map(f32::to_bits).collect::<Vec<u32>>();
            (
                bits(&mut out.sigma.iter().copied()),
                bits(&mut out.color.iter().copied()),
                bits(&mut g.iter().copied()),
            )
        })
    };
    let one = run(1);
    assert_eq!(run(2), one);
    assert_eq!(run(3), one);
}

/// The op on a tape (whose backward reads the decays its forward kept) and its stateless `vjp`
/// (which recomputes them from the raw values) give bitwise the same gradients, for `F`, over
/// several chunks of rows, the general channel count and a missing upstream gradient.
/// The values' bits, as f64 (exact for f32), in order.
fn bits<'a, F: fogray_tape::Float>(values: impl IntoIterator<Item = &'a F>) -> Vec<u64> {
    values.into_iter().map(|v| v.as_f64().to_bits()).collect()
}

fn kept_decays_give_the_recomputed_gradients<F: fogray_tape::Float>() {
    let op = DensityColor::new(-4.0).unwrap();
    for (k, n) in [(4, 2 * 2048 + 5), (2, 300), (6, 2048 + 1)] {
        let mut x = raw(21, n, k, 30.0);
        // Saturated tails, exact zeros and infinities, in both columns.
        x.row_mut(0).fill(0.0);
        x[[1, 0]] = f64::INFINITY;
        x[[1, 1]] = f64::NEG_INFINITY;
        x[[2, 0]] = -800.0;
        x[[2, k - 1]] = 745.5;
        let x = x.mapv(F::lit);
        let gs = raw(22, n, 1, 2.0).index_axis(Axis(1), 0).mapv(F::lit);
        let gc = raw(23, n, k - 1, 2.0).mapv(F::lit);
        for (with_sigma, with_color) in [(true, true), (false, true), (true, false)] {
            let mut tape = Tape::<F>::new();
            let r = tape.param(x.clone());
            let out = op.apply(&mut tape, r).unwrap();
            // d(sum(ws sigma) + sum(wc color)) / d(sigma, color) = (ws, wc), exactly.
            let mut terms = Vec::new();
            if with_sigma {
                let w = tape.constant(gs.clone());
                let p = tape.mul(out.sigma, w).unwrap();
                terms.push(tape.sum(p).unwrap());
            }
            if with_color {
                let w = tape.constant(gc.clone());
                let p = tape.mul(out.color, w).unwrap();
                terms.push(tape.sum(p).unwrap());
            }
            let loss = match terms[..] {
                [a, b] => tape.add(a, b).unwrap(),
                [a] => a,
                _ => unreachable!(),
            };
            let taped = tape.backward(loss).unwrap().get(r).unwrap().to_owned();
            let upstream = ActivatedGrads {
                sigma: with_sigma.then(|| gs.view()),
                color: with_color.then(|| gc.view()),
            };
            let recomputed = op.vjp(x.view(), &upstream).unwrap();
            assert_eq!(
                bits(&taped),
                bits(&recomputed),
                "{} k = {k}, sigma {with_sigma}, colour {with_color}",
                F::NAME
            );
        }
    }
}

#[test]
fn the_tape_backward_from_kept_decays_is_bitwise_the_recomputed_one() {
    kept_decays_give_the_recomputed_gradients::<f32>();
    kept_decays_give_the_recomputed_gradients::<f64>();
}

/// Under `no_grad` (or on a constant) the activation keeps no decays; its outputs must be the
/// recorded application's, bit for bit, and a NaN the same typed error.
fn unrecorded_outputs_are_the_recorded_ones<F: fogray_tape::Float>() {
    let op = DensityColor::new(-2.0).unwrap();
    let value_bits = |t: &Tape<F>, v: Var| bits(t.value(v).unwrap());
    for (k, n) in [(4, 2 * 2048 + 5), (2, 300)] {
        let mut x = raw(24, n, k, 30.0);
        x[[1, 0]] = f64::INFINITY;
        x[[2, k - 1]] = -800.0;
        let x = x.mapv(F::lit);
        let mut tape = Tape::<F>::new();
        let r = tape.param(x.clone());
        let recorded = op.apply(&mut tape, r).unwrap();
        let c = tape.constant(x.clone());
        let unrecorded = [
            tape.no_grad(|t| op.apply(t, r)).unwrap(),
            op.apply(&mut tape, c).unwrap(),
        ];
        assert_eq!(tape.stats().records, 1, "{} k = {k}", F::NAME);
        for out in unrecorded {
            assert_eq!(
                value_bits(&tape, out.sigma),
                value_bits(&tape, recorded.sigma),
                "{} k = {k}",
                F::NAME
            );
            assert_eq!(
                value_bits(&tape, out.color),
                value_bits(&tape, recorded.color),
                "{} k = {k}",
                F::NAME
            );
        }
        let mut bad = x;
        bad[[n - 1, 1]] = F::lit(f64::NAN);
        let b = tape.param(bad);
        let e = tape.no_grad(|t| op.apply(t, b)).unwrap_err();
        let at = At::Entry { row: n - 1, column: 1 };
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::Domain { op: Op::DensityColor, at: a, value, .. }) if *a == at && value.is_nan()
            ),
            "{e}"
        );
    }
}

#[test]
fn an_unrecorded_application_gives_the_recorded_outputs_and_errors() {
    unrecorded_outputs_are_the_recorded_ones::<f32>();
    unrecorded_outputs_are_the_recorded_ones::<f64>();
}

#[test]
fn the_into_forms_write_strided_buffers_and_zero_the_missing_gradients() {
    let op = DensityColor::new(0.3).unwrap();
    let x = raw(21, 50, 4, 6.0);
    let want = op.evaluate(x.view()).unwrap();
    // Strided outputs: a column of a matrix and a transposed matrix.
    let mut sigma_home = Array2::<f64>::from_elem((50, 2), -7.0);
    let mut color_home = Array2::<f64>::from_elem((3, 50), -7.0);
    op.evaluate_into(
        x.view(),
        ActivatedMut {
            sigma: sigma_home.column_mut(1),
            color: color_home.view_mut().reversed_axes(),
        },
    )
    .unwrap();
    assert_eq!(sigma_home.column(1), want.sigma);
    assert!(sigma_home.column(0).iter().all(|&v| v == -7.0));
    assert_eq!(color_home.t(), want.color);
    // Contiguous ones, through the kernel directly: the same bits.
    let (mut s, mut c) = (Array1::zeros(50), Array2::zeros((50, 3)));
    op.evaluate_into(
        x.view(),
        ActivatedMut {
            sigma: s.view_mut(),
            color: c.view_mut(),
        },
    )
    .unwrap();
    assert_eq!((s, c), (want.sigma.clone(), want.color.clone()));
    assert_eq!(op.density(x.view()).unwrap(), want.sigma);
    assert_eq!(op.density(x.slice(ndarray::s![.., ..1])).unwrap(), want.sigma);

    let gc = raw(22, 50, 3, 1.0);
    let only_color = ActivatedGrads {
        sigma: None,
        color: Some(gc.view()),
    };
    let mut g = Array2::<f64>::from_elem((4, 50), f64::NAN);
    op.vjp_into(x.view(), &only_color, g.view_mut().reversed_axes())
        .unwrap();
    assert!(g.row(0).iter().all(|&v| v == 0.0));
    let full = op.vjp(x.view(), &only_color).unwrap();
    assert_eq!(g.t(), full);
    for i in 0..50 {
        for c in 0..3 {
            let s = want.color[[i, c]];
            // Against y (1 - y) where it is accurate (|x| <= 6 here).
            assert!((full[[i, c + 1]] - gc[[i, c]] * s * (1.0 - s)).abs() < 1e-15);
        }
    }
    let nothing = ActivatedGrads::<f64> {
        sigma: None,
        color: None,
    };
    assert!(op.vjp(x.view(), &nothing).unwrap().iter().all(|&v| v == 0.0));
}

#[test]
fn bad_input_is_a_typed_error_and_changes_nothing() {
    assert_eq!(
        DensityColor::new(f64::NAN).unwrap_err().to_string(),
        "density_color: shift is NaN (must be finite)"
    );
    assert!(matches!(
        DensityColor::new(f64::INFINITY),
        Err(OpsError::Config {
            op: Op::DensityColor,
            what: "shift",
            ..
        })
    ));
    let op = DensityColor::new(0.0).unwrap();

    let narrow = Array2::<f64>::zeros((3, 1));
    assert!(matches!(
        op.evaluate(narrow.view()),
        Err(OpsError::Shape {
            op: Op::DensityColor,
            ..
        })
    ));
    let mut x = raw(31, 9000, 4, 1.0);
    x[[8001, 2]] = f64::NAN;
    x[[8500, 0]] = f64::NAN;
    assert!(matches!(
        op.evaluate(x.view()).unwrap_err(),
        OpsError::Domain {
            op: Op::DensityColor,
            at: At::Entry { row: 8001, column: 2 },
            ..
        }
    ));
    assert!(matches!(
        op.density(x.view()).unwrap_err(),
        OpsError::Domain {
            op: Op::DensityColor,
            at: At::Entry { row: 8500, column: 0 },
            ..
        }
    ));

    // Buffers of the wrong shape, or input at fault: the buffers keep their values.
    let good = raw(32, 5, 4, 1.0);
    let (mut s, mut c) = (Array1::from_elem(5, 9.0), Array2::from_elem((5, 4), 9.0));
    let e = op.evaluate_into(
        good.view(),
        ActivatedMut {
            sigma: s.view_mut(),
            color: c.view_mut(),
        },
    );
    assert!(matches!(
        e,
        Err(OpsError::Shape {
            op: Op::DensityColor,
            what: "color",
            ..
        })
    ));
    let mut bad = good.clone();
    bad[[4, 3]] = f64::NAN;
    let mut c3 = Array2::from_elem((5, 3), 9.0);
    assert!(op
        .evaluate_into(
            bad.view(),
            ActivatedMut {
                sigma: s.view_mut(),
                color: c3.view_mut()
            }
        )
        .is_err());
    assert!(s.iter().chain(c.iter()).chain(c3.iter()).all(|&v| v == 9.0));
    let gs = Array1::ones(4);
    let mut g = Array2::from_elem((5, 4), 9.0);
    let e = op.vjp_into(
        good.view(),
        &ActivatedGrads {
            sigma: Some(gs.view()),
            color: None,
        },
        g.view_mut(),
    );
    assert!(matches!(
        e,
        Err(OpsError::Shape {
            op: Op::DensityColor,
            what: "sigma gradient",
            ..
        })
    ));
    assert!(g.iter().all(|&v| v == 9.0));

    // Through a tape: the error arrives whole and nothing is recorded.
    let mut tape = Tape::<f64>::new();
    let r = tape.param(bad);
    let t3 = tape.param(ndarray::Array3::<f64>::zeros((2, 2, 2)));
    let n = tape.param(narrow);
    let before = tape.len();
    let err = op.apply(&mut tape, r).unwrap_err();
    assert!(matches!(
        err.downcast_ref::<OpsError>(),
        Some(OpsError::Domain {
            op: Op::DensityColor,
            at: At::Entry { row: 4, column: 3 },
            ..
        })
    ));
    for v in [t3, n] {
        let err = op.apply(&mut tape, v).unwrap_err();
        assert!(
            matches!(
                err.downcast_ref::<OpsError>(),
                Some(OpsError::Shape {
                    op: Op::DensityColor,
                    ..
                })
            ),
            "{err}"
        );
        let err = twin::density_color(&mut tape, &op, v).unwrap_err();
        assert!(
            matches!(
                err.downcast_ref::<OpsError>(),
                Some(OpsError::Shape {
                    op: Op::DensityColor,
                    ..
                })
            ),
            "{err}"
        );
    }
    assert_eq!(tape.len(), before);
}
