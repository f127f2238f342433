//! Reductions: `sum` and `mean` over everything (to a 0-d value), `sum_axis` over one axis.
//! Their backward broadcasts the upstream gradient back over what was reduced.

use ndarray::{ArrayD, ArrayViewD, Axis, IxDyn};

use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// Which reduction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reduce {
    /// Sum of all elements, a 0-d output; derivative 1 for each element.
    Sum,
    /// Mean of all elements, a 0-d output; derivative 1/n. Errors on an empty input.
    Mean,
    /// Sum over one axis, which is removed; derivative 1.
    SumAxis(usize),
}

impl<F: Float> CustomOp<F> for Reduce {
    type Saved = ();

    fn name(&self) -> &'static str {
        match self {
            Reduce::Sum => "sum",
            Reduce::Mean => "mean",
            Reduce::SumAxis(_) => "sum_axis",
        }
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [x] = inputs else {
            return Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len())));
        };
        let y = match *self {
            Reduce::Sum => ArrayD::from_elem(IxDyn(&[]), x.sum()),
            Reduce::Mean if x.is_empty() => return Err(OpError::InvalidArgument("mean of an empty array".into())),
            Reduce::Mean => ArrayD::from_elem(IxDyn(&[]), x.sum() / F::lit(x.len() as f64)),
            Reduce::SumAxis(k) if k >= x.ndim() => {
                return Err(OpError::InvalidArgument(format!(
                    "axis {k} out of range for shape {:?}",
                    x.shape()
                )))
            }
            Reduce::SumAxis(k) => x.sum_axis(Axis(k)),
        };
        Ok((vec![y], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        let x = ctx.input(0);
        let shape = IxDyn(x.shape());
        let spread = |g: ArrayViewD<'_, F>| {
            g.broadcast(x.shape())
                .map(|b| b.to_owned())
                .ok_or_else(|| OpError::ShapeMismatch {
                    lhs: x.shape().to_vec(),
                    rhs: g.shape().to_vec(),
                })
        };
        // The 0-d upstream value of a whole reduction, filled in one contiguous pass: copying a
        // broadcast view of dynamic dimension goes index by index, several times slower.
        let whole = || match g.iter().next() {
            Some(&v) if g.len() == 1 => Ok(v),
            _ => Err(OpError::ShapeMismatch {
                lhs: Vec::new(),
                rhs: g.shape().to_vec(),
            }),
        };
        let gx = match *self {
            Reduce::Sum => ArrayD::from_elem(shape, whole()?),
            Reduce::Mean => ArrayD::from_elem(shape, whole()? / F::lit(x.len() as f64)),
            Reduce::SumAxis(k) => spread(g.view().insert_axis(Axis(k)))?,
        };
        Ok(vec![Some(gx)])
    }
}

impl<F: Float> Tape<F> {
    /// Sum of all elements, as a 0-d value.
    pub fn sum(&mut self, x: Var) -> Result<Var> {
        self.apply1(Reduce::Sum, &[x])
    }
    /// Mean of all elements, as a 0-d value; errors on an empty input.
    pub fn mean(&mut self, x: Var) -> Result<Var> {
        self.apply1(Reduce::Mean, &[x])
    }
    /// Sum over `axis`, which is removed from the shape; errors if the axis does not exist.
    pub fn sum_axis(&mut self, x: Var, axis: usize) -> Result<Var> {
        self.apply1(Reduce::SumAxis(axis), &[x])
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{assert_gradcheck, values_close};
    use crate::{Tape, TapeError};
    use ndarray::{arr2, ArrayD, IxDyn};

    #[test]
    fn values_and_gradients() {
        let mut t = Tape::<f32>::new();
        let x = t.param(arr2(&[[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]]));
        let s = t.sum(x).unwrap();
        let m = t.mean(x).unwrap();
        let r = t.sum_axis(x, 1).unwrap();
        assert_eq!(t.value(s).unwrap().shape(), &[] as &[usize]);
        assert_eq!(t.value(s).unwrap()[[]], 21.0);
        assert_eq!(t.value(m).unwrap()[[]], 3.5);
        assert_eq!(t.value(r).unwrap().iter().copied().collect::<Vec<_>>(), vec![6.0, 15.0]);
        // d mean / dx = 1/6 for every element.
        let g = t.backward(m).unwrap();
        let gm: Vec<f64> = g.get(x).unwrap().iter().map(|&v| f64::from(v)).collect();
        values_close(
            "dmean",
            ArrayD::from_shape_vec(vec![6], gm).unwrap().view(),
            &[1.0 / 6.0; 6],
            1e-7,
        );
    }

    #[test]
    fn errors() {
        let mut t = Tape::<f64>::new();
        let e = t.param(ArrayD::zeros(IxDyn(&[0])));
        assert!(matches!(t.mean(e), Err(TapeError::InvalidArgument { op: "mean", .. })));
        let x = t.param(ArrayD::zeros(IxDyn(&[2])));
        assert!(matches!(
            t.sum_axis(x, 1),
            Err(TapeError::InvalidArgument { op: "sum_axis", .. })
        ));
        assert_eq!(t.len(), 2);
    }

    #[test]
    fn gradcheck_reductions() {
        let x = ArrayD::from_shape_vec(vec![2, 3], vec![0.3, -0.7, 1.3, 2.1, 0.9, -1.4]).unwrap();
        assert_gradcheck("sum", std::slice::from_ref(&x), |t, v| t.sum(v[0]));
        assert_gradcheck("mean", std::slice::from_ref(&x), |t, v| t.mean(v[0]));
        assert_gradcheck("sum_axis0", std::slice::from_ref(&x), |t, v| t.sum_axis(v[0], 0));
        assert_gradcheck("sum_axis1", &[x], |t, v| t.sum_axis(v[0], 1));
    }
}
