//! The total-variation prior against a twin built from tape primitives, finite differences,
//! hand values, f32 accumulation and thread counts.

use fogray_ops::prior::TotalVariation;
use fogray_ops::{Op, OpsError};
use fogray_tape::{gradcheck, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{Array, ArrayD, Dimension, IxDyn};

fn grid(shape: &[usize]) -> ArrayD<f64> {
    Array::from_shape_fn(IxDyn(shape), |i| {
        let s: usize = i.slice().iter().enumerate().map(|(a, &v)| (a + 2) * v * v).sum();
        (s as f64 * 0.731).sin() * 3.0
    })
}

/// The prior from tape primitives: for each spatial axis, the grid without its first slab
/// minus the grid without its last, squared and summed; scaled by weight / terms.
fn twin(tape: &mut Tape<f64>, g: Var, weight: f64) -> Result<Var, TapeError> {
    let shape = tape.shape(g)?.to_vec();
    let spatial = shape.len() - 1;
    let mut total: Option<Var> = None;
    let mut terms = 0usize;
    for axis in 0..spatial {
        let n = shape[axis];
        if n < 2 {
            continue;
        }
        terms += shape.iter().product::<usize>() / n * (n - 1);
        let hi = tape.slice(g, axis, 1, n)?;
        let lo = tape.slice(g, axis, 0, n - 1)?;
        let d = tape.sub(hi, lo)?;
        let d = tape.square(d)?;
        let s = tape.sum(d)?;
        total = Some(match total {
            Some(t) => tape.add(t, s)?,
            None => s,
        });
    }
    let total = total.expect("a test grid with neighbours");
    tape.mul_scalar(total, weight / terms as f64)
}

#[test]
fn fused_matches_its_taped_twin_in_2d_and_3d() {
    for shape in [vec![5, 4, 3], vec![4, 5, 3, 2], vec![1, 6, 2, 4], vec![3, 1, 1, 1]] {
        let g0 = grid(&shape);
        let mut tape = Tape::<f64>::new();
        let g = tape.param(g0.clone());
        let tv = TotalVariation::new(0.37).unwrap();
        let fused = tv.apply(&mut tape, g).unwrap();
        let taped = twin(&mut tape, g, 0.37).unwrap();
        let (a, b) = (tape.value(fused).unwrap().sum(), tape.value(taped).unwrap().sum());
        assert!((a - b).abs() <= 1e-12 * b.abs(), "{shape:?}: {a} vs {b}");
        let ga = tape.backward(fused).unwrap().get(g).unwrap().to_owned();
        let gb = tape.backward(taped).unwrap().get(g).unwrap().to_owned();
        for (x, y) in ga.iter().zip(gb.iter()) {
            assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "{shape:?}: {x} vs {y}");
        }
    }
}

#[test]
fn gradient_agrees_with_finite_differences() {
    let tv = TotalVariation::new(1.3).unwrap();
    let f = move |t: &mut Tape<f64>, v: &[Var]| tv.apply(t, v[0]);
    let report = gradcheck(f, &[grid(&[3, 4, 2, 2])], &GradcheckOptions::default()).unwrap();
    assert!(report.passes(), "{report}");
}

#[test]
fn the_f32_sum_is_accumulated_in_f64() {
    // One difference of 4096 (squared 2^24) and a thousand of 1: in f32, 2^24 + 1 rounds to
    // 2^24, so a running f32 sum would stay at 2^24.
    let n = 1002;
    let values: Vec<f32> = (0..n)
        .map(|i| if i == 0 { 0.0 } else { 4096.0 + (i - 1) as f32 })
        .collect();
    let mut naive = 0f32;
    for w in values.windows(2) {
        naive += (w[1] - w[0]) * (w[1] - w[0]);
    }
    assert_eq!(naive, 16_777_216.0);
    let g = ArrayD::from_shape_vec(IxDyn(&[n, 1, 1, 1]), values).unwrap();
    let tv = TotalVariation::new(1.0).unwrap();
    let terms = (n - 1) as f64;
    assert_eq!(tv.value(&g.view()).unwrap() * terms, 16_777_216.0 + 1000.0);
}

#[test]
fn value_and_gradient_do_not_depend_on_the_thread_count() {
    let g = grid(&[7, 5, 6, 4]).mapv(|v| v as f32);
    let tv = TotalVariation::new(0.5).unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let v = tv.value(&g.view()).unwrap();
            let mut out = ArrayD::<f32>::zeros(g.shape());
            tv.gradient_into(&g.view(), 1.0, out.view_mut()).unwrap();
            (v.to_bits(), out.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
}

/// The gradient one node at a time, as the definition reads: `2 weight / terms` times the sum
/// over the node's neighbours n, in the order x+, x-, y+, y-, z+, z-, of `g - g[n]` in f64.
fn gradient_oracle(g: &ArrayD<f64>, weight: f64) -> Vec<f64> {
    let [nx, ny, nz, nc] = [g.shape()[0], g.shape()[1], g.shape()[2], g.shape()[3]];
    let terms = ((nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)) * nc;
    let factor = 2.0 * weight / terms as f64;
    let mut out = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                for c in 0..nc {
                    let v = g[[i, j, k, c]];
                    let mut acc = 0.0;
                    let neighbours = [
                        (i + 1 < nx).then(|| [i + 1, j, k]),
                        (i > 0).then(|| [i.wrapping_sub(1), j, k]),
                        (j + 1 < ny).then(|| [i, j + 1, k]),
                        (j > 0).then(|| [i, j.wrapping_sub(1), k]),
                        (k + 1 < nz).then(|| [i, j, k + 1]),
                        (k > 0).then(|| [i, j, k.wrapping_sub(1)]),
                    ];
                    for [a, b, d] in neighbours.into_iter().flatten() {
                        acc += v - g[[a, b, d, c]];
                    }
                    out.push(factor * acc);
                }
            }
        }
    }
    out
}

#[test]
fn the_gradient_is_bitwise_the_per_node_definition() {
    // Rows of odd lengths (z * channels = 15 and 7) exercise the vector loops' remainders. In
    // f64 the order of a node's six terms shows in the last bits (from an f32 grid it rarely
    // does: the differences of f32 values add exactly in f64 unless far apart in magnitude).
    let tv = TotalVariation::new(0.37).unwrap();
    for shape in [[5, 4, 5, 3], [3, 6, 7, 1], [4, 3, 1, 2]] {
        let g = grid(&shape);
        let mut out = ArrayD::<f64>::zeros(g.shape());
        tv.gradient_into(&g.view(), 1.0, out.view_mut()).unwrap();
        let want: Vec<u64> = gradient_oracle(&g, 0.37).iter().map(|v| v.to_bits()).collect();
        assert_eq!(
            out.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            want,
            "f64 {shape:?}"
        );

        let g32 = g.mapv(|v| v as f32);
        let mut out = ArrayD::<f32>::zeros(g.shape());
        tv.gradient_into(&g32.view(), 1.0, out.view_mut()).unwrap();
        let want: Vec<u32> = gradient_oracle(&g32.mapv(f64::from), 0.37)
            .iter()
            .map(|&v| (v as f32).to_bits())
            .collect();
        assert_eq!(
            out.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            want,
            "f32 {shape:?}"
        );
    }
}

#[test]
fn a_reused_tape_overwrites_its_pooled_gradient_buffer() {
    // The backward writes into a buffer of the tape's pool, which holds the step before's
    // gradient: every value must be overwritten. 32^3 f64 nodes are large enough to be pooled.
    let tv = TotalVariation::new(0.37).unwrap();
    let shape = [32, 32, 32, 1];
    let (first, second) = (grid(&shape).mapv(|v| v * 1e6 + 7.0), grid(&shape));
    let want: Vec<u64> = gradient_oracle(&second, 0.37).iter().map(|v| v.to_bits()).collect();
    let mut tape = Tape::<f64>::new();
    for (step, values) in [first, second].into_iter().enumerate() {
        let g = tape.param(values);
        let prior = tv.apply(&mut tape, g).unwrap();
        let grads = tape.backward(prior).unwrap();
        let got: Vec<u64> = grads.get(g).unwrap().iter().map(|v| v.to_bits()).collect();
        if step == 1 {
            assert_eq!(got, want);
        }
        tape.clear();
        tape.recycle(grads);
    }
}

#[test]
fn a_grid_without_neighbours_has_no_prior() {
    let g = ArrayD::<f64>::from_elem(IxDyn(&[1, 1, 1, 3]), 5.0);
    let tv = TotalVariation::new(2.0).unwrap();
    assert_eq!(tv.value(&g.view()).unwrap(), 0.0);
    let mut out = ArrayD::from_elem(IxDyn(&[1, 1, 1, 3]), 9.0);
    tv.gradient_into(&g.view(), 1.0, out.view_mut()).unwrap();
    assert!(out.iter().all(|&v| v == 0.0));
}

#[test]
fn bad_input_is_refused_and_nothing_changes() {
    for w in [-1.0, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(
                TotalVariation::new(w),
                Err(OpsError::Config {
                    op: Op::TotalVariation,
                    what: "weight",
                    ..
                })
            ),
            "{w}"
        );
    }
    let tv = TotalVariation::new(1.0).unwrap();
    for shape in [vec![4, 3], vec![2, 2, 2, 2, 2]] {
        let g = ArrayD::<f64>::zeros(IxDyn(&shape));
        assert!(
            matches!(
                tv.value(&g.view()),
                Err(OpsError::Shape {
                    op: Op::TotalVariation,
                    ..
                })
            ),
            "{shape:?}"
        );
    }
    let g = grid(&[3, 3, 2]);
    let mut out = ArrayD::from_elem(IxDyn(&[3, 3, 3]), 7.0);
    assert!(matches!(
        tv.gradient_into(&g.view(), 1.0, out.view_mut()),
        Err(OpsError::Shape {
            op: Op::TotalVariation,
            ..
        })
    ));
    assert!(out.iter().all(|&v| v == 7.0));
    let mut tape = Tape::<f64>::new();
    let bad = tape.param(ArrayD::<f64>::zeros(IxDyn(&[4])));
    let before = tape.len();
    let err = tv.apply(&mut tape, bad).unwrap_err();
    assert_eq!(tape.len(), before);
    assert_eq!(
        err.downcast_ref::<OpsError>().map(OpsError::op),
        Some(Op::TotalVariation),
        "{err}"
    );
}
