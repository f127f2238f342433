//! The marcher's walk from exit tables against the walk it replaced (exits computed a step
//! ahead, one at a time), run by run and bit for bit, and the marcher's samples with either.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::march::ExitTables;
use super::march_walk_tests::{grid_with, patterns, tricky_rays};
use super::packed::pack;
use super::stratified::RayJitter;
use super::*;
use crate::rays::{Aabb, Intrinsics, PinholeCamera, RayBatch, RayIntervals};

/// The walk before exit tables, as it was: the oracle.
/// The axis whose exit comes first (the lowest axis on a tie), chosen without branches: the
/// choice follows the ray's geometry, which a branch predictor cannot guess.
#[inline]
fn first_exit(t_exit: &[f64; 3]) -> usize {
    let a01 = usize::from(t_exit[1] < t_exit[0]);
    let t01 = if a01 == 1 { t_exit[1] } else { t_exit[0] };
    if t_exit[2] < t01 {
        2
    } else {
        a01
    }
}

fn stepped_runs(g: &OccupancyGrid, o: [f64; 3], d: [f64; 3], lo: f64, hi: f64, mut run: impl FnMut(f64, f64)) {
    let r = g.resolution as i64;
    let min = g.bounds.min();
    let start = g.cell_of(std::array::from_fn(|a| {
        (o[a] + lo * d[a]).clamp(min[a], g.bounds.max()[a])
    }));
    let Some(start) = start else { return };
    let mut idx = start.map(|i| i as i64);
    let dir: [i64; 3] = std::array::from_fn(|a| {
        if d[a] > 0.0 {
            1
        } else if d[a] < 0.0 {
            -1
        } else {
            0
        }
    });
    // The t at which the ray leaves cell idx across axis a: a product with 1/d, not a
    // division, on the DDA's one dependent chain.
    let inv: [f64; 3] = std::array::from_fn(|a| 1.0 / d[a]);
    let exit = |a: usize, i: i64| -> f64 {
        match dir[a] {
            0 => f64::INFINITY,
            s => (min[a] + (i + i64::from(s > 0)) as f64 * g.cell[a] - o[a]) * inv[a],
        }
    };
    let mut t_exit: [f64; 3] = std::array::from_fn(|a| exit(a, idx[a]));
    // The exit of the next cell along each axis, computed a step ahead: a step's new exit
    // is then a copy, and the next choice of axis need not wait for the arithmetic.
    let mut t_after: [f64; 3] = std::array::from_fn(|a| exit(a, idx[a] + dir[a]));
    // The last cell along each axis before the ray leaves the grid (an axis the ray does
    // not move along is never the first exit).
    let last: [i64; 3] = dir.map(|s| if s > 0 { r - 1 } else { 0 });
    // The linear cell index, stepped with the cell index (see OccupancyGrid's layout).
    let stride = [r * r, r, 1];
    let step: [i64; 3] = std::array::from_fn(|a| dir[a] * stride[a]);
    let mut linear = idx[0] * stride[0] + idx[1] * stride[1] + idx[2];
    // The run being grown, handed to `run` once the next one does not touch it.
    let mut pending: Option<(f64, f64)> = None;
    let mut t = lo;
    loop {
        let axis = first_exit(&t_exit);
        let leaving = idx[axis] == last[axis];
        if g.is_occupied_linear(linear as usize) {
            // The last cell before the grid's far face runs to hi: the face's t, rounded
            // differently from the clip that gave hi, must not leave a sliver.
            let t_end = if leaving { hi } else { t_exit[axis].min(hi) };
            if t_end > t {
                match &mut pending {
                    Some(p) if p.1 == t => p.1 = t_end,
                    _ => {
                        if let Some((a, b)) = pending {
                            run(a, b);
                        }
                        pending = Some((t, t_end));
                    }
                }
            }
        }
        if leaving || t_exit[axis] >= hi {
            break;
        }
        t = t.max(t_exit[axis]);
        idx[axis] += dir[axis];
        linear += step[axis];
        // Only the crossed axis has a new exit, computed a step ago.
        t_exit[axis] = t_after[axis];
        t_after[axis] = exit(axis, idx[axis] + dir[axis]);
    }
    if let Some((a, b)) = pending {
        run(a, b);
    }
}


/// The marcher as it was, on the oracle's walk.
fn stepped_march(g: &OccupancyGrid, rays: &RayBatch<f64>, intervals: &RayIntervals, step: f64, jitter: Jitter) -> PackedSamples<f64> {
    pack(rays, |r, pieces| {
        let (o, d) = rays.ray(r);
        let (Some((near, far)), Some((box_near, box_far))) = (intervals.segment(r), g.bounds.clip_ray(o, d)) else {
            return;
        };
        let (lo, hi) = (near.max(box_near), far.min(box_far));
        if hi > lo {
            let mut jitter = RayJitter::for_ray(jitter, r);
            stepped_runs(g, o, d, lo, hi, |a, b| jitter.cut(a, b, lo, step, pieces));
        }
    })
}

/// The occupancy patterns of the walk's tests, and an empty and a full grid.
fn grids(r: usize, rng: &mut StdRng) -> Vec<OccupancyGrid> {
    let mut grids = patterns(r, rng);
    grids.push(grid_with(r, |_| true));
    grids.push(grid_with(r, |_| false));
    grids
}

#[test]
fn the_walk_from_exit_tables_gives_the_runs_of_the_stepped_walk_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(33);
    // One scratch for every ray, as the marcher reuses it: a longer ray's table must not leak
    // into a shorter one's.
    let mut tables = ExitTables::default();
    let mut runs_seen = 0;
    for r in [1, 2, 5, 8, 9, 14, 33] {
        for g in grids(r, &mut rng) {
            for (o, d) in tricky_rays(r, &mut rng) {
                let Some((lo, hi)) = g.bounds.clip_ray(o, d) else {
                    continue;
                };
                // The whole crossing, parts starting or ending inside the box, and a part
                // shorter than a cell.
                let parts = [
                    (lo, hi),
                    (lo + 0.3 * (hi - lo), lo + 0.8 * (hi - lo)),
                    (lo, lo + 0.5 * (hi - lo)),
                    (lo + 0.6 * (hi - lo), hi),
                    (lo + 0.5 * (hi - lo), lo + 0.5 * (hi - lo) + 0.1 / r as f64),
                ];
                for (lo, hi) in parts {
                    let mut want = Vec::new();
                    stepped_runs(&g, o, d, lo, hi, |a, b| want.push((a, b)));
                    let mut got = Vec::new();
                    g.occupied_runs(o, d, lo, hi, &mut tables, |a, b| got.push((a, b)));
                    assert_eq!(got, want, "r {r}, ray {o:?} + t {d:?}, t in [{lo}, {hi}]");
                    runs_seen += want.len();
                }
            }
        }
    }
    assert!(runs_seen > 20_000, "too few runs to mean anything: {runs_seen}");
}

/// 16x16 pixels from each of 6 cameras around the box [-1, 1]^3, one inside it.
fn camera_rays() -> RayBatch<f64> {
    let k = Intrinsics::from_vertical_fov(16, 16, 40f64.to_radians()).unwrap();
    let eyes: [[f64; 3]; 6] = [
        [0.0, -3.0, 0.0],
        [2.1, 2.1, 0.3],
        [0.0, 0.5, 2.9],
        [-1.0, 0.4, -2.8],
        [0.3, 0.2, 0.1],
        [-2.9, 0.0, 0.5],
    ];
    let cams: Vec<RayBatch<f64>> = eyes
        .iter()
        .map(|&eye| {
            let up = if eye[2].abs() > 2.0 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            PinholeCamera::look_at(k, eye, [0.0; 3], up).unwrap().rays()
        })
        .collect();
    RayBatch::concat(&cams)
}

#[test]
fn the_marcher_samples_as_it_did_with_the_stepped_walk() {
    let mut rng = StdRng::seed_from_u64(4);
    let rays = camera_rays();
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    // The box's crossings, and intervals at random (some missing the box).
    let crossings = bounds.clip(&rays);
    let t_near: Vec<f64> = (0..rays.len()).map(|_| rng.gen_range(0.0..3.0)).collect();
    let t_far: Vec<f64> = t_near.iter().map(|&t| t + rng.gen_range(0.0..3.0)).collect();
    let random = RayIntervals::new(t_near, t_far).unwrap();
    let mut samples = 0;
    for g in grids(13, &mut rng) {
        for iv in [&crossings, &random] {
            for jitter in [Jitter::None, Jitter::PerRay { seed: 7 }, Jitter::PerSample { seed: 9 }] {
                let want = stepped_march(&g, &rays, iv, 0.05, jitter);
                samples += want.len();
                assert_eq!(g.march(&rays, iv, 0.05, jitter).unwrap(), want);
            }
        }
    }
    assert!(samples > 20_000, "too few samples to mean anything: {samples}");
}
