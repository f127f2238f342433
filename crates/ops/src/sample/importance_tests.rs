//! Importance resampling against probabilities integrated independently, and by hand.

use super::importance::resample;
use super::stratified::{Jitter, RayJitter};
use super::*;
use crate::rays::RayBatch;
use crate::{At, Op, OpsError};
use ndarray::{arr1, arr2, Array1};

fn close(got: &[(f64, f64)], want: &[(f64, f64)]) {
    assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!(
            (g.0 - w.0).abs() < 1e-12 && (g.1 - w.1).abs() < 1e-12,
            "{got:?} vs {want:?}"
        );
    }
}

#[test]
fn pieces_by_hand() {
    let prev = [(0.0, 1.0), (1.0, 2.0)];
    // All the weight on [1, 2]: four equal pieces of it.
    let p = resample(&prev, &[0.0, 1.0], 0.0, 4, RayJitter::none());
    close(&p, &[(1.0, 1.25), (1.25, 1.5), (1.5, 1.75), (1.75, 2.0)]);
    // A floor of 1/2: masses 1/4 and 3/4; cuts at u = 1/4, 1/2, 3/4 map to
    // 1, 1 + (1/4)/(3/4) = 4/3, 1 + (2/4)/(3/4) = 5/3.
    let p = resample(&prev, &[0.0, 1.0], 0.5, 4, RayJitter::none());
    close(
        &p,
        &[(0.0, 1.0), (1.0, 4.0 / 3.0), (4.0 / 3.0, 5.0 / 3.0), (5.0 / 3.0, 2.0)],
    );
    // Zero weight everywhere: uniform over [0, 2].
    let p = resample(&prev, &[0.0, 0.0], 0.0, 2, RayJitter::none());
    close(&p, &[(0.0, 1.0), (1.0, 2.0)]);
    // A gap between [0, 1] and [3, 4], equal weights, three pieces: cuts at u = 1/3, 2/3 map
    // to 2/3 and 3 + (1/6)/(1/2) = 10/3; the middle piece [2/3, 10/3] is split at the gap.
    let p = resample(&[(0.0, 1.0), (3.0, 4.0)], &[1.0, 1.0], 0.0, 3, RayJitter::none());
    close(
        &p,
        &[(0.0, 2.0 / 3.0), (2.0 / 3.0, 1.0), (3.0, 10.0 / 3.0), (10.0 / 3.0, 4.0)],
    );
    // No previous samples, or only zero-length ones: nothing.
    assert!(resample(&[], &[], 0.0, 3, RayJitter::none()).is_empty());
    assert!(resample(&[(1.0, 1.0)], &[1.0], 0.0, 3, RayJitter::none()).is_empty());
}

/// The probability of `[a, b]` under the mixture pdf, integrated piece by piece (the forward
/// direction of what `resample` inverts).
fn mass(prev: &[(f64, f64)], w: &[f64], floor: f64, a: f64, b: f64) -> f64 {
    let total: f64 = w.iter().sum();
    let length: f64 = prev.iter().map(|p| p.1 - p.0).sum();
    prev.iter()
        .zip(w)
        .map(|(&(lo, hi), &wk)| {
            let m = (1.0 - floor) * wk / total + floor * (hi - lo) / length;
            let overlap = (b.min(hi) - a.max(lo)).max(0.0);
            m * overlap / (hi - lo)
        })
        .sum()
}

#[test]
fn every_piece_holds_an_equal_share_of_probability() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    for trial in 0..50 {
        // 20 contiguous previous pieces of random lengths and weights (some zero).
        let mut prev = Vec::new();
        let mut at = rng.gen_range(0.0..2.0);
        for _ in 0..20 {
            let len = rng.gen_range(0.01..0.3);
            prev.push((at, at + len));
            at += len;
        }
        let w: Vec<f64> = (0..20)
            .map(|_| {
                if rng.gen_bool(0.3) {
                    0.0
                } else {
                    rng.gen_range(0.0..1.0)
                }
            })
            .collect();
        let n = 16;
        for jitter in [Jitter::None, Jitter::PerSample { seed: trial }] {
            let p = resample(&prev, &w, 0.05, n, RayJitter::for_ray(jitter, 0));
            assert_eq!(p.len(), n);
            assert!((p[0].0 - prev[0].0).abs() < 1e-12 && (p[n - 1].1 - at).abs() < 1e-12);
            let mut total = 0.0;
            for (k, &(a, b)) in p.iter().enumerate() {
                assert!(b > a && (k == 0 || a == p[k - 1].1), "sorted and contiguous");
                let m = mass(&prev, &w, 0.05, a, b);
                if jitter == Jitter::None {
                    assert!((m - 1.0 / n as f64).abs() < 1e-12, "trial {trial} piece {k}: {m}");
                }
                total += m;
            }
            assert!((total - 1.0).abs() < 1e-12);
        }
    }
}

#[test]
fn resamples_packed_rays_from_the_composite_weights() {
    // Two rays along +x from the origin: ray 0 with uniform samples on [0, 2], ray 1 a miss.
    let rays = RayBatch::new(
        arr2(&[[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]]),
        arr2(&[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
    )
    .unwrap();
    let iv = crate::rays::RayIntervals::new(vec![0.0, 0.0], vec![2.0, 0.0]).unwrap();
    let coarse = Uniform::new(Spacing::Count(2)).unwrap().sample(&rays, &iv).unwrap();
    assert_eq!(coarse.offsets, vec![0, 2, 2]);
    let fine = Importance::new(4, 0.0, Jitter::None)
        .unwrap()
        .sample(&rays, &coarse, arr1(&[0.0, 3.0]).view())
        .unwrap();
    assert_eq!(fine.offsets, vec![0, 4, 4]);
    assert_eq!(fine.t.to_vec(), vec![1.125, 1.375, 1.625, 1.875]);
    assert_eq!(fine.delta.to_vec(), vec![0.25; 4]);
    assert_eq!(fine.positions.column(0).to_vec(), vec![1.125, 1.375, 1.625, 1.875]);
    assert_eq!(fine.ray, vec![0; 4]);
}

#[test]
fn bad_inputs_are_errors() {
    assert!(Importance::new(0, 0.0, Jitter::None).is_err());
    assert!(Importance::new(4, 1.5, Jitter::None).is_err());
    let rays = RayBatch::new(arr2(&[[0.0, 0.0, 0.0]]), arr2(&[[1.0, 0.0, 0.0]])).unwrap();
    let iv = crate::rays::RayIntervals::new(vec![0.0], vec![2.0]).unwrap();
    let coarse = Uniform::new(Spacing::Count(2)).unwrap().sample(&rays, &iv).unwrap();
    let imp = Importance::new(4, 0.01, Jitter::None).unwrap();
    let bad = |w: Array1<f64>| imp.sample(&rays, &coarse, w.view()).unwrap_err();
    assert!(matches!(
        bad(arr1(&[1.0])),
        OpsError::Shape {
            op: Op::Sample,
            what: "weights",
            ..
        }
    ));
    assert!(matches!(
        bad(arr1(&[1.0, -0.5])),
        OpsError::Domain {
            op: Op::Sample,
            at: At::Sample { ray: 0, sample: 1 },
            value: -0.5,
            ..
        }
    ));
    assert!(matches!(
        bad(arr1(&[f64::NAN, 1.0])),
        OpsError::Domain {
            op: Op::Sample,
            at: At::Sample { ray: 0, sample: 0 },
            ..
        }
    ));
    let two = RayBatch::concat(&[rays.clone(), rays.clone()]);
    assert!(matches!(
        imp.sample(&two, &coarse, arr1(&[1.0, 1.0]).view()),
        Err(OpsError::Shape {
            op: Op::Sample,
            what: "previous samples",
            ..
        })
    ));
    let mut broken = coarse.clone();
    broken.delta[1] = f64::INFINITY;
    assert!(imp.sample(&rays, &broken, arr1(&[1.0, 1.0]).view()).is_err());
    broken.offsets = fogray_tape::Offsets::new(&[0, 3]).unwrap();
    assert!(imp.sample(&rays, &broken, arr1(&[1.0, 1.0]).view()).is_err());
}
