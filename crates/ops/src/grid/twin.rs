//! The grid field written with tape primitives only: the reference the fused op is checked
//! against and the baseline it is measured against.
//!
//! Each position's cell (its corner node indices) and whether it lies in the box are read
//! from the positions' values and enter the tape as constants; the fractions
//! `t_a = (p_a - min_a) (n_a - 1) / (max_a - min_a) - i_a` are computed on the tape from the
//! positions, so the twin differentiates into the grid values (through `gather`) and into the
//! positions (through the weights). Out of the box, `select` gives the fractions an exact zero
//! gradient and a 0/1 mask zeroes the output.

use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array2, ArrayD};
use rayon::prelude::*;

use super::config::GridField;
use super::geometry::Layout;

fn invalid(reason: String) -> TapeError {
    TapeError::InvalidArgument {
        op: "grid_field_twin",
        reason,
    }
}

/// What the twin takes from the positions' values: per position, the cell's first node and
/// each axis's cell index (0 out of the box), and whether it is in the box.
struct Cells {
    node: Vec<usize>,
    index: Vec<Array2<f64>>,
    inside: Vec<bool>,
}

/// Positions a parallel task of [`cells`] locates.
const CELLS_CHUNK: usize = 4096;

/// Every position's cell, located on rayon's threads in chunks (each position's entries are
/// written by one task, so nothing depends on the threads).
fn cells<F: Float, const D: usize>(layout: &Layout<D>, positions: &[F], n: usize) -> Cells {
    let mut node = vec![0; n];
    let mut index = vec![0.0f64; n * D];
    let mut inside = vec![false; n];
    node.par_chunks_mut(CELLS_CHUNK)
        .zip(index.par_chunks_mut(CELLS_CHUNK * D))
        .zip(inside.par_chunks_mut(CELLS_CHUNK))
        .zip(positions.par_chunks(CELLS_CHUNK * D))
        .for_each(|(((node, index), inside), positions)| {
            for (s, p) in positions.chunks_exact(D).enumerate() {
                let p: [f64; D] = std::array::from_fn(|a| p[a].as_f64());
                if let Some(cell) = layout.locate(p) {
                    node[s] = cell.node;
                    inside[s] = true;
                    for (a, &i) in cell.index.iter().enumerate() {
                        index[s * D + a] = i as f64;
                    }
                }
            }
        });
    let index = (0..D)
        .map(|a| Array2::from_shape_fn((n, 1), |(s, _)| index[s * D + a]))
        .collect();
    Cells { node, index, inside }
}

/// The lookup of `grid` at `positions` as [`GridField::apply`] computes it, with tape ops
/// (`reshape`, `slice`, scalar arithmetic, `select`, `mul`, `gather`, `add`); gradients reach
/// both the grid values and the positions. Same inputs and output as the fused op.
///
/// Errors: the fused op's ([`GridField::evaluate`]'s, in words, as
/// [`TapeError::InvalidArgument`]), or a stale handle; the tape is unchanged on a rejected
/// input.
pub fn lookup<F: Float>(tape: &mut Tape<F>, field: &GridField, grid: Var, positions: Var) -> Result<Var, TapeError> {
    match field.dims() {
        2 => lookup_in::<F, 2>(tape, field, grid, positions),
        _ => lookup_in::<F, 3>(tape, field, grid, positions),
    }
}

fn lookup_in<F: Float, const D: usize>(
    tape: &mut Tape<F>,
    field: &GridField,
    grid: Var,
    positions: Var,
) -> Result<Var, TapeError> {
    let layout = Layout::<D>::new(&field.bbox, field.nodes());
    let (c, n) = {
        let (g, p) = (tape.value(grid)?, tape.value(positions)?);
        let x = field.check(&g, &p).map_err(|e| invalid(e.to_string()))?;
        (cells(&layout, &x.positions, x.n), x.n)
    };
    let ch = field.channels();
    let nodes: usize = field.nodes().iter().product();
    let rows = tape.reshape(grid, &[nodes, ch])?;
    let inside = ArrayD::from_shape_vec(vec![n, 1], c.inside.clone()).map_err(|e| invalid(e.to_string()))?;
    let zero = tape.scalar(F::zero());
    let mut t = Vec::with_capacity(D);
    let mut one_minus_t = Vec::with_capacity(D);
    for a in 0..D {
        let axis = layout.axes[a];
        let p = tape.slice(positions, 1, a, a + 1)?;
        let shifted = tape.sub_scalar(p, F::lit(axis.min))?;
        let u = tape.mul_scalar(shifted, F::lit(axis.scale))?;
        let i = tape.constant(c.index[a].mapv(F::lit));
        let frac = tape.sub(u, i)?;
        let ta = tape.select(inside.clone(), frac, zero)?;
        one_minus_t.push(tape.rsub_scalar(ta, F::one())?);
        t.push(ta);
    }
    let mut sum = None;
    for k in 0..1usize << D {
        let factor = |a: usize| {
            if k >> (D - 1 - a) & 1 == 1 {
                t[a]
            } else {
                one_minus_t[a]
            }
        };
        let mut w = factor(0);
        for a in 1..D {
            w = tape.mul(w, factor(a))?;
        }
        let corner = layout.corners[k];
        let idx: Vec<usize> = c.node.par_iter().map(|&node| node + corner).collect();
        let values = tape.gather(rows, &idx)?;
        let term = tape.mul(values, w)?;
        sum = Some(match sum {
            None => term,
            Some(s) => tape.add(s, term)?,
        });
    }
    let mask = tape.constant(Array2::from_shape_fn((n, 1), |(s, _)| {
        if c.inside[s] {
            F::one()
        } else {
            F::zero()
        }
    }));
    let sum = sum.ok_or_else(|| invalid("no corner".into()))?;
    tape.mul(sum, mask)
}
