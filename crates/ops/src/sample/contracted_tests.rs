//! The contracted sampler against closed forms: radial rays' edges, world lengths, the
//! contracted spacing, occupancy skipping against a brute-force filter, and composites of
//! densities whose optical depth is known.

use fogray_tape::{Float, Tape};
use ndarray::{arr2, Array1, Array2, Array3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::{ContractedSampler, Jitter, OccupancyConfig, OccupancyGrid, OccupancyState, PackedSamples};
use crate::rays::RayBatch;
use crate::space::{Contraction, InnerRegion};
use crate::{Background, Composite, CompositeInputs};

const C: [f64; 3] = [0.5, -1.0, 2.0];
const R: f64 = 2.0;
const STEP: f64 = 1.0 / 16.0;
const GAP: f64 = 1e-3;

fn sampler() -> ContractedSampler {
    let space = Contraction::new(InnerRegion::new(C, R).unwrap()).unwrap();
    ContractedSampler::new(space, STEP).unwrap().with_far_gap(GAP).unwrap()
}

fn one_ray<F: Float>(o: [f64; 3], d: [f64; 3]) -> RayBatch<F> {
    RayBatch::new(arr2(&[o.map(F::lit)]), arr2(&[d.map(F::lit)])).unwrap()
}

/// The world edges of ray `r`'s pieces, rebuilt from midpoints and lengths.
fn edges(s: &PackedSamples<f64>, r: usize) -> Vec<(f64, f64)> {
    s.range(r)
        .unwrap()
        .map(|k| (s.t[k] - 0.5 * s.delta[k], s.t[k] + 0.5 * s.delta[k]))
        .collect()
}

/// Radial ray from the centre along unit `d`: the contracted path is the straight segment
/// `y = |y| d / |d|`, so the edge at contracted distance `k s` is at world depth
/// `t = k s r` inside (`|u| = t / r`), and outside, with `n = ||d||_inf` and
/// `m = t n / r`, `|y| = (2 - 1/m) / n = k s`: `t = r / (n (2 - k s n))`.
fn radial_edge(d: [f64; 3], k: usize) -> f64 {
    let n = d.iter().fold(0f64, |a, v| a.max(v.abs()));
    let along = k as f64 * STEP;
    if along * n <= 1.0 {
        along * R
    } else {
        R / (n * (2.0 - along * n))
    }
}

#[test]
fn radial_rays_have_closed_form_edges() {
    let s3 = 1.0 / 3f64.sqrt();
    for d in [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [s3, s3, s3], [0.6, -0.8, 0.0]] {
        let n = d.iter().fold(0f64, |a, v| a.max(v.abs()));
        let samples = sampler()
            .sample(&one_ray::<f64>(C, d), &[0.0], Jitter::None, None)
            .unwrap();
        let e = edges(&samples, 0);
        // Edges at k s along the path until |y| reaches (2 - gap) / n, the far end
        // t_far = r / (gap n); the last piece is shorter.
        let path = (2.0 - GAP) / n;
        let count = (path / STEP).ceil() as usize;
        assert_eq!(e.len(), count, "{d:?}");
        for (k, &(lo, hi)) in e.iter().enumerate() {
            let m = (hi * n / R).max(1.0);
            // The chord is solved to 1e-12 in contracted units; a world depth moves by that
            // over the speed, at least 1 / (r m^2) here: relative error 1e-12 m, plus the
            // rounding of rebuilding the edges.
            let tol = 1e-12 * m * hi + 1e-14 * hi.max(1.0);
            assert!(
                (lo - radial_edge(d, k)).abs() <= tol,
                "{d:?} piece {k}: {lo} vs {}",
                radial_edge(d, k)
            );
            let far = if k + 1 == count {
                R / (GAP * n)
            } else {
                radial_edge(d, k + 1)
            };
            assert!((hi - far).abs() <= tol, "{d:?} piece {k}: {hi} vs {far}");
        }
        // The positions are the contracted midpoints: |y| along d, in closed form.
        let k = count / 2;
        let t_mid = samples.t[k];
        let m = t_mid * n / R;
        let along = if m <= 1.0 { t_mid / R } else { (2.0 - 1.0 / m) / n };
        for (&p, &da) in samples.positions.row(k).iter().zip(&d) {
            assert!((p - along * da).abs() < 1e-14);
        }
    }
}

fn random_rays(n: usize, seed: u64, spread: f64) -> (RayBatch<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let o = Array2::from_shape_fn((n, 3), |(_, a)| C[a] + R * rng.gen_range(-spread..spread));
    let d = Array2::from_shape_fn((n, 3), |_| rng.gen_range(-1.0..1.0));
    let near = (0..n).map(|_| rng.gen_range(0.0..0.5 * R)).collect();
    (RayBatch::new(o, d).unwrap(), near)
}

/// The far end by hand: where the ray leaves the box `|x - c|_inf <= r / gap`.
fn exit(o: [f64; 3], d: [f64; 3]) -> f64 {
    let h = R / GAP;
    (0..3)
        .filter(|&a| d[a] != 0.0)
        .map(|a| {
            if d[a] > 0.0 {
                (C[a] + h - o[a]) / d[a]
            } else {
                (C[a] - h - o[a]) / d[a]
            }
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn pieces_tile_the_ray_and_are_a_step_apart_in_contracted_space() {
    let (rays, near) = random_rays(64, 7, 3.0);
    let s = sampler();
    let samples = s.sample(&rays, &near, Jitter::None, None).unwrap();
    for (r, &near) in near.iter().enumerate() {
        let (o, d) = rays.ray(r);
        let e = edges(&samples, r);
        let t_far = exit(o, d);
        // The sum of the world lengths is the length covered, near to far.
        let total: f64 = samples.range(r).unwrap().map(|k| samples.delta[k]).sum();
        assert!((total - (t_far - near)).abs() <= 1e-12 * t_far, "ray {r}: {total}");
        // Consecutive pieces share their edges.
        for w in e.windows(2) {
            assert!((w[0].1 - w[1].0).abs() <= 1e-15 * w[1].0.max(1.0) * 4.0);
        }
        // Every piece but the last spans exactly the step in contracted space: the solver's
        // 1e-12, and rebuilding an edge from (t, delta) moves it by about 1e-16 t, which
        // moves its contracted point by at most 1e-16 (t |J d| <= 2 on a ray from near the
        // region).
        let at = |t: f64| s.contraction().contract(std::array::from_fn(|a| o[a] + t * d[a]));
        for (k, &(lo, hi)) in e.iter().enumerate() {
            let chord = {
                let (a, b) = (at(lo), at(hi));
                (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
            };
            if k + 1 < e.len() {
                assert!((chord - STEP).abs() < 2e-12, "ray {r} piece {k}: {chord}");
            } else {
                assert!(chord <= STEP + 2e-12);
            }
        }
    }
}

#[test]
fn contracted_paths_are_short() {
    // Rays from anywhere within 10 inner radii, any direction: the image of a half-line
    // stays below MAX_CONTRACTED_PATH, so no ray reaches the default cap.
    let (rays, near) = random_rays(256, 8, 10.0);
    let s = sampler();
    let samples = s.sample(&rays, &near, Jitter::None, None).unwrap();
    for r in 0..rays.len() {
        let n = samples.range(r).unwrap().len();
        assert!(((n as f64 - 1.0) * STEP) < super::MAX_CONTRACTED_PATH, "ray {r}: {n}");
        assert!(n < s.max_samples());
    }
}

/// A random occupancy state over the cube, a third of its cells occupied.
fn random_grid(seed: u64) -> OccupancyGrid {
    let mut grid = OccupancyGrid::new(Contraction::cube(), 8, OccupancyConfig::density(1.0).unwrap()).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let occupied = Array3::from_shape_fn((8, 8, 8), |_| rng.gen::<f64>() < 0.35);
    let estimate = Array3::zeros((8, 8, 8));
    grid.restore(&OccupancyState { estimate, occupied }).unwrap();
    grid
}

#[test]
fn occupancy_skipping_drops_exactly_the_samples_in_empty_cells() {
    let (rays, near) = random_rays(40, 9, 4.0);
    let grid = random_grid(10);
    let s = sampler();
    for jitter in [Jitter::None, Jitter::PerRay { seed: 3 }] {
        let all = s.sample(&rays, &near, jitter, None).unwrap();
        let kept = s.sample(&rays, &near, jitter, Some(&grid)).unwrap();
        // Brute force: every sample's contracted position tested on its own.
        let mut expect = Vec::new();
        let mut counts = vec![0usize; rays.len()];
        for k in 0..all.len() {
            let p = [all.positions[[k, 0]], all.positions[[k, 1]], all.positions[[k, 2]]];
            if grid.is_occupied_at(p) {
                expect.push(k);
                counts[all.ray[k]] += 1;
            }
        }
        assert!(!expect.is_empty() && expect.len() < all.len());
        assert_eq!(kept.len(), expect.len());
        for (j, &k) in expect.iter().enumerate() {
            assert_eq!(kept.t[j], all.t[k]);
            assert_eq!(kept.delta[j], all.delta[k]);
            assert_eq!(kept.positions.row(j), all.positions.row(k));
            assert_eq!(kept.ray[j], all.ray[k]);
        }
        for (r, &c) in counts.iter().enumerate() {
            assert_eq!(kept.range(r).unwrap().len(), c);
        }
    }
}

#[test]
fn per_ray_jitter_shortens_the_first_piece_only() {
    let (rays, near) = random_rays(16, 11, 2.0);
    let s = sampler();
    let a = s.sample(&rays, &near, Jitter::PerRay { seed: 5 }, None).unwrap();
    let b = s.sample(&rays, &near, Jitter::PerRay { seed: 5 }, None).unwrap();
    assert_eq!(a, b);
    for r in 0..rays.len() {
        let (o, d) = rays.ray(r);
        let e = edges(&a, r);
        let at = |t: f64| s.contraction().contract(std::array::from_fn(|k| o[k] + t * d[k]));
        let chord = |lo: f64, hi: f64| {
            let (p, q) = (at(lo), at(hi));
            (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt()
        };
        assert!(chord(e[0].0, e[0].1) <= STEP + 2e-12);
        assert!((chord(e[1].0, e[1].1) - STEP).abs() < 2e-12);
    }
    assert!(s.sample(&rays, &near, Jitter::PerSample { seed: 1 }, None).is_err());
}

/// The opacity `1 - exp(-sum sigma delta)` of one ray's samples through the composite.
fn composite_opacity<F: Float>(samples: &PackedSamples<F>, sigma: Array1<F>) -> f64 {
    let mut tape = Tape::<F>::new();
    let n = samples.len();
    let inputs = CompositeInputs {
        sigma: tape.constant(sigma),
        delta: tape.constant(samples.delta.clone()),
        color: tape.constant(Array2::<F>::ones((n, 1))),
        background: None,
        t: None,
    };
    let op = Composite::new(&samples.offsets).unwrap().background(Background::None);
    let out = op.apply(&mut tape, &inputs).unwrap();
    tape.value(out.opacity).unwrap()[0].as_f64()
}

fn world_point<F: Float>(rays: &RayBatch<F>, samples: &PackedSamples<F>, k: usize) -> [f64; 3] {
    let (o, d) = rays.ray(samples.ray[k]);
    let t = samples.t[k].as_f64();
    std::array::from_fn(|a| o[a] + t * d[a])
}

/// A far shell of uniform density on a radial ray: its faces at the edges k1 and k2, so
/// every piece lies wholly inside or outside it and the sampled optical depth is the
/// world integral `sigma (R2 - R1)` to rounding.
fn far_shell<F: Float>(tol: f64) {
    let s3 = 1.0 / 3f64.sqrt();
    let d = [s3, -s3, s3];
    // |y| from 2.5 to 3.125 along the diagonal (sqrt 3 at the inner corner): m from about
    // 1.8 to 5.1, where a piece is up to 26 times longer in the world than inside.
    let (k1, k2) = (40, 50);
    let (r1, r2) = (radial_edge(d, k1), radial_edge(d, k2));
    let sigma1 = 0.8 / (r2 - r1);
    let rays = one_ray::<F>(C, d);
    let samples = sampler().sample(&rays, &[0.0], Jitter::None, None).unwrap();
    let sigma = Array1::from_iter((0..samples.len()).map(|k| {
        let p = world_point(&rays, &samples, k);
        let dist = (0..3).map(|a| (p[a] - C[a]).powi(2)).sum::<f64>().sqrt();
        F::lit(if dist > r1 && dist < r2 { sigma1 } else { 0.0 })
    }));
    let opacity = composite_opacity(&samples, sigma);
    let expect = 1.0 - (-0.8f64).exp();
    assert!((opacity - expect).abs() < tol, "{} {opacity} vs {expect}", F::NAME);
}

#[test]
fn a_far_shell_composites_to_its_closed_form() {
    // f64: each edge is solved to 1e-12 in contracted units, 1e-12 r m^2 in the world
    // (m <= 5.1), against a shell of thickness r2 - r1 of optical depth 0.8.
    far_shell::<f64>(1e-10);
    // f32: the direction rounded to f32 (relative 6e-8, moving the shell's edges by that
    // much of r2) and ten deltas rounded (6e-8 each).
    far_shell::<f32>(2e-6);
}

/// A ball of density `sigma0` and radius 0.6 r at the centre, crossed off-centre at
/// distance b: optical depth `2 sigma0 sqrt((0.6 r)^2 - b^2)`. The inner region's pieces
/// are `s r` long in the world, and a piece across the ball's surface is counted wholly
/// or not at all by its midpoint: at most half a piece wrong at each of the two crossings,
/// `|tau_sampled - tau| <= sigma0 s r`.
fn inner_ball<F: Float>() {
    let b = 0.3 * R;
    let rho = 0.6 * R;
    let sigma0 = 0.5;
    let o = [C[0] - 10.0 * R, C[1] + b, C[2]];
    let rays = one_ray::<F>(o, [1.0, 0.0, 0.0]);
    let samples = sampler()
        .sample(&rays, &[0.0], Jitter::PerRay { seed: 2 }, None)
        .unwrap();
    let sigma = Array1::from_iter((0..samples.len()).map(|k| {
        let p = world_point(&rays, &samples, k);
        let dist = (0..3).map(|a| (p[a] - C[a]).powi(2)).sum::<f64>().sqrt();
        F::lit(if dist < rho { sigma0 } else { 0.0 })
    }));
    let tau = 2.0 * sigma0 * (rho * rho - b * b).sqrt();
    let opacity = composite_opacity(&samples, sigma);
    let expect = 1.0 - (-tau).exp();
    // d opacity / d tau = exp(-tau) <= 1.
    assert!(
        (opacity - expect).abs() <= sigma0 * STEP * R,
        "{} {opacity} vs {expect}",
        F::NAME
    );
}

#[test]
fn an_inner_ball_composites_to_its_closed_form() {
    inner_ball::<f64>();
    inner_ball::<f32>();
}

#[test]
fn f32_samples_are_the_f64_samples_rounded() {
    let (rays, near) = random_rays(8, 12, 3.0);
    let rays32 = RayBatch::<f32>::new(rays.origins().mapv(|v| v as f32), rays.directions().mapv(|v| v as f32)).unwrap();
    // The f32 rays' own values, widened: the same rays in f64.
    let rays64 = RayBatch::<f64>::new(rays32.origins().mapv(f64::from), rays32.directions().mapv(f64::from)).unwrap();
    let s = sampler();
    let a = s.sample(&rays32, &near, Jitter::None, None).unwrap();
    let b = s.sample(&rays64, &near, Jitter::None, None).unwrap();
    // RayBatch renormalises the widened directions in f64, so the two batches differ by
    // about 1e-8 in direction: the same pieces, within f32's rounding.
    assert_eq!(a.offsets, b.offsets);
    for k in 0..a.len() {
        let close = |x: f32, y: f64| (f64::from(x) - y).abs() <= 1e-6 * y.abs().max(1.0);
        assert!(close(a.t[k], b.t[k]) && close(a.delta[k], b.delta[k]), "sample {k}");
        for c in 0..3 {
            assert!(close(a.positions[[k, c]], b.positions[[k, c]]));
        }
    }
}

#[test]
fn bad_input_is_an_error() {
    let s = sampler();
    let rays = one_ray::<f64>(C, [1.0, 0.0, 0.0]);
    assert!(s.sample(&rays, &[], Jitter::None, None).is_err());
    let e = s.sample(&rays, &[f64::NAN], Jitter::None, None).unwrap_err();
    assert!(e.to_string().contains("ray 0"), "{e}");
    assert!(s.sample(&rays, &[-1.0], Jitter::None, None).is_err());
    let boxed = OccupancyGrid::new(
        crate::rays::Aabb::new([-1.0; 3], [1.0; 3]).unwrap(),
        4,
        OccupancyConfig::density(0.0).unwrap(),
    )
    .unwrap();
    assert!(s.sample(&rays, &[0.0], Jitter::None, Some(&boxed)).is_err());
    let space = *s.contraction();
    assert!(ContractedSampler::new(space, 0.0).is_err());
    assert!(ContractedSampler::new(space, 5.0).is_err());
    assert!(s.with_far_gap(1.0).is_err());
    assert!(s.with_max_samples(0).is_err());
    // A ray starting past the far gap and leading away has no sample.
    let away = one_ray::<f64>([C[0] + 2.0 * R / GAP, C[1], C[2]], [1.0, 0.0, 0.0]);
    assert!(s.sample(&away, &[0.0], Jitter::None, None).unwrap().is_empty());
    // The cap: a ray stops after max_samples pieces.
    let capped = s
        .with_max_samples(5)
        .unwrap()
        .sample(&rays, &[0.0], Jitter::None, None)
        .unwrap();
    assert_eq!(capped.len(), 5);
}
