//! The spherical-harmonics colour: its basis against closed forms written out here and its
//! orthonormality on the sphere, degree 0's view independence, the fused op against its taped
//! twin (f64 to 1e-12, f32 to 1e-6) for every degree, f64 finite differences, bitwise the same
//! results on other thread counts, and each error.

use fogray_ops::sh::{basis::basis, twin, ShColor};
use fogray_ops::{At, Op, OpsError};
use fogray_tape::{gradcheck, Float, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};

/// The constants as svox2 and 3D Gaussian splatting print them, written out again here so that
/// a wrong constant in the crate cannot agree with itself.
const C0: f64 = 0.28209479177387814;
const C1: f64 = 0.4886025119029199;
const C2: [f64; 5] = [
    1.0925484305920792,
    -1.0925484305920792,
    0.31539156525252005,
    -1.0925484305920792,
    0.5462742152960396,
];
const C3: [f64; 7] = [
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
];

/// `n x k` values ~ U[-scale, scale].
fn uniform(seed: u64, n: usize, k: usize, scale: f64) -> Array2<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    Array2::from_shape_fn((n, k), |_| rng.gen_range(-scale..=scale))
}

/// `n` unit directions, uniform on the sphere (points of the unit ball, by rejection from the
/// cube, normalised).
fn directions(seed: u64, n: usize) -> Array2<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut d = Array2::zeros((n, 3));
    for mut row in d.rows_mut() {
        loop {
            let v: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..=1.0));
            let r = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if r > 0.1 && r <= 1.0 {
                for k in 0..3 {
                    row[k] = v[k] / r;
                }
                break;
            }
        }
    }
    d
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

#[test]
fn the_basis_is_the_closed_forms_at_hand_picked_directions() {
    let s3 = 3f64.sqrt();
    let cases: [([f64; 3], [f64; 16]); 4] = [
        // Along +z every term with x or y vanishes; the zonal terms are their factors times
        // 2z^2 = 2 and 2z^3 = 2.
        (
            [0.0, 0.0, 1.0],
            [
                C0,
                0.0,
                C1,
                0.0,
                0.0,
                0.0,
                0.31539156525252005 * 2.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                C3[3] * 2.0,
                0.0,
                0.0,
                0.0,
            ],
        ),
        // Along +x: -C1 x, the -x^2 of the zonal terms, x^2 - y^2 = 1, -x^3, x^3.
        (
            [1.0, 0.0, 0.0],
            [
                C0, 0.0, 0.0, -C1, 0.0, 0.0, -C2[2], 0.0, C2[4], 0.0, 0.0, 0.0, 0.0, -C3[4], 0.0, C3[6],
            ],
        ),
        // Along -y: -C1 y = C1, x^2 - y^2 = -1, y (3x^2 - y^2) = 1, y (-y^2) = 1.
        (
            [0.0, -1.0, 0.0],
            [
                C0, C1, 0.0, 0.0, 0.0, 0.0, -C2[2], 0.0, -C2[4], C3[0], 0.0, C3[2], 0.0, 0.0, 0.0, 0.0,
            ],
        ),
        // Along (1, 1, 1) / sqrt 3: every product of two is 1/3, of three 1/(3 sqrt 3); the
        // terms that balance the axes (2z^2 - x^2 - y^2, x^2 - y^2) vanish.
        (
            [1.0 / s3, 1.0 / s3, 1.0 / s3],
            [
                C0,
                -C1 / s3,
                C1 / s3,
                -C1 / s3,
                C2[0] / 3.0,
                C2[1] / 3.0,
                0.0,
                C2[3] / 3.0,
                0.0,
                C3[0] * (2.0 / 3.0) / s3,
                C3[1] / (3.0 * s3),
                C3[2] * (2.0 / 3.0) / s3,
                C3[3] * (-4.0 / 3.0) / s3,
                C3[4] * (2.0 / 3.0) / s3,
                0.0,
                C3[6] * (-2.0 / 3.0) / s3,
            ],
        ),
    ];
    for (d, want) in cases {
        let got = basis(d);
        for (b, (g, w)) in got.iter().zip(want).enumerate() {
            assert!((g - w).abs() <= 1e-15, "d = {d:?}, Y_{b}: {g} against {w}");
        }
    }
}

#[test]
fn the_basis_is_orthonormal_on_the_sphere() {
    // A Fibonacci sphere of equal-area points: the mean of Y_a Y_b times 4 pi is the integral.
    let n = 40_000;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut gram = [[0.0f64; 16]; 16];
    for i in 0..n {
        let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = golden * i as f64;
        let y = basis([r * phi.cos(), r * phi.sin(), z]);
        for a in 0..16 {
            for b in 0..16 {
                gram[a][b] += y[a] * y[b];
            }
        }
    }
    let weight = 4.0 * std::f64::consts::PI / n as f64;
    for (a, row) in gram.iter().enumerate() {
        for (b, v) in row.iter().enumerate() {
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((v * weight - want).abs() < 1e-3, "<Y_{a}, Y_{b}> = {}", v * weight);
        }
    }
}

#[test]
fn degree_0_is_the_sigmoid_of_c0_times_the_coefficient_whatever_the_view() {
    let op = ShColor::new(0).unwrap();
    let k = uniform(1, 1, 3, 6.0);
    let n = 500;
    let coeffs = Array2::from_shape_fn((n, 3), |(_, c)| k[[0, c]]);
    let color = op.evaluate(coeffs.view(), directions(2, n).view()).unwrap();
    for c in 0..3 {
        let want = sigmoid(C0 * k[[0, c]]);
        assert!(
            (color[[0, c]] - want).abs() <= 2e-16,
            "{} against {want}",
            color[[0, c]]
        );
        assert!(color.column(c).iter().all(|&v| v == color[[0, c]]), "view dependent");
    }
}

/// `sum(w * color)` and its gradient for the coefficients, fused or through the twin.
fn run<F: Float>(
    op: &ShColor,
    fused: bool,
    coeffs: &Array2<F>,
    dirs: &Array2<F>,
    w: &Array2<F>,
) -> (Array2<F>, Array2<F>) {
    let mut tape = Tape::<F>::new();
    let c = tape.param(coeffs.clone());
    let d = tape.constant(dirs.clone());
    let color = if fused {
        op.apply(&mut tape, c, d).unwrap()
    } else {
        twin::sh_color(&mut tape, op, c, d).unwrap()
    };
    let wv = tape.constant(w.clone());
    let p = tape.mul(color, wv).unwrap();
    let loss = tape.sum(p).unwrap();
    let grads = tape.backward(loss).unwrap();
    let value = tape.value(color).unwrap().to_owned().into_dimensionality().unwrap();
    let grad = grads.get(c).unwrap().to_owned().into_dimensionality().unwrap();
    (value, grad)
}

/// The largest `|a - b|`; values are in [0, 1] and gradients below 1 here.
fn max_diff<F: Float>(a: &Array2<F>, b: &Array2<F>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.as_f64() - y.as_f64()).abs())
        .fold(0.0, f64::max)
}

fn fused_matches_twin<F: Float>(tol: f64) {
    for degree in 0..=3 {
        let op = ShColor::new(degree).unwrap();
        let n = 2 * 1024 + 37;
        // The sums' spread is then the same for every degree (the mean of sum_b Y_b^2 is B / 4 pi).
        let scale = 8.0 / (op.basis_count() as f64).sqrt();
        let coeffs = uniform(10 + degree as u64, n, op.coefficient_count(), scale).mapv(F::lit);
        let dirs = directions(20 + degree as u64, n).mapv(F::lit);
        let w = uniform(30, n, 3, 1.0).mapv(F::lit);
        let (v_fused, g_fused) = run(&op, true, &coeffs, &dirs, &w);
        let (v_twin, g_twin) = run(&op, false, &coeffs, &dirs, &w);
        let (dv, dg) = (max_diff(&v_fused, &v_twin), max_diff(&g_fused, &g_twin));
        assert!(dv <= tol, "{} degree {degree}: colour differs by {dv:e}", F::NAME);
        assert!(dg <= tol, "{} degree {degree}: gradient differs by {dg:e}", F::NAME);
        // Something to agree on: colours spread over (0, 1), gradients not all zero.
        assert!(v_fused.iter().any(|v| v.as_f64() < 0.2) && v_fused.iter().any(|v| v.as_f64() > 0.8));
        assert!(g_fused.iter().any(|g| g.as_f64().abs() > 1e-2));
        // The tape's backward is the stateless vjp, bit for bit, and evaluate is the forward.
        assert_eq!(op.evaluate(coeffs.view(), dirs.view()).unwrap(), v_fused);
        assert_eq!(op.vjp(coeffs.view(), dirs.view(), w.view()).unwrap(), g_fused);
    }
}

#[test]
fn the_fused_op_matches_its_taped_twin_for_every_degree() {
    fused_matches_twin::<f64>(1e-12);
    fused_matches_twin::<f32>(1e-6);
}

#[test]
fn the_fused_op_and_its_twin_pass_gradcheck_in_f64() {
    for degree in 0..=3 {
        let op = ShColor::new(degree).unwrap();
        let n = 5;
        let coeffs = uniform(40 + degree as u64, n, op.coefficient_count(), 1.5).into_dyn();
        let dirs = directions(41, n);
        let w = uniform(42, n, 3, 1.0);
        for fused in [true, false] {
            let f = |t: &mut Tape<f64>, v: &[Var]| -> Result<Var, TapeError> {
                let d = t.constant(dirs.clone());
                let color = if fused {
                    op.apply(t, v[0], d)?
                } else {
                    twin::sh_color(t, &op, v[0], d)?
                };
                let w = t.constant(w.clone());
                let p = t.mul(color, w)?;
                t.sum(p)
            };
            let report = gradcheck(f, std::slice::from_ref(&coeffs), &GradcheckOptions::default()).unwrap();
            assert!(report.passes(), "degree {degree}, fused {fused}: {report}");
        }
    }
}

fn bitwise_on_thread_counts<F: Float>() {
    let op = ShColor::new(3).unwrap();
    let n = 3 * 1024 + 17;
    let coeffs = uniform(50, n, 48, 3.0).mapv(F::lit);
    let dirs = directions(51, n).mapv(F::lit);
    let g = uniform(52, n, 3, 1.0).mapv(F::lit);
    let bits = |a: &Array2<F>| a.iter().map(|v| v.as_f64().to_bits()).collect::<Vec<u64>>();
    let at = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let color = op.evaluate(coeffs.view(), dirs.view()).unwrap();
            let grad = op.vjp(coeffs.view(), dirs.view(), g.view()).unwrap();
            (bits(&color), bits(&grad))
        })
    };
    let one = at(1);
    assert_eq!(at(2), one, "{}", F::NAME);
    assert_eq!(at(3), one, "{}", F::NAME);
}

#[test]
fn results_are_bitwise_the_same_on_1_2_and_3_threads() {
    bitwise_on_thread_counts::<f32>();
    bitwise_on_thread_counts::<f64>();
}

#[test]
fn bad_input_is_a_typed_error_naming_the_row() {
    assert_eq!(
        ShColor::new(4).unwrap_err(),
        OpsError::Config {
            op: Op::ShColor,
            what: "degree",
            value: 4.0,
            rule: "must be 0, 1, 2 or 3"
        }
    );
    assert_eq!(ShColor::new(3).unwrap().coefficient_count(), 48);
    let op = ShColor::new(2).unwrap();
    let n = 2000;
    let coeffs = uniform(60, n, 27, 1.0);
    let dirs = directions(61, n);
    assert!(op.evaluate(coeffs.view(), dirs.view()).is_ok());

    let shape_of = |e: OpsError| match e {
        OpsError::Shape {
            op: Op::ShColor, what, ..
        } => what,
        other => panic!("{other:?}"),
    };
    // Coefficients of another degree, directions not [n, 3], a differing n.
    let e = op.evaluate(uniform(62, n, 12, 1.0).view(), dirs.view()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "sh_color: coefficients: expected [n, 27] (3 channels of 9 for degree 2), got [2000, 12]"
    );
    assert_eq!(
        shape_of(
            op.evaluate(coeffs.view(), Array2::<f64>::zeros((n, 4)).view())
                .unwrap_err()
        ),
        "directions"
    );
    assert_eq!(
        shape_of(
            op.evaluate(coeffs.view(), dirs.slice(ndarray::s![1.., ..]))
                .unwrap_err()
        ),
        "directions"
    );
    assert_eq!(
        shape_of(
            op.vjp(coeffs.view(), dirs.view(), Array2::zeros((n, 2)).view())
                .unwrap_err()
        ),
        "color gradient"
    );

    // Non-finite values: the first row at fault, its direction before its coefficients.
    let mut c = coeffs.clone();
    c[[1500, 20]] = f64::NAN;
    c[[1700, 0]] = f64::INFINITY;
    let mut d = dirs.clone();
    d[[1700, 1]] = f64::NEG_INFINITY;
    assert!(matches!(
        op.evaluate(c.view(), dirs.view()).unwrap_err(),
        OpsError::Domain { op: Op::ShColor, at: At::Entry { row: 1500, column: 20 }, what, value, .. }
            if what == "coefficient" && value.is_nan()
    ));
    assert_eq!(
        op.evaluate(coeffs.view(), d.view()).unwrap_err(),
        OpsError::Domain {
            op: Op::ShColor,
            at: At::Entry { row: 1700, column: 1 },
            what: "direction".into(),
            value: f64::NEG_INFINITY,
            rule: "must be finite"
        }
    );
    // Not unit: 1.01 long is rejected, 1.0005 long accepted.
    let mut d = dirs.clone();
    d.row_mut(1234).mapv_inplace(|v| v * 1.01);
    d.row_mut(77).mapv_inplace(|v| v * 1.0005);
    let e = op.evaluate(coeffs.view(), d.view()).unwrap_err();
    match e {
        OpsError::NotUnit {
            op: Op::ShColor,
            row,
            norm,
        } => assert!(row == 1234 && (norm - 1.01).abs() < 1e-12, "{e}"),
        other => panic!("{other:?}"),
    }
    assert!(e
        .to_string()
        .starts_with("sh_color: direction at row 1234 has length 1.01"));
    let mut zero = dirs.clone();
    zero.row_mut(5).fill(0.0);
    assert_eq!(
        op.vjp(coeffs.view(), zero.view(), Array2::zeros((n, 3)).view())
            .unwrap_err(),
        OpsError::NotUnit {
            op: Op::ShColor,
            row: 5,
            norm: 0.0
        }
    );

    // Through a tape, fused or twin: the error arrives whole and nothing is recorded.
    let mut tape = Tape::<f64>::new();
    let good_c = tape.param(coeffs.clone());
    let bad_c = tape.param(c);
    let good_d = tape.constant(dirs.clone());
    let bad_d = tape.constant(d);
    let three_d = tape.param(Array3::<f64>::zeros((n, 3, 9)));
    let before = tape.len();
    for fused in [true, false] {
        let mut apply = |c, d| {
            if fused {
                op.apply(&mut tape, c, d)
            } else {
                twin::sh_color(&mut tape, &op, c, d)
            }
        };
        let e = apply(bad_c, good_d).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::Domain {
                    op: Op::ShColor,
                    at: At::Entry { row: 1500, .. },
                    ..
                })
            ),
            "{e}"
        );
        let e = apply(good_c, bad_d).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::NotUnit {
                    op: Op::ShColor,
                    row: 1234,
                    ..
                })
            ),
            "{e}"
        );
        let e = apply(three_d, good_d).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::Shape {
                    op: Op::ShColor,
                    what: "coefficients",
                    ..
                })
            ),
            "{e}"
        );
        let e = apply(good_c, good_c).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::Shape {
                    op: Op::ShColor,
                    what: "directions",
                    ..
                })
            ),
            "{e}"
        );
    }
    assert_eq!(tape.len(), before);
    let e = ShColor::new(7).map_err(TapeError::from).unwrap_err();
    assert_eq!(e.to_string(), "sh_color: degree is 7 (must be 0, 1, 2 or 3)");
    assert_eq!(e.downcast_ref::<OpsError>().map(OpsError::op), Some(Op::ShColor));
}
