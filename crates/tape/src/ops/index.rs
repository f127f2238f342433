//! Indexing along axis 0: `gather` (index select) and its adjoint `scatter_add`.
//! Each is the other's backward.
//!
//! A table is a sequence of rows (axis 0), each row the elements of the remaining axes. On a
//! contiguous table a row is a slice, so both ops are loops of slice copies and adds over the
//! indices (rows of 1 to 4 elements get loops with the row length known at compile time), and
//! `gather` copies pieces of its output rows on rayon's threads; a strided view is read row by
//! row. `scatter_add` adds each output row's terms in index order
//! (on rayon's threads, each owning a band of output rows), so its result never depends on the
//! machine or the number of threads; in `f32` it accumulates in `f64` and rounds once, so a
//! row that receives many small terms after a large one keeps them.
//!
//! ```
//! use fogray_tape::Tape;
//! use ndarray::arr2;
//!
//! let mut tape = Tape::<f32>::new();
//! let table = tape.param(arr2(&[[1.0f32, 2.0], [3.0, 4.0], [5.0, 6.0]]));
//! let rows = tape.gather(table, &[2, 0, 2])?;
//! assert_eq!(tape.value(rows)?, arr2(&[[5.0f32, 6.0], [1.0, 2.0], [5.0, 6.0]]).into_dyn());
//! let loss = tape.sum(rows)?;
//! let grads = tape.backward(loss)?;
//! // Each row's gradient counts how often it was picked.
//! assert_eq!(grads.get(table).unwrap(), arr2(&[[1.0f32, 1.0], [0.0, 0.0], [2.0, 2.0]]).into_dyn());
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

use ndarray::{ArrayD, ArrayViewD, Axis, IxDyn};
use rayon::prelude::*;

use crate::buffer::{pieces, scratch, whole_runs, zeroed, PIECE};
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

/// `shape` with its first axis (the rows) replaced by `rows`, and the elements of one row.
fn rows_shape(shape: &[usize], rows: usize) -> (Vec<usize>, usize) {
    let mut out = shape.to_vec();
    out[0] = rows;
    (out, shape[1..].iter().product())
}

fn into_array<F: Float>(shape: Vec<usize>, data: Vec<F>) -> Result<ArrayD<F>, OpError> {
    ArrayD::from_shape_vec(IxDyn(&shape), data).map_err(|e| OpError::InvalidArgument(e.to_string()))
}

/// Rows `indices` of `x` (every index already checked to be below `x`'s row count). From a
/// contiguous table the output is cut into pieces of whole rows on rayon's threads (each
/// output row is one copy, so nothing depends on the threads); a strided table is read row by
/// row on the calling thread.
fn gather<F: Float>(x: &ArrayViewD<'_, F>, indices: &[usize]) -> Result<ArrayD<F>, OpError> {
    let (shape, c) = rows_shape(x.shape(), indices.len());
    let mut out = scratch::<F>(indices.len() * c);
    if c > 0 {
        match x.as_slice() {
            Some(table) => {
                pieces(&mut out, whole_runs(c), |start, out| {
                    let first = start / c;
                    copy_rows(table, &indices[first..first + out.len() / c], c, out)
                });
            }
            None => {
                for (dst, &i) in out.chunks_exact_mut(c).zip(indices) {
                    for (d, &v) in dst.iter_mut().zip(x.index_axis(Axis(0), i).iter()) {
                        *d = v;
                    }
                }
            }
        }
    }
    into_array(shape, out)
}

/// `out` (one row of `c` elements per index) = rows `indices` of the row-major `table`.
fn copy_rows<F: Float>(table: &[F], indices: &[usize], c: usize, out: &mut [F]) {
    match c {
        1 => copy_rows_of::<F, 1>(table, indices, out),
        2 => copy_rows_of::<F, 2>(table, indices, out),
        3 => copy_rows_of::<F, 3>(table, indices, out),
        4 => copy_rows_of::<F, 4>(table, indices, out),
        _ => {
            for (dst, &i) in out.chunks_exact_mut(c).zip(indices) {
                dst.copy_from_slice(&table[i * c..(i + 1) * c]);
            }
        }
    }
}

/// [`copy_rows`] for rows of `C` elements, which the compiler unrolls.
fn copy_rows_of<F: Float, const C: usize>(table: &[F], indices: &[usize], out: &mut [F]) {
    for (dst, &i) in out.chunks_exact_mut(C).zip(indices) {
        dst.copy_from_slice(&table[i * C..(i + 1) * C]);
    }
}

/// Row `k` of `x` added into row `indices[k]` of `rows` zero rows (indices already checked).
fn scatter_add<F: Float>(x: &ArrayViewD<'_, F>, indices: &[usize], rows: usize) -> Result<ArrayD<F>, OpError> {
    let (shape, c) = rows_shape(x.shape(), rows);
    let len = rows * c;
    let standard = x.as_standard_layout();
    let Some(xs) = standard.as_slice() else {
        return Err(OpError::InvalidArgument("could not lay the input out in rows".into()));
    };
    if c == 0 {
        return into_array(shape, zeroed(len));
    }
    // f32 sums go through f64: a row can receive thousands of terms.
    let out = if F::NAME == f64::NAME {
        let mut out = zeroed::<F>(len);
        add_rows_in_bands(&mut out, xs, indices, c);
        out
    } else {
        let mut wide = vec![0.0f64; len];
        add_rows_in_bands(&mut wide, xs, indices, c);
        let mut out = scratch::<F>(len);
        pieces(&mut out, PIECE, |start, out| {
            for (o, &w) in out.iter_mut().zip(&wide[start..]) {
                *o = F::lit(w);
            }
        });
        out
    };
    into_array(shape, out)
}

/// Terms (input rows) below which a scatter stays on the calling thread.
const PARALLEL_ROWS: usize = 1 << 14;

/// `acc[indices[k]] += xs[k]` row by row, the terms widened to `A`, with the output rows cut
/// into one band per thread of rayon's pool: each band's task reads every index and adds the
/// rows that fall in its band, in index order. Every output row therefore sums the same terms
/// in the same order as one sequential pass, whatever the number of threads.
fn add_rows_in_bands<A: Float, F: Float>(acc: &mut [A], xs: &[F], indices: &[usize], c: usize) {
    let rows = acc.len() / c;
    let threads = rayon::current_num_threads();
    if threads == 1 || indices.len() < PARALLEL_ROWS || rows < threads {
        add_rows(acc, xs, indices, c, 0);
        return;
    }
    let band = rows.div_ceil(threads);
    acc.par_chunks_mut(band * c)
        .enumerate()
        .for_each(|(b, acc)| add_rows(acc, xs, indices, c, b * band));
}

/// `acc[indices[k] - first] += xs[k]` in index order for the indices in `first..first + rows`
/// (`rows` being `acc`'s row count), the terms widened to `A`; other indices are skipped.
fn add_rows<A: Float, F: Float>(acc: &mut [A], xs: &[F], indices: &[usize], c: usize, first: usize) {
    match c {
        1 => add_rows_of::<A, F, 1>(acc, xs, indices, first),
        2 => add_rows_of::<A, F, 2>(acc, xs, indices, first),
        3 => add_rows_of::<A, F, 3>(acc, xs, indices, first),
        4 => add_rows_of::<A, F, 4>(acc, xs, indices, first),
        _ => {
            let rows = acc.len() / c;
            for (src, &i) in xs.chunks_exact(c).zip(indices) {
                // Below `first`, the subtraction wraps to a huge row: skipped as well.
                let r = i.wrapping_sub(first);
                if r < rows {
                    for (a, &v) in acc[r * c..(r + 1) * c].iter_mut().zip(src) {
                        *a += A::lit(v.as_f64());
                    }
                }
            }
        }
    }
}

/// [`add_rows`] for rows of `C` elements.
fn add_rows_of<A: Float, F: Float, const C: usize>(acc: &mut [A], xs: &[F], indices: &[usize], first: usize) {
    let rows = acc.len() / C;
    for (src, &i) in xs.chunks_exact(C).zip(indices) {
        let r = i.wrapping_sub(first);
        if r < rows {
            for (a, &v) in acc[r * C..(r + 1) * C].iter_mut().zip(src) {
                *a += A::lit(v.as_f64());
            }
        }
    }
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
        Ok((vec![gather(x, &self.0)?], ()))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        Ok(vec![Some(scatter_add(g, &self.0, ctx.input(0).shape()[0])?)])
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
        Ok((vec![scatter_add(x, &self.indices, self.rows)?], ()))
    }
    fn backward(
        &self,
        _ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else { return Ok(vec![None]) };
        Ok(vec![Some(gather(g, &self.indices)?)])
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
    use crate::{Tape, TapeError, Var};
    use ndarray::{arr1, arr2, ArrayD, Axis, IxDyn};
    use rand::{Rng, SeedableRng};

    /// The tables of the oracle tests: every row length with its own loop (1 to 4), a longer
    /// one, rows of several axes, and empty rows; each in standard layout and as the
    /// column-major layout of the same values (a strided value on the tape).
    fn tables(rng: &mut rand::rngs::StdRng) -> Vec<ArrayD<f64>> {
        let shapes: [&[usize]; 8] = [&[5], &[5, 1], &[5, 2], &[5, 3], &[5, 4], &[5, 7], &[5, 2, 3], &[5, 0]];
        let mut out = Vec::new();
        for shape in shapes {
            let x = ArrayD::from_shape_fn(IxDyn(shape), |_| rng.gen_range(-1.0..1.0));
            let column_major = x
                .clone()
                .reversed_axes()
                .as_standard_layout()
                .into_owned()
                .reversed_axes();
            assert_eq!(column_major, x);
            if shape[1..].iter().product::<usize>() > 1 {
                assert!(
                    !column_major.is_standard_layout(),
                    "{shape:?} must take the strided path"
                );
            }
            out.push(x);
            out.push(column_major);
        }
        out
    }

    /// Row by row through ndarray's indexing, summed in index order as the op does.
    fn scatter_oracle(x: &ArrayD<f64>, indices: &[usize], rows: usize) -> ArrayD<f64> {
        let mut shape = x.shape().to_vec();
        shape[0] = rows;
        let mut out = ArrayD::zeros(IxDyn(&shape));
        for (k, &i) in indices.iter().enumerate() {
            let mut row = out.index_axis_mut(Axis(0), i);
            row += &x.index_axis(Axis(0), k);
        }
        out
    }

    /// The values of `op` applied to an f32 parameter of `shape` holding `values`, on a pool of
    /// `threads` threads.
    fn on_threads(
        threads: usize,
        shape: &[usize],
        values: &[f32],
        op: impl Fn(&mut Tape<f32>, Var) -> Result<Var, TapeError> + Send + Sync,
    ) -> Vec<f32> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut t = Tape::<f32>::new();
            let x = t.param(ArrayD::from_shape_vec(IxDyn(shape), values.to_vec()).unwrap());
            let y = op(&mut t, x).unwrap();
            t.value(y).unwrap().iter().copied().collect()
        })
    }

    #[test]
    fn a_large_scatter_in_bands_is_the_sequential_sum_on_any_number_of_threads() {
        // Past the parallel threshold, rows that do not divide into the bands evenly, repeated
        // indices (about 37 terms a row) and the row lengths with their own loops and without.
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let (rows, n) = (1331, 50_000);
        let indices: Vec<usize> = (0..n).map(|_| rng.gen_range(0..rows)).collect();
        for c in [1, 4, 5] {
            let x: Vec<f32> = (0..n * c).map(|_| rng.gen_range(-1.0f32..1.0)).collect();
            // The oracle: one pass in index order, f64 sums rounded once.
            let mut sums = vec![0.0f64; rows * c];
            for (k, &i) in indices.iter().enumerate() {
                for j in 0..c {
                    sums[i * c + j] += x[k * c + j] as f64;
                }
            }
            let want: Vec<f32> = sums.iter().map(|&v| v as f32).collect();
            for threads in [1, 2, 3] {
                let got = on_threads(threads, &[n, c], &x, |t, x| t.scatter_add(x, &indices, rows));
                assert!(
                    got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "row length {c} on {threads} threads"
                );
            }
        }
    }

    #[test]
    fn a_large_gather_in_pieces_is_the_row_by_row_copy_on_any_number_of_threads() {
        // Past the parallel threshold, with row lengths that divide the default piece (1, 4)
        // and one whose pieces are cut down to whole rows (5), and more rows than a piece.
        let mut rng = rand::rngs::StdRng::seed_from_u64(6);
        let (rows, n) = (1331, 50_001);
        let indices: Vec<usize> = (0..n).map(|_| rng.gen_range(0..rows)).collect();
        for c in [1, 4, 5] {
            let table: Vec<f32> = (0..rows * c).map(|_| rng.gen_range(-1.0f32..1.0)).collect();
            let want: Vec<f32> = indices
                .iter()
                .flat_map(|&i| table[i * c..(i + 1) * c].iter().copied())
                .collect();
            for threads in [1, 2, 3] {
                let got = on_threads(threads, &[rows, c], &table, |t, x| t.gather(x, &indices));
                assert_eq!(got.len(), n * c);
                assert!(got == want, "row length {c} on {threads} threads");
            }
        }
    }

    #[test]
    fn gather_and_scatter_match_an_ndarray_oracle_for_every_row_length_and_layout() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for x in tables(&mut rng) {
            let indices: Vec<usize> = (0..23).map(|_| rng.gen_range(0..5)).collect();
            let mut t = Tape::<f64>::new();
            let xv = t.param(x.clone());
            let g = t.gather(xv, &indices).unwrap();
            assert_eq!(
                t.value(g).unwrap(),
                x.select(Axis(0), &indices),
                "gather {:?}",
                x.shape()
            );
            // The backward of gather is a scatter of the upstream rows.
            let seed = ArrayD::from_shape_fn(IxDyn(t.shape(g).unwrap()), |_| rng.gen_range(-1.0..1.0));
            let grads = t.backward_with(g, seed.clone()).unwrap();
            assert_eq!(
                grads.get(xv).unwrap(),
                scatter_oracle(&seed, &indices, 5),
                "d gather {:?}",
                x.shape()
            );
            // scatter_add forward from a strided or contiguous input, into 7 rows.
            let targets: Vec<usize> = (0..5).map(|_| rng.gen_range(0..7)).collect();
            let s = t.scatter_add(xv, &targets, 7).unwrap();
            assert_eq!(
                t.value(s).unwrap(),
                scatter_oracle(&x, &targets, 7),
                "scatter {:?}",
                x.shape()
            );
        }
    }

    #[test]
    fn f32_scatter_keeps_small_terms_after_a_large_one() {
        // Row 0 receives 1e8 and then a thousand ones: 100001000, a multiple of 8 and so exactly
        // an f32 (the spacing of f32 at 1e8 is 8). Summed in f32, each 1e8 + 1 rounds back to 1e8.
        let mut values = vec![1.0f32; 1001];
        values[0] = 1e8;
        let naive = values.iter().fold(0.0f32, |a, &v| a + v);
        assert_eq!(naive, 1e8, "the f32 sum must really lose the ones");
        let mut t = Tape::<f32>::new();
        let x = t.param(arr1(&values));
        let s = t.scatter_add(x, &[0; 1001], 2).unwrap();
        assert_eq!(t.value(s).unwrap().as_slice().unwrap(), &[100_001_000.0f32, 0.0]);
    }

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
        // The message names the index, its position and the rows; the tape is unchanged.
        let before = t.stats();
        let e = t.gather(x, &[0, 1, 5]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "gather: index 5 at position 2 is out of range for 2 rows"
        );
        assert_eq!(t.stats(), before);
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
