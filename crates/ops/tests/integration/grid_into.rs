//! The grid field into buffers the caller keeps (`evaluate_into`, `vjp_into`): the same bits
//! as the allocating calls with every value overwritten, each gradient only where its buffer
//! is given, and on bad input an error with every buffer unchanged.

use crate::grid_common;

use fogray_ops::{At, GridField, GridGradientBuffers, GridWanted, Op, OpsError};
use grid_common::random_field;
use ndarray::{Array2, ArrayD, ShapeBuilder};
use rand::{Rng, SeedableRng};

fn bits<F: fogray_tape::Float>(a: &ArrayD<F>) -> Vec<u64> {
    a.iter().map(|v| v.as_f64().to_bits()).collect()
}

struct Case<F> {
    field: GridField,
    grid: ArrayD<F>,
    pts: ArrayD<F>,
    up: ArrayD<F>,
}

/// Positions in and around the box of a random 2-D or 3-D field.
fn case<F: fogray_tape::Float>(seed: u64, nodes: &[usize], ch: usize, n: usize) -> Case<F> {
    let (field, grid) = random_field(seed, nodes, ch);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed + 1);
    let d = field.dims();
    let pts = Array2::from_shape_fn((n, d), |(_, a)| {
        let (lo, hi) = (field.bbox().min()[a], field.bbox().max()[a]);
        F::lit(rng.gen_range(lo - 0.1..hi + 0.1))
    });
    let up = Array2::from_shape_fn((n, ch), |_| F::lit(rng.gen_range(-1.0..1.0)));
    Case {
        grid: grid.mapv(F::lit),
        pts: pts.into_dyn(),
        up: up.into_dyn(),
        field,
    }
}

fn same_bits_as_the_allocating_calls<F: fogray_tape::Float>() {
    for (seed, nodes, ch) in [(1, vec![7, 5, 6], 4), (2, vec![9, 4], 3), (3, vec![5, 6, 4], 8)] {
        let x = case::<F>(seed, &nodes, ch, 3000);
        let (g, p, u) = (x.grid.view(), x.pts.view(), x.up.view());
        let want_out = x.field.evaluate(&g, &p).unwrap();
        let mut out = ArrayD::from_elem(want_out.shape(), F::lit(f64::NAN));
        x.field.evaluate_into(&g, &p, &mut out.view_mut()).unwrap();
        assert_eq!(bits(&out), bits(&want_out), "output, {nodes:?}");
        for (grid, positions) in [(true, true), (true, false), (false, true), (false, false)] {
            let want = x.field.vjp(&g, &p, &u, GridWanted { grid, positions }).unwrap();
            let mut dgrid = ArrayD::from_elem(x.grid.shape(), F::lit(f64::NAN));
            let mut dpos = ArrayD::from_elem(x.pts.shape(), F::lit(f64::NAN));
            let mut buffers = GridGradientBuffers {
                grid: grid.then(|| dgrid.view_mut()),
                positions: positions.then(|| dpos.view_mut()),
            };
            x.field.vjp_into(&g, &p, &u, &mut buffers).unwrap();
            let nan = |a: &ArrayD<F>| a.iter().all(|v| v.as_f64().is_nan());
            match want.grid {
                Some(w) => assert_eq!(bits(&dgrid), bits(&w), "grid gradient, {nodes:?}"),
                None => assert!(nan(&dgrid), "grid gradient written unasked"),
            }
            match want.positions {
                Some(w) => assert_eq!(bits(&dpos), bits(&w), "position gradient, {nodes:?}"),
                None => assert!(nan(&dpos), "position gradient written unasked"),
            }
        }
    }
}

#[test]
fn into_buffers_give_the_same_bits_f32() {
    same_bits_as_the_allocating_calls::<f32>();
}

#[test]
fn into_buffers_give_the_same_bits_f64() {
    same_bits_as_the_allocating_calls::<f64>();
}

#[test]
fn bad_buffers_are_errors_and_nothing_is_written() {
    let x = case::<f64>(4, &[6, 5, 4], 3, 100);
    let (g, p, u) = (x.grid.view(), x.pts.view(), x.up.view());
    let shape_error = |r: Result<(), OpsError>, what: &str| match r {
        Err(OpsError::Shape {
            op: Op::GridField,
            what: w,
            ..
        }) => assert_eq!(w, what),
        other => panic!("{what}: {other:?}"),
    };
    // The output: a wrong shape, then the right shape but strided (column-major).
    let mut short = ArrayD::from_elem(vec![99, 3], 7.0);
    shape_error(x.field.evaluate_into(&g, &p, &mut short.view_mut()), "output buffer");
    assert!(short.iter().all(|&v| v == 7.0));
    let mut strided = ArrayD::from_elem(vec![100, 3].f(), 7.0);
    shape_error(x.field.evaluate_into(&g, &p, &mut strided.view_mut()), "output buffer");
    assert!(strided.iter().all(|&v| v == 7.0));
    // A good grid buffer beside a bad position buffer: neither is written.
    let mut dgrid = ArrayD::from_elem(x.grid.shape(), 7.0);
    let mut dpos = ArrayD::from_elem(vec![100, 2], 7.0);
    let mut buffers = GridGradientBuffers {
        grid: Some(dgrid.view_mut()),
        positions: Some(dpos.view_mut()),
    };
    shape_error(x.field.vjp_into(&g, &p, &u, &mut buffers), "position gradient buffer");
    assert!(dgrid.iter().chain(dpos.iter()).all(|&v| v == 7.0));
    // A bad grid buffer.
    let mut dgrid = ArrayD::from_elem(vec![6, 5, 4, 2], 7.0);
    let mut buffers = GridGradientBuffers {
        grid: Some(dgrid.view_mut()),
        positions: None,
    };
    shape_error(x.field.vjp_into(&g, &p, &u, &mut buffers), "grid gradient buffer");
    assert!(dgrid.iter().all(|&v| v == 7.0));
    // A NaN position: its error, and nothing written.
    let mut pts = x.pts.clone();
    pts[[17, 1]] = f64::NAN;
    let mut out = ArrayD::from_elem(vec![100, 3], 7.0);
    let r = x.field.evaluate_into(&g, &pts.view(), &mut out.view_mut());
    assert!(matches!(
        r,
        Err(OpsError::Domain {
            op: Op::GridField,
            at: At::Entry { row: 17, column: 1 },
            ..
        })
    ));
    let mut dgrid = ArrayD::from_elem(x.grid.shape(), 7.0);
    let mut buffers = GridGradientBuffers {
        grid: Some(dgrid.view_mut()),
        positions: None,
    };
    let r = x.field.vjp_into(&g, &pts.view(), &u, &mut buffers);
    assert!(matches!(
        r,
        Err(OpsError::Domain {
            op: Op::GridField,
            at: At::Entry { row: 17, column: 1 },
            ..
        })
    ));
    assert!(out.iter().chain(dgrid.iter()).all(|&v| v == 7.0));
}
