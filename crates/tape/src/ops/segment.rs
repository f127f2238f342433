//! Segment ops over packed rows: axis 0 of the input is cut into consecutive segments by
//! `offsets` (segment `r` owns rows `offsets[r]..offsets[r+1]`), as packed rays are.
//!
//! - `segment_sum`: one row per segment, the sum of its rows; backward copies the
//!   segment's gradient to each row.
//! - `segment_exclusive_cumsum`: `y_i = sum_{j<i} x_j` within the segment; backward is the
//!   exclusive suffix sum `dx_i = sum_{k>i} g_k`.
//! - `segment_cumprod` (inclusive, `y_i = prod_{j<=i} x_j`) and
//!   `segment_exclusive_cumprod` (`y_i = prod_{j<i} x_j`). Their backward never divides by
//!   the input, so an exact zero factor gives no NaN: with exclusive prefix products
//!   `P_{i-1}`, inclusive `dx_i = P_{i-1} R_i` with `R_i = g_i + x_{i+1} R_{i+1}`; exclusive
//!   `dx_i = y_i Q_i` with `Q_i = g_{i+1} + x_{i+1} Q_{i+1}`, `Q_last = 0`. Both are O(n).
//!
//! The cumulative product is here to show why it is the wrong way to compute a
//! transmittance (it rounds to 0 or loses every digit as `1 - alpha` approaches 0); use the
//! exclusive cumsum of optical depth and `exp` instead.

use ndarray::{ArrayD, ArrayViewD, IxDyn};

use crate::buffer::{flat, zeroed};
use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::offsets::Offsets;
use crate::tape::Tape;
use crate::var::Var;

/// Which segment op.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentFn {
    /// One row per segment: the sum of its rows (zeros for an empty segment).
    Sum,
    /// Exclusive running sum within each segment.
    ExclusiveCumsum,
    /// Inclusive running product within each segment.
    Cumprod,
    /// Exclusive running product within each segment (1 at each segment's first row).
    ExclusiveCumprod,
}

/// A segment op with its validated offsets.
#[derive(Debug, Clone)]
pub struct Segment {
    kind: SegmentFn,
    offsets: Offsets,
}

impl SegmentFn {
    fn name(self) -> &'static str {
        match self {
            SegmentFn::Sum => "segment_sum",
            SegmentFn::ExclusiveCumsum => "segment_exclusive_cumsum",
            SegmentFn::Cumprod => "segment_cumprod",
            SegmentFn::ExclusiveCumprod => "segment_exclusive_cumprod",
        }
    }
}

impl Segment {
    /// Validates `offsets`: at least one entry, starting at 0, non-decreasing.
    /// (That the last equals the number of rows is checked when the op is applied.)
    pub fn new(kind: SegmentFn, offsets: &[usize]) -> Result<Self, OpError> {
        let offsets = Offsets::new(offsets).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        Ok(Segment { kind, offsets })
    }

    /// The op over an already validated packing.
    pub fn packed(kind: SegmentFn, offsets: Offsets) -> Self {
        Segment { kind, offsets }
    }

    fn segments(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.offsets.ranges()
    }
}

fn from_flat<F: Float>(shape: Vec<usize>, data: Vec<F>) -> Result<ArrayD<F>, OpError> {
    ArrayD::from_shape_vec(IxDyn(&shape), data).map_err(|e| OpError::InvalidArgument(e.to_string()))
}

impl<F: Float> CustomOp<F> for Segment {
    type Saved = ();

    fn name(&self) -> &'static str {
        self.kind.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [x] = inputs else {
            return Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len())));
        };
        let rows = x.shape().first().copied().unwrap_or(0);
        let last = self.offsets.last().copied().unwrap_or(0);
        if x.ndim() == 0 || last != rows {
            return Err(OpError::InvalidArgument(format!(
                "offsets end at {last} but the input has shape {:?} ({rows} rows)",
                x.shape()
            )));
        }
        let m = x.shape()[1..].iter().product::<usize>();
        let xs = flat(x);
        let mut shape = x.shape().to_vec();
        let out = match self.kind {
            SegmentFn::Sum => {
                shape[0] = self.offsets.len() - 1;
                let mut out = zeroed(shape[0] * m);
                for (r, seg) in self.segments().enumerate() {
                    for i in seg {
                        for c in 0..m {
                            out[r * m + c] += xs[i * m + c];
                        }
                    }
                }
                out
            }
            kind => {
                let mut out = zeroed(rows * m);
                for seg in self.segments() {
                    for c in 0..m {
                        let mut acc = if kind == SegmentFn::ExclusiveCumsum {
                            F::zero()
                        } else {
                            F::one()
                        };
                        for i in seg.clone() {
                            let x = xs[i * m + c];
                            out[i * m + c] = match kind {
                                SegmentFn::ExclusiveCumsum => {
                                    let before = acc;
                                    acc += x;
                                    before
                                }
                                SegmentFn::ExclusiveCumprod => {
                                    let before = acc;
                                    acc *= x;
                                    before
                                }
                                _ => {
                                    acc *= x;
                                    acc
                                }
                            };
                        }
                    }
                }
                out
            }
        };
        Ok((vec![from_flat(shape, out)?], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        let x = ctx.input(0);
        let y = ctx.output(0);
        let m = x.shape()[1..].iter().product::<usize>();
        let (gs, xs, ys) = (flat(g), flat(&x), flat(&y));
        let mut gx = zeroed(x.len());
        for (r, seg) in self.segments().enumerate() {
            for c in 0..m {
                let at = |i: usize| i * m + c;
                match self.kind {
                    SegmentFn::Sum => seg.clone().for_each(|i| gx[at(i)] = gs[r * m + c]),
                    SegmentFn::ExclusiveCumsum => {
                        let mut suffix = F::zero();
                        for i in seg.clone().rev() {
                            gx[at(i)] = suffix;
                            suffix += gs[at(i)];
                        }
                    }
                    SegmentFn::Cumprod => {
                        // R_i = g_i + x_{i+1} R_{i+1}; dx_i = P_{i-1} R_i with P_{i-1} = y_{i-1} (1 first).
                        let mut carry = F::zero();
                        for i in seg.clone().rev() {
                            if i + 1 < seg.end {
                                carry *= xs[at(i + 1)];
                            }
                            carry += gs[at(i)];
                            let prefix = if i == seg.start { F::one() } else { ys[at(i - 1)] };
                            gx[at(i)] = prefix * carry;
                        }
                    }
                    SegmentFn::ExclusiveCumprod => {
                        // Q_i = g_{i+1} + x_{i+1} Q_{i+1}, Q_last = 0; dx_i = y_i Q_i.
                        let mut carry = F::zero();
                        for i in seg.clone().rev() {
                            if i + 1 < seg.end {
                                carry = gs[at(i + 1)] + xs[at(i + 1)] * carry;
                            }
                            gx[at(i)] = ys[at(i)] * carry;
                        }
                    }
                }
            }
        }
        Ok(vec![Some(from_flat(x.shape().to_vec(), gx)?)])
    }
}

impl<F: Float> Tape<F> {
    fn segment(&mut self, kind: SegmentFn, x: Var, offsets: &[usize]) -> Result<Var> {
        let op = Segment::new(kind, offsets).map_err(|e| crate::TapeError::from_op(kind.name(), e))?;
        self.apply1(op, &[x])
    }
    /// Per segment of rows, the sum of its rows: shape `[R, ..]` for `R + 1` offsets.
    ///
    /// `offsets` must start at 0, not decrease, and end at `x`'s number of rows.
    pub fn segment_sum(&mut self, x: Var, offsets: &[usize]) -> Result<Var> {
        self.segment(SegmentFn::Sum, x, offsets)
    }
    /// Within each segment, the sum of the rows before each row (0 for its first row).
    pub fn segment_exclusive_cumsum(&mut self, x: Var, offsets: &[usize]) -> Result<Var> {
        self.segment(SegmentFn::ExclusiveCumsum, x, offsets)
    }
    /// Within each segment, the product of the rows up to and including each row.
    pub fn segment_cumprod(&mut self, x: Var, offsets: &[usize]) -> Result<Var> {
        self.segment(SegmentFn::Cumprod, x, offsets)
    }
    /// Within each segment, the product of the rows before each row (1 for its first row).
    pub fn segment_exclusive_cumprod(&mut self, x: Var, offsets: &[usize]) -> Result<Var> {
        self.segment(SegmentFn::ExclusiveCumprod, x, offsets)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{assert_gradcheck, values_close};
    use crate::{Tape, TapeError};
    use ndarray::{arr1, arr2, ArrayD, IxDyn};
    use proptest::prelude::*;

    const OFFSETS: [usize; 4] = [0, 3, 3, 5]; // segments of 3, 0 and 2 rows

    #[test]
    fn values_by_hand() {
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[1.0, 2.0, 3.0, 4.0, 5.0]));
        let s = t.segment_sum(x, &OFFSETS).unwrap();
        let c = t.segment_exclusive_cumsum(x, &OFFSETS).unwrap();
        let p = t.segment_cumprod(x, &OFFSETS).unwrap();
        let q = t.segment_exclusive_cumprod(x, &OFFSETS).unwrap();
        values_close("sum", t.value(s).unwrap(), &[6.0, 0.0, 9.0], 0.0);
        values_close("excl cumsum", t.value(c).unwrap(), &[0.0, 1.0, 3.0, 0.0, 4.0], 0.0);
        values_close("cumprod", t.value(p).unwrap(), &[1.0, 2.0, 6.0, 4.0, 20.0], 0.0);
        values_close("excl cumprod", t.value(q).unwrap(), &[1.0, 1.0, 2.0, 1.0, 4.0], 0.0);
    }

    #[test]
    fn rows_with_channels() {
        let mut t = Tape::<f32>::new();
        let x = t.param(arr2(&[[1.0f32, 10.0], [2.0, 20.0], [3.0, 30.0]]));
        let s = t.segment_sum(x, &[0, 2, 3]).unwrap();
        assert_eq!(t.value(s).unwrap(), arr2(&[[3.0f32, 30.0], [3.0, 30.0]]).into_dyn());
        let c = t.segment_exclusive_cumsum(x, &[0, 2, 3]).unwrap();
        assert_eq!(
            t.value(c).unwrap(),
            arr2(&[[0.0f32, 0.0], [1.0, 10.0], [0.0, 0.0]]).into_dyn()
        );
    }

    #[test]
    fn cumprod_backward_has_no_nan_at_an_exact_zero() {
        // y = prod(x0, x1, x2) with x1 = 0: dy/dx1 = x0 x2 = 6, dy/dx0 = dy/dx2 = 0.
        // A backward that divides y by x would give 0/0 = NaN here.
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[2.0, 0.0, 3.0]));
        let p = t.segment_cumprod(x, &[0, 3]).unwrap();
        let last = t.slice(p, 0, 2, 3).unwrap();
        let y = t.sum(last).unwrap();
        let g = t.backward(y).unwrap();
        values_close("dprod", g.get(x).unwrap(), &[0.0, 6.0, 0.0], 0.0);
        // Exclusive form: y = sum of exclusive products (1, 2, 0): dy/dx0 = 1 + x1 = 1, dy/dx1 = x0 = 2.
        let q = t.segment_exclusive_cumprod(x, &[0, 3]).unwrap();
        let y2 = t.sum(q).unwrap();
        let g2 = t.backward(y2).unwrap();
        values_close("dexcl", g2.get(x).unwrap(), &[1.0, 2.0, 0.0], 0.0);
    }

    #[test]
    fn bad_offsets_are_errors() {
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[1.0, 2.0]));
        for bad in [&[][..], &[1, 2][..], &[0, 2, 1][..], &[0, 3][..], &[0, 1][..]] {
            assert!(
                matches!(
                    t.segment_sum(x, bad),
                    Err(TapeError::InvalidArgument { op: "segment_sum", .. })
                ),
                "{bad:?}"
            );
        }
        assert_eq!(t.len(), 1);
    }

    #[test]
    fn gradcheck_every_segment_op() {
        let x = ArrayD::from_shape_vec(vec![5, 2], vec![0.3, -0.7, 1.3, 2.1, 0.9, -1.4, 0.5, 0.8, -1.2, 1.7]).unwrap();
        for kind in 0..4 {
            assert_gradcheck("segment", std::slice::from_ref(&x), move |t, v| {
                let y = match kind {
                    0 => t.segment_sum(v[0], &OFFSETS)?,
                    1 => t.segment_exclusive_cumsum(v[0], &OFFSETS)?,
                    2 => t.segment_cumprod(v[0], &OFFSETS)?,
                    _ => t.segment_exclusive_cumprod(v[0], &OFFSETS)?,
                };
                t.square(y)
            });
        }
    }

    proptest! {
        // Random segment lengths (empty ones included) and values: each op matches a
        // per-segment loop written here independently, and its gradient matches FD.
        #[test]
        fn random_segments(lengths in proptest::collection::vec(0usize..5, 1..5), seed in any::<u64>(), ch in 1usize..3) {
            use rand::{Rng, SeedableRng};
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let mut offsets = vec![0];
            for l in &lengths { offsets.push(offsets.last().unwrap() + l); }
            let n = *offsets.last().unwrap();
            let x = ArrayD::from_shape_fn(IxDyn(&[n, ch]), |_| rng.gen_range(-1.5..1.5));
            let mut t = Tape::<f64>::new();
            let v = t.param(x.clone());
            let c = t.segment_exclusive_cumsum(v, &offsets).unwrap();
            let s = t.segment_sum(v, &offsets).unwrap();
            for w in offsets.windows(2) {
                for k in 0..ch {
                    let mut acc = 0.0;
                    for i in w[0]..w[1] {
                        prop_assert!((t.value(c).unwrap()[[i, k]] - acc).abs() < 1e-12);
                        acc += x[[i, k]];
                    }
                }
            }
            let total: f64 = t.value(s).unwrap().sum();
            prop_assert!((total - x.sum()).abs() < 1e-12);
            let offs = offsets.clone();
            assert_gradcheck("segment ops", &[x], move |t, v| {
                let a = t.segment_exclusive_cumsum(v[0], &offs)?;
                let b = t.segment_cumprod(v[0], &offs)?;
                let ab = t.mul(a, b)?;
                t.segment_sum(ab, &offs)
            });
        }
    }
}
