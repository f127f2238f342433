//! The lockstep walk (several rays at once) against the one-ray walk it stands in for, run by
//! run and bit for bit, and the marcher's samples with either walk.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::march_lanes::{RaySpan, SpanRuns};
use super::march_walk_tests::{grid_with, patterns, tricky_rays};
use super::*;
use crate::rays::{Aabb, Intrinsics, PinholeCamera, RayBatch};

/// Each span's runs from the one-ray walk: the oracle.
fn one_by_one(g: &OccupancyGrid, spans: &[RaySpan]) -> Vec<Vec<(f64, f64)>> {
    spans
        .iter()
        .map(|s| {
            let mut runs = Vec::new();
            g.occupied_runs(s.o, s.d, s.lo, s.hi, |a, b| runs.push((a, b)));
            runs
        })
        .collect()
}

fn lockstep<const K: usize>(g: &OccupancyGrid, spans: &[RaySpan], out: &mut SpanRuns) -> Vec<Vec<(f64, f64)>> {
    g.occupied_runs_of_spans::<K>(spans, out);
    (0..spans.len()).map(|i| out.of(i).to_vec()).collect()
}

/// Spans of the tricky rays: each whole crossing of the box, and a part starting and ending
/// inside it, shuffled so that long and short walks share the lanes in every order.
fn spans_of(g: &OccupancyGrid, rng: &mut StdRng) -> Vec<RaySpan> {
    let mut spans = Vec::new();
    for (o, d) in tricky_rays(g.resolution(), rng) {
        let Some((lo, hi)) = g.bounds().clip_ray(o, d) else {
            continue;
        };
        spans.push(RaySpan { o, d, lo, hi });
        let (a, b) = (lo + 0.3 * (hi - lo), lo + 0.8 * (hi - lo));
        spans.push(RaySpan { o, d, lo: a, hi: b });
    }
    for i in (1..spans.len()).rev() {
        spans.swap(i, rng.gen_range(0..=i));
    }
    spans
}

#[test]
fn walking_rays_in_lockstep_gives_every_ray_the_runs_of_its_own_walk_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(33);
    let mut out = SpanRuns::default();
    let mut runs_seen = 0;
    for r in [1, 2, 5, 8, 9, 14] {
        let mut grids = patterns(r, &mut rng);
        grids.push(grid_with(r, |_| true));
        grids.push(grid_with(r, |_| false));
        for g in &grids {
            let spans = spans_of(g, &mut rng);
            let want = one_by_one(g, &spans);
            runs_seen += want.iter().map(Vec::len).sum::<usize>();
            // The same buffers reused from one call to the next, as the marcher does not.
            assert_eq!(lockstep::<1>(g, &spans, &mut out), want, "r {r}, 1 lane");
            assert_eq!(lockstep::<3>(g, &spans, &mut out), want, "r {r}, 3 lanes");
            assert_eq!(lockstep::<4>(g, &spans, &mut out), want, "r {r}, 4 lanes");
            assert_eq!(lockstep::<8>(g, &spans, &mut out), want, "r {r}, 8 lanes");
            // Fewer spans than lanes, and none.
            assert_eq!(lockstep::<8>(g, &spans[..3], &mut out), want[..3], "r {r}, 3 spans");
            assert!(lockstep::<4>(g, &[], &mut out).is_empty());
        }
    }
    assert!(runs_seen > 5000, "too few runs to mean anything: {runs_seen}");
}

/// 16x16 pixels from each of 6 cameras at distance 3 around a box of [-1, 1]^3.
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
fn the_marcher_samples_the_same_with_either_walk() {
    let mut rng = StdRng::seed_from_u64(4);
    let rays = camera_rays();
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    // The box's crossings, and intervals cut short at random (some missing the box).
    let full = bounds.clip(&rays);
    let t_near: Vec<f64> = (0..rays.len()).map(|_| rng.gen_range(0.0..3.0)).collect();
    let t_far: Vec<f64> = t_near.iter().map(|&t| t + rng.gen_range(0.0..3.0)).collect();
    let cut_short = crate::rays::RayIntervals::new(t_near, t_far).unwrap();
    let r = 13;
    let mut grids = patterns(r, &mut rng);
    grids.push(grid_with(r, |_| true));
    grids.push(grid_with(r, |_| false));
    let mut samples = 0;
    for g in &grids {
        for iv in [&full, &cut_short] {
            for jitter in [Jitter::None, Jitter::PerRay { seed: 7 }, Jitter::PerSample { seed: 9 }] {
                let want = g.march_walked::<0, f64>(&rays, iv, 0.05, jitter);
                samples += want.len();
                assert_eq!(g.march(&rays, iv, 0.05, jitter).unwrap(), want);
                assert_eq!(g.march_walked::<8, f64>(&rays, iv, 0.05, jitter), want);
            }
        }
    }
    assert!(samples > 20_000, "too few samples to mean anything: {samples}");
}
