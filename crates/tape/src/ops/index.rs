//! Indexing along axis 0: `gather` (index select) and its adjoint `scatter_add`.
//! Each is the other's backward.

use ndarray::{ArrayD, ArrayViewD, Axis};

use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// `out[i, ..] = x[indices[i], ..]`; indices may repeat.
#[derive(Debug, Clone)]
pub struct Gather(pub Vec<usize>);

/// `out[indices[i], ..] += x[i, ..]` into `rows` zero rows.
#[derive(Debug, Clone)]
pub struct ScatterAdd {
    /// Target row of each input row.
    pub indices: Vec<usize>,
    /// Number of rows of the output.
    pub rows: usize,
}

fn check_indices(indices: &[usize], rows: usize) -> Result<(), OpError> {
    match indices.iter().position(|&i| i >= rows) {
        Some(k) => Err(OpError::InvalidArgument(format!(
            "index {} at position {k} is out of range for {rows} rows",
            indices[k]
        ))),
        None => Ok(()),
    }
}

fn gather<F: Float>(x: &ArrayViewD<'_, F>, indices: &[usize]) -> ArrayD<F> {
    x.select(Axis(0), indices)
}

fn scatter_add<F: Float>(x: &ArrayViewD<'_, F>, indices: &[usize], rows: usize) -> ArrayD<F> {
    let mut shape = x.shape().to_vec();
    shape[0] = rows;
    let mut out = ArrayD::zeros(shape);
    for (row, &i) in x.axis_iter(Axis(0)).zip(indices) {
        let mut target = out.index_axis_mut(Axis(0), i);
        target += &row;
    }
    out
}

fn first_input<'a, 'b, F: Float>(inputs: &'a [ArrayViewD<'b, F>]) -> Result<&'a ArrayViewD<'b, F>, OpError> {
    match inputs {
        [x] if x.ndim() >= 1 => Ok(x),
        [_] => Err(OpError::InvalidArgument("needs an input with at least one axis".into())),
        _ => Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len()))),
    }
}

impl<F: Float> CustomOp<F> for Gather {
    type Saved = ();
    fn name(&self) -> &'static str {
        "gather"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let x = first_input(inputs)?;
        check_indices(&self.0, x.shape()[0])?;
        Ok((vec![gather(x, &self.0)], ()))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        Ok(vec![Some(scatter_add(g, &self.0, ctx.input(0).shape()[0]))])
    }
}

impl<F: Float> CustomOp<F> for ScatterAdd {
    type Saved = ();
    fn name(&self) -> &'static str {
        "scatter_add"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let x = first_input(inputs)?;
        if x.shape()[0] != self.indices.len() {
            return Err(OpError::ShapeMismatch {
                lhs: vec![self.indices.len()],
                rhs: x.shape().to_vec(),
            });
        }
        check_indices(&self.indices, self.rows)?;
        Ok((vec![scatter_add(x, &self.indices, self.rows)], ()))
    }
    fn backward(
        &self,
        _ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        Ok(vec![Some(gather(g, &self.indices))])
    }
}

impl<F: Float> Tape<F> {
    /// Rows of `x` (axis 0) picked by `indices`, repeats allowed; errors on an index out of range.
    pub fn gather(&mut self, x: Var, indices: &[usize]) -> Result<Var> {
        self.apply1(Gather(indices.to_vec()), &[x])
    }
    /// Adds row `i` of `x` into row `indices[i]` of `rows` zero rows; `indices.len()` must be
    /// `x`'s number of rows and every index below `rows`.
    pub fn scatter_add(&mut self, x: Var, indices: &[usize], rows: usize) -> Result<Var> {
        self.apply1(
            ScatterAdd {
                indices: indices.to_vec(),
                rows,
            },
            &[x],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::assert_gradcheck;
    use crate::{Tape, TapeError};
    use ndarray::{arr1, arr2, ArrayD};

    #[test]
    fn values_and_adjointness() {
        let mut t = Tape::<f64>::new();
        let x = t.param(arr2(&[[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]));
        let g = t.gather(x, &[2, 0, 2]).unwrap();
        assert_eq!(
            t.value(g).unwrap(),
            arr2(&[[5.0, 6.0], [1.0, 2.0], [5.0, 6.0]]).into_dyn()
        );
        let s = t.scatter_add(g, &[1, 1, 0], 2).unwrap();
        // row 1 = (5,6) + (1,2); row 0 = (5,6)
        assert_eq!(t.value(s).unwrap(), arr2(&[[5.0, 6.0], [6.0, 8.0]]).into_dyn());
        // d sum(gather(x, [2,0,2])) / dx counts how often each row was picked: (1, 0, 2).
        let y = t.sum(g).unwrap();
        let gr = t.backward(y).unwrap();
        assert_eq!(
            gr.get(x).unwrap(),
            arr2(&[[1.0, 1.0], [0.0, 0.0], [2.0, 2.0]]).into_dyn()
        );
    }

    #[test]
    fn out_of_range_is_an_error() {
        let mut t = Tape::<f32>::new();
        let x = t.param(arr1(&[1.0f32, 2.0]));
        assert!(matches!(
            t.gather(x, &[2]),
            Err(TapeError::InvalidArgument { op: "gather", .. })
        ));
        assert!(matches!(
            t.scatter_add(x, &[0, 3], 3),
            Err(TapeError::InvalidArgument { op: "scatter_add", .. })
        ));
        assert!(matches!(
            t.scatter_add(x, &[0], 3),
            Err(TapeError::ShapeMismatch { op: "scatter_add", .. })
        ));
        let s = t.scalar(1.0);
        assert!(t.gather(s, &[0]).is_err());
    }

    #[test]
    fn gradcheck_index_ops() {
        let x = ArrayD::from_shape_vec(vec![3, 2], vec![0.3, -0.7, 1.3, 2.1, 0.9, -1.4]).unwrap();
        assert_gradcheck("gather", std::slice::from_ref(&x), |t, v| {
            let g = t.gather(v[0], &[2, 0, 2, 1])?;
            t.square(g)
        });
        assert_gradcheck("scatter_add", &[x], |t, v| {
            let s = t.scatter_add(v[0], &[1, 1, 0], 4)?;
            t.square(s)
        });
    }
}
