//! Element-wise functions of two inputs, with numpy broadcasting.
//!
//! Broadcasting is undone in backward by the one shared helper
//! [`sum_to_shape`](crate::broadcast::sum_to_shape()). At ties `maximum` and `minimum` split the
//! gradient 0.5 / 0.5 between their inputs (as candle and tinygrad).

use ndarray::{ArrayD, ArrayViewD, IxDyn, Zip};

use super::strong_mul;
use crate::broadcast::{broadcast_shape, sum_to_shape};
use crate::buffer::{map1, map2};
use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// Which element-wise function of two inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinaryFn {
    /// `a + b`.
    Add,
    /// `a - b`.
    Sub,
    /// `a * b`.
    Mul,
    /// `a / b`.
    Div,
    /// `max(a, b)`.
    Maximum,
    /// `min(a, b)`.
    Minimum,
}

impl BinaryFn {
    fn name(self) -> &'static str {
        match self {
            BinaryFn::Add => "add",
            BinaryFn::Sub => "sub",
            BinaryFn::Mul => "mul",
            BinaryFn::Div => "div",
            BinaryFn::Maximum => "maximum",
            BinaryFn::Minimum => "minimum",
        }
    }

    /// Partial derivatives (d/da, d/db) at (a, b) with output y.
    fn df<F: Float>(self, a: F, b: F, y: F) -> (F, F) {
        let (one, zero, half) = (F::one(), F::zero(), F::lit(0.5));
        let pick = |first_wins: bool| {
            if a == b {
                (half, half)
            } else if first_wins {
                (one, zero)
            } else {
                (zero, one)
            }
        };
        match self {
            BinaryFn::Add => (one, one),
            BinaryFn::Sub => (one, -one),
            BinaryFn::Mul => (b, a),
            BinaryFn::Div => (one / b, -y / b),
            BinaryFn::Maximum => pick(a > b),
            BinaryFn::Minimum => pick(a < b),
        }
    }
}

/// An element-wise op of two broadcastable inputs (see [`BinaryFn`]).
#[derive(Debug, Clone, Copy)]
pub struct Binary(pub BinaryFn);

impl<F: Float> CustomOp<F> for Binary {
    type Saved = ();

    fn name(&self) -> &'static str {
        self.0.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [a, b] = inputs else {
            return Err(OpError::InvalidArgument(format!(
                "takes 2 inputs, got {}",
                inputs.len()
            )));
        };
        let shape = broadcast_shape(a.shape(), b.shape())?;
        let (a, b) = broadcast_pair(a, b, &shape)?;
        // One closure per function, chosen outside the loop, so that each loop vectorises.
        let y = match self.0 {
            BinaryFn::Add => map2(&a, &b, |a, b| a + b),
            BinaryFn::Sub => map2(&a, &b, |a, b| a - b),
            BinaryFn::Mul => map2(&a, &b, |a, b| a * b),
            BinaryFn::Div => map2(&a, &b, |a, b| a / b),
            BinaryFn::Maximum => map2(&a, &b, |a, b| a.max(b)),
            BinaryFn::Minimum => map2(&a, &b, |a, b| a.min(b)),
        };
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
        let (a0, b0) = (ctx.input(0), ctx.input(1));
        let y = ctx.output(0);
        let (a, b) = broadcast_pair(&a0, &b0, y.shape())?;
        let f = self.0;
        let mut out = vec![None, None];
        for (k, slot) in out.iter_mut().enumerate() {
            if !ctx.needs_input_grad(k) {
                continue;
            }
            // The common cases read only what they need; the rest go through `df`.
            let full = match (f, k) {
                (BinaryFn::Add, _) | (BinaryFn::Sub, 0) => map1(g, |g| g),
                (BinaryFn::Sub, _) => map1(g, |g| -g),
                (BinaryFn::Mul, 0) => map2(g, &b, strong_mul),
                (BinaryFn::Mul, _) => map2(g, &a, strong_mul),
                _ => Zip::from(g).and(&a).and(&b).and(&y).map_collect(|&g, &a, &b, &y| {
                    let (da, db) = f.df(a, b, y);
                    strong_mul(g, if k == 0 { da } else { db })
                }),
            };
            let shape = if k == 0 { a0.shape() } else { b0.shape() };
            *slot = Some(sum_to_shape(full, shape));
        }
        Ok(out)
    }
}

fn broadcast_pair<'a, F: Float>(
    a: &'a ArrayViewD<'_, F>,
    b: &'a ArrayViewD<'_, F>,
    shape: &[usize],
) -> Result<(ArrayViewD<'a, F>, ArrayViewD<'a, F>), OpError> {
    let mismatch = || OpError::ShapeMismatch {
        lhs: a.shape().to_vec(),
        rhs: b.shape().to_vec(),
    };
    let a = a.broadcast(IxDyn(shape)).ok_or_else(mismatch)?;
    let b = b.broadcast(IxDyn(shape)).ok_or_else(mismatch)?;
    Ok((a, b))
}

impl<F: Float> Tape<F> {
    fn binary(&mut self, a: Var, b: Var, f: BinaryFn) -> Result<Var> {
        self.apply1(Binary(f), &[a, b])
    }
    /// `a + b`, broadcasting.
    pub fn add(&mut self, a: Var, b: Var) -> Result<Var> {
        self.binary(a, b, BinaryFn::Add)
    }
    /// `a - b`, broadcasting.
    pub fn sub(&mut self, a: Var, b: Var) -> Result<Var> {
        self.binary(a, b, BinaryFn::Sub)
    }
    /// `a * b`, broadcasting.
    pub fn mul(&mut self, a: Var, b: Var) -> Result<Var> {
        self.binary(a, b, BinaryFn::Mul)
    }
    /// `a / b`, broadcasting (IEEE results for division by zero).
    pub fn div(&mut self, a: Var, b: Var) -> Result<Var> {
        self.binary(a, b, BinaryFn::Div)
    }
    /// `max(a, b)`, broadcasting; ties split the gradient in halves.
    pub fn maximum(&mut self, a: Var, b: Var) -> Result<Var> {
        self.binary(a, b, BinaryFn::Maximum)
    }
    /// `min(a, b)`, broadcasting; ties split the gradient in halves.
    pub fn minimum(&mut self, a: Var, b: Var) -> Result<Var> {
        self.binary(a, b, BinaryFn::Minimum)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{assert_gradcheck, values_close};
    use crate::{Tape, TapeError};
    use ndarray::{arr1, arr2, ArrayD, IxDyn};
    use proptest::prelude::*;

    #[test]
    fn values_with_broadcasting() {
        let mut t = Tape::<f64>::new();
        let a = t.param(arr2(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]));
        let b = t.param(arr1(&[10.0, 20.0, 30.0]));
        let cases: Vec<(&str, [f64; 6])> = vec![
            ("add", [11.0, 22.0, 33.0, 14.0, 25.0, 36.0]),
            ("sub", [-9.0, -18.0, -27.0, -6.0, -15.0, -24.0]),
            ("mul", [10.0, 40.0, 90.0, 40.0, 100.0, 180.0]),
            ("div", [0.1, 0.1, 0.1, 0.4, 0.25, 0.2]),
        ];
        for (name, want) in cases {
            let y = match name {
                "add" => t.add(a, b),
                "sub" => t.sub(a, b),
                "mul" => t.mul(a, b),
                _ => t.div(a, b),
            }
            .unwrap();
            values_close(name, t.value(y).unwrap(), &want, 1e-15);
        }
        // y = sum(a * b): dy/da = b broadcast, dy/db = column sums of a = (5, 7, 9).
        let m = t.mul(a, b).unwrap();
        let y = t.sum(m).unwrap();
        let g = t.backward(y).unwrap();
        values_close("da", g.get(a).unwrap(), &[10.0, 20.0, 30.0, 10.0, 20.0, 30.0], 0.0);
        values_close("db", g.get(b).unwrap(), &[5.0, 7.0, 9.0], 0.0);
    }

    #[test]
    fn maximum_minimum_split_ties() {
        let mut t = Tape::<f32>::new();
        let a = t.param(arr1(&[1.0f32, 2.0, 3.0]));
        let b = t.param(arr1(&[3.0f32, 2.0, 1.0]));
        let mx = t.maximum(a, b).unwrap();
        let mn = t.minimum(a, b).unwrap();
        let mxv: Vec<f64> = t.value(mx).unwrap().iter().map(|&v| f64::from(v)).collect();
        assert_eq!(mxv, vec![3.0, 2.0, 3.0]);
        let s = t.sum(mx).unwrap();
        let g = t.backward(s).unwrap();
        // max picks b, ties (half each), a.
        let ga: Vec<f32> = g.get(a).unwrap().iter().copied().collect();
        assert_eq!(ga, vec![0.0, 0.5, 1.0]);
        let s2 = t.sum(mn).unwrap();
        let g2 = t.backward(s2).unwrap();
        let gb: Vec<f32> = g2.get(b).unwrap().iter().copied().collect();
        assert_eq!(gb, vec![0.0, 0.5, 1.0]);
    }

    #[test]
    fn shape_mismatch_names_op_and_shapes_and_leaves_tape_unchanged() {
        let mut t = Tape::<f64>::new();
        let a = t.param(ArrayD::zeros(IxDyn(&[2, 3])));
        let b = t.param(ArrayD::zeros(IxDyn(&[4])));
        let before = t.stats();
        let e = t.mul(a, b).unwrap_err();
        assert_eq!(
            e,
            TapeError::ShapeMismatch {
                op: "mul",
                lhs: vec![2, 3],
                rhs: vec![4]
            }
        );
        assert_eq!(t.stats(), before);
    }

    #[test]
    fn strong_zero_in_mul_by_infinity() {
        // y = a * b with b = inf and seed 0: the contribution to a is 0, not 0 * inf = NaN.
        let mut t = Tape::<f64>::new();
        let a = t.param(arr1(&[1.0, 2.0]));
        let b = t.constant(arr1(&[f64::INFINITY, 3.0]));
        let y = t.mul(a, b).unwrap();
        let g = t.backward_with(y, arr1(&[0.0, 1.0]).into_dyn()).unwrap();
        values_close("da", g.get(a).unwrap(), &[0.0, 3.0], 0.0);
    }

    #[test]
    fn every_binary_op_passes_gradcheck_with_broadcasting() {
        let a = ArrayD::from_shape_vec(vec![2, 3], vec![0.3, -0.7, 1.3, 2.1, 0.9, -1.4]).unwrap();
        let b = ArrayD::from_shape_vec(vec![3], vec![1.1, 0.2, -0.5]).unwrap();
        for name in ["add", "sub", "mul", "div", "maximum", "minimum"] {
            assert_gradcheck(name, &[a.clone(), b.clone()], move |t, v| match name {
                "add" => t.add(v[0], v[1]),
                "sub" => t.sub(v[0], v[1]),
                "mul" => t.mul(v[0], v[1]),
                "div" => t.div(v[0], v[1]),
                "maximum" => t.maximum(v[0], v[1]),
                _ => t.minimum(v[0], v[1]),
            });
        }
    }

    proptest! {
        // Random broadcastable shapes and values: the gradient of sum(w * (a op b)) agrees
        // with central differences (f64), in both operand roles.
        #[test]
        fn broadcasting_gradients_agree_with_finite_differences(
            shape in proptest::collection::vec(1usize..4, 1..4),
            mask in proptest::collection::vec(any::<bool>(), 4),
            seed in any::<u64>(),
            op in 0usize..4,
        ) {
            use rand::{Rng, SeedableRng};
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let b_shape: Vec<usize> = shape.iter().zip(&mask).map(|(&d, &m)| if m { 1 } else { d }).collect();
            let b_shape = b_shape[b_shape.len().min(1)..].to_vec();
            let a = ArrayD::from_shape_fn(IxDyn(&shape), |_| rng.gen_range(0.5..2.0));
            let b = ArrayD::from_shape_fn(IxDyn(&b_shape), |_| rng.gen_range(0.5..2.0));
            let name = ["add", "sub", "mul", "div"][op];
            assert_gradcheck(name, &[a, b], move |t, v| match op {
                0 => t.add(v[0], v[1]),
                1 => t.sub(v[0], v[1]),
                2 => t.mul(v[0], v[1]),
                _ => t.div(v[0], v[1]),
            });
        }
    }
}
