//! The occupancy grid's update against thresholds and decays worked by hand.

use std::convert::Infallible;

use super::*;
use crate::rays::Aabb;
use crate::sample::Refresh;
use crate::{At, Op, OpsError};
use ndarray::{Array1, ArrayView2};

fn cube() -> Aabb {
    Aabb::new([-1.0; 3], [1.0; 3]).unwrap()
}

fn constant(value: f64) -> impl Fn(ArrayView2<'_, f64>) -> Result<Array1<f64>, Infallible> + Sync {
    move |p| Ok(Array1::from_elem(p.nrows(), value))
}

#[test]
fn opacity_threshold_by_hand() {
    // One step of 0.1 at least 1 % opaque: density > -ln(0.99) / 0.1 = 0.1005033585...
    let c = OccupancyConfig::opacity(0.1, 0.01).unwrap();
    assert!((c.density_threshold() - 0.100_503_358_535_014_4).abs() < 1e-15);
    // For tiny opacities -ln(1 - a) = a + a^2/2: 1 - a rounds, ln_1p(-a) does not.
    let tiny = OccupancyConfig::opacity(1.0, 1e-12).unwrap();
    assert!((tiny.density_threshold() - (1e-12 + 0.5e-24)).abs() < 1e-27);
    assert!((-(1.0f64 - 1e-12).ln() - 1e-12).abs() > 1e-17);
    let mut grid = OccupancyGrid::new(cube(), 4, c).unwrap();
    grid.update(constant(0.1), CellPoints::Centre).unwrap();
    assert_eq!(grid.occupied_fraction(), 0.0);
    // Every cell occupied again, the estimates kept for the next update.
    grid.occupy_all();
    assert_eq!(grid.occupied_fraction(), 1.0);
    assert!(grid.estimate().iter().all(|&e| e == 0.1));
    grid.update(constant(0.11), CellPoints::Centre).unwrap();
    assert_eq!(grid.occupied_fraction(), 1.0);
}

#[test]
fn estimates_decay_and_keep_the_maximum() {
    let config = OccupancyConfig::density(3.0).unwrap().with_decay(0.5).unwrap();
    let mut grid = OccupancyGrid::new(cube(), 2, config).unwrap();
    // Before any update every cell is occupied with estimate 0.
    assert_eq!(grid.occupied_fraction(), 1.0);
    grid.update(constant(10.0), CellPoints::Centre).unwrap();
    // max(0 * 0.5, 10) = 10, then max(10 * 0.5, 0) = 5 > 3, then 2.5 <= 3: empty.
    assert!(grid.estimate().iter().all(|&e| e == 10.0));
    grid.update(constant(0.0), CellPoints::Centre).unwrap();
    assert!(grid.estimate().iter().all(|&e| e == 5.0));
    assert_eq!(grid.occupied_fraction(), 1.0);
    grid.update(constant(0.0), CellPoints::Centre).unwrap();
    assert!(grid.estimate().iter().all(|&e| e == 2.5));
    assert_eq!(grid.occupied_fraction(), 0.0);
    // A new density above the decayed estimate replaces it.
    grid.update(constant(4.0), CellPoints::Centre).unwrap();
    assert!(grid.estimate().iter().all(|&e| e == 4.0));
}

#[test]
fn ball_occupancy_matches_a_cell_by_cell_loop() {
    let r = 16;
    let mut grid = OccupancyGrid::new(cube(), r, OccupancyConfig::density(0.5).unwrap()).unwrap();
    let ball = |p: ArrayView2<'_, f32>| {
        Ok::<_, Infallible>(Array1::from_iter(p.rows().into_iter().map(|q| {
            if q.dot(&q) < 0.36 {
                1.0
            } else {
                0.0
            }
        })))
    };
    grid.update(ball, CellPoints::Centre).unwrap();
    let mut count = 0;
    for ix in 0..r {
        for iy in 0..r {
            for iz in 0..r {
                let c = [ix, iy, iz].map(|i| -1.0 + (i as f64 + 0.5) * 2.0 / r as f64);
                let inside = c.iter().map(|x| x * x).sum::<f64>() < 0.36;
                assert_eq!(grid.is_occupied([ix, iy, iz]), inside, "cell {ix} {iy} {iz}");
                assert_eq!(grid.is_occupied_at(c), inside);
                count += usize::from(inside);
            }
        }
    }
    assert_eq!(grid.occupied_fraction(), count as f64 / (r * r * r) as f64);
    // A slice across z at the middle: the disc of cells whose centres are within 0.6 of the
    // axis (centre z = 0.0625 adds 0.0039 to the squared distance).
    let s = grid.slice(GridAxis::Z, r / 2).unwrap();
    assert_eq!(s.occupied.dim(), (r, r));
    for ((i, j), &o) in s.occupied.indexed_iter() {
        assert_eq!(o, grid.is_occupied([i, j, r / 2]));
        assert_eq!(s.estimate[[i, j]], grid.estimate()[[i, j, r / 2]]);
    }
    assert!(s.occupied[[r / 2, r / 2]] && !s.occupied[[0, 0]]);
    assert!(grid.slice(GridAxis::X, r).is_err());
}

#[test]
fn random_points_stay_in_their_cells_and_are_seeded() {
    // The density is the point's x: each cell's estimate is its random point's x, which must
    // lie within the cell's x range, and differ between cells of one x column.
    let r = 8;
    let config = OccupancyConfig::density(0.0).unwrap().with_decay(0.0).unwrap();
    let mut grid = OccupancyGrid::new(Aabb::new([0.0; 3], [2.0; 3]).unwrap(), r, config).unwrap();
    let x = |p: ArrayView2<'_, f64>| Ok::<_, Infallible>(p.column(0).to_owned());
    grid.update(x, CellPoints::Random { seed: 3 }).unwrap();
    let est = grid.estimate().to_owned();
    for ((ix, _, _), &e) in est.indexed_iter() {
        let lo = ix as f32 * 0.25;
        assert!(lo <= e && e <= lo + 0.25, "cell x {ix}: {e}");
    }
    assert_ne!(est[[3, 0, 0]], est[[3, 1, 0]]);
    let mut again = OccupancyGrid::new(Aabb::new([0.0; 3], [2.0; 3]).unwrap(), r, config).unwrap();
    again.update(x, CellPoints::Random { seed: 3 }).unwrap();
    assert_eq!(again, grid);
    // With the centre too, the larger x wins: at least the centre's.
    again.update(x, CellPoints::CentreAndRandom { seed: 4 }).unwrap();
    for ((ix, _, _), &e) in again.estimate().indexed_iter() {
        assert!(e >= ix as f32 * 0.25 + 0.125);
    }
}

#[test]
fn bad_densities_are_errors_and_change_nothing() {
    let mut grid = OccupancyGrid::new(cube(), 4, OccupancyConfig::density(1.0).unwrap()).unwrap();
    grid.update(constant(2.0), CellPoints::Centre).unwrap();
    let before = grid.clone();
    let nan_at_7 = |p: ArrayView2<'_, f64>| {
        Ok::<_, Infallible>(Array1::from_iter((0..p.nrows()).map(|i| {
            if i == 7 {
                f64::NAN
            } else {
                0.0
            }
        })))
    };
    assert!(matches!(
        grid.update(nan_at_7, CellPoints::Centre),
        Err(OpsError::Domain {
            op: Op::Occupancy,
            at: At::Cell(7),
            ..
        })
    ));
    assert!(grid.update(constant(-1.0), CellPoints::Centre).is_err());
    let short = |p: ArrayView2<'_, f64>| Ok::<_, Infallible>(Array1::zeros(p.nrows() - 1));
    assert!(matches!(
        grid.update(short, CellPoints::Centre),
        Err(OpsError::Density { op: Op::Occupancy, .. })
    ));
    let failing = |_: ArrayView2<'_, f64>| Err::<Array1<f64>, _>("no grid yet");
    assert_eq!(
        grid.update(failing, CellPoints::Centre),
        Err(OpsError::Density {
            op: Op::Occupancy,
            problem: "no grid yet".into()
        })
    );
    assert_eq!(grid, before);
    assert!(OccupancyGrid::new(cube(), 0, OccupancyConfig::density(1.0).unwrap()).is_err());
    assert!(OccupancyConfig::opacity(0.0, 0.01).is_err());
    assert!(OccupancyConfig::opacity(0.1, 1.0).is_err());
    assert!(OccupancyConfig::density(f64::NAN).is_err());
    assert!(OccupancyConfig::density(1.0).unwrap().with_decay(1.5).is_err());
}

fn ball_density(p: ArrayView2<'_, f64>) -> Result<Array1<f64>, Infallible> {
    Ok(Array1::from_iter(p.rows().into_iter().map(|q| {
        if q.dot(&q) < 0.3 {
            5.0 + q[0]
        } else {
            0.01
        }
    })))
}

#[test]
fn a_restored_state_is_the_grid_it_was_taken_from() {
    let config = OccupancyConfig::density(0.5).unwrap().with_decay(0.9).unwrap();
    // r = 5: 125 cells, so the last word of bits is partly used.
    for updates in 0..3 {
        let mut grid = OccupancyGrid::new(cube(), 5, config).unwrap();
        for k in 0..updates {
            grid.update(ball_density, CellPoints::CentreAndRandom { seed: k })
                .unwrap();
        }
        let state = grid.state();
        let expected_fraction = if updates == 0 { 1.0 } else { grid.occupied_fraction() };
        assert_eq!(
            state.occupied.iter().filter(|&&o| o).count() as f64 / 125.0,
            expected_fraction
        );
        let mut back = OccupancyGrid::new(cube(), 5, config).unwrap();
        back.update(constant(100.0), CellPoints::Centre).unwrap(); // something to overwrite
        back.restore(&state).unwrap();
        assert_eq!(back, grid, "after {updates} updates");
        // And they go on alike.
        grid.update(ball_density, CellPoints::Random { seed: 9 }).unwrap();
        back.update(ball_density, CellPoints::Random { seed: 9 }).unwrap();
        assert_eq!(back, grid);
    }
}

#[test]
fn a_fresh_grid_restored_from_a_state_of_its_own_is_unchanged() {
    let config = OccupancyConfig::density(0.5).unwrap();
    let fresh = OccupancyGrid::new(cube(), 3, config).unwrap();
    let mut back = fresh.clone();
    back.restore(&fresh.state()).unwrap();
    assert_eq!(back, fresh);
    assert_eq!(back.occupied_fraction(), 1.0);
}

#[test]
fn restore_rejects_bad_states_and_leaves_the_grid_alone() {
    let config = OccupancyConfig::density(0.5).unwrap();
    let mut grid = OccupancyGrid::new(cube(), 4, config).unwrap();
    grid.update(ball_density, CellPoints::Centre).unwrap();
    let before = grid.clone();
    let good = grid.state();
    let mut wrong_shape = good.clone();
    wrong_shape.occupied = ndarray::Array3::from_elem((4, 4, 3), true);
    assert!(matches!(
        grid.restore(&wrong_shape),
        Err(OpsError::Shape {
            op: Op::Occupancy,
            what: "occupied cells",
            ..
        })
    ));
    for (cell, bad) in [(7usize, -1.0f32), (63, f32::NAN), (0, f32::INFINITY)] {
        let mut s = good.clone();
        s.estimate.as_slice_mut().unwrap()[cell] = bad;
        match grid.restore(&s) {
            Err(OpsError::Domain {
                op: Op::Occupancy,
                at: At::Cell(c),
                ..
            }) => assert_eq!(c, cell),
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(grid, before);
}

#[test]
fn a_refresh_policy_updates_from_its_warmup_every_n_steps_only() {
    let config = OccupancyConfig::density(0.5)
        .unwrap()
        .with_refresh(Refresh { warmup: 10, every: 4 })
        .unwrap();
    let mut grid = OccupancyGrid::new(cube(), 2, config).unwrap();
    // Steps 1..=20: due at 12, 16, 20 (at least 10, a multiple of 4); 8 is before the warmup.
    let due: Vec<usize> = (1..=20)
        .filter(|&s| grid.update_every_n_steps(s, constant(0.0), CellPoints::Centre).unwrap())
        .collect();
    assert_eq!(due, vec![12, 16, 20]);
    assert_eq!(config.refresh().first_due(), 12);
    assert_eq!(Refresh { warmup: 64, every: 16 }.first_due(), 64);
    // Before any due step the grid is untouched (every cell occupied); after, density 0 empties it.
    let mut fresh = OccupancyGrid::new(cube(), 2, config).unwrap();
    assert!(!fresh
        .update_every_n_steps(11, constant(0.0), CellPoints::Centre)
        .unwrap());
    assert_eq!(fresh.occupied_fraction(), 1.0);
    assert_eq!(grid.occupied_fraction(), 0.0);
    assert!(OccupancyConfig::density(0.5)
        .unwrap()
        .with_refresh(Refresh { warmup: 0, every: 0 })
        .is_err());
}

/// The ball's density outside the radius-0.5 ball replaced by `fog`: constant there.
fn ball_in_fog(fog: f64) -> impl Fn(ArrayView2<'_, f64>) -> Result<Array1<f64>, Infallible> + Sync {
    move |p| {
        let inside = ball_density(p)?;
        Ok(Array1::from_shape_fn(p.nrows(), |i| {
            let r2: f64 = (0..3).map(|a| p[[i, a]] * p[[i, a]]).sum();
            if r2 <= 0.25 {
                inside[i]
            } else {
                fog
            }
        }))
    }
}

#[test]
fn known_cells_give_the_update_of_every_cell_bit_for_bit_and_are_not_evaluated() {
    let fog = 0.0183;
    let config = OccupancyConfig::density(0.5).unwrap();
    let mut every = OccupancyGrid::new(cube(), 16, config).unwrap();
    let mut known = every.clone();
    // The cells wholly outside a ball of radius 0.5 + a cell's diagonal, where the density is
    // the fog at every point.
    let r = 16;
    let cells: Vec<bool> = (0..r * r * r)
        .map(|l| {
            let c = [l / (r * r), l / r % r, l % r];
            let centre: f64 = (0..3)
                .map(|a| (-1.0 + (c[a] as f64 + 0.5) * 2.0 / r as f64).powi(2))
                .sum();
            centre.sqrt() > 0.5 + 3f64.sqrt() * 2.0 / r as f64
        })
        .collect();
    let marked = cells.iter().filter(|&&k| k).count();
    assert!(marked > r * r * r / 2, "{marked}");
    known.set_known_cells(Some(KnownCells { cells, density: fog })).unwrap();
    let evaluated = std::sync::atomic::AtomicUsize::new(0);
    let counting = |p: ArrayView2<'_, f64>| {
        evaluated.fetch_add(p.nrows(), std::sync::atomic::Ordering::Relaxed);
        ball_in_fog(fog)(p)
    };
    for seed in [1, 2, 3] {
        let points = CellPoints::CentreAndRandom { seed };
        every.update(ball_in_fog(fog), points).unwrap();
        known.update(counting, points).unwrap();
        assert_eq!(every.state(), known.state(), "seed {seed}");
    }
    // Two points a cell, for the unknown cells only.
    assert_eq!(evaluated.into_inner(), 3 * 2 * (r * r * r - marked));
    assert!(every.occupied_fraction() > 0.0 && every.occupied_fraction() < 0.5);
}

#[test]
fn known_cells_of_the_wrong_size_or_density_are_refused() {
    let mut grid = OccupancyGrid::new(cube(), 4, OccupancyConfig::density(0.5).unwrap()).unwrap();
    for (cells, density) in [
        (vec![true; 63], 0.0),
        (vec![true; 64], -1.0),
        (vec![true; 64], f64::NAN),
    ] {
        assert!(grid.set_known_cells(Some(KnownCells { cells, density })).is_err());
        assert_eq!(grid.known_cells(), None);
    }
}

#[test]
fn cell_of_by_hand_at_faces_and_boundaries() {
    // [-1, 1]^3 in 4 cells a side of 0.5: cell k holds [-1 + 0.5 k, -0.5 + 0.5 k).
    let grid = OccupancyGrid::new(cube(), 4, OccupancyConfig::density(1.0).unwrap()).unwrap();
    let cell = |x: f64| grid.cell_of([x, 0.0, 0.0]).map(|c| c[0]);
    assert_eq!(cell(-1.0), Some(0)); // the lower face
    assert_eq!(cell(-0.75), Some(0)); // a cell's middle: rounding would give 1
    assert_eq!(cell(f64::from_bits((-0.5f64).to_bits() + 1)), Some(0)); // just below a boundary
    assert_eq!(cell(-0.5), Some(1)); // on a boundary: the upper cell
    assert_eq!(cell(0.0), Some(2));
    assert_eq!(cell(0.999_999_999_999), Some(3));
    assert_eq!(cell(1.0), Some(3)); // the upper face belongs to the last cell
    assert_eq!(cell(1.0 + 1e-12), None);
    assert_eq!(cell(-1.0 - 1e-12), None);
    assert_eq!(cell(f64::NAN), None);
    assert_eq!(grid.cell_of([0.1, -0.6, 0.76]), Some([2, 0, 3]));
}
