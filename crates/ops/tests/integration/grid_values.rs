//! The grid field's values and gradients against hand computations, a linear field (which
//! trilinear interpolation reproduces exactly), a plain-loop oracle, and one-sided differences
//! on cell faces; out-of-box positions; bad input.

use crate::grid_common;

use fogray_ops::{At, GridBox, GridField, GridWanted, Op, OpsError};
use fogray_tape::{Tape, TapeError};
use grid_common::{node_position, oracle, oracle_grid_gradient, positions_in_cells, random_field};
use ndarray::{arr2, Array2, Array3, Array4, ArrayD, IxDyn};
use rand::{Rng, SeedableRng};

const BOTH: GridWanted = GridWanted {
    grid: true,
    positions: true,
};

#[test]
fn hand_computed_trilinear_values() {
    // Box [-1, 3] x [0, 2] x [10, 11] with 2 nodes per axis: one cell. Channel 0 is 1 at the
    // corner (1, 1, 1) only, channel 1 is 8 at the corner (0, 0, 0) only.
    let field = GridField::new(
        GridBox::new(&[-1.0, 0.0, 10.0], &[3.0, 2.0, 11.0]).unwrap(),
        &[2, 2, 2, 2],
    )
    .unwrap();
    let mut grid = Array4::<f64>::zeros((2, 2, 2, 2));
    grid[[1, 1, 1, 0]] = 1.0;
    grid[[0, 0, 0, 1]] = 8.0;
    // p = (0, 0.5, 10.75): t = (1/4, 1/4, 3/4).
    // channel 0 = tx ty tz = 1/4 1/4 3/4 = 3/64; channel 1 = 8 (3/4)(3/4)(1/4) = 9/8.
    let p = arr2(&[[0.0, 0.5, 10.75]]);
    let out = field.evaluate(&grid.view().into_dyn(), &p.view().into_dyn()).unwrap();
    assert_eq!(out, arr2(&[[3.0 / 64.0, 9.0 / 8.0]]).into_dyn());
    // dL/dp for L = out_0: d(tx ty tz)/dp = (ty tz, tx tz, tx ty) * (1/4, 1/2, 1) (cells per
    // unit length) = (3/16 / 4, 3/16 / 2, 1/16) = (3/64, 3/32, 1/16).
    let g = field
        .vjp(
            &grid.view().into_dyn(),
            &p.view().into_dyn(),
            &arr2(&[[1.0, 0.0]]).view().into_dyn(),
            BOTH,
        )
        .unwrap();
    assert_eq!(
        g.positions.unwrap(),
        arr2(&[[3.0 / 64.0, 3.0 / 32.0, 1.0 / 16.0]]).into_dyn()
    );
    // dL/dgrid: channel 0 of each corner gets its weight; (0, 1, 1) has (3/4)(1/4)(3/4) = 9/64.
    let gg = g.grid.unwrap();
    assert_eq!(gg[[0, 1, 1, 0]], 9.0 / 64.0);
    assert_eq!(gg[[1, 1, 1, 0]], 3.0 / 64.0);
    assert_eq!(gg[[0, 1, 1, 1]], 0.0);
}

#[test]
fn hand_computed_bilinear_values() {
    // Box [0, 2] x [0, 1] with 3 x 2 nodes: cells of 1 x 1. Values v(i, j) = 10 i + j
    // (one channel) and w(i, j) = i j (a second one).
    let field = GridField::new(GridBox::new(&[0.0, 0.0], &[2.0, 1.0]).unwrap(), &[3, 2, 2]).unwrap();
    let grid = Array3::from_shape_fn((3, 2, 2), |(i, j, c)| {
        if c == 0 {
            10.0 * i as f64 + j as f64
        } else {
            (i * j) as f64
        }
    });
    // p = (1.5, 0.25): cell (1, 0), t = (0.5, 0.25). v is linear: 15.25. w = (1 - 0.5) 0.25 * 1 +
    // 0.5 * 0.25 * 2 = 0.375.
    let p = arr2(&[[1.5, 0.25]]);
    let out = field.evaluate(&grid.view().into_dyn(), &p.view().into_dyn()).unwrap();
    assert_eq!(out, arr2(&[[15.25, 0.375]]).into_dyn());
}

/// f(x) = a.x + b per channel, sampled at the nodes, is reproduced exactly by the interpolant
/// anywhere in the box, faces included; its gradient in the positions is a.
#[test]
fn linear_fields_are_reproduced_exactly() {
    for dims in [2, 3] {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7 + dims as u64);
        let nodes: Vec<usize> = (0..dims).map(|_| rng.gen_range(2..7)).collect();
        let (field, _) = random_field(dims as u64, &nodes, 2);
        let a: Vec<[f64; 3]> = (0..2)
            .map(|_| {
                [
                    rng.gen_range(-3.0..3.0),
                    rng.gen_range(-3.0..3.0),
                    rng.gen_range(-3.0..3.0),
                ]
            })
            .collect();
        let b = [0.5, -1.25];
        let f = |c: usize, p: &[f64]| b[c] + p.iter().zip(&a[c]).map(|(x, a)| x * a).sum::<f64>();
        let grid = ArrayD::from_shape_fn(IxDyn(field.shape()), |ix| {
            let p: Vec<f64> = (0..dims).map(|ax| node_position(&field, ax, ix[ax] as f64)).collect();
            f(ix[dims], &p)
        });
        // Random points, plus points on nodes, on faces and on the max corner.
        let mut pts = positions_in_cells(3, &field, 200, 0.0..1.0);
        for s in 0..40 {
            for ax in 0..dims {
                if (s + ax) % 2 == 0 {
                    let i = rng.gen_range(0..field.nodes()[ax]);
                    pts[[s, ax]] = node_position(&field, ax, i as f64);
                }
            }
        }
        for ax in 0..dims {
            pts[[199, ax]] = field.bbox().max()[ax];
        }
        let out = field.evaluate(&grid.view(), &pts.view().into_dyn()).unwrap();
        for (s, p) in pts.rows().into_iter().enumerate() {
            for c in 0..2 {
                let want = f(c, p.as_slice().unwrap());
                assert!(
                    (out[[s, c]] - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{dims}-D sample {s}: {} vs {want}",
                    out[[s, c]]
                );
            }
        }
        let upstream = Array2::from_shape_fn((pts.nrows(), 2), |(_, c)| if c == 0 { 1.0 } else { 0.0 });
        let g = field
            .vjp(&grid.view(), &pts.view().into_dyn(), &upstream.view().into_dyn(), BOTH)
            .unwrap();
        for row in g.positions.unwrap().rows() {
            for ax in 0..dims {
                assert!(
                    (row[ax] - a[0][ax]).abs() < 1e-11,
                    "{dims}-D: {} vs {}",
                    row[ax],
                    a[0][ax]
                );
            }
        }
    }
}

/// The grid gradient on grids cut into many slabs (one and two cell layers each; see the
/// scatter's docs) against a one-position-at-a-time scatter.
#[test]
fn grid_gradient_agrees_with_the_plain_scatter() {
    for (seed, nodes) in [
        (1, vec![12, 64, 64]),
        (2, vec![20, 64, 32]),
        (3, vec![9, 4096]),
        (4, vec![3, 4, 5]),
    ] {
        let (field, grid) = random_field(seed, &nodes, 4);
        let pts = positions_in_cells(seed, &field, 40_000, 0.0..1.0);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let upstream = Array2::from_shape_fn((pts.nrows(), 4), |_| rng.gen_range(-1.0..1.0));
        let g = field
            .vjp(
                &grid.view(),
                &pts.view().into_dyn(),
                &upstream.view().into_dyn(),
                GridWanted {
                    grid: true,
                    positions: false,
                },
            )
            .unwrap();
        assert!(g.positions.is_none());
        let want = oracle_grid_gradient(&field, &pts, &upstream);
        // Each weight carries the rounding of its fractions, about 1e-16 times the cell index
        // (absolute, so relative to a small weight 1 - t it is large), and sums cancel: the
        // error is bounded by the rounding times the sum of the terms' sizes.
        let rounding = 1e-15 * *nodes.iter().max().unwrap() as f64;
        let scale = oracle_grid_gradient(&field, &pts, &upstream.mapv(f64::abs));
        for ((a, b), s) in g.grid.unwrap().iter().zip(want.iter()).zip(scale.iter()) {
            assert!((a - b).abs() <= rounding * (s + 1.0), "{a} vs {b} (terms {s})");
        }
    }
}

#[test]
fn agrees_with_the_plain_loop_oracle() {
    for (seed, nodes) in [(1, vec![5, 4, 3]), (2, vec![7, 2]), (3, vec![2, 2, 2])] {
        let (field, grid) = random_field(seed, &nodes, 3);
        let pts = positions_in_cells(seed, &field, 500, 0.0..1.0);
        let out = field.evaluate(&grid.view(), &pts.view().into_dyn()).unwrap();
        let want = oracle(&field, &grid, &pts);
        for (o, w) in out.iter().zip(want.iter()) {
            assert!((o - w).abs() <= 1e-14 * w.abs().max(1.0), "{o} vs {w}");
        }
    }
}

/// On nodes, faces and the box's corners: node values exactly, the forward and the grid
/// gradient agree (the gradient is the transposed Jacobian of the forward, built column by
/// column from unit grids), and the position gradient is the one-sided derivative in the
/// position's cell (the cell above on an inner face, the last cell on the max face).
#[test]
fn faces_and_corners_are_consistent() {
    let field = GridField::new(GridBox::new(&[0.0; 3], &[2.0, 3.0, 4.0]).unwrap(), &[3, 4, 5, 2]).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let grid = Array4::from_shape_fn((3, 4, 5, 2), |_| rng.gen_range(-1.0..1.0)).into_dyn();
    let pts = arr2(&[
        [1.0, 2.0, 3.0],  // an inner node
        [2.0, 3.0, 4.0],  // the max corner
        [0.0, 0.0, 0.0],  // the min corner
        [1.0, 1.5, 4.0],  // an inner x face and the max z face
        [2.0, 0.25, 2.0], // the max x face and an inner z face
        [0.5, 3.0, 0.0],  // the max y face and the min z face
    ]);
    let out = field.evaluate(&grid.view(), &pts.view().into_dyn()).unwrap();
    for c in 0..2 {
        assert_eq!(out[[0, c]], grid[[1, 2, 3, c]]);
        assert_eq!(out[[1, c]], grid[[2, 3, 4, c]]);
        assert_eq!(out[[2, c]], grid[[0, 0, 0, c]]);
        let face: f64 = 0.5 * grid[[1, 1, 4, c]] + 0.5 * grid[[1, 2, 4, c]];
        assert!((out[[3, c]] - face).abs() < 1e-15);
    }
    // The Jacobian of the forward in the grid values, from unit grids.
    let upstream = Array2::from_shape_fn((pts.nrows(), 2), |_| rng.gen_range(-1.0..1.0));
    let g = field
        .vjp(&grid.view(), &pts.view().into_dyn(), &upstream.view().into_dyn(), BOTH)
        .unwrap();
    let gg = g.grid.unwrap();
    for flat in 0..grid.len() {
        let mut unit = ArrayD::zeros(grid.shape());
        unit.as_slice_mut().unwrap()[flat] = 1.0;
        let column = field.evaluate(&unit.view(), &pts.view().into_dyn()).unwrap();
        let want: f64 = column.iter().zip(upstream.iter()).map(|(j, u)| j * u).sum();
        assert!((gg.as_slice().unwrap()[flat] - want).abs() < 1e-15, "value {flat}");
    }
    // One-sided differences: the interpolant is linear along each axis within a cell, so a
    // step h into the position's own cell gives its derivative up to rounding.
    let gp = g.positions.unwrap();
    let h = 1e-4;
    let loss = |p: &Array2<f64>| -> f64 {
        let o = field.evaluate(&grid.view(), &p.view().into_dyn()).unwrap();
        (o * &upstream).sum()
    };
    for s in 0..pts.nrows() {
        for ax in 0..3 {
            let at_max = pts[[s, ax]] == field.bbox().max()[ax];
            let mut q = pts.clone();
            q[[s, ax]] += if at_max { -h } else { h };
            let one_sided = (loss(&q) - loss(&pts)) / if at_max { -h } else { h };
            assert!(
                (gp[[s, ax]] - one_sided).abs() < 1e-9,
                "sample {s} axis {ax}: {} vs {one_sided}",
                gp[[s, ax]]
            );
        }
    }
}

#[test]
fn outside_reads_zero_and_gets_no_gradient() {
    let (field, grid) = random_field(5, &[4, 3, 5], 2);
    let (lo, hi) = (field.bbox().min().to_vec(), field.bbox().max().to_vec());
    let mid: Vec<f64> = lo.iter().zip(&hi).map(|(a, b)| 0.5 * (a + b)).collect();
    let above = |x: f64| f64::from_bits(x.to_bits() + 1);
    let below = |x: f64| -f64::from_bits((-x).to_bits() + 1);
    let mut rows = vec![mid.clone()];
    for (ax, v) in [
        (0, below(lo[0])),
        (1, above(hi[1])),
        (2, f64::INFINITY),
        (0, f64::NEG_INFINITY),
        (2, 1e300),
    ] {
        let mut p = mid.clone();
        p[ax] = v;
        rows.push(p);
    }
    let pts = Array2::from_shape_fn((rows.len(), 3), |(s, a)| rows[s][a]);
    let upstream = Array2::from_elem((rows.len(), 2), 1.0);
    let out = field.evaluate(&grid.view(), &pts.view().into_dyn()).unwrap();
    let g = field
        .vjp(&grid.view(), &pts.view().into_dyn(), &upstream.view().into_dyn(), BOTH)
        .unwrap();
    let inside = pts.slice(ndarray::s![0..1, ..]).to_owned();
    let g_inside = field
        .vjp(
            &grid.view(),
            &inside.view().into_dyn(),
            &upstream.slice(ndarray::s![0..1, ..]).into_dyn(),
            BOTH,
        )
        .unwrap();
    assert!(out.rows().into_iter().skip(1).all(|r| r.iter().all(|&v| v == 0.0)));
    assert!(out[[0, 0]] != 0.0);
    let gp = g.positions.unwrap();
    assert!(gp.rows().into_iter().skip(1).all(|r| r.iter().all(|&v| v == 0.0)));
    assert_eq!(g.grid.unwrap(), g_inside.grid.unwrap());
}

#[test]
fn bad_input_is_an_error_and_changes_nothing() {
    let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
    assert!(matches!(
        GridField::new(bbox, &[2, 0, 2, 1]),
        Err(OpsError::Shape { op: Op::GridField, .. })
    ));
    assert!(matches!(
        GridField::new(bbox, &[2, 1, 2, 1]),
        Err(OpsError::Shape { op: Op::GridField, .. })
    ));
    assert!(matches!(
        GridField::new(bbox, &[2, 2, 2, 0]),
        Err(OpsError::Shape { op: Op::GridField, .. })
    ));
    assert!(matches!(
        GridField::new(bbox, &[2, 2, 1]),
        Err(OpsError::Shape { op: Op::GridField, .. })
    ));
    assert!(matches!(
        GridField::new(bbox, &[usize::MAX, 2, 2, 2]),
        Err(OpsError::Shape { op: Op::GridField, .. })
    ));
    assert!(matches!(
        GridBox::new(&[0.0; 3], &[1.0, -1.0, 1.0]),
        Err(OpsError::Box {
            op: Op::GridField,
            axis: 1,
            ..
        })
    ));
    assert!(matches!(
        GridBox::new(&[0.0, f64::NEG_INFINITY], &[1.0; 2]),
        Err(OpsError::Box {
            op: Op::GridField,
            axis: 0,
            ..
        }) | Err(OpsError::Box {
            op: Op::GridField,
            axis: 1,
            ..
        })
    ));

    let field = GridField::new(bbox, &[2, 2, 2, 1]).unwrap();
    let grid = Array4::<f64>::zeros((2, 2, 2, 1)).into_dyn();
    let wrong_width = Array2::<f64>::zeros((4, 2)).into_dyn();
    assert!(matches!(
        field.evaluate(&grid.view(), &wrong_width.view()),
        Err(OpsError::Shape {
            op: Op::GridField,
            what: "positions",
            ..
        })
    ));
    let flat = ndarray::Array1::<f64>::zeros(3).into_dyn();
    assert!(matches!(
        field.evaluate(&grid.view(), &flat.view()),
        Err(OpsError::Shape {
            op: Op::GridField,
            what: "positions",
            ..
        })
    ));
    let mut nan = Array2::<f64>::zeros((4, 3));
    nan[[2, 1]] = f64::NAN;
    nan[[3, 0]] = f64::NAN;
    assert!(matches!(
        field.evaluate(&grid.view(), &nan.view().into_dyn()),
        Err(OpsError::Domain {
            op: Op::GridField,
            at: At::Entry { row: 2, column: 1 },
            ..
        })
    ));
    let wrong_grid = Array4::<f64>::zeros((2, 2, 3, 1)).into_dyn();
    let ok = Array2::<f64>::zeros((4, 3)).into_dyn();
    assert!(matches!(
        field.evaluate(&wrong_grid.view(), &ok.view()),
        Err(OpsError::Shape {
            op: Op::GridField,
            what: "grid",
            ..
        })
    ));
    let bad_upstream = Array2::<f64>::zeros((3, 1)).into_dyn();
    assert!(matches!(
        field.vjp(&grid.view(), &ok.view(), &bad_upstream.view(), BOTH),
        Err(OpsError::Shape {
            op: Op::GridField,
            what: "upstream gradient",
            ..
        })
    ));

    // Through the tape: an error naming the op, and the tape as it was.
    let mut tape = Tape::<f64>::new();
    let g = tape.param(grid.clone());
    let p = tape.param(nan.into_dyn());
    let before = tape.len();
    let err = field.apply(&mut tape, g, p).unwrap_err();
    assert!(matches!(&err, TapeError::Op { op: "grid_field", .. }), "{err}");
    assert!(
        matches!(
            err.downcast_ref::<OpsError>(),
            Some(OpsError::Domain {
                op: Op::GridField,
                at: At::Entry { .. },
                ..
            })
        ),
        "{err}"
    );
    assert!(fogray_ops::grid::twin::lookup(&mut tape, &field, g, p).is_err());
    assert_eq!(tape.len(), before);
}
