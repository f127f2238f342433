//! The midpoint sampler against the uniform and stratified samplers filtered by the grid's
//! own point test, by hand, and against the march.

use std::convert::Infallible;

use super::march_tests::{balls_grid, camera_rays, cube, random_rays};
use super::*;
use crate::rays::RayBatch;
use crate::{Op, OpsError};
use fogray_tape::Offsets;
use ndarray::{arr2, ArrayView2};

const JITTERS: [Jitter; 3] = [Jitter::None, Jitter::PerRay { seed: 3 }, Jitter::PerSample { seed: 3 }];

#[test]
fn a_fully_occupied_grid_gives_the_uniform_and_stratified_samples() {
    let miss = RayBatch::new(arr2(&[[0.0, 0.0, 3.0]]), arr2(&[[1.0, 0.0, 0.0]])).unwrap();
    let rays = RayBatch::concat(&[camera_rays(), miss]);
    let iv = cube().clip(&rays);
    let grid = OccupancyGrid::new(cube(), 8, OccupancyConfig::opacity(0.07, 0.01).unwrap()).unwrap();
    let uniform = Uniform::new(Spacing::Step(0.07)).unwrap().sample(&rays, &iv).unwrap();
    assert_eq!(grid.march_midpoints(&rays, &iv, 0.07, Jitter::None).unwrap(), uniform);
    for jitter in JITTERS {
        let stratified = Stratified::new(Spacing::Step(0.07), jitter)
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        assert_eq!(
            grid.march_midpoints(&rays, &iv, 0.07, jitter).unwrap(),
            stratified,
            "{jitter:?}"
        );
    }
}

#[test]
fn keeps_exactly_the_stratified_samples_in_occupied_cells() {
    // The reference: every sample of the stratified sampler (same pieces), kept where the
    // grid's point test (a division per axis, not the sampler's products) says occupied.
    let rays = RayBatch::concat(&[random_rays(17, 300), camera_rays()]);
    let iv = cube().clip(&rays);
    for resolution in [16, 37] {
        let grid = balls_grid(resolution);
        let occupied = grid.occupied_fraction();
        assert!(occupied > 0.02 && occupied < 0.3, "{occupied}");
        for jitter in JITTERS {
            let all = Stratified::new(Spacing::Step(0.05), jitter)
                .unwrap()
                .sample(&rays, &iv)
                .unwrap();
            let got = grid.march_midpoints(&rays, &iv, 0.05, jitter).unwrap();
            let (mut kept, mut lengths) = (Vec::new(), Vec::new());
            for r in 0..rays.len() {
                let before = kept.len();
                let (o, d) = rays.ray(r);
                for k in all.range(r).unwrap() {
                    let p = std::array::from_fn(|a| o[a] + all.t[k] * d[a]);
                    if grid.is_occupied_at(p) {
                        kept.push(k);
                    }
                }
                lengths.push(kept.len() - before);
            }
            assert!(
                kept.len() * 3 < all.len(),
                "most samples dropped: {} of {}",
                kept.len(),
                all.len()
            );
            assert_eq!(got.offsets, Offsets::from_lengths(lengths), "{resolution} {jitter:?}");
            for (i, &k) in kept.iter().enumerate() {
                assert_eq!(
                    (got.t[i], got.delta[i], got.ray[i]),
                    (all.t[k], all.delta[k], all.ray[k])
                );
                assert_eq!(got.positions.row(i), all.positions.row(k));
            }
        }
    }
}

#[test]
fn samples_by_hand_on_one_occupied_slab() {
    // 4 cells per axis over [-1, 1]; only the slab x in [0, 0.5] has matter. A ray along +x
    // from x = -3 crosses the cube for t in [2, 4]; its pieces 2 + 0.3 i have midpoints
    // 2.15, 2.45, ..., 3.85 (the last piece [3.8, 4] has midpoint 3.9): those in [3, 3.5]
    // (x in [0, 0.5]) are 3.05 and 3.35, each a whole piece of 0.3 (the march would cut
    // them at 3 and 3.5 instead).
    let mut grid = OccupancyGrid::new(cube(), 4, OccupancyConfig::density(0.5).unwrap()).unwrap();
    let slab = |p: ArrayView2<'_, f64>| {
        Ok::<_, Infallible>(p.column(0).mapv(|x| if (0.0..0.5).contains(&x) { 1.0 } else { 0.0 }))
    };
    grid.update(slab, CellPoints::Centre).unwrap();
    let rays: RayBatch<f64> =
        RayBatch::new(arr2(&[[-3.0, 0.1, 0.1], [-3.0, 3.0, 0.0]]), arr2(&[[1.0, 0.0, 0.0]; 2])).unwrap();
    let iv = cube().clip(&rays);
    let s = grid.march_midpoints(&rays, &iv, 0.3, Jitter::None).unwrap();
    assert_eq!(s.offsets, vec![0, 2, 2]);
    for (k, want) in [3.05f64, 3.35].into_iter().enumerate() {
        assert!(
            (s.t[k] - want).abs() < 1e-12 && (s.delta[k] - 0.3).abs() < 1e-12,
            "sample {k}: {}",
            s.t[k]
        );
        assert!((s.positions[[k, 0]] - (want - 3.0)).abs() < 1e-12);
    }
    // The march cuts the same slab at its faces: 3 to 3.2, 3.2 to 3.5.
    let m = grid.march(&rays, &iv, 0.3, Jitter::None).unwrap();
    assert_eq!(m.offsets, vec![0, 2, 2]);
    assert!((m.t[0] - 3.1).abs() < 1e-12 && (m.delta[1] - 0.3).abs() < 1e-12);
}

#[test]
fn draws_the_march_s_pieces_less_at_most_two_per_occupied_run() {
    // On the same step grid, a piece with an occupied midpoint meets an occupied run, so the
    // march has it too (cut at the run's faces); the march's other pieces each hold one of
    // the faces, two per run. So per ray: march - 2 runs <= midpoints <= march.
    let grid = balls_grid(32);
    let rays = RayBatch::concat(&[random_rays(23, 300), camera_rays()]);
    let iv = cube().clip(&rays);
    let step = 1.0 / 32.0;
    let marched = grid.march(&rays, &iv, step, Jitter::None).unwrap();
    let midpoints = grid.march_midpoints(&rays, &iv, step, Jitter::None).unwrap();
    let (mut fewer, mut runs_total) = (0, 0);
    for r in 0..rays.len() {
        let m = marched.range(r).unwrap();
        // A run ends where the next piece does not start at this one's end.
        let end = |k: usize| marched.t[k] + marched.delta[k] / 2.0;
        let start = |k: usize| marched.t[k] - marched.delta[k] / 2.0;
        let runs = m
            .clone()
            .filter(|&k| k == m.start || (start(k) - end(k - 1)).abs() > 1e-12)
            .count();
        let (nm, np) = (m.len(), midpoints.range(r).unwrap().len());
        assert!(
            np <= nm && nm <= np + 2 * runs,
            "ray {r}: {np} midpoints, {nm} marched, {runs} runs"
        );
        fewer += nm - np;
        runs_total += runs;
    }
    assert!(runs_total > 100 && fewer > 0, "{runs_total} runs, {fewer} fewer");
}

#[test]
fn output_does_not_depend_on_the_thread_count() {
    let grid = balls_grid(16);
    let rays = RayBatch::concat(&[random_rays(5, 300), camera_rays()]);
    let iv = cube().clip(&rays);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            grid.march_midpoints(&rays, &iv, 0.04, Jitter::PerSample { seed: 9 })
                .unwrap()
        })
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn bad_steps_and_intervals_are_errors() {
    let grid = balls_grid(4);
    let rays = camera_rays();
    let iv = cube().clip(&rays);
    for step in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        let e = grid.march_midpoints(&rays, &iv, step, Jitter::None).unwrap_err();
        assert!(
            matches!(
                e,
                OpsError::Config {
                    op: Op::Sample,
                    what: "step",
                    ..
                }
            ),
            "{e}"
        );
    }
    let other = cube().clip(&random_rays(1, 300));
    let e = grid.march_midpoints(&rays, &other, 0.1, Jitter::None).unwrap_err();
    assert!(
        matches!(
            e,
            OpsError::Shape {
                op: Op::Sample,
                what: "intervals",
                ..
            }
        ),
        "{e}"
    );
}
