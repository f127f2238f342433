//! The grid field's results do not depend on the number of threads (bitwise), and its grid
//! gradient sums long runs of terms in f64.

mod grid_common;

use fogray_ops::{GridBox, GridField, GridWanted};
use grid_common::random_field;
use ndarray::{Array2, Array4, ArrayD};
use rand::{Rng, SeedableRng};

const BOTH: GridWanted = GridWanted {
    grid: true,
    positions: true,
};

type Results = (ArrayD<f32>, ArrayD<f32>, ArrayD<f32>);

fn on_threads(threads: usize, field: &GridField, grid: &ArrayD<f32>, pts: &Array2<f32>, up: &Array2<f32>) -> Results {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let out = field.evaluate(&grid.view(), &pts.view().into_dyn()).unwrap();
        let g = field
            .vjp(&grid.view(), &pts.view().into_dyn(), &up.view().into_dyn(), BOTH)
            .unwrap();
        (out, g.grid.unwrap(), g.positions.unwrap())
    })
}

/// Many positions per cell (so that the order of the sums shows in the last bits), more
/// positions than one sorting block holds, on grids cut into one slab, into slabs of one
/// cell layer (64 x 64 x 4 values per layer) and of two (64 x 32 x 4), 2-D and 3-D.
#[test]
fn results_are_bitwise_the_same_on_any_thread_count() {
    let cases = [
        (1, vec![9, 6, 5], 3),
        (2, vec![40, 3, 2], 4),
        (3, vec![30, 30], 2),
        (4, vec![12, 64, 64], 4),
        (5, vec![20, 64, 32], 4),
        (6, vec![9, 4096], 4),
    ];
    for (seed, nodes, ch) in cases {
        let (field, grid) = random_field(seed, &nodes, ch);
        let grid = grid.mapv(|v| v as f32);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let n = 70_000;
        let d = field.dims();
        let pts = Array2::from_shape_fn((n, d), |(_, a)| {
            let (lo, hi) = (field.bbox().min()[a], field.bbox().max()[a]);
            rng.gen_range(lo - 0.05..hi + 0.05) as f32
        });
        let up = Array2::from_shape_fn((n, ch), |_| rng.gen_range(-1.0f32..1.0));
        let one = on_threads(1, &field, &grid, &pts, &up);
        for threads in [2, 3] {
            let other = on_threads(threads, &field, &grid, &pts, &up);
            let bits = |a: &ArrayD<f32>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&one.0), bits(&other.0), "output, {threads} threads");
            assert_eq!(bits(&one.1), bits(&other.1), "grid gradient, {threads} threads");
            assert_eq!(bits(&one.2), bits(&other.2), "position gradient, {threads} threads");
        }
        assert!(one.1.iter().any(|&v| v != 0.0));
    }
}

/// 2^20 positions at the centre of one cell, each with upstream gradient 0.1 (in f32): each of
/// the 8 nodes collects 2^20 terms of 0.125 * 0.1. Summed in f64 and rounded once the
/// gradient is within f32 rounding of the exact 2^17 * 0.1; the same sum in f32 drifts by
/// about a percent (shown below).
#[test]
fn grid_gradient_sums_in_f64() {
    let field = GridField::new(GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap(), &[2, 2, 2, 1]).unwrap();
    let n = 1 << 20;
    let grid = Array4::<f32>::zeros((2, 2, 2, 1)).into_dyn();
    let pts = Array2::from_elem((n, 3), 0.5f32);
    let up = Array2::from_elem((n, 1), 0.1f32);
    let g = field
        .vjp(
            &grid.view(),
            &pts.view().into_dyn(),
            &up.view().into_dyn(),
            GridWanted {
                grid: true,
                positions: false,
            },
        )
        .unwrap();
    let exact = f64::from(0.1f32) * 0.125 * n as f64;
    for &v in g.grid.unwrap().iter() {
        assert!((f64::from(v) - exact).abs() <= 1e-7 * exact, "{v} vs {exact}");
    }
    let naive = (0..n).fold(0.0f32, |acc, _| acc + 0.125 * 0.1f32);
    assert!(
        (f64::from(naive) - exact).abs() > 1e-3 * exact,
        "the naive f32 sum {naive} is too good"
    );
}
