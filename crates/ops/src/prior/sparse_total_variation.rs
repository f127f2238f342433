//! The total-variation prior of a sparse grid's packed values, with its gradient written by
//! hand: the dense prior's terms over the pairs of neighbouring nodes that are both stored.

use std::sync::Arc;

use fogray_tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD, IxDyn};
use rayon::prelude::*;

use super::TotalVariation;
use crate::error::{Op, OpsError};
use crate::grid::{NodeIndex, SparseGridField};

/// [`TotalVariation`] on the packed values `[kept, C]` of a [`SparseGridField`]:
///
/// ```text
/// TV(v) = weight * mean over axes a, stored nodes i whose neighbour i + e_a is stored,
///                  channels c of (v[i + e_a, c] - v[i, c])^2
/// ```
///
/// With every node stored it is the dense prior of the same lattice. Each row's gradient,
/// `2 weight / terms * sum over its stored neighbours n of (v[i, c] - v[n, c])`, is computed
/// by its own row from its neighbours (x+, x-, y+, y-, z+, z-), so nothing is scattered; the
/// value is summed in f64 in fixed chunks of rows. Both are bitwise the same for any number
/// of threads, and cost what the rows kept cost.
///
/// ```
/// use fogray_ops::grid::{NodeIndex, SparseGridField};
/// use fogray_ops::prior::{SparseTotalVariation, TotalVariation};
/// use fogray_ops::GridBox;
/// use ndarray::arr2;
///
/// // A 2x2x2 lattice keeping the x = 0 face and node (1, 0, 0): 4 pairs within the face, one
/// // along x.
/// let keep: Vec<bool> = (0..8).map(|l| l < 5).collect();
/// let field = SparseGridField::new(GridBox::new(&[0.0; 3], &[1.0; 3])?, NodeIndex::from_mask([2; 3], &keep)?, 1)?;
/// let tv = SparseTotalVariation::new(TotalVariation::new(1.0)?, &field);
/// let v = arr2(&[[0.0], [1.0], [2.0], [4.0], [3.0]]);
/// // Pairs: (0,1) z, (2,3) z, (0,2) y, (1,3) y, (0,4) x.
/// assert_eq!(tv.value(&v.view().into_dyn())?, (1.0 + 4.0 + 4.0 + 9.0 + 9.0) / 5.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct SparseTotalVariation {
    weight: f64,
    channels: usize,
    /// Each row's stored neighbours' rows in the order x+, x-, y+, y-, z+, z- ([`NONE`] for
    /// none), found once: a step's prior then reads no index.
    neighbours: Arc<Vec<[u32; 6]>>,
    /// Pairs of stored neighbours times the channels.
    terms: usize,
}

/// Rows per parallel task (the results do not depend on it).
const ROWS: usize = 4096;

/// No neighbour.
const NONE: u32 = u32::MAX;

/// The rows of node `node`'s stored neighbours (absent: `None`), in the order x+, x-, y+, y-,
/// z+, z-.
fn neighbours_of(index: &NodeIndex, node: usize) -> [Option<usize>; 6] {
    let [n0, n1, n2] = index.nodes();
    let at = [node / (n1 * n2), node / n2 % n1, node % n2];
    let (strides, len) = ([n1 * n2, n2, 1], [n0, n1, n2]);
    std::array::from_fn(|s| {
        let a = s / 2;
        if s % 2 == 0 {
            (at[a] + 1 < len[a]).then(|| index.row_at(node + strides[a])).flatten()
        } else {
            (at[a] > 0).then(|| index.row_at(node - strides[a])).flatten()
        }
    })
}

impl SparseTotalVariation {
    /// The prior `prior` (its weight) on `field`'s packed values.
    pub fn new(prior: TotalVariation, field: &SparseGridField) -> Self {
        let index = field.index();
        let neighbours = index
            .kept_nodes()
            .par_iter()
            .map(|&l| neighbours_of(index, l).map(|n| n.map_or(NONE, |r| r as u32)))
            .collect::<Vec<_>>();
        let pairs: usize = neighbours
            .iter()
            .map(|n| n.iter().step_by(2).filter(|&&r| r != NONE).count())
            .sum();
        SparseTotalVariation {
            weight: prior.weight(),
            channels: field.channels(),
            neighbours: Arc::new(neighbours),
            terms: pairs * field.channels(),
        }
    }

    /// The weight.
    pub fn weight(&self) -> f64 {
        self.weight
    }

    fn check<'a, F: Float>(&self, data: &'a ArrayViewD<'_, F>) -> Result<std::borrow::Cow<'a, [F]>, OpsError> {
        let want = [self.neighbours.len(), self.channels];
        if data.shape() != want {
            return Err(OpsError::Shape {
                op: Op::SparseTotalVariation,
                what: "sparse grid values",
                expected: format!("{want:?}"),
                got: format!("{:?}", data.shape()),
            });
        }
        Ok(match data.as_slice() {
            Some(s) => std::borrow::Cow::Borrowed(s),
            None => std::borrow::Cow::Owned(data.iter().copied().collect()),
        })
    }

    /// The prior of `data` (`[kept, C]`), without a tape.
    ///
    /// Errors: values of another shape ([`OpsError::Shape`]).
    pub fn value<F: Float>(&self, data: &ArrayViewD<'_, F>) -> Result<f64, OpsError> {
        let v = self.check(data)?;
        let terms = self.terms;
        if terms == 0 {
            return Ok(0.0);
        }
        let ch = self.channels;
        let chunks: Vec<f64> = self
            .neighbours
            .par_chunks(ROWS)
            .enumerate()
            .map(|(c, rows)| {
                let mut sum = 0.0;
                for (i, neighbours) in rows.iter().enumerate() {
                    let r = c * ROWS + i;
                    for &n in neighbours.iter().step_by(2).filter(|&&n| n != NONE) {
                        let n = n as usize;
                        for k in 0..ch {
                            let d = v[n * ch + k].as_f64() - v[r * ch + k].as_f64();
                            sum += d * d;
                        }
                    }
                }
                sum
            })
            .collect();
        Ok(self.weight * chunks.iter().sum::<f64>() / terms as f64)
    }

    /// `scale` times the gradient of the prior at `data`.
    ///
    /// Errors: values of another shape ([`OpsError::Shape`]).
    pub fn gradient<F: Float>(&self, data: &ArrayViewD<'_, F>, scale: f64) -> Result<ArrayD<F>, OpsError> {
        let v = self.check(data)?;
        let terms = self.terms;
        let ch = self.channels;
        let mut out = vec![F::zero(); v.len()];
        if terms > 0 {
            let factor = scale * 2.0 * self.weight / terms as f64;
            out.par_chunks_mut(ROWS * ch).enumerate().for_each(|(c, out)| {
                let mut acc = vec![0.0f64; ch];
                for (i, o) in out.chunks_exact_mut(ch).enumerate() {
                    let r = c * ROWS + i;
                    acc.fill(0.0);
                    for &n in self.neighbours[r].iter().filter(|&&n| n != NONE) {
                        let n = n as usize;
                        for (k, a) in acc.iter_mut().enumerate() {
                            *a += v[r * ch + k].as_f64() - v[n * ch + k].as_f64();
                        }
                    }
                    for (o, &a) in o.iter_mut().zip(&acc) {
                        *o = F::lit(factor * a);
                    }
                }
            });
        }
        ArrayD::from_shape_vec(IxDyn(&[self.neighbours.len(), ch]), out).map_err(|e| OpsError::Shape {
            op: Op::SparseTotalVariation,
            what: "gradient",
            expected: format!("[{}, {ch}]", self.neighbours.len()),
            got: e.to_string(),
        })
    }

    /// Records the prior of `data` on `tape` (a 0-d value).
    ///
    /// Errors: as [`SparseTotalVariation::value`] (inside [`TapeError::Op`]), or a stale
    /// handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, data: Var) -> Result<Var, TapeError> {
        tape.apply1(self.clone(), &[data])
    }
}

impl<F: Float> CustomOp<F> for SparseTotalVariation {
    type Saved = ();

    fn name(&self) -> &'static str {
        Op::SparseTotalVariation.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [data] = inputs else {
            return Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len())));
        };
        let value = self.value(data).map_err(OpError::typed)?;
        Ok((vec![ArrayD::from_elem(IxDyn(&[]), F::lit(value))], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else {
            return Ok(vec![None]);
        };
        let scale = g.iter().next().map_or(0.0, |v| v.as_f64());
        Ok(vec![Some(self.gradient(&ctx.input(0), scale).map_err(OpError::typed)?)])
    }
}
