//! Broadcasting: the shape rule, and the one place where a broadcast is undone in backward.

use ndarray::{ArrayD, Axis, Dimension, Zip};

use crate::buffer::zeroed;
use crate::error::OpError;
use crate::float::Float;
use crate::pool;

/// The numpy broadcast of two shapes: aligned from the right, each pair equal or one of them 1.
pub fn broadcast_shape(a: &[usize], b: &[usize]) -> Result<Vec<usize>, OpError> {
    let n = a.len().max(b.len());
    let dim = |s: &[usize], k: usize| if k + s.len() >= n { s[k + s.len() - n] } else { 1 };
    (0..n)
        .map(|k| match (dim(a, k), dim(b, k)) {
            (x, y) if x == y => Ok(x),
            (1, y) => Ok(y),
            (x, 1) => Ok(x),
            _ => Err(OpError::ShapeMismatch {
                lhs: a.to_vec(),
                rhs: b.to_vec(),
            }),
        })
        .collect()
}

/// Sums a gradient of a broadcast result back to the shape of the operand that was broadcast.
///
/// Leading axes the operand did not have are summed away; axes where the operand had size 1
/// are summed and kept. `shape` must be broadcastable to `g`'s shape.
pub fn sum_to_shape<F: Float>(g: ArrayD<F>, shape: &[usize]) -> ArrayD<F> {
    if g.shape() == shape {
        return g;
    }
    let mut g = g;
    while g.ndim() > shape.len() {
        g = sum_axis(g, 0).remove_axis(Axis(0));
    }
    for (k, &s) in shape.iter().enumerate() {
        if s == 1 && g.shape()[k] != 1 {
            g = sum_axis(g, k);
        }
    }
    g
}

/// `g` summed along `axis`, kept as an axis of length 1, in a [`zeroed`] buffer (from the
/// tape's pool inside a backward); `g`'s own buffer goes back to that pool.
fn sum_axis<F: Float>(g: ArrayD<F>, axis: usize) -> ArrayD<F> {
    let mut dim = g.raw_dim();
    dim[axis] = 1;
    let len = dim.size();
    let Ok(mut out) = ArrayD::from_shape_vec(dim, zeroed(len)) else {
        return g.sum_axis(Axis(axis)).insert_axis(Axis(axis));
    };
    match (g.as_slice(), out.as_slice_mut()) {
        // Row-major: each index of the axes before `axis` owns `len * inner` consecutive
        // values, summed lane by lane into its `inner` outputs, in the same order as below.
        (Some(gs), Some(sums)) if g.shape()[axis + 1..].iter().product::<usize>() == 1 => {
            // The last axis with data (`[n, c]` to `[n, 1]`): runs of `len` values to one sum.
            let len = g.shape()[axis];
            for (a, run) in sums.iter_mut().zip(gs.chunks_exact(len.max(1))) {
                *a = run.iter().fold(*a, |a, &x| a + x);
            }
        }
        (Some(gs), Some(sums)) => {
            let (len, inner) = (g.shape()[axis], g.shape()[axis + 1..].iter().product::<usize>());
            for (sums, block) in sums
                .chunks_exact_mut(inner.max(1))
                .zip(gs.chunks_exact((len * inner).max(1)))
            {
                for lane in block.chunks_exact(inner.max(1)) {
                    for (a, &x) in sums.iter_mut().zip(lane) {
                        *a += x;
                    }
                }
            }
        }
        _ => {
            let mut acc = out.index_axis_mut(Axis(axis), 0);
            for lane in g.axis_iter(Axis(axis)) {
                Zip::from(&mut acc).and(&lane).for_each(|a, &x| *a += x);
            }
        }
    }
    pool::give(g.into_raw_vec_and_offset().0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{ArrayD, Dimension, IxDyn, ShapeBuilder};
    use proptest::prelude::*;

    #[test]
    fn shapes_follow_numpy() {
        assert_eq!(broadcast_shape(&[3, 1], &[4]).unwrap(), vec![3, 4]);
        assert_eq!(broadcast_shape(&[], &[2, 5]).unwrap(), vec![2, 5]);
        assert_eq!(broadcast_shape(&[2, 1, 3], &[5, 1]).unwrap(), vec![2, 5, 3]);
        assert!(matches!(
            broadcast_shape(&[3], &[4]),
            Err(OpError::ShapeMismatch { .. })
        ));
    }

    /// A shape that `s` broadcasts to: `extra` leading axes, and each axis of length 1 in `s`
    /// stretched to its entry of `stretch`.
    fn stretched(s: &[usize], extra: &[usize], stretch: &[usize]) -> Vec<usize> {
        extra
            .iter()
            .copied()
            .chain(s.iter().zip(stretch).map(|(&d, &k)| if d == 1 { k } else { d }))
            .collect()
    }

    proptest! {
        // sum_to_shape(ones(broadcast), s) counts how many broadcast elements each operand
        // element stands for: the product of the broadcast sizes it was stretched over.
        #[test]
        fn sum_to_shape_counts_broadcast_copies(
            s in proptest::collection::vec(prop_oneof![Just(1usize), 2usize..4], 0..4),
            extra in proptest::collection::vec(1usize..4, 0..3),
            stretch in proptest::collection::vec(1usize..4, 4),
        ) {
            let big = stretched(&s, &extra, &stretch);
            let g = ArrayD::<f64>::ones(IxDyn(&big));
            let r = sum_to_shape(g, &s);
            prop_assert_eq!(r.shape(), s.as_slice());
            let copies: usize = big.iter().product::<usize>() / s.iter().product::<usize>().max(1);
            let all_equal = r.iter().all(|&v| v == copies as f64);
            prop_assert!(all_equal || r.is_empty());
        }

        // Distinct integer values (exact sums in any order) against a brute-force oracle that
        // adds every element of `g` to the operand element it was broadcast from, for a
        // row-major `g` (the flat path) and for the same values in column-major memory (the
        // general path).
        #[test]
        fn sum_to_shape_matches_a_brute_force_oracle(
            s in proptest::collection::vec(prop_oneof![Just(1usize), 2usize..4], 0..4),
            extra in proptest::collection::vec(1usize..4, 0..3),
            stretch in proptest::collection::vec(1usize..4, 4),
        ) {
            let big = stretched(&s, &extra, &stretch);
            let g = ArrayD::<f64>::from_shape_fn(IxDyn(&big), |ix| {
                (0..ix.ndim()).fold(0.0, |acc, k| acc * 7.0 + ix[k] as f64 + 1.0)
            });
            let mut want = ArrayD::<f64>::zeros(IxDyn(&s));
            for (ix, &v) in g.indexed_iter() {
                let from: Vec<usize> = (0..s.len())
                    .map(|k| if s[k] == 1 { 0 } else { ix[k + big.len() - s.len()] })
                    .collect();
                want[IxDyn(&from)] += v;
            }
            prop_assert_eq!(&sum_to_shape(g.clone(), &s), &want);
            // The same logical array in column-major memory.
            let mut column_major = ArrayD::<f64>::zeros(IxDyn(&big).f());
            column_major.assign(&g);
            prop_assert_eq!(&sum_to_shape(column_major, &s), &want);
        }
    }
}
