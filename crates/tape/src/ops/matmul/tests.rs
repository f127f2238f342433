use super::super::test_util::{assert_gradcheck, values_close};
use crate::{Tape, TapeError};
use ndarray::{arr1, arr2, Array2, ArrayD, IxDyn};
use rand::{Rng, SeedableRng};

#[test]
fn values_and_gradients_by_hand_in_f64_and_f32() {
    // [[1,2],[3,4],[5,6]] [[1,0,-1],[2,1,0]]: row r is (a_r1 + 2 a_r2, a_r2, -a_r1).
    let want = [5.0, 2.0, -1.0, 11.0, 4.0, -3.0, 17.0, 6.0, -5.0];
    // d sum(AB)/dA = 1 B^T: every row is B's row sums (0, 3); d/dB = A^T 1: row i is the sum
    // of A's column i (9 and 12) in every column.
    let (want_da, want_db) = ([0.0, 3.0, 0.0, 3.0, 0.0, 3.0], [9.0, 9.0, 9.0, 12.0, 12.0, 12.0]);
    let a = arr2(&[[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]);
    let b = arr2(&[[1.0, 0.0, -1.0], [2.0, 1.0, 0.0]]);
    let mut t = Tape::<f64>::new();
    let (av, bv) = (t.param(a.clone()), t.param(b.clone()));
    let c = t.matmul(av, bv).unwrap();
    assert_eq!(t.shape(c).unwrap(), &[3, 3]);
    values_close("ab", t.value(c).unwrap(), &want, 0.0);
    let s = t.sum(c).unwrap();
    let g = t.backward(s).unwrap();
    values_close("da", g.get(av).unwrap(), &want_da, 0.0);
    values_close("db", g.get(bv).unwrap(), &want_db, 0.0);
    let mut t = Tape::<f32>::new();
    let (av, bv) = (t.param(a.mapv(|v| v as f32)), t.param(b.mapv(|v| v as f32)));
    let c = t.matmul(av, bv).unwrap();
    let s = t.sum(c).unwrap();
    let g = t.backward(s).unwrap();
    let wide = |x: ndarray::ArrayViewD<'_, f32>| x.mapv(f64::from);
    values_close("ab f32", wide(t.value(c).unwrap()).view(), &want, 0.0);
    values_close("da f32", wide(g.get(av).unwrap()).view(), &want_da, 0.0);
    values_close("db f32", wide(g.get(bv).unwrap()).view(), &want_db, 0.0);
}

/// The textbook triple loop.
fn oracle(a: &Array2<f64>, b: &Array2<f64>) -> Array2<f64> {
    Array2::from_shape_fn((a.nrows(), b.ncols()), |(i, j)| {
        (0..a.ncols()).map(|k| a[[i, k]] * b[[k, j]]).sum()
    })
}

#[test]
fn agrees_with_a_triple_loop_for_contiguous_and_strided_inputs() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let a = Array2::from_shape_fn((7, 5), |_| rng.gen_range(-1.0..1.0));
    let b = Array2::from_shape_fn((5, 4), |_| rng.gen_range(-1.0..1.0));
    let want = oracle(&a, &b);
    // The same values in column-major layout: strided values on the tape.
    let column_major = |x: &Array2<f64>| x.t().as_standard_layout().into_owned().reversed_axes();
    for (a, b) in [(a.clone(), b.clone()), (column_major(&a), column_major(&b))] {
        let mut t = Tape::<f64>::new();
        let (av, bv) = (t.constant(a), t.constant(b));
        let c = t.matmul(av, bv).unwrap();
        let got = t.value(c).unwrap();
        assert!(
            got.iter().zip(want.iter()).all(|(g, w)| (g - w).abs() < 1e-14),
            "{got} vs {want}"
        );
    }
}

#[test]
fn gradcheck_matmul_alone_and_in_a_dense_layer() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(6);
    let mut random = |shape: &[usize]| ArrayD::from_shape_fn(IxDyn(shape), |_| rng.gen_range(-1.0..1.0));
    let (x, w, b) = (random(&[6, 3]), random(&[3, 4]), random(&[4]));
    assert_gradcheck("matmul", &[x.clone(), w.clone()], |t, v| t.matmul(v[0], v[1]));
    assert_gradcheck("tanh(x W + b)", &[x, w, b], |t, v| {
        let xw = t.matmul(v[0], v[1])?;
        let z = t.add(xw, v[2])?;
        t.tanh(z)
    });
}

#[test]
fn a_bias_broadcast_over_the_batch_gets_the_column_sums() {
    // (x W + b) with x W = [[1,2],[3,4],[5,6]] (W the identity) and b = (10, 20): every row
    // gets b; d sum(seed * (xW + b)) / db is the seed's column sums.
    let mut t = Tape::<f64>::new();
    let x = t.constant(arr2(&[[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]));
    let w = t.param(arr2(&[[1.0, 0.0], [0.0, 1.0]]));
    let b = t.param(arr1(&[10.0, 20.0]));
    let xw = t.matmul(x, w).unwrap();
    let z = t.add(xw, b).unwrap();
    values_close(
        "xW + b",
        t.value(z).unwrap(),
        &[11.0, 22.0, 13.0, 24.0, 15.0, 26.0],
        0.0,
    );
    let seed = arr2(&[[1.0, 0.5], [2.0, -1.0], [0.25, 3.0]]).into_dyn();
    let g = t.backward_with(z, seed).unwrap();
    values_close("db", g.get(b).unwrap(), &[3.25, 2.5], 0.0);
    // The constant x gets no gradient.
    assert!(g.get(x).is_none());
}

#[test]
fn empty_inner_dimension_gives_zeros() {
    let mut t = Tape::<f32>::new();
    let a = t.param(Array2::<f32>::zeros((2, 0)));
    let b = t.param(Array2::<f32>::zeros((0, 3)));
    let c = t.matmul(a, b).unwrap();
    assert_eq!(t.value(c).unwrap(), ArrayD::<f32>::zeros(IxDyn(&[2, 3])));
    let g = t.backward_with(c, ArrayD::ones(IxDyn(&[2, 3]))).unwrap();
    assert_eq!(g.get(a).unwrap().shape(), &[2, 0]);
    assert_eq!(g.get(b).unwrap().shape(), &[0, 3]);
}

#[test]
fn bad_shapes_are_named_and_leave_the_tape_unchanged() {
    let mut t = Tape::<f64>::new();
    let a = t.param(ArrayD::zeros(IxDyn(&[2, 3])));
    let v = t.param(ArrayD::zeros(IxDyn(&[3])));
    let before = t.stats();
    assert_eq!(
        t.matmul(a, a).unwrap_err(),
        TapeError::ShapeMismatch {
            op: "matmul",
            lhs: vec![2, 3],
            rhs: vec![2, 3]
        }
    );
    assert_eq!(
        t.matmul(a, v).unwrap_err().to_string(),
        "matmul: needs 2-D inputs, the right has shape [3]"
    );
    assert_eq!(
        t.matmul(v, a).unwrap_err().to_string(),
        "matmul: needs 2-D inputs, the left has shape [3]"
    );
    assert_eq!(t.stats(), before);
}
