//! The total-variation prior of a dense grid, with its gradient written by hand.

use std::borrow::Cow;

use fogray_tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD, ArrayViewMutD, IxDyn};
use rayon::prelude::*;

use crate::error::{Op, OpsError};

/// The total-variation prior of a grid `[X, Y, C]` or `[X, Y, Z, C]` (spatial axes, then
/// channels, as a [`GridField`](crate::GridField) holds it):
///
/// ```text
/// TV(g) = weight * mean over spatial axes a, nodes i with a neighbour i + e_a, channels c
///                  of (g[i + e_a, c] - g[i, c])^2
/// ```
///
/// The mean (not the sum) keeps a weight meaningful when the grid is refined. A grid with no
/// neighbouring nodes (every spatial axis of size 1) has no term: its prior is 0.
///
/// The sum is accumulated in f64 whatever the grid's type, slab by slab in a fixed order, so
/// the value and the gradient are bitwise the same for any number of threads.
///
/// ```
/// use fogray_ops::prior::TotalVariation;
/// use fogray_tape::Tape;
/// use ndarray::arr3;
///
/// // A 2 x 2 grid of one channel: differences 3 and 6 along x, 1 and 4 along y.
/// let tv = TotalVariation::new(2.0)?;
/// let grid = arr3(&[[[0.0], [1.0]], [[3.0], [7.0]]]);
/// assert_eq!(tv.value(&grid.view().into_dyn())?, 2.0 * (9.0 + 36.0 + 1.0 + 16.0) / 4.0);
///
/// let mut tape = Tape::<f64>::new();
/// let g = tape.param(grid);
/// let prior = tv.apply(&mut tape, g)?;
/// let grads = tape.backward(prior)?;
/// // d/dg[0,0] = 2 * weight / 4 * ((0 - 3) + (0 - 1)) = -4
/// assert_eq!(grads.get(g).unwrap()[[0, 0, 0]], -4.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TotalVariation {
    weight: f64,
}

/// A grid's shape as `[X, Y, Z, C]` (a 2-D grid has `Z = 1`) and its number of terms.
#[derive(Debug, Clone, Copy)]
struct Dims {
    n: [usize; 4],
    terms: usize,
}

impl Dims {
    fn of(shape: &[usize]) -> Result<Self, OpsError> {
        let n = match *shape {
            [x, y, c] => [x, y, 1, c],
            [x, y, z, c] => [x, y, z, c],
            _ => {
                return Err(OpsError::Shape {
                    op: Op::TotalVariation,
                    what: "grid",
                    expected: "[X, Y, C] or [X, Y, Z, C]".into(),
                    got: format!("{shape:?}"),
                })
            }
        };
        let [x, y, z, c] = n;
        let pairs = x.saturating_sub(1) * y * z + x * y.saturating_sub(1) * z + x * y * z.saturating_sub(1);
        Ok(Dims { n, terms: pairs * c })
    }

    /// Strides of x, y and z in the flat row-major grid.
    fn strides(&self) -> [usize; 3] {
        let [_, y, z, c] = self.n;
        [y * z * c, z * c, c]
    }
}

fn flat<'a, F: Float>(grid: &'a ArrayViewD<'_, F>) -> Cow<'a, [F]> {
    match grid.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(grid.iter().copied().collect()),
    }
}

impl TotalVariation {
    /// A prior of weight `weight` (finite and non-negative).
    ///
    /// Errors: [`OpsError::Config`].
    pub fn new(weight: f64) -> Result<Self, OpsError> {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(OpsError::config(
                Op::TotalVariation,
                "weight",
                weight,
                "must be finite and non-negative",
            ));
        }
        Ok(TotalVariation { weight })
    }

    /// The weight.
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// The prior of `grid` (`[X, Y, C]` or `[X, Y, Z, C]`), without a tape.
    ///
    /// Errors: a grid of another rank ([`OpsError::Shape`]).
    pub fn value<F: Float>(&self, grid: &ArrayViewD<'_, F>) -> Result<f64, OpsError> {
        let dims = Dims::of(grid.shape())?;
        Ok(self.value_flat(&flat(grid), dims))
    }

    fn value_flat<F: Float>(&self, g: &[F], dims: Dims) -> f64 {
        if dims.terms == 0 {
            return 0.0;
        }
        let [nx, ny, nz, nc] = dims.n;
        let [sx, sy, _] = dims.strides();
        // Row by row (the contiguous run of a node's z and channels): the differences along x
        // and y pair a row with the same row of the next slab or the next row, those along z
        // pair a row with itself shifted by one node; each a loop the compiler vectorises.
        let slabs: Vec<f64> = (0..nx)
            .into_par_iter()
            .map(|i| {
                let mut lanes = [0.0f64; LANES];
                for j in 0..ny {
                    let base = i * sx + j * sy;
                    let row = &g[base..base + sy];
                    if i + 1 < nx {
                        add_squared_differences(&mut lanes, row, &g[base + sx..base + sx + sy]);
                    }
                    if j + 1 < ny {
                        add_squared_differences(&mut lanes, row, &g[base + sy..base + 2 * sy]);
                    }
                    if nz > 1 {
                        add_squared_differences(&mut lanes, &row[..sy - nc], &row[nc..]);
                    }
                }
                lanes.iter().sum::<f64>()
            })
            .collect();
        self.weight * slabs.iter().sum::<f64>() / dims.terms as f64
    }

    /// Writes `scale` times the gradient of the prior at `grid` into `out` (same shape):
    /// `d TV / d g[i, c] = 2 weight / terms * sum over i's neighbours n of (g[i, c] - g[n, c])`.
    ///
    /// Errors: a grid of another rank, or `out` not of the grid's shape
    /// ([`OpsError::Shape`]); `out` is unchanged then.
    pub fn gradient_into<F: Float>(
        &self,
        grid: &ArrayViewD<'_, F>,
        scale: f64,
        mut out: ArrayViewMutD<'_, F>,
    ) -> Result<(), OpsError> {
        let dims = Dims::of(grid.shape())?;
        if out.shape() != grid.shape() {
            return Err(OpsError::Shape {
                op: Op::TotalVariation,
                what: "gradient buffer",
                expected: format!("{:?}", grid.shape()),
                got: format!("{:?}", out.shape()),
            });
        }
        let g = flat(grid);
        match out.as_slice_mut() {
            Some(o) => self.gradient_flat(&g, dims, scale, o),
            None => {
                let mut o = vec![F::zero(); g.len()];
                self.gradient_flat(&g, dims, scale, &mut o);
                out.iter_mut().zip(o).for_each(|(d, s)| *d = s);
            }
        }
        Ok(())
    }

    fn gradient_flat<F: Float>(&self, g: &[F], dims: Dims, scale: f64, out: &mut [F]) {
        let [nx, ny, nz, nc] = dims.n;
        let [sx, sy, _] = dims.strides();
        if dims.terms == 0 || sx == 0 {
            out.iter_mut().for_each(|o| *o = F::zero());
            return;
        }
        let factor = scale * 2.0 * self.weight / dims.terms as f64;
        // Row by row as in `value_flat`; each node's neighbours are added in the order
        // x+, x-, y+, y-, z+, z-, whatever the row's position in the grid.
        out.par_chunks_mut(sx).enumerate().for_each(|(i, slab)| {
            let mut acc = vec![0.0f64; sy];
            for j in 0..ny {
                let base = i * sx + j * sy;
                let row = &g[base..base + sy];
                if i > 0 && i + 1 < nx && j > 0 && j + 1 < ny && nz > 1 {
                    // An inner row, the bulk of a grid: every neighbour along x and y, in
                    // one pass (the same sums in the same order as the passes below).
                    let rows = [
                        &g[base + sx..base + sx + sy],
                        &g[base - sx..base - sx + sy],
                        &g[base + sy..base + 2 * sy],
                        &g[base - sy..base],
                    ];
                    inner_row(row, rows, nc, factor, &mut slab[j * sy..(j + 1) * sy]);
                    continue;
                }
                acc.fill(0.0);
                if i + 1 < nx {
                    add_differences(&mut acc, row, &g[base + sx..base + sx + sy]);
                }
                if i > 0 {
                    add_differences(&mut acc, row, &g[base - sx..base - sx + sy]);
                }
                if j + 1 < ny {
                    add_differences(&mut acc, row, &g[base + sy..base + 2 * sy]);
                }
                if j > 0 {
                    add_differences(&mut acc, row, &g[base - sy..base]);
                }
                if nz > 1 {
                    add_differences(&mut acc[..sy - nc], &row[..sy - nc], &row[nc..]);
                    add_differences(&mut acc[nc..], &row[nc..], &row[..sy - nc]);
                }
                for (o, a) in slab[j * sy..(j + 1) * sy].iter_mut().zip(&acc) {
                    *o = F::lit(factor * a);
                }
            }
        });
    }

    /// Records the prior of `grid` (a tape value `[X, Y, C]` or `[X, Y, Z, C]`) as a scalar,
    /// to add to a loss.
    ///
    /// Errors: a grid of another rank (a [`TapeError`] naming the op), a stale handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, grid: Var) -> Result<Var, TapeError> {
        Ok(tape.apply(*self, &[grid])?[0])
    }
}

/// Independent f64 sums of the value's squares: one running sum would chain every addition
/// on the one before.
const LANES: usize = 8;

/// `lanes[t % LANES] += (b[t] - a[t])^2` in f64, for `a` and `b` of one length.
fn add_squared_differences<F: Float>(lanes: &mut [f64; LANES], a: &[F], b: &[F]) {
    let (a_chunks, b_chunks) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (a_rest, b_rest) = (a_chunks.remainder(), b_chunks.remainder());
    for (ca, cb) in a_chunks.zip(b_chunks) {
        for l in 0..LANES {
            let d = cb[l].as_f64() - ca[l].as_f64();
            lanes[l] += d * d;
        }
    }
    for (l, (x, y)) in a_rest.iter().zip(b_rest).enumerate() {
        let d = y.as_f64() - x.as_f64();
        lanes[l] += d * d;
    }
}

/// `out[t] = factor * (0 + sum over n of (row[t] - n[t]))` over the four rows `xy` (x+, x-,
/// y+, y-) and then the row shifted by `nc` (z+, z-) where it has those neighbours: the order
/// of the row-by-row passes, in one pass over the row. Expects `row.len() >= 2 nc`.
fn inner_row<F: Float>(row: &[F], xy: [&[F]; 4], nc: usize, factor: f64, out: &mut [F]) {
    let len = row.len();
    let [xn, xp, yn, yp] = xy;
    let planar = |t: usize| {
        let x = row[t].as_f64();
        0.0 + (x - xn[t].as_f64()) + (x - xp[t].as_f64()) + (x - yn[t].as_f64()) + (x - yp[t].as_f64())
    };
    for t in 0..nc {
        out[t] = F::lit(factor * (planar(t) + (row[t].as_f64() - row[t + nc].as_f64())));
    }
    for t in nc..len - nc {
        let x = row[t].as_f64();
        out[t] = F::lit(factor * (planar(t) + (x - row[t + nc].as_f64()) + (x - row[t - nc].as_f64())));
    }
    for t in len - nc..len {
        out[t] = F::lit(factor * (planar(t) + (row[t].as_f64() - row[t - nc].as_f64())));
    }
}

/// `acc[t] += v[t] - n[t]` in f64, for slices of one length.
fn add_differences<F: Float>(acc: &mut [f64], v: &[F], n: &[F]) {
    for ((a, x), y) in acc.iter_mut().zip(v).zip(n) {
        *a += x.as_f64() - y.as_f64();
    }
}

impl<F: Float> CustomOp<F> for TotalVariation {
    type Saved = ();

    fn name(&self) -> &'static str {
        Op::TotalVariation.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let value = self.value(&inputs[0]).map_err(OpError::typed)?;
        Ok((vec![ArrayD::from_elem(IxDyn(&[]), F::lit(value))], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let (true, Some(upstream)) = (ctx.needs_input_grad(0), grads[0].as_ref()) else {
            return Ok(vec![None]);
        };
        let scale = upstream.iter().next().map_or(0.0, |v| v.as_f64());
        let grid = ctx.input(0);
        // Every value is overwritten, so the tape's pooled buffer needs no zeros (a grid's
        // worth of them was a serial pass on every step).
        let len = grid.len();
        let mut out =
            ArrayD::from_shape_vec(IxDyn(grid.shape()), fogray_tape::buffer::scratch(len)).map_err(OpError::typed)?;
        self.gradient_into(&grid, scale, out.view_mut())
            .map_err(OpError::typed)?;
        Ok(vec![Some(out)])
    }
}
