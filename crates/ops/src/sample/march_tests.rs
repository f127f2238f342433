//! The occupancy marcher against a dense march, against the uniform sampler, and by hand.

use std::convert::Infallible;

use super::*;
use crate::rays::{Aabb, Intrinsics, PinholeCamera, RayBatch, RayIntervals};
use crate::{Op, OpsError};
use ndarray::{arr2, Array1, ArrayView2};
use rand::{Rng, SeedableRng};

pub(super) fn cube() -> Aabb {
    Aabb::new([-1.0; 3], [1.0; 3]).unwrap()
}

/// Four views of the cube from distance 3, 12x12 pixels, 40 degrees.
pub(super) fn camera_rays() -> RayBatch<f64> {
    let k = Intrinsics::from_vertical_fov(12, 12, 40f64.to_radians()).unwrap();
    let eyes: [[f64; 3]; 4] = [[0.0, -3.0, 0.0], [2.1, 2.1, 0.3], [0.0, 0.5, 2.9], [-1.0, 0.4, -2.8]];
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

/// Density 10 inside three balls of radius 0.3, 0 elsewhere.
fn balls(p: ArrayView2<'_, f64>) -> Result<Array1<f64>, Infallible> {
    let centres = [[0.3, -0.2, 0.1], [-0.5, 0.5, -0.4], [0.6, 0.6, 0.6]];
    Ok(Array1::from_iter(p.rows().into_iter().map(|q| {
        let inside = centres
            .iter()
            .any(|c| (0..3).map(|a| (q[a] - c[a]).powi(2)).sum::<f64>() < 0.09);
        if inside {
            10.0
        } else {
            0.0
        }
    })))
}

/// A grid of `resolution^3` cells over the cube marking the cells whose centre is in a ball.
pub(super) fn balls_grid(resolution: usize) -> OccupancyGrid {
    let mut grid = OccupancyGrid::new(cube(), resolution, OccupancyConfig::density(1.0).unwrap()).unwrap();
    grid.update(balls, CellPoints::Centre).unwrap();
    grid
}

#[test]
fn a_fully_occupied_grid_marches_as_the_uniform_sampler() {
    let miss = RayBatch::new(arr2(&[[0.0, 0.0, 3.0]]), arr2(&[[1.0, 0.0, 0.0]])).unwrap();
    let rays = RayBatch::concat(&[camera_rays(), miss]);
    let iv = cube().clip(&rays);
    let grid = OccupancyGrid::new(cube(), 8, OccupancyConfig::opacity(0.07, 0.01).unwrap()).unwrap();
    let marched = grid.march(&rays, &iv, 0.07, Jitter::None).unwrap();
    let uniform = Uniform::new(Spacing::Step(0.07)).unwrap().sample(&rays, &iv).unwrap();
    assert_eq!(marched, uniform);
    assert!(iv.hit().iter().any(|h| !h), "some rays miss the cube");
}

#[test]
fn counts_by_hand_on_one_occupied_slab() {
    // 4 cells per axis over [-1, 1] (size 0.5); only the slab x in [0, 0.5] (ix = 2) has
    // matter. A ray along +x from x = -3 crosses the cube for t in [2, 4] and the slab for
    // t in [3, 3.5]; the step grid 2 + 0.2 i cuts that at 3.2 and 3.4: three samples
    // (t 3.1, 3.3, 3.45; delta 0.2, 0.2, 0.1) against ten for the uniform sampler.
    let config = OccupancyConfig::density(0.5).unwrap();
    let mut grid = OccupancyGrid::new(cube(), 4, config).unwrap();
    let slab = |p: ArrayView2<'_, f64>| {
        Ok::<_, Infallible>(p.column(0).mapv(|x| if (0.0..0.5).contains(&x) { 1.0 } else { 0.0 }))
    };
    grid.update(slab, CellPoints::Centre).unwrap();
    assert_eq!(grid.occupied_fraction(), 0.25);
    let rays = RayBatch::new(
        arr2(&[[-3.0, 0.1, 0.1], [-3.0, 3.0, 0.0], [0.2, 0.0, 0.0]]),
        arr2(&[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    )
    .unwrap();
    let iv = cube().clip(&rays);
    let s = grid.march(&rays, &iv, 0.2, Jitter::None).unwrap();
    // Ray 1 misses the cube; ray 2 starts inside the slab and runs along it, y in [0, 1]:
    // pieces [0, 0.2], [0.2, 0.4], ... [0.8, 1.0].
    assert_eq!(s.offsets, vec![0, 3, 3, 8]);
    let want_t: [f64; 8] = [3.1, 3.3, 3.45, 0.1, 0.3, 0.5, 0.7, 0.9];
    let want_delta: [f64; 8] = [0.2, 0.2, 0.1, 0.2, 0.2, 0.2, 0.2, 0.2];
    for k in 0..8 {
        assert!(
            (s.t[k] - want_t[k]).abs() < 1e-12 && (s.delta[k] - want_delta[k]).abs() < 1e-12,
            "sample {k}"
        );
    }
    let u = Uniform::new(Spacing::Step(0.2)).unwrap().sample(&rays, &iv).unwrap();
    assert_eq!(u.offsets, vec![0, 10, 10, 15]);
}

/// `n` random rays from `seed`: half start inside the cube, and every 25th runs along z
/// through cell faces of power-of-two grids.
pub(super) fn random_rays(seed: u64, n: usize) -> RayBatch<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut o = ndarray::Array2::zeros((n, 3));
    let mut d = ndarray::Array2::zeros((n, 3));
    for i in 0..n {
        for a in 0..3 {
            // Half the rays start inside the cube.
            o[[i, a]] = if i % 2 == 0 {
                rng.gen_range(-3.0..3.0)
            } else {
                rng.gen_range(-1.0..1.0)
            };
            d[[i, a]] = rng.gen_range(-1.0..1.0);
        }
        // A few axis-parallel rays through cell boundaries.
        if i % 25 == 0 {
            d.row_mut(i).assign(&ndarray::arr1(&[0.0, 0.0, 1.0]));
            o.row_mut(i).assign(&ndarray::arr1(&[0.25, -0.125, -2.0]));
        }
    }
    RayBatch::new(o, d).unwrap()
}

#[test]
fn matches_a_dense_march_on_random_rays() {
    let r = 16;
    let grid = balls_grid(r);
    let occupied = grid.occupied_fraction();
    assert!(occupied > 0.02 && occupied < 0.2, "{occupied}");
    let n = 300;
    let rays = random_rays(11, n);
    let iv = cube().clip(&rays);
    let step = 0.05;
    for jitter in [Jitter::None, Jitter::PerRay { seed: 2 }, Jitter::PerSample { seed: 2 }] {
        let s = grid.march(&rays, &iv, step, jitter).unwrap();
        let mut covered_total = 0.0;
        for ray in 0..n {
            let (orig, dir) = rays.ray(ray);
            let at = |t: f64| -> [f64; 3] { std::array::from_fn(|a| orig[a] + t * dir[a]) };
            let pieces: Vec<(f64, f64)> = s
                .range(ray)
                .unwrap()
                .map(|k| (s.t[k] - s.delta[k] / 2.0, s.t[k] + s.delta[k] / 2.0))
                .collect();
            let Some((near, far)) = iv.segment(ray) else {
                assert!(pieces.is_empty());
                continue;
            };
            for (k, &(lo, hi)) in pieces.iter().enumerate() {
                // Inside the segment, sorted, not overlapping, at most a step (2 with per-sample jitter).
                assert!(near - 1e-12 <= lo && hi <= far + 1e-12 && lo < hi);
                assert!(k == 0 || pieces[k - 1].1 <= lo + 1e-12);
                let longest = if matches!(jitter, Jitter::PerSample { .. }) {
                    2.0 * step
                } else {
                    step
                };
                assert!(hi - lo <= longest * (1.0 + 1e-6));
                // The sample point is in an occupied cell.
                assert!(
                    grid.is_occupied_at(at(0.5 * (lo + hi))),
                    "ray {ray} sample {k} in an empty cell"
                );
            }
            // Dense oracle: every point of a march 50 times finer that lies in an occupied cell
            // is covered by a piece, and no piece covers a point in an empty cell (away from
            // cell faces, where rounding decides).
            let fine = step / 50.0;
            let mut t = near + fine / 2.0;
            while t < far {
                let in_piece = pieces.iter().any(|&(lo, hi)| lo - 1e-9 <= t && t <= hi + 1e-9);
                let strictly_inside = pieces.iter().any(|&(lo, hi)| lo + 1e-9 < t && t < hi - 1e-9);
                let occupied = grid.is_occupied_at(at(t));
                assert!(!occupied || in_piece, "ray {ray}: occupied t {t} not covered");
                if strictly_inside && !occupied {
                    let near_face = [-1e-9, 1e-9].iter().any(|e| grid.is_occupied_at(at(t + e)));
                    assert!(near_face, "ray {ray}: empty t {t} covered");
                }
                covered_total += if occupied { fine } else { 0.0 };
                t += fine;
            }
        }
        let sampled: f64 = s.delta.sum();
        assert!(
            (sampled - covered_total).abs() < 0.01 * covered_total,
            "{sampled} vs {covered_total}"
        );
    }
}

#[test]
fn output_does_not_depend_on_the_thread_count() {
    let mut grid = OccupancyGrid::new(cube(), 16, OccupancyConfig::density(1.0).unwrap()).unwrap();
    grid.update(balls, CellPoints::CentreAndRandom { seed: 9 }).unwrap();
    let rays = camera_rays();
    let iv = cube().clip(&rays);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut g = OccupancyGrid::new(cube(), 16, OccupancyConfig::density(1.0).unwrap()).unwrap();
            g.update(balls, CellPoints::CentreAndRandom { seed: 9 }).unwrap();
            (
                g.clone(),
                g.march(&rays, &iv, 0.03, Jitter::PerSample { seed: 4 }).unwrap(),
            )
        })
    };
    let (g1, s1) = run(1);
    let (g3, s3) = run(3);
    assert_eq!(g1, grid);
    assert_eq!(g1, g3);
    assert_eq!(s1, s3);
}

#[test]
fn bad_marches_are_errors() {
    let grid = OccupancyGrid::new(cube(), 4, OccupancyConfig::density(1.0).unwrap()).unwrap();
    let rays = camera_rays();
    let iv = cube().clip(&rays);
    assert!(matches!(
        grid.march(&rays, &iv, 0.0, Jitter::None),
        Err(OpsError::Config {
            op: Op::Sample,
            what: "step",
            ..
        })
    ));
    let short = RayIntervals::new(vec![0.0], vec![1.0]).unwrap();
    assert!(matches!(
        grid.march(&rays, &short, 0.1, Jitter::None),
        Err(OpsError::Shape { op: Op::Sample, .. })
    ));
}

/// Rays are walked two at a time: every ray's samples must be those of its walk alone (the
/// per-ray walk and cut), bit for bit, whatever its neighbour does: misses the box, ends
/// sooner or later, starts inside, or is the odd one out of its task.
#[test]
fn rays_walked_in_pairs_sample_as_each_walked_alone() {
    let r = 16;
    let grid = balls_grid(r);
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    // More than two parallel tasks of rays, and an odd count.
    let n = 2 * super::packed::RAYS_PER_TASK + 37;
    let mut o = ndarray::Array2::zeros((n, 3));
    let mut d = ndarray::Array2::zeros((n, 3));
    let centres = [[0.3, -0.2, 0.1], [-0.5, 0.5, -0.4], [0.6, 0.6, 0.6]];
    for i in 0..n {
        let aim = centres[i % 3];
        for a in 0..3 {
            // From outside towards a ball, from inside anywhere, or from outside away.
            let (start, dir) = match i % 4 {
                0 | 1 => {
                    let s = rng.gen_range(-3.0..3.0);
                    (s, aim[a] + rng.gen_range(-0.2..0.2) - s)
                }
                2 => (rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)),
                _ => (rng.gen_range(2.0..4.0), rng.gen_range(0.1..1.0)),
            };
            o[[i, a]] = start;
            d[[i, a]] = dir;
        }
    }
    let rays = RayBatch::new(o, d).unwrap();
    let iv = cube().clip(&rays);
    assert!(iv.hit().iter().filter(|h| !**h).count() > 10, "some rays miss");
    let step = 0.05;
    for jitter in [Jitter::None, Jitter::PerRay { seed: 3 }, Jitter::PerSample { seed: 3 }] {
        let marched = grid.march(&rays, &iv, step, jitter).unwrap();
        let alone = super::packed::pack(&rays, |ray, pieces| {
            let (orig, dir) = rays.ray(ray);
            let (Some((near, far)), Some((bn, bf))) = (iv.segment(ray), cube().clip_ray(orig, dir)) else {
                return;
            };
            let (lo, hi) = (near.max(bn), far.min(bf));
            if hi > lo {
                let mut j = super::stratified::RayJitter::for_ray(jitter, ray);
                grid.occupied_runs(orig, dir, lo, hi, |a, b| j.cut(a, b, lo, step, pieces));
            }
        });
        let rays_with_samples = (0..n).filter(|&r| !marched.range(r).unwrap().is_empty()).count();
        assert!(
            rays_with_samples > n / 5,
            "{jitter:?}: {rays_with_samples} rays with samples"
        );
        assert_eq!(marched, alone, "{jitter:?}");
    }
}
