//! `select`: element-wise choice between two inputs by a fixed boolean mask (numpy's `where`).
//!
//! The mask is configuration, not a tape value. The inactive branch gets an exact zero
//! gradient, and with the strong-zero rule nothing upstream of it turns that into NaN:
//! `select(x > 0, sqrt(x), x)` is finite at `x = 0`.

use ndarray::{ArrayD, ArrayViewD, IxDyn, Zip};

use crate::broadcast::{broadcast_shape, sum_to_shape};
use crate::buffer::scratch;
use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// `out = if mask { a } else { b }`, with `a` and `b` broadcast to the mask's shape.
#[derive(Debug, Clone)]
pub struct Select(pub ArrayD<bool>);

impl<F: Float> CustomOp<F> for Select {
    type Saved = ();
    fn name(&self) -> &'static str {
        "select"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [a, b] = inputs else {
            return Err(OpError::InvalidArgument(format!(
                "takes 2 inputs, got {}",
                inputs.len()
            )));
        };
        let shape = self.0.shape();
        for x in [a, b] {
            if broadcast_shape(x.shape(), shape)? != shape {
                return Err(OpError::ShapeMismatch {
                    lhs: shape.to_vec(),
                    rhs: x.shape().to_vec(),
                });
            }
        }
        if let Some(y) = select_flat(&self.0, a, b) {
            return Ok((vec![y], ()));
        }
        let (a, b) = (a.broadcast(IxDyn(shape)), b.broadcast(IxDyn(shape)));
        let (Some(a), Some(b)) = (a, b) else {
            return Err(OpError::InvalidArgument("operands do not broadcast to the mask".into()));
        };
        let y = Zip::from(&self.0)
            .and(&a)
            .and(&b)
            .map_collect(|&m, &a, &b| if m { a } else { b });
        Ok((vec![y], ()))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else {
            return Ok(vec![None, None]);
        };
        let branch = |k: usize, on: bool| {
            ctx.needs_input_grad(k).then(|| {
                let pick = |m: bool, g: F| if m == on { g } else { F::zero() };
                let full = match (self.0.as_slice(), g.as_slice()) {
                    (Some(mask), Some(gs)) if self.0.shape() == g.shape() => {
                        let mut out = scratch(gs.len());
                        for ((o, &m), &g) in out.iter_mut().zip(mask).zip(gs) {
                            *o = pick(m, g);
                        }
                        ArrayD::from_shape_vec(g.raw_dim(), out).ok()
                    }
                    _ => None,
                };
                let full = full.unwrap_or_else(|| Zip::from(&self.0).and(g).map_collect(|&m, &g| pick(m, g)));
                sum_to_shape(full, ctx.input(k).shape())
            })
        };
        Ok(vec![branch(0, true), branch(1, false)])
    }
}

/// One operand of a flat select: its elements in the mask's order, or one value for all.
enum Operand<'a, F> {
    Each(&'a [F]),
    One(F),
}

impl<'a, F: Float> Operand<'a, F> {
    /// `x` as a flat operand for a mask of shape `shape`: contiguous in that shape, or a single
    /// element; `None` for other broadcasts.
    fn of(x: &'a ArrayViewD<'_, F>, shape: &[usize]) -> Option<Self> {
        if x.len() == 1 {
            return x.iter().next().map(|&v| Operand::One(v));
        }
        (x.shape() == shape).then(|| x.as_slice().map(Operand::Each)).flatten()
    }

    #[inline(always)]
    fn at(&self, i: usize) -> F {
        match self {
            Operand::Each(v) => v[i],
            Operand::One(v) => *v,
        }
    }
}

/// The select as one loop over flat memory, when the mask is contiguous and each operand is
/// either contiguous in its shape or a single value (the common cases); `None` otherwise.
/// The same values as the general path, which iterates an `IxDyn` view index by index.
fn select_flat<F: Float>(mask: &ArrayD<bool>, a: &ArrayViewD<'_, F>, b: &ArrayViewD<'_, F>) -> Option<ArrayD<F>> {
    let m = mask.as_slice()?;
    let (a, b) = (Operand::of(a, mask.shape())?, Operand::of(b, mask.shape())?);
    let mut out = scratch(m.len());
    for (i, (o, &m)) in out.iter_mut().zip(m).enumerate() {
        *o = if m { a.at(i) } else { b.at(i) };
    }
    ArrayD::from_shape_vec(mask.raw_dim(), out).ok()
}

impl<F: Float> Tape<F> {
    /// `mask ? a : b` element-wise; `a` and `b` must broadcast to the mask's shape.
    pub fn select(&mut self, mask: ArrayD<bool>, a: Var, b: Var) -> Result<Var> {
        self.apply1(Select(mask), &[a, b])
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::assert_gradcheck;
    use crate::{Tape, TapeError};
    use ndarray::{arr1, ArrayD, Dimension, IxDyn, ShapeBuilder};
    use proptest::prelude::*;

    #[test]
    fn masked_sqrt_is_finite_at_zero() {
        // y = sum(select(x > 0, sqrt(x), x)); dy/dx = 1/(2 sqrt x) for x > 0, else 1.
        let mut t = Tape::<f64>::new();
        let xv = arr1(&[-1.0, 0.0, 4.0]);
        let x = t.param(xv.clone());
        let s = t.sqrt(x).unwrap(); // NaN at -1, and an infinite derivative at 0
        let mask = xv.mapv(|v| v > 0.0).into_dyn();
        let y = t.select(mask, s, x).unwrap();
        assert_eq!(
            t.value(y).unwrap().iter().copied().collect::<Vec<_>>(),
            vec![-1.0, 0.0, 2.0]
        );
        let total = t.sum(y).unwrap();
        let g = t.backward(total).unwrap();
        assert_eq!(
            g.get(x).unwrap().iter().copied().collect::<Vec<_>>(),
            vec![1.0, 1.0, 0.25]
        );
    }

    #[test]
    fn broadcasting_and_errors() {
        let mut t = Tape::<f32>::new();
        let a = t.param(arr1(&[1.0f32, 2.0]));
        let b = t.scalar(9.0);
        let y = t.select(arr1(&[true, false]).into_dyn(), a, b).unwrap();
        assert_eq!(t.value(y).unwrap().iter().copied().collect::<Vec<_>>(), vec![1.0, 9.0]);
        let c = t.param(arr1(&[1.0f32, 2.0, 3.0]));
        assert!(matches!(
            t.select(arr1(&[true, false]).into_dyn(), c, b),
            Err(TapeError::ShapeMismatch { op: "select", .. })
        ));
    }

    proptest! {
        // Forward and both gradients against ndarray's broadcast and element-wise choice, with
        // each operand of the mask's shape (row- or column-major), a single value, or a row
        // broadcast along the last axis (the general path).
        #[test]
        fn select_matches_an_oracle_for_every_operand_kind(
            shape in proptest::collection::vec(1usize..4, 1..4),
            bits in proptest::collection::vec(any::<bool>(), 64),
            kinds in (0usize..4, 0usize..4),
        ) {
            let mask = ArrayD::from_shape_fn(IxDyn(&shape), |ix| {
                bits[(0..ix.ndim()).fold(0, |acc, k| acc * 4 + ix[k]) % 64]
            });
            let operand = |kind: usize, base: f64| -> ArrayD<f64> {
                let full = ArrayD::from_shape_fn(IxDyn(&shape), |ix| {
                    base + (0..ix.ndim()).fold(0.0, |acc, k| acc * 4.0 + ix[k] as f64)
                });
                match kind {
                    0 => full,
                    1 => {
                        let mut f = ArrayD::zeros(IxDyn(&shape).f());
                        f.assign(&full);
                        f
                    }
                    2 => ArrayD::from_elem(IxDyn(&[]), base),
                    _ => ArrayD::from_shape_fn(IxDyn(&shape[shape.len() - 1..]), |ix| base + ix[0] as f64),
                }
            };
            let (a, b) = (operand(kinds.0, 100.0), operand(kinds.1, -100.0));
            let (ab, bb) = (a.broadcast(IxDyn(&shape)).unwrap(), b.broadcast(IxDyn(&shape)).unwrap());
            let want = ndarray::Zip::from(&mask).and(&ab).and(&bb).map_collect(|&m, &a, &b| if m { a } else { b });
            let upstream = ArrayD::from_shape_fn(IxDyn(&shape), |ix| 1.0 + ix[0] as f64);
            let mut want_a = ArrayD::<f64>::zeros(a.raw_dim());
            let mut want_b = ArrayD::<f64>::zeros(b.raw_dim());
            for (ix, &m) in mask.indexed_iter() {
                let g = upstream[&ix];
                let (target, full) = if m { (&mut want_a, &a) } else { (&mut want_b, &b) };
                let from: Vec<usize> = (0..full.ndim()).map(|k| {
                    let axis = k + shape.len() - full.ndim();
                    if full.shape()[k] == 1 { 0 } else { ix[axis] }
                }).collect();
                target[IxDyn(&from)] += g;
            }
            let mut t = Tape::<f64>::new();
            let (av, bv) = (t.param(a), t.param(b));
            let y = t.select(mask, av, bv).unwrap();
            prop_assert_eq!(&t.value(y).unwrap().to_owned(), &want);
            let g = t.backward_with(y, upstream).unwrap();
            prop_assert_eq!(&g.get(av).unwrap().to_owned(), &want_a);
            prop_assert_eq!(&g.get(bv).unwrap().to_owned(), &want_b);
        }
    }

    #[test]
    fn gradcheck_select() {
        let a = ArrayD::from_shape_vec(vec![2, 2], vec![0.3, -0.7, 1.3, 2.1]).unwrap();
        let b = ArrayD::from_shape_vec(vec![2], vec![0.5, 1.5]).unwrap();
        let mask = ArrayD::from_shape_vec(vec![2, 2], vec![true, false, false, true]).unwrap();
        assert_gradcheck("select", &[a, b], move |t, v| {
            let sq = t.square(v[0])?;
            t.select(mask.clone(), sq, v[1])
        });
    }
}
