//! The marcher's walk (branch-free axis choice, exits computed a step ahead, runs handed on
//! as they close) against the plain walk it replaced, and against a dense march, on
//! occupancy patterns and rays made to trip a DDA: isolated occupied cells at the corners of
//! groups of cells, rays along axes, along cell faces and edges, through cell corners, from
//! corners, and starting inside the box.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::*;
use crate::rays::Aabb;

/// The marcher as it was before this walk, runs collected: the reference.
fn walked_runs(g: &OccupancyGrid, o: [f64; 3], d: [f64; 3], lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let mut runs: Vec<(f64, f64)> = Vec::new();
    let r = g.resolution as i64;
    let min = g.bounds.min();
    let start = g.cell_of(std::array::from_fn(|a| {
        (o[a] + lo * d[a]).clamp(min[a], g.bounds.max()[a])
    }));
    let Some(start) = start else { return runs };
    let mut idx = start.map(|i| i as i64);
    let dir: [i64; 3] = std::array::from_fn(|a| (d[a] > 0.0) as i64 - (d[a] < 0.0) as i64);
    let inv: [f64; 3] = std::array::from_fn(|a| 1.0 / d[a]);
    let exit = |a: usize, i: i64| -> f64 {
        match dir[a] {
            0 => f64::INFINITY,
            s => (min[a] + (i + i64::from(s > 0)) as f64 * g.cell[a] - o[a]) * inv[a],
        }
    };
    let mut t_exit: [f64; 3] = std::array::from_fn(|a| exit(a, idx[a]));
    let mut t = lo;
    loop {
        let axis = if t_exit[0] <= t_exit[1] {
            if t_exit[0] <= t_exit[2] {
                0
            } else {
                2
            }
        } else if t_exit[1] <= t_exit[2] {
            1
        } else {
            2
        };
        let leaving = !(0..r).contains(&(idx[axis] + dir[axis]));
        let t_end = if leaving { hi } else { t_exit[axis].min(hi) };
        let linear = ((idx[0] * r + idx[1]) * r + idx[2]) as usize;
        if t_end > t && g.is_occupied_linear(linear) {
            match runs.last_mut() {
                Some(run) if run.1 == t => run.1 = t_end,
                _ => runs.push((t, t_end)),
            }
        }
        if leaving || t_exit[axis] >= hi {
            break;
        }
        t = t.max(t_exit[axis]);
        idx[axis] += dir[axis];
        t_exit[axis] = exit(axis, idx[axis]);
    }
    runs
}

fn marched_runs(g: &OccupancyGrid, o: [f64; 3], d: [f64; 3], lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let mut runs = Vec::new();
    g.occupied_runs(o, d, lo, hi, |a, b| runs.push((a, b)));
    runs
}

/// A grid over [-1, 1]^3 whose occupied cells are exactly `occupied` (by a restore).
fn grid_with(r: usize, occupied: impl Fn([usize; 3]) -> bool) -> OccupancyGrid {
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    let mut g = OccupancyGrid::new(bounds, r, OccupancyConfig::density(0.5).unwrap()).unwrap();
    let state = OccupancyState {
        estimate: ndarray::Array3::zeros((r, r, r)),
        occupied: ndarray::Array3::from_shape_fn((r, r, r), |(x, y, z)| occupied([x, y, z])),
    };
    g.restore(&state).unwrap();
    g
}

/// The point at `frac` of the way along the cells (in cell units) of a grid of `r` over [-1, 1].
fn at_cells(r: usize, c: [f64; 3]) -> [f64; 3] {
    c.map(|x| -1.0 + 2.0 * x / r as f64)
}

/// Rays meant to meet cell faces, edges and corners head on, plus random ones (half of
/// them starting inside the box), as (origin, unit direction).
fn tricky_rays(r: usize, rng: &mut StdRng) -> Vec<([f64; 3], [f64; 3])> {
    // Cell faces, edges and corners every `b` cells.
    let b = 4.0f64;
    let unit = |v: [f64; 3]| {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.map(|x| x / n)
    };
    let mut rays = Vec::new();
    // Along each axis, both ways, on cell edges (lines where two cell faces meet), on cell
    // faces, and through cell centres.
    for axis in 0..3 {
        for sign in [1.0, -1.0] {
            for off in [[b, b], [b, 1.5], [0.5, 0.5], [2.0 * b, b + 0.5]] {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let mut c = [0.0; 3];
                c[u] = off[0].min(r as f64);
                c[v] = off[1].min(r as f64);
                let mut o = at_cells(r, c);
                o[axis] = -3.0 * sign;
                let mut d = [0.0; 3];
                d[axis] = sign;
                rays.push((o, d));
            }
        }
    }
    // Diagonals through cell corners: from a corner, along (+-1, +-1, +-1) and along
    // directions in a cell face plane.
    for corner in [[b, b, b], [0.0, 0.0, 0.0], [b, 2.0 * b, b], [r as f64; 3]] {
        let p = at_cells(r, corner.map(|x: f64| x.min(r as f64)));
        for d in [
            [1.0, 1.0, 1.0],
            [1.0, -1.0, 1.0],
            [-1.0, -1.0, -1.0],
            [1.0, 1.0, 0.0],
            [0.0, -1.0, 1.0],
            [2.0, 1.0, 0.0],
        ] {
            let d = unit(d);
            // Start outside the box on the line through the corner.
            rays.push((std::array::from_fn(|a| p[a] - 4.0 * d[a]), d));
            // And start exactly at the corner.
            rays.push((p, d));
        }
    }
    for i in 0..400 {
        let o: [f64; 3] = std::array::from_fn(|_| {
            if i % 2 == 0 {
                rng.gen_range(-3.0..3.0)
            } else {
                rng.gen_range(-1.0..1.0)
            }
        });
        let d = unit(std::array::from_fn(|_| rng.gen_range(-1.0..1.0)));
        rays.push((o, d));
    }
    rays
}

/// Occupancy patterns: single cells at the corners of groups of 4^3 cells, a few random
/// cells, a random quarter, and the far corner cell alone.
fn patterns(r: usize, rng: &mut StdRng) -> Vec<OccupancyGrid> {
    let b = 4;
    let corner = |i: usize| i % b == 0 || i % b == b - 1 || i == r - 1;
    let sparse: Vec<[usize; 3]> = (0..12).map(|_| std::array::from_fn(|_| rng.gen_range(0..r))).collect();
    let quarter: Vec<bool> = (0..r * r * r).map(|_| rng.gen_bool(0.25)).collect();
    let seed = rng.gen::<u64>();
    vec![
        // Every fourth corner cell of a group, by a hash of its index.
        grid_with(r, |c| {
            c.iter().all(|&i| corner(i)) && (c[0] * 7 + c[1] * 13 + c[2] * 29 + seed as usize % 5) % 4 == 0
        }),
        grid_with(r, |c| sparse.contains(&c)),
        grid_with(r, |c| quarter[(c[0] * r + c[1]) * r + c[2]]),
        // Nothing but the grid's far corner.
        grid_with(r, |c| c == [r - 1; 3]),
    ]
}

#[test]
fn the_walk_gives_the_runs_of_the_plain_walk_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(21);
    for r in [1, 3, 5, 8, 9, 14] {
        for g in patterns(r, &mut rng) {
            for (o, d) in tricky_rays(r, &mut rng) {
                let Some((lo, hi)) = g.bounds.clip_ray(o, d) else {
                    continue;
                };
                // The whole crossing, and a part starting and ending inside the box.
                for (lo, hi) in [(lo, hi), (lo + 0.3 * (hi - lo), lo + 0.8 * (hi - lo))] {
                    let want = walked_runs(&g, o, d, lo, hi);
                    let got = marched_runs(&g, o, d, lo, hi);
                    assert_eq!(got, want, "r {r}, ray {o:?} + t {d:?}, t in [{lo}, {hi}]");
                }
            }
        }
    }
}

#[test]
fn the_walk_misses_no_occupied_point_of_a_dense_march() {
    // Independent of the walk: points every 1/40 of a cell along each ray, looked up by
    // position; each one in an occupied cell (away from faces, where rounding decides) lies in
    // a run, and each run's midpoint is in an occupied cell.
    let mut rng = StdRng::seed_from_u64(5);
    let r = 9;
    let fine = 2.0 / r as f64 / 40.0;
    let mut covered = 0;
    for g in patterns(r, &mut rng) {
        for (o, d) in tricky_rays(r, &mut rng) {
            let Some((lo, hi)) = g.bounds.clip_ray(o, d) else {
                continue;
            };
            let runs = marched_runs(&g, o, d, lo, hi);
            let at = |t: f64| -> [f64; 3] { std::array::from_fn(|a| o[a] + t * d[a]) };
            for &(a, b) in &runs {
                assert!(lo <= a && a < b && b <= hi);
                // A run a rounding error long (where the ray grazes a cell's edge or corner)
                // may look up a neighbour: then one of the cells within 1e-9 is occupied.
                let mid = at(0.5 * (a + b));
                let occupied = if b - a > 1e-9 {
                    g.is_occupied_at(mid)
                } else {
                    (0..8).any(|k| {
                        g.is_occupied_at(std::array::from_fn(|ax| {
                            mid[ax] + if k >> ax & 1 == 1 { 1e-9 } else { -1e-9 }
                        }))
                    })
                };
                assert!(occupied, "run [{a}, {b}] of {o:?} + t {d:?}");
            }
            let mut t = lo + fine / 2.0;
            while t < hi {
                let clear_of_faces = [-1e-9, 1e-9].iter().all(|e| g.is_occupied_at(at(t + e)));
                if clear_of_faces {
                    assert!(
                        runs.iter().any(|&(a, b)| a <= t && t <= b),
                        "{o:?} + t {d:?}: occupied t {t} not in {runs:?}"
                    );
                    covered += 1;
                }
                t += fine;
            }
        }
    }
    assert!(covered > 1000, "too few occupied points to mean anything: {covered}");
}
