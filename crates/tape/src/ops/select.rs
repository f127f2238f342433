//! `select`: element-wise choice between two inputs by a fixed boolean mask (numpy's `where`).
//!
//! The mask is configuration, not a tape value. The inactive branch gets an exact zero
//! gradient, and with the strong-zero rule nothing upstream of it turns that into NaN:
//! `select(x > 0, sqrt(x), x)` is finite at `x = 0`.

use ndarray::{ArrayD, ArrayViewD, IxDyn, Zip};

use crate::broadcast::{broadcast_shape, sum_to_shape};
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
                let full = Zip::from(&self.0)
                    .and(g)
                    .map_collect(|&m, &g| if m == on { g } else { F::zero() });
                sum_to_shape(full, ctx.input(k).shape())
            })
        };
        Ok(vec![branch(0, true), branch(1, false)])
    }
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
    use ndarray::{arr1, ArrayD};

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
