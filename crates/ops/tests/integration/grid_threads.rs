//! The grid field's results do not depend on the number of threads (bitwise), and its grid
//! gradient sums long runs of terms in f64.

use crate::grid_common;

use fogray_ops::{GridBox, GridField, GridGradientBuffers, GridWanted};
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

/// Positions along rays, in ray order (as a renderer's samples come): `rays` rays through
/// random points of the box in random directions, a sample every half cell along each.
fn ray_ordered(seed: u64, field: &GridField, rays: usize) -> Array2<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let (lo, hi) = (field.bbox().min().to_vec(), field.bbox().max().to_vec());
    let step = (0..3)
        .map(|a| (hi[a] - lo[a]) / (field.nodes()[a] - 1) as f64)
        .fold(f64::INFINITY, f64::min)
        / 2.0;
    let mut pts = Vec::new();
    for _ in 0..rays {
        let o: Vec<f64> = (0..3).map(|a| rng.gen_range(lo[a]..hi[a])).collect();
        let d: Vec<f64> = (0..3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-3);
        let mut p = o.clone();
        // Back to the box's edge, then forward across it.
        while (0..3).all(|a| (lo[a]..=hi[a]).contains(&(p[a] - step * d[a] / norm))) {
            (0..3).for_each(|a| p[a] -= step * d[a] / norm);
        }
        while (0..3).all(|a| (lo[a]..=hi[a]).contains(&p[a])) {
            pts.extend_from_slice(&p);
            (0..3).for_each(|a| p[a] += step * d[a] / norm);
        }
    }
    Array2::from_shape_vec((pts.len() / 3, 3), pts).unwrap()
}

/// The fit's case: samples ordered ray by ray (consecutive positions in neighbouring cells)
/// on a grid cut into many slabs and tiles. The f32 results are bitwise the same on 1, 2 and 3
/// threads, and the grid gradient is the f64 oracle's rounded once to f32 (its sums are exact
/// to far below an f32 rounding step).
#[test]
fn ray_ordered_lookups_are_deterministic_and_rounded_once() {
    let (field, grid) = random_field(11, &[40, 36, 44], 4);
    let pts = ray_ordered(12, &field, 1500);
    assert!(
        pts.nrows() > 2 * 32_768,
        "{} samples: more than two sorting blocks",
        pts.nrows()
    );
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    // f32-representable upstream gradients, so the oracle sees the op's exact inputs.
    let up = Array2::from_shape_fn((pts.nrows(), 4), |_| f64::from(rng.gen_range(-1.0f32..1.0)));
    let pts32 = pts.mapv(|v| v as f32);
    let (grid32, up32) = (grid.mapv(|v| v as f32), up.mapv(|v| v as f32));
    let one = on_threads(1, &field, &grid32, &pts32, &up32);
    for threads in [2, 3] {
        let other = on_threads(threads, &field, &grid32, &pts32, &up32);
        let bits = |a: &ArrayD<f32>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&one.0), bits(&other.0), "output, {threads} threads");
        assert_eq!(bits(&one.1), bits(&other.1), "grid gradient, {threads} threads");
        assert_eq!(bits(&one.2), bits(&other.2), "position gradient, {threads} threads");
    }
    let exact = grid_common::oracle_grid_gradient(&field, &pts32.mapv(f64::from), &up);
    let mut nonzero = 0;
    for (&got, &want) in one.1.iter().zip(exact.iter()) {
        assert_eq!(got, want as f32, "{got} vs {want}");
        nonzero += usize::from(want != 0.0);
    }
    assert!(nonzero > exact.len() / 2, "{nonzero} of {} nodes reached", exact.len());
}

/// A field keeps its backward's buffers between calls: a second call with other inputs (more
/// positions, then fewer, then in f64) gives what a new field gives, bit for bit.
#[test]
fn kept_buffers_leave_no_trace() {
    let (field, grid) = random_field(21, &[30, 20, 25], 3);
    let mut rng = rand::rngs::StdRng::seed_from_u64(22);
    let mut case = |n: usize| {
        let pts = Array2::from_shape_fn((n, 3), |(_, a)| {
            rng.gen_range(field.bbox().min()[a] - 0.1..field.bbox().max()[a] + 0.1)
        });
        let up = Array2::from_shape_fn((n, 3), |_| rng.gen_range(-1.0..1.0));
        (pts, up)
    };
    let cases = [case(50_000), case(90_000), case(7_000)];
    let grad = |field: &GridField, (pts, up): &(Array2<f64>, Array2<f64>), f32: bool| -> Vec<u64> {
        let wanted = GridWanted {
            grid: true,
            positions: false,
        };
        if f32 {
            let (g, p, u) = (grid.mapv(|v| v as f32), pts.mapv(|v| v as f32), up.mapv(|v| v as f32));
            let out = field.vjp(&g.view(), &p.view().into_dyn(), &u.view().into_dyn(), wanted);
            out.unwrap()
                .grid
                .unwrap()
                .iter()
                .map(|v| u64::from(v.to_bits()))
                .collect()
        } else {
            let out = field.vjp(&grid.view(), &pts.view().into_dyn(), &up.view().into_dyn(), wanted);
            out.unwrap().grid.unwrap().iter().map(|v| v.to_bits()).collect()
        }
    };
    let kept = field.clone();
    for f32 in [true, false, true] {
        for c in &cases {
            let fresh = GridField::new(*field.bbox(), field.shape()).unwrap();
            assert_eq!(grad(&kept, c, f32), grad(&fresh, c, f32), "{} positions", c.0.nrows());
        }
    }
    kept.release_buffers();
    assert_eq!(grad(&kept, &cases[0], true), grad(&field, &cases[0], true));
}

/// The training loop's path: ray-ordered lookups with 8 channels (summed in groups of 4)
/// through `evaluate_into` and `vjp_into`, into kept buffers first filled with NaN. On 1, 2 and
/// 3 threads the f32 results are bitwise the same, every value is written, the output is the
/// f64 oracle's within f32 rounding of its terms, and the grid gradient is the f64 oracle's
/// rounded once.
#[test]
fn ray_ordered_lookups_into_kept_buffers_with_channel_groups() {
    let ch = 8;
    let (field, grid) = random_field(31, &[24, 20, 28], ch);
    let pts = ray_ordered(32, &field, 900);
    assert!(
        pts.nrows() > 32_768,
        "{} samples: more than one sorting block",
        pts.nrows()
    );
    let mut rng = rand::rngs::StdRng::seed_from_u64(33);
    let up = Array2::from_shape_fn((pts.nrows(), ch), |_| f64::from(rng.gen_range(-1.0f32..1.0)));
    let (grid32, pts32, up32) = (grid.mapv(|v| v as f32), pts.mapv(|v| v as f32), up.mapv(|v| v as f32));
    let mut out = ArrayD::from_elem(vec![pts.nrows(), ch], f32::NAN);
    let mut dgrid = ArrayD::from_elem(field.shape(), f32::NAN);
    let mut dpos = ArrayD::from_elem(vec![pts.nrows(), 3], f32::NAN);
    let mut run = |threads: usize| -> Vec<Vec<u32>> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let (g, p, u) = (grid32.view(), pts32.view().into_dyn(), up32.view().into_dyn());
            field.evaluate_into(&g, &p, &mut out.view_mut()).unwrap();
            let mut buffers = GridGradientBuffers {
                grid: Some(dgrid.view_mut()),
                positions: Some(dpos.view_mut()),
            };
            field.vjp_into(&g, &p, &u, &mut buffers).unwrap();
        });
        [&out, &dgrid, &dpos]
            .map(|a| a.iter().map(|v| v.to_bits()).collect())
            .to_vec()
    };
    let one = run(1);
    for threads in [2, 3] {
        assert_eq!(one, run(threads), "{threads} threads");
    }
    let exact_out = grid_common::oracle(&field, &grid32.mapv(f64::from), &pts32.mapv(f64::from));
    for (&got, &want) in out.iter().zip(exact_out.iter()) {
        assert!((f64::from(got) - want).abs() <= 4e-7, "{got} vs {want}");
    }
    let exact = grid_common::oracle_grid_gradient(&field, &pts32.mapv(f64::from), &up);
    for (&got, &want) in dgrid.iter().zip(exact.iter()) {
        assert_eq!(got, want as f32, "{got} vs {want}");
    }
    assert!(dpos.iter().all(|v| v.is_finite()));
}
