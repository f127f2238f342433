//! Helpers shared by the grid field tests: random grids and positions, and a plain-loop f64
//! oracle written from the formulas (independent of the op's kernels).

#![allow(dead_code)]

use fogray_ops::{GridBox, GridField};
use ndarray::{Array2, ArrayD, IxDyn};
use rand::{Rng, SeedableRng};

/// A field with random box and node counts `nodes`, and random values in [-1, 1].
pub fn random_field(seed: u64, nodes: &[usize], ch: usize) -> (GridField, ArrayD<f64>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let min: Vec<f64> = nodes.iter().map(|_| rng.gen_range(-2.0..1.0)).collect();
    let max: Vec<f64> = min.iter().map(|m| m + rng.gen_range(0.5..3.0)).collect();
    let mut shape = nodes.to_vec();
    shape.push(ch);
    let field = GridField::new(GridBox::new(&min, &max).unwrap(), &shape).unwrap();
    let values = ArrayD::from_shape_fn(IxDyn(&shape), |_| rng.gen_range(-1.0..1.0));
    (field, values)
}

/// Where node `i` of axis `a` sits.
pub fn node_position(field: &GridField, a: usize, i: f64) -> f64 {
    let (lo, hi) = (field.bbox().min()[a], field.bbox().max()[a]);
    lo + i * (hi - lo) / (field.nodes()[a] - 1) as f64
}

/// `n` positions: each coordinate at a random cell index plus a fraction in `frac`, so that
/// `frac = 0.1..0.9` keeps them away from cell faces.
pub fn positions_in_cells(seed: u64, field: &GridField, n: usize, frac: std::ops::Range<f64>) -> Array2<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let d = field.dims();
    Array2::from_shape_fn((n, d), |(_, a)| {
        let cell = rng.gen_range(0..field.nodes()[a] - 1) as f64;
        node_position(field, a, cell + rng.gen_range(frac.clone()))
    })
}

/// For each position inside the box: its cell along each axis and fractions, by `floor` (the
/// last cell on the max face).
fn cell_of(field: &GridField, p: ndarray::ArrayView1<'_, f64>) -> Option<(Vec<usize>, Vec<f64>)> {
    let d = field.dims();
    let mut cell = vec![0usize; d];
    let mut t = vec![0.0; d];
    for a in 0..d {
        let (lo, hi, n) = (field.bbox().min()[a], field.bbox().max()[a], field.nodes()[a]);
        if !(lo..=hi).contains(&p[a]) {
            return None;
        }
        let u = (p[a] - lo) / (hi - lo) * (n - 1) as f64;
        cell[a] = (u.floor() as usize).min(n - 2);
        t[a] = u - cell[a] as f64;
    }
    Some((cell, t))
}

/// Each corner of a cell: its node's index and its weight.
fn corners(cell: &[usize], t: &[f64]) -> Vec<(Vec<usize>, f64)> {
    let d = cell.len();
    (0..1usize << d)
        .map(|corner| {
            let mut w = 1.0;
            let mut index = Vec::with_capacity(d + 1);
            for a in 0..d {
                let upper = corner >> a & 1;
                w *= if upper == 1 { t[a] } else { 1.0 - t[a] };
                index.push(cell[a] + upper);
            }
            (index, w)
        })
        .collect()
}

/// dL/dgrid for L = sum(output * upstream), scattered one position at a time, in f64.
pub fn oracle_grid_gradient(field: &GridField, positions: &Array2<f64>, upstream: &Array2<f64>) -> ArrayD<f64> {
    let mut out = ArrayD::zeros(IxDyn(field.shape()));
    for (s, p) in positions.rows().into_iter().enumerate() {
        let Some((cell, t)) = cell_of(field, p) else { continue };
        for (mut index, w) in corners(&cell, &t) {
            for c in 0..field.channels() {
                index.push(c);
                out[IxDyn(&index)] += w * upstream[[s, c]];
                index.pop();
            }
        }
    }
    out
}

/// The lookup by the textbook formula: for each position, the cell by `floor` (the last cell
/// on the max face), then the sum over the 2^D corners of the product of the per-axis weights.
pub fn oracle(field: &GridField, grid: &ArrayD<f64>, positions: &Array2<f64>) -> Array2<f64> {
    let ch = field.channels();
    let mut out = Array2::zeros((positions.nrows(), ch));
    for (s, p) in positions.rows().into_iter().enumerate() {
        let Some((cell, t)) = cell_of(field, p) else { continue };
        for (mut index, w) in corners(&cell, &t) {
            for c in 0..ch {
                index.push(c);
                out[[s, c]] += w * grid[IxDyn(&index)];
                index.pop();
            }
        }
    }
    out
}
