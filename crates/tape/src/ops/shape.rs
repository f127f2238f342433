//! Shape ops: `reshape` (row-major), `slice` along one axis, `concat` along one axis.

use ndarray::{concatenate, ArrayD, ArrayViewD, Axis, Dimension, IxDyn, Slice};

use crate::buffer::{map1, scratch, zeroed};

use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// Reinterprets the elements in row-major order with a new shape of the same size.
#[derive(Debug, Clone)]
pub struct Reshape(pub Vec<usize>);

/// Keeps indices `start..end` of one axis.
#[derive(Debug, Clone, Copy)]
pub struct SliceAxis {
    /// The axis.
    pub axis: usize,
    /// First kept index.
    pub start: usize,
    /// One past the last kept index.
    pub end: usize,
}

/// Joins its inputs along one axis; all other axes must agree.
#[derive(Debug, Clone, Copy)]
pub struct Concat(pub usize);

fn reshaped<F: Float>(x: &ArrayViewD<'_, F>, shape: &[usize]) -> Result<ArrayD<F>, OpError> {
    let c = x.to_shape(IxDyn(shape)).map_err(|_| OpError::ShapeMismatch {
        lhs: x.shape().to_vec(),
        rhs: shape.to_vec(),
    })?;
    // A view (the usual, contiguous case) is copied into a pooled buffer; a copy is kept.
    Ok(if c.is_view() { copied(&c.view()) } else { c.into_owned() })
}

/// An owned copy of `x` in a pooled or fresh buffer (see [`crate::buffer`]).
fn copied<F: Float>(x: &ArrayViewD<'_, F>) -> ArrayD<F> {
    map1(x, |v| v)
}

impl<F: Float> CustomOp<F> for Reshape {
    type Saved = ();
    fn name(&self) -> &'static str {
        "reshape"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [x] = inputs else {
            return Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len())));
        };
        Ok((vec![reshaped(x, &self.0)?], ()))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        Ok(vec![Some(reshaped(g, ctx.input(0).shape())?)])
    }
}

/// A slice of a row-major array as runs of memory: the input is `outer` runs of `whole`
/// elements (one index of the axes before the sliced one each), of which the slice keeps the
/// `kept` elements after the first `skipped`. One copy per run instead of one iterator step
/// per element, which `IxDyn` views pay dearly for when the kept part is narrow (a column).
struct Runs {
    outer: usize,
    whole: usize,
    skipped: usize,
    kept: usize,
}

impl Runs {
    /// `shape` is the input's; the slice must fit it (checked by the caller).
    fn new(shape: &[usize], slice: SliceAxis) -> Self {
        let inner: usize = shape[slice.axis + 1..].iter().product();
        Runs {
            outer: shape[..slice.axis].iter().product(),
            whole: shape[slice.axis] * inner,
            skipped: slice.start * inner,
            kept: (slice.end - slice.start) * inner,
        }
    }
}

/// `values` (row-major) shaped as the slice of an input of shape `shape`.
fn sliced_shape<F: Float>(shape: &[usize], slice: SliceAxis, values: Vec<F>) -> Result<ArrayD<F>, OpError> {
    let mut out = shape.to_vec();
    out[slice.axis] = slice.end - slice.start;
    ArrayD::from_shape_vec(IxDyn(&out), values).map_err(|e| OpError::InvalidArgument(e.to_string()))
}

impl<F: Float> CustomOp<F> for SliceAxis {
    type Saved = ();
    fn name(&self) -> &'static str {
        "slice"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [x] = inputs else {
            return Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len())));
        };
        let SliceAxis { axis, start, end } = *self;
        if axis >= x.ndim() || start > end || end > x.shape()[axis] {
            return Err(OpError::InvalidArgument(format!(
                "range {start}..{end} of axis {axis} does not fit shape {:?}",
                x.shape()
            )));
        }
        let y = match x.as_slice() {
            Some(xs) => {
                let runs = Runs::new(x.shape(), *self);
                let mut out = scratch(runs.outer * runs.kept);
                for (o, run) in out
                    .chunks_exact_mut(runs.kept.max(1))
                    .zip(xs.chunks_exact(runs.whole.max(1)))
                {
                    o.copy_from_slice(&run[runs.skipped..runs.skipped + runs.kept]);
                }
                sliced_shape(x.shape(), *self, out)?
            }
            None => copied(&x.slice_axis(Axis(axis), Slice::from(start..end))),
        };
        Ok((vec![y], ()))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        let shape = ctx.input(0).raw_dim();
        let mut gx = ArrayD::from_shape_vec(shape.clone(), zeroed(shape.size()))
            .map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        match (g.as_slice(), gx.as_slice_mut()) {
            (Some(gs), Some(out)) => {
                let runs = Runs::new(shape.slice(), *self);
                for (run, g) in out
                    .chunks_exact_mut(runs.whole.max(1))
                    .zip(gs.chunks_exact(runs.kept.max(1)))
                {
                    run[runs.skipped..runs.skipped + runs.kept].copy_from_slice(g);
                }
            }
            _ => gx
                .slice_axis_mut(Axis(self.axis), Slice::from(self.start..self.end))
                .assign(g),
        }
        Ok(vec![Some(gx)])
    }
}

impl<F: Float> CustomOp<F> for Concat {
    type Saved = ();
    fn name(&self) -> &'static str {
        "concat"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let Some(first) = inputs.first() else {
            return Err(OpError::InvalidArgument("needs at least one input".into()));
        };
        let axis = self.0;
        if axis >= first.ndim() {
            return Err(OpError::InvalidArgument(format!(
                "axis {axis} out of range for shape {:?}",
                first.shape()
            )));
        }
        for x in inputs {
            let same_rank = x.ndim() == first.ndim();
            if !same_rank || (0..x.ndim()).any(|k| k != axis && x.shape()[k] != first.shape()[k]) {
                return Err(OpError::ShapeMismatch {
                    lhs: first.shape().to_vec(),
                    rhs: x.shape().to_vec(),
                });
            }
        }
        let joined = concatenate(Axis(axis), inputs).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        Ok((vec![joined], ()))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let n = ctx.num_inputs();
        let Some(g) = &grads[0] else { return Ok(vec![None; n]) };
        let mut start = 0;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let len = ctx.input(i).shape()[self.0];
            let part = g.slice_axis(Axis(self.0), Slice::from(start..start + len));
            out.push(ctx.needs_input_grad(i).then(|| copied(&part)));
            start += len;
        }
        Ok(out)
    }
}

impl<F: Float> Tape<F> {
    /// The same elements (row-major order) with a new shape of the same number of elements.
    pub fn reshape(&mut self, x: Var, shape: &[usize]) -> Result<Var> {
        self.apply1(Reshape(shape.to_vec()), &[x])
    }
    /// Indices `start..end` of `axis`; errors if the range does not fit.
    pub fn slice(&mut self, x: Var, axis: usize, start: usize, end: usize) -> Result<Var> {
        self.apply1(SliceAxis { axis, start, end }, &[x])
    }
    /// Joins `xs` along `axis`; every other axis must agree, and `xs` must not be empty.
    pub fn concat(&mut self, xs: &[Var], axis: usize) -> Result<Var> {
        self.apply1(Concat(axis), xs)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::assert_gradcheck;
    use crate::{Tape, TapeError};
    use ndarray::{arr1, arr2, ArrayD, Axis, Dimension, IxDyn, ShapeBuilder, Slice};
    use proptest::prelude::*;

    #[test]
    fn values() {
        let mut t = Tape::<f64>::new();
        let x = t.param(arr2(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]));
        let r = t.reshape(x, &[3, 2]).unwrap();
        assert_eq!(
            t.value(r).unwrap(),
            arr2(&[[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]).into_dyn()
        );
        let s = t.slice(x, 1, 1, 3).unwrap();
        assert_eq!(t.value(s).unwrap(), arr2(&[[2.0, 3.0], [5.0, 6.0]]).into_dyn());
        let c = t.concat(&[x, s], 1).unwrap();
        assert_eq!(
            t.value(c).unwrap(),
            arr2(&[[1.0, 2.0, 3.0, 2.0, 3.0], [4.0, 5.0, 6.0, 5.0, 6.0]]).into_dyn()
        );
        // d sum(concat(x, x[:,1:3])) / dx = 1 + [column >= 1].
        let y = t.sum(c).unwrap();
        let g = t.backward(y).unwrap();
        assert_eq!(g.get(x).unwrap(), arr2(&[[1.0, 2.0, 2.0], [1.0, 2.0, 2.0]]).into_dyn());
    }

    #[test]
    fn errors_name_the_op() {
        let mut t = Tape::<f32>::new();
        let x = t.param(arr1(&[1.0f32, 2.0, 3.0]));
        let y = t.param(arr2(&[[1.0f32]]));
        assert!(matches!(
            t.reshape(x, &[2, 2]),
            Err(TapeError::ShapeMismatch { op: "reshape", .. })
        ));
        assert!(matches!(
            t.slice(x, 0, 2, 4),
            Err(TapeError::InvalidArgument { op: "slice", .. })
        ));
        assert!(matches!(
            t.concat(&[x, y], 0),
            Err(TapeError::ShapeMismatch { op: "concat", .. })
        ));
        assert!(matches!(
            t.concat(&[], 0),
            Err(TapeError::InvalidArgument { op: "concat", .. })
        ));
        assert_eq!(t.len(), 2);
    }

    proptest! {
        // Forward against ndarray's own slice, backward against zeros with the upstream
        // assigned into the slice, for a row-major input (the runs of memory) and the same
        // values in column-major memory (the general path).
        #[test]
        fn slice_matches_ndarray_in_both_layouts(
            shape in proptest::collection::vec(0usize..4, 1..4),
            axis_pick in 0usize..3,
            bounds in (0usize..4, 0usize..4),
        ) {
            let axis = axis_pick % shape.len();
            let (start, end) = (bounds.0.min(bounds.1).min(shape[axis]), bounds.0.max(bounds.1).min(shape[axis]));
            let x = ArrayD::<f64>::from_shape_fn(IxDyn(&shape), |ix| {
                (0..ix.ndim()).fold(0.0, |acc, k| acc * 5.0 + ix[k] as f64 + 1.0)
            });
            let mut column_major = ArrayD::<f64>::zeros(IxDyn(&shape).f());
            column_major.assign(&x);
            let want = x.slice_axis(Axis(axis), Slice::from(start..end)).to_owned();
            let upstream = want.mapv(|v| -2.0 * v - 1.0);
            let mut want_grad = ArrayD::<f64>::zeros(IxDyn(&shape));
            want_grad.slice_axis_mut(Axis(axis), Slice::from(start..end)).assign(&upstream);
            for input in [x.clone(), column_major] {
                let mut t = Tape::<f64>::new();
                let xv = t.param(input);
                let y = t.slice(xv, axis, start, end).unwrap();
                prop_assert_eq!(&t.value(y).unwrap().to_owned(), &want);
                let g = t.backward_with(y, upstream.clone()).unwrap();
                prop_assert_eq!(&g.get(xv).unwrap().to_owned(), &want_grad);
            }
        }
    }

    #[test]
    fn gradcheck_shape_ops() {
        let x = ArrayD::from_shape_vec(vec![2, 3], vec![0.3, -0.7, 1.3, 2.1, 0.9, -1.4]).unwrap();
        let w = ArrayD::from_shape_vec(vec![3, 2], vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        assert_gradcheck("reshape", &[x.clone(), w], |t, v| {
            let r = t.reshape(v[0], &[3, 2])?;
            t.mul(r, v[1])
        });
        assert_gradcheck("slice", std::slice::from_ref(&x), |t, v| t.slice(v[0], 1, 1, 3));
        assert_gradcheck("concat", &[x.clone(), x], |t, v| {
            let sq = t.square(v[1])?;
            t.concat(&[v[0], sq], 0)
        });
    }
}
