//! The distortion loss: closed forms of one and two samples, the fused op against a direct
//! O(n^2) f64 reference written here, against its taped twin (values and gradients, f64 to
//! 1e-12, f32 to 1e-4 of the scale), central finite differences in f64, large depths in f32
//! where a prefix-sum form loses the answer, opaque and faint samples, empty rays, bitwise the
//! same results on other thread counts, and each error.

// Index loops mirror the formulas' subscripts in these tests.
#![allow(clippy::needless_range_loop)]

use fogray_ops::distortion::twin;
use fogray_ops::{At, DistortionLoss, Op, OpsError};
use fogray_tape::gradcheck::Domain;
use fogray_tape::{gradcheck, Float, GradcheckOptions, OffsetsError, Tape, TapeError, Var};
use ndarray::{arr1, Array1};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};

/// Packed rays in f64: densities, interval lengths and midpoints.
#[derive(Debug, Clone)]
struct Rays {
    offsets: Vec<usize>,
    sigma: Vec<f64>,
    delta: Vec<f64>,
    t: Vec<f64>,
}

impl Rays {
    fn op(&self) -> DistortionLoss {
        DistortionLoss::new(&self.offsets).unwrap()
    }

    fn rays(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The inputs as arrays of `F`.
    fn arrays<F: Float>(&self) -> [Array1<F>; 3] {
        let a = |v: &Vec<f64>| v.iter().map(|&x| F::lit(x)).collect();
        [a(&self.sigma), a(&self.delta), a(&self.t)]
    }

    /// The same rays rounded to f32 and back, so that both precisions see identical inputs
    /// (rounding is monotone: the midpoints still do not decrease).
    fn f32_representable(&self) -> Rays {
        let r = |v: &Vec<f64>| v.iter().map(|&x| f64::from(x as f32)).collect();
        Rays {
            offsets: self.offsets.clone(),
            sigma: r(&self.sigma),
            delta: r(&self.delta),
            t: r(&self.t),
        }
    }
}

/// Random rays: lengths in `0..max_len`, densities exactly 0 (one in five) or log-uniform in
/// [1e-2, 1e2], lengths log-uniform in [1e-3, 1e-1], consecutive intervals touching or with a
/// gap (one in four), the first starting in [2, 6]; f32-representable.
fn random_rays(seed: u64, rays: usize, max_len: usize) -> Rays {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let (mut offsets, mut sigma, mut delta, mut t) = (vec![0], Vec::new(), Vec::new(), Vec::new());
    for _ in 0..rays {
        let len = rng.gen_range(0..max_len);
        let mut end = rng.gen_range(2.0..6.0);
        for _ in 0..len {
            let d = 10f64.powf(rng.gen_range(-3.0..-1.0));
            if rng.gen_bool(0.25) {
                end += rng.gen_range(0.0..0.2);
            }
            t.push(end + d / 2.0);
            end += d;
            delta.push(d);
            sigma.push(if rng.gen_bool(0.2) {
                0.0
            } else {
                10f64.powf(rng.gen_range(-2.0..2.0))
            });
        }
        offsets.push(t.len());
    }
    Rays {
        offsets,
        sigma,
        delta,
        t,
    }
    .f32_representable()
}

/// The weights of one ray in f64, with the C library's `exp` and `expm1`.
fn weights(sigma: &[f64], delta: &[f64]) -> Vec<f64> {
    let mut depth = 0.0f64;
    sigma
        .iter()
        .zip(delta)
        .map(|(s, d)| {
            let w = (-depth).exp() * -(-s * d).exp_m1();
            depth += s * d;
            w
        })
        .collect()
}

/// `L_r` of every ray by the definition: every ordered pair, in f64.
fn direct_losses(r: &Rays) -> Vec<f64> {
    (0..r.rays())
        .map(|ray| {
            let s = r.offsets[ray]..r.offsets[ray + 1];
            let (t, d) = (&r.t[s.clone()], &r.delta[s.clone()]);
            let w = weights(&r.sigma[s.clone()], d);
            let mut pairs = 0.0;
            for i in 0..w.len() {
                for j in 0..w.len() {
                    pairs += w[i] * w[j] * (t[i] - t[j]).abs();
                }
            }
            pairs + w.iter().zip(d).map(|(w, d)| w * w * d).sum::<f64>() / 3.0
        })
        .collect()
}

fn direct_mean(r: &Rays) -> f64 {
    direct_losses(r).iter().sum::<f64>() / r.rays() as f64
}

/// The loss and `dL/dsigma` (times `upstream`) through a tape, fused or through the twin, as f64.
fn on_tape<F: Float>(r: &Rays, fused: bool, upstream: f64) -> (f64, Vec<f64>) {
    let op = r.op();
    let [s, d, t] = r.arrays::<F>();
    let mut tape = Tape::<F>::new();
    let sigma = tape.param(s);
    let delta = tape.constant(d);
    let t = tape.constant(t);
    let loss = if fused {
        op.apply(&mut tape, sigma, delta, t).unwrap()
    } else {
        twin::distortion_loss(&mut tape, &op, sigma, delta, t).unwrap()
    };
    let scaled = tape.mul_scalar(loss, F::lit(upstream)).unwrap();
    let grads = tape.backward(scaled).unwrap();
    let value = tape.value(loss).unwrap()[[]].as_f64();
    let g = grads.get(sigma).unwrap().iter().map(|v| v.as_f64()).collect();
    (value, g)
}

/// `|a_k - b_k| <= tol * (largest |b| of k's ray)` for every sample (the gradient is a
/// difference, "what it adds minus what it hides", so a sample's own scale can be far below
/// its terms').
fn assert_close_by_ray(what: &str, r: &Rays, a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len());
    for ray in 0..r.rays() {
        let s = r.offsets[ray]..r.offsets[ray + 1];
        let scale = b[s.clone()].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for k in s {
            assert!(
                (a[k] - b[k]).abs() <= tol * scale,
                "{what}: ray {ray}, sample {k}: {} against {} (scale {scale:e})",
                a[k],
                b[k]
            );
        }
    }
}

fn assert_rel(what: &str, got: f64, want: f64, tol: f64) {
    assert!(
        (got - want).abs() <= tol * want.abs(),
        "{what}: {got:e} against {want:e} (relative {:e})",
        (got - want).abs() / want.abs()
    );
}

#[test]
fn one_sample_is_w_squared_delta_over_three() {
    for (sigma, delta) in [(0.0, 0.5), (1e-3, 0.25), (0.7, 0.1), (3.0, 2.0), (50.0, 0.5)] {
        let r = Rays {
            offsets: vec![0, 1],
            sigma: vec![sigma],
            delta: vec![delta],
            t: vec![4.0],
        }
        .f32_representable();
        let (sigma, delta): (f64, f64) = (r.sigma[0], r.delta[0]);
        let w = -(-sigma * delta).exp_m1();
        let want = w * w * delta / 3.0;
        // dL/dsigma = (2/3) w delta dw/dsigma, dw/dsigma = delta exp(-sigma delta).
        let want_grad = 2.0 / 3.0 * w * delta * delta * (-sigma * delta).exp();
        let op = r.op();
        let got = op
            .evaluate(arr1(&[sigma]).view(), arr1(&[delta]).view(), arr1(&[4.0]).view())
            .unwrap();
        assert!(
            (got - want).abs() <= 2e-16 * want,
            "{sigma}, {delta}: {got} against {want}"
        );
        let (v, g) = on_tape::<f64>(&r, true, 1.0);
        assert_eq!(v, got);
        assert!(
            (g[0] - want_grad).abs() <= 2e-15 * want_grad,
            "{} against {want_grad}",
            g[0]
        );
        let (v32, g32) = on_tape::<f32>(&r, true, 1.0);
        assert!((v32 - want).abs() <= 1e-7 * want, "f32: {v32} against {want}");
        assert!(
            (g32[0] - want_grad).abs() <= 1e-7 * want_grad,
            "f32: {} against {want_grad}",
            g32[0]
        );
    }
}

#[test]
fn two_samples_are_the_hand_computed_value_and_gradient() {
    // tau = ln 2 for both: alpha = 1/2 and 1/2, weights 1/2 and 1/4, one apart.
    let ln2 = std::f64::consts::LN_2;
    let r = Rays {
        offsets: vec![0, 2],
        sigma: vec![2.0 * ln2, 4.0 * ln2],
        delta: vec![0.5, 0.25],
        t: vec![1.0, 2.0],
    };
    // L = 2 (1/2)(1/4) 1 + (1/3)((1/4) 0.5 + (1/16) 0.25) = 19/64.
    // With a = alpha_0, b = alpha_1: L = 2 a (1 - a) b + (1/3)(a^2 delta_0 + (1 - a)^2 b^2 delta_1),
    // dL/da = 2 b (1 - 2a) + (2/3)(a delta_0 - (1 - a) b^2 delta_1) = 7/48,
    // dL/db = 2 a (1 - a) + (2/3)(1 - a)^2 b delta_1 = 25/48, and
    // da/dsigma_0 = delta_0 (1 - a) = 1/4, db/dsigma_1 = delta_1 (1 - b) = 1/8.
    for fused in [true, false] {
        let (v, g) = on_tape::<f64>(&r, fused, 1.0);
        assert!((v - 19.0 / 64.0).abs() < 1e-15, "fused {fused}: {v}");
        assert!((g[0] - 7.0 / 192.0).abs() < 1e-15, "fused {fused}: {}", g[0]);
        assert!((g[1] - 25.0 / 384.0).abs() < 1e-15, "fused {fused}: {}", g[1]);
    }
    let (v, g) = on_tape::<f32>(&r, true, 1.0);
    assert!((v - 19.0 / 64.0).abs() < 1e-7 && (g[0] - 7.0 / 192.0).abs() < 1e-8 && (g[1] - 25.0 / 384.0).abs() < 1e-8);
}

#[test]
fn the_fused_op_is_the_direct_pairwise_sum() {
    for seed in 0..4 {
        let r = random_rays(seed, 600, 80);
        let want = direct_losses(&r);
        let op = r.op();
        let [s, d, t] = r.arrays::<f64>();
        let got = op.evaluate_rays(s.view(), d.view(), t.view()).unwrap();
        for (ray, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!((g - w).abs() <= 1e-13 * w, "ray {ray}: {g:e} against {w:e}");
        }
        assert_rel(
            "mean f64",
            op.evaluate(s.view(), d.view(), t.view()).unwrap(),
            direct_mean(&r),
            1e-13,
        );
        // f32 data, the same values: the f64 reference to the rounding of the result.
        let [s, d, t] = r.arrays::<f32>();
        let got = op.evaluate_rays(s.view(), d.view(), t.view()).unwrap();
        for (ray, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!((g.as_f64() - w).abs() <= 1e-7 * w, "f32 ray {ray}: {g:e} against {w:e}");
        }
        assert_rel(
            "mean f32",
            op.evaluate(s.view(), d.view(), t.view()).unwrap().as_f64(),
            direct_mean(&r),
            1e-7,
        );
    }
}

fn fused_matches_twin<F: Float>(seed: u64, rays: usize, max_len: usize, tol: f64) {
    let r = random_rays(seed, rays, max_len);
    let (v_fused, g_fused) = on_tape::<F>(&r, true, 1.7);
    let (v_twin, g_twin) = on_tape::<F>(&r, false, 1.7);
    assert_rel(&format!("{} value, seed {seed}", F::NAME), v_fused, v_twin, tol);
    assert_close_by_ray(
        &format!("{} dL/dsigma, seed {seed}", F::NAME),
        &r,
        &g_fused,
        &g_twin,
        tol,
    );
    // Something to agree on.
    assert!(v_fused > 0.0 && g_fused.iter().any(|&g| g.abs() > 1e-3 * v_fused));
    // The tape's backward is the stateless vjp, bit for bit, and evaluate is the forward.
    let op = r.op();
    let [s, d, t] = r.arrays::<F>();
    assert_eq!(op.evaluate(s.view(), d.view(), t.view()).unwrap().as_f64(), v_fused);
    let vjp = op.vjp(s.view(), d.view(), t.view(), F::lit(1.7)).unwrap();
    assert_eq!(vjp.iter().map(|v| v.as_f64()).collect::<Vec<_>>(), g_fused);
}

#[test]
fn the_fused_op_matches_its_taped_twin() {
    for seed in 0..3 {
        fused_matches_twin::<f64>(seed, 300, 64, 1e-12);
        fused_matches_twin::<f32>(seed, 300, 64, 1e-4);
    }
}

#[test]
fn delta_and_t_get_no_gradient_even_as_params() {
    let r = random_rays(7, 5, 10);
    let op = r.op();
    for fused in [true, false] {
        let [s, d, t] = r.arrays::<f64>();
        let mut tape = Tape::<f64>::new();
        let (sigma, delta, t) = (tape.param(s), tape.param(d), tape.param(t));
        let loss = if fused {
            op.apply(&mut tape, sigma, delta, t).unwrap()
        } else {
            twin::distortion_loss(&mut tape, &op, sigma, delta, t).unwrap()
        };
        let grads = tape.backward(loss).unwrap();
        assert!(grads.get(sigma).is_some(), "fused {fused}");
        assert!(grads.get(delta).is_none(), "fused {fused}");
        assert!(grads.get(t).is_none(), "fused {fused}");
    }
}

#[test]
fn the_fused_op_and_its_twin_pass_gradcheck_in_f64() {
    // Densities of order 1 over steps of 0.1 to 0.4 (weights that matter), two of them 0 (the
    // domain's end: one-sided differences), ties of t included, and an empty ray.
    let r = Rays {
        offsets: vec![0, 4, 4, 5, 9],
        sigma: vec![0.0, 1.3, 4.0, 0.6, 2.2, 0.9, 0.0, 7.5, 1.1],
        delta: vec![0.2, 0.1, 0.3, 0.4, 0.25, 0.1, 0.2, 0.15, 0.3],
        t: vec![1.0, 1.15, 1.35, 1.35, 2.0, 0.5, 0.65, 0.8, 1.3],
    };
    let op = r.op();
    let [s, d, t] = r.arrays::<f64>();
    for fused in [true, false] {
        let f = |tape: &mut Tape<f64>, v: &[Var]| -> Result<Var, TapeError> {
            let delta = tape.constant(d.clone());
            let t = tape.constant(t.clone());
            if fused {
                op.apply(tape, v[0], delta, t)
            } else {
                twin::distortion_loss(tape, &op, v[0], delta, t)
            }
        };
        let opts = GradcheckOptions {
            names: vec!["sigma".into()],
            domains: vec![Domain::at_least(0.0)],
            ..Default::default()
        };
        let report = gradcheck(f, &[s.clone().into_dyn()], &opts).unwrap();
        report
            .check(1e-8, 1e-6)
            .unwrap_or_else(|r| panic!("fused {fused}: {r}"));
    }
}

/// `rays` rays of 48 samples at t ~ 1e4, spaced by 2^-10 (f32's resolution there: every value
/// exact in f32), with densities that spread the weights over the ray.
fn far_ray(rays: usize) -> Rays {
    let (mut offsets, mut sigma, mut delta, mut t) = (vec![0], Vec::new(), Vec::new(), Vec::new());
    let step = 1.0 / 1024.0;
    for r in 0..rays {
        for k in 0..48 {
            t.push(10_000.0 + 16.0 * r as f64 + step * k as f64);
            delta.push(step);
            sigma.push(20.0 + (k % 7) as f64 * 5.0);
        }
        offsets.push(t.len());
    }
    Rays {
        offsets,
        sigma,
        delta,
        t,
    }
}

/// The loss by the prefix sums `2 sum_i w_i (t_i S_{<i} - U_{<i})` in f32, as a taped or
/// naive f32 implementation would compute it (weights from the f64 reference, rounded).
fn prefix_sums_in_f32(r: &Rays) -> f64 {
    let mut total = 0.0f32;
    for ray in 0..r.rays() {
        let s = r.offsets[ray]..r.offsets[ray + 1];
        let w: Vec<f32> = weights(&r.sigma[s.clone()], &r.delta[s.clone()])
            .iter()
            .map(|&w| w as f32)
            .collect();
        let (t, d) = (&r.t[s.clone()], &r.delta[s]);
        let (mut sum, mut moment, mut loss) = (0.0f32, 0.0f32, 0.0f32);
        for i in 0..w.len() {
            let (ti, di) = (t[i] as f32, d[i] as f32);
            loss += 2.0 * w[i] * (ti * sum - moment) + w[i] * w[i] * di / 3.0;
            sum += w[i];
            moment += w[i] * ti;
        }
        total += loss;
    }
    f64::from(total / r.rays() as f32)
}

#[test]
fn far_samples_in_f32_keep_the_answer_that_prefix_sums_lose() {
    let r = far_ray(8);
    let want = direct_mean(&r);
    let naive = prefix_sums_in_f32(&r);
    let naive_err = (naive - want).abs() / want;
    let op = r.op();
    let [s, d, t] = r.arrays::<f32>();
    let got = op.evaluate(s.view(), d.view(), t.view()).unwrap().as_f64();
    let err = (got - want).abs() / want;
    eprintln!("t ~ 1e4 in f32: prefix sums relative error {naive_err:.2e}, fused {err:.2e}");
    // The prefix sums are off by 3 % (their t_i S_{<i} is rounded to 1e-3 of a sum of
    // distances of that order); the op's recurrences keep f32's rounding.
    assert!(
        naive_err > 1e-2,
        "the f32 prefix sums were expected to fail: {naive_err:e}"
    );
    assert!(err <= 1e-6, "fused f32: {got} against {want} (relative {err:e})");
    // Its gradient is the f64 op's on the same values to f32's rounding.
    let g32 = op.vjp(s.view(), d.view(), t.view(), 1.0).unwrap();
    let [s, d, t] = r.arrays::<f64>();
    let g64 = op.vjp(s.view(), d.view(), t.view(), 1.0).unwrap();
    let g32: Vec<f64> = g32.iter().map(|&v| v.as_f64()).collect();
    assert_close_by_ray("dL/dsigma f32 against f64", &r, &g32, g64.as_slice().unwrap(), 1e-6);
}

#[test]
fn opaque_and_faint_samples_are_finite_and_correct() {
    // Opaque: sigma delta = 1e29, the first sample takes all the weight; faint: sigma delta =
    // 1e-12 everywhere, weights of 1e-12 whose digits 1 - exp would lose; a mix.
    let opaque = Rays {
        offsets: vec![0, 3],
        sigma: vec![1e30, 2.0, 3.0],
        delta: vec![0.1, 0.1, 0.1],
        t: vec![1.0, 1.1, 1.2],
    };
    let faint = Rays {
        offsets: vec![0, 4],
        sigma: vec![1e-11; 4],
        delta: vec![0.1; 4],
        t: vec![1.0, 1.1, 1.2, 1.3],
    };
    let mix = Rays {
        offsets: vec![0, 4],
        sigma: vec![1e-11, 1.0, 1e30, 1e-11],
        delta: vec![0.1; 4],
        t: vec![1.0, 1.1, 1.2, 1.3],
    };
    for r in [opaque, faint, mix] {
        let r = r.f32_representable();
        let want = direct_mean(&r);
        for precision in ["f64", "f32"] {
            let (tol, (v, g)) = match precision {
                "f64" => (1e-13, on_tape::<f64>(&r, true, 1.0)),
                _ => (1e-6, on_tape::<f32>(&r, true, 1.0)),
            };
            assert!(
                v.is_finite() && g.iter().all(|g| g.is_finite()),
                "{precision} {r:?}: {v}, {g:?}"
            );
            assert_rel(&format!("{precision} {:?}", r.sigma), v, want, tol);
            let (_, g_twin) = on_tape::<f64>(&r, false, 1.0);
            for (k, (a, b)) in g.iter().zip(&g_twin).enumerate() {
                assert!(
                    (a - b).abs() <= tol * b.abs() + 1e-300,
                    "{precision} {:?} sample {k}: {a:e} against {b:e}",
                    r.sigma
                );
            }
        }
    }
    // The opaque ray is the one-sample closed form of its first sample; nothing behind it or
    // in it can change the loss.
    let r = Rays {
        offsets: vec![0, 3],
        sigma: vec![1e30, 2.0, 3.0],
        delta: vec![0.1, 0.1, 0.1],
        t: vec![1.0, 1.1, 1.2],
    };
    let (v, g) = on_tape::<f64>(&r, true, 1.0);
    assert_rel("opaque", v, 0.1 / 3.0, 1e-15);
    assert_eq!(g, vec![0.0; 3]);
    // The faint ray: L ~ 1e-24, to full relative precision (checked above), not 0.
    let (v, _) = on_tape::<f32>(
        &Rays {
            offsets: vec![0, 2],
            sigma: vec![1e-11; 2],
            delta: vec![0.1; 2],
            t: vec![1.0, 1.1],
        },
        true,
        1.0,
    );
    assert!(v > 1e-25 && v < 1e-23, "{v:e}");
}

#[test]
fn empty_rays_count_in_the_mean() {
    let r = Rays {
        offsets: vec![0, 0, 3, 3, 3, 5],
        sigma: vec![1.0, 2.0, 0.5, 3.0, 0.2],
        delta: vec![0.1, 0.2, 0.1, 0.3, 0.1],
        t: vec![1.0, 1.2, 1.4, 2.0, 2.3],
    };
    let op = r.op();
    let [s, d, t] = r.arrays::<f64>();
    let per_ray = op.evaluate_rays(s.view(), d.view(), t.view()).unwrap();
    let want = direct_losses(&r);
    assert_eq!(per_ray[0], 0.0);
    assert_eq!(per_ray[2], 0.0);
    assert_eq!(per_ray[3], 0.0);
    assert_rel("ray 1", per_ray[1], want[1], 1e-14);
    assert_rel("ray 4", per_ray[4], want[4], 1e-14);
    let mean = op.evaluate(s.view(), d.view(), t.view()).unwrap();
    assert_rel("mean over 5 rays", mean, (want[1] + want[4]) / 5.0, 1e-14);
    // The gradient is divided by the 5 rays too: the same rays without the empty ones, read
    // by an op over 2 rays, give 5/2 times the gradient.
    let g5 = op.vjp(s.view(), d.view(), t.view(), 1.0).unwrap();
    let g2 = DistortionLoss::new(&[0, 3, 5])
        .unwrap()
        .vjp(s.view(), d.view(), t.view(), 1.0)
        .unwrap();
    for k in 0..5 {
        assert!(
            (g2[k] - 2.5 * g5[k]).abs() <= 1e-15 * g2[k].abs(),
            "{k}: {} {}",
            g2[k],
            g5[k]
        );
    }
    // Only empty rays, and no ray at all: 0, with an empty gradient; the twin agrees.
    let empty = Array1::<f64>::zeros(0);
    for offsets in [vec![0, 0, 0], vec![0]] {
        let op = DistortionLoss::new(&offsets).unwrap();
        assert_eq!(op.evaluate(empty.view(), empty.view(), empty.view()).unwrap(), 0.0);
        assert_eq!(op.vjp(empty.view(), empty.view(), empty.view(), 1.0).unwrap().len(), 0);
        for fused in [true, false] {
            let mut tape = Tape::<f64>::new();
            let sigma = tape.param(empty.clone());
            let (delta, t) = (tape.constant(empty.clone()), tape.constant(empty.clone()));
            let loss = if fused {
                op.apply(&mut tape, sigma, delta, t).unwrap()
            } else {
                twin::distortion_loss(&mut tape, &op, sigma, delta, t).unwrap()
            };
            assert_eq!(tape.value(loss).unwrap()[[]], 0.0, "{offsets:?}, fused {fused}");
            assert_eq!(tape.shape(loss).unwrap(), &[] as &[usize]);
        }
    }
}

fn bitwise_on_thread_counts<F: Float>() {
    // More rays than three chunks hold, of uneven lengths.
    let r = random_rays(11, 1000, 40);
    let op = r.op();
    let [s, d, t] = r.arrays::<F>();
    let at = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let loss = op.evaluate(s.view(), d.view(), t.view()).unwrap();
            let g = op.vjp(s.view(), d.view(), t.view(), F::lit(0.3)).unwrap();
            (
                loss.as_f64().to_bits(),
                g.iter().map(|v| v.as_f64().to_bits()).collect::<Vec<u64>>(),
            )
        })
    };
    let one = at(1);
    assert_eq!(at(2), one, "{}", F::NAME);
    assert_eq!(at(3), one, "{}", F::NAME);
    assert!(one.1.iter().any(|&b| b != 0));
}

#[test]
fn results_are_bitwise_the_same_on_1_2_and_3_threads() {
    bitwise_on_thread_counts::<f32>();
    bitwise_on_thread_counts::<f64>();
}

#[test]
fn bad_input_is_a_composite_error_naming_the_ray_and_sample() {
    assert_eq!(
        DistortionLoss::new(&[0, 3, 2]).unwrap_err(),
        OpsError::Offsets {
            op: Op::DistortionLoss,
            source: OffsetsError::Decreasing {
                segment: 1,
                start: 3,
                end: 2
            }
        }
    );
    assert_eq!(
        DistortionLoss::new(&[1, 3]).unwrap_err(),
        OpsError::Offsets {
            op: Op::DistortionLoss,
            source: OffsetsError::Start(1)
        }
    );
    let r = random_rays(20, 700, 12);
    let op = r.op();
    let n = r.sigma.len();
    let [s, d, t] = r.arrays::<f64>();
    assert!(op.evaluate(s.view(), d.view(), t.view()).is_ok());

    // Shapes: each input against the packing.
    let short = Array1::<f64>::zeros(n - 1);
    let shape_of = |e: OpsError| match e {
        OpsError::Shape {
            op: Op::DistortionLoss,
            what,
            ..
        } => what,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        shape_of(op.evaluate(short.view(), d.view(), t.view()).unwrap_err()),
        "sigma"
    );
    assert_eq!(
        shape_of(op.evaluate(s.view(), short.view(), t.view()).unwrap_err()),
        "delta"
    );
    assert_eq!(
        shape_of(op.vjp(s.view(), d.view(), short.view(), 1.0).unwrap_err()),
        "t"
    );
    assert_eq!(
        op.evaluate(short.view(), d.view(), t.view()).unwrap_err().to_string(),
        format!(
            "distortion_loss: sigma: expected [{n}] (the offsets end at {n}), got [{}]",
            n - 1
        )
    );

    // Values: the sample within its ray, the first fault in sample order.
    let ray = 400;
    let (start, len) = (r.offsets[ray], r.offsets[ray + 1] - r.offsets[ray]);
    assert!(len >= 3, "ray {ray} has {len} samples");
    let at = |what: &str, k: usize, value: f64| -> OpsError {
        let (mut s, mut d, mut t) = (s.clone(), d.clone(), t.clone());
        match what {
            "sigma" => s[start + k] = value,
            "delta" => d[start + k] = value,
            _ => t[start + k] = value,
        }
        op.evaluate(s.view(), d.view(), t.view()).unwrap_err()
    };
    let named = |e: &OpsError| match e {
        OpsError::Domain {
            op: Op::DistortionLoss,
            at: At::Sample { ray, sample },
            what,
            ..
        } => (*ray, *sample, what.clone()),
        other => panic!("{other:?}"),
    };
    for value in [-1e-30, f64::NAN, f64::INFINITY] {
        assert_eq!(named(&at("sigma", 1, value)), (ray, 1, "sigma".into()), "sigma {value}");
    }
    for value in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        assert_eq!(named(&at("delta", 2, value)), (ray, 2, "delta".into()), "delta {value}");
    }
    for value in [f64::NAN, f64::NEG_INFINITY] {
        assert_eq!(named(&at("t", 0, value)), (ray, 0, "t".into()), "t {value}");
    }
    // A midpoint below its predecessor; a tie is fine; a ray may start below the last one's end.
    let below = t[start + 1] - 1e-3;
    let e = at("t", 2, below);
    assert_eq!(named(&e), (ray, 2, "t".into()));
    assert_eq!(
        e.to_string(),
        format!(
            "distortion_loss: ray {ray}, sample 2: t is {below} (midpoints must not decrease along a ray (below the previous sample's))"
        )
    );
    let mut tied = t.clone();
    tied[start + 2] = tied[start + 1];
    assert!(op.evaluate(s.view(), d.view(), tied.view()).is_ok());
    let mut restart = t.clone();
    restart[start] = -5.0;
    assert!(op.evaluate(s.view(), d.view(), restart.view()).is_ok());
    // Two faults: the earlier sample is named, whichever thread finds which.
    let (mut s2, mut d2) = (s.clone(), d.clone());
    s2[start + 2] = -1.0;
    d2[start + 1] = 0.0;
    s2[n - 1] = f64::NAN;
    assert_eq!(
        named(&op.evaluate(s2.view(), d2.view(), t.view()).unwrap_err()),
        (ray, 1, "delta".into())
    );

    // Through a tape, fused or twin: the error arrives whole and nothing is recorded.
    let mut tape = Tape::<f64>::new();
    let good_s = tape.param(s.clone());
    let bad_s = tape.param(s2);
    let good_d = tape.constant(d.clone());
    let good_t = tape.constant(t.clone());
    let mut t_down = t.clone();
    t_down[start + 2] = below;
    let bad_t = tape.constant(t_down);
    let two_d = tape.param(ndarray::Array2::<f64>::zeros((n, 1)));
    let before = tape.len();
    for fused in [true, false] {
        let mut apply = |s, d, t| {
            if fused {
                op.apply(&mut tape, s, d, t)
            } else {
                twin::distortion_loss(&mut tape, &op, s, d, t)
            }
        };
        let e = apply(bad_s, good_d, good_t).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::Domain {
                    op: Op::DistortionLoss,
                    at: At::Sample { ray: 400, sample: 2 },
                    ..
                })
            ),
            "fused {fused}: {e}"
        );
        assert!(
            e.to_string()
                .starts_with("distortion_loss: ray 400, sample 2: sigma is -1"),
            "{e}"
        );
        let e = apply(good_s, good_d, bad_t).unwrap_err();
        assert!(
            matches!(e.downcast_ref::<OpsError>(), Some(OpsError::Domain { op: Op::DistortionLoss, at: At::Sample { ray: 400, sample: 2 }, what, .. }) if what == "t"),
            "fused {fused}: {e}"
        );
        let e = apply(two_d, good_d, good_t).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<OpsError>(),
                Some(OpsError::Shape {
                    op: Op::DistortionLoss,
                    what: "sigma",
                    ..
                })
            ),
            "fused {fused}: {e}"
        );
    }
    assert_eq!(tape.len(), before);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, .. ProptestConfig::default() })]

    #[test]
    fn fused_matches_twin_and_the_direct_sum_on_random_rays(seed in any::<u64>(), rays in 1usize..8, max_len in 1usize..40) {
        let r = random_rays(seed, rays, max_len);
        let (v_fused, g_fused) = on_tape::<f64>(&r, true, 1.0);
        let (v_twin, g_twin) = on_tape::<f64>(&r, false, 1.0);
        let want = direct_mean(&r);
        prop_assert!((v_fused - want).abs() <= 1e-13 * want, "{} against {}", v_fused, want);
        prop_assert!((v_fused - v_twin).abs() <= 1e-12 * want, "{} against twin {}", v_fused, v_twin);
        assert_close_by_ray("dL/dsigma f64", &r, &g_fused, &g_twin, 1e-12);
        let (v32, g32) = on_tape::<f32>(&r, true, 1.0);
        prop_assert!((v32 - want).abs() <= 1e-6 * want, "f32 {} against {}", v32, want);
        assert_close_by_ray("dL/dsigma f32", &r, &g32, &g_fused, 1e-5);
    }
}
