//! Hard numerical cases: every one must give finite, accurate outputs and gradients. Where a
//! numerics choice is tested, the naive form is shown failing on the same case.

use crate::composite_common;

use composite_common::{all_finite, assert_close_scaled, grad_scale, run, run_with, worst_scaled, Method, Rays};
use fogray_ops::{At, Background, Composite, CompositeInputs, Op, OpsError};
use fogray_tape::{gradcheck, GradcheckOptions, Tape, TapeError};
use ndarray::{arr1, arr2, Array1, Array2, ArrayD};
use rand::{Rng, SeedableRng};

fn rel(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x.abs()).collect()
}

#[test]
fn zero_density_everywhere_is_exactly_the_background() {
    let rays = Rays::one(
        &[0.0; 4],
        &[0.5, 0.25, 0.0, 1.0],
        &[0.9, 0.1, 0.2, 0.8, 0.3, 0.3, 0.7, 0.6],
        2,
        &[0.25, 0.75],
    );
    for (r, eps) in [
        (run::<f64>(&rays, Method::Fused), 1e-15),
        (run::<f32>(&rays, Method::Fused), 1e-7),
    ] {
        assert_eq!(r.color, vec![0.25, 0.75]);
        assert_eq!(r.opacity, vec![0.0]);
        assert!(r.weights.iter().all(|&w| w == 0.0));
        assert_eq!(r.d_background, vec![1.0, 1.0]);
        // dC/dsigma_k = delta_k (c_k - c_bg), summed over the two channels (upstream ones).
        for k in 0..4 {
            let want = rays.delta[k] * ((rays.color[2 * k] - 0.25) + (rays.color[2 * k + 1] - 0.75));
            // Judged against the size of the terms: delta_k (|c_k| + |c_bg|), summed over channels.
            let scale = rays.delta[k] * (rays.color[2 * k] + rays.color[2 * k + 1] + 1.0);
            assert!(
                (r.d_sigma[k] - want).abs() <= eps * scale,
                "k={k}: {} vs {want}",
                r.d_sigma[k]
            );
        }
    }
}

#[test]
fn huge_optical_depths_give_alpha_one_and_finite_gradients() {
    // sigma * delta of 1e3, 1e6, 1e30, and an f32 product that overflows (1e30 * 1e10 = 1e40).
    for (sigma, delta) in [(2e3, 0.5), (2e6, 0.5), (2e30, 0.5), (1e30, 1e10)] {
        let rays = Rays::one(&[sigma], &[delta], &[0.3, 0.6, 0.9], 3, &[1.0, 1.0, 1.0]);
        for (how, r) in [
            ("f64", run::<f64>(&rays, Method::Fused)),
            ("f32", run::<f32>(&rays, Method::Fused)),
        ] {
            assert!(all_finite(&r), "{how} tau={}: {r:?}", sigma * delta);
            let c32: Vec<f64> = [0.3f32, 0.6, 0.9].iter().map(|&c| f64::from(c)).collect();
            let want: &[f64] = if how == "f32" { &c32 } else { &[0.3, 0.6, 0.9] };
            assert_eq!(r.color, want, "{how}");
            assert_eq!((r.opacity[0], r.weights[0]), (1.0, 1.0));
            assert_eq!(r.d_sigma, vec![0.0]);
            assert_eq!(r.d_delta, vec![0.0]);
            assert_eq!(r.d_color, vec![1.0, 1.0, 1.0]);
            assert_eq!(r.d_background, vec![0.0, 0.0, 0.0]);
        }
    }
}

#[test]
fn an_opaque_first_sample_hides_everything_behind_it() {
    let rays = Rays::one(&[1e4, 1.0, 2.0, 3.0], &[0.1; 4], &[0.2, 0.9, 0.9, 0.9], 1, &[1.0]);
    for (r, c0) in [
        (run::<f64>(&rays, Method::Fused), 0.2),
        (run::<f32>(&rays, Method::Fused), f64::from(0.2f32)),
    ] {
        assert!(all_finite(&r));
        assert_eq!(r.color, vec![c0], "the pixel is the wall's colour");
        assert_eq!(&r.d_sigma[1..], &[0.0, 0.0, 0.0]);
        assert_eq!(&r.weights[1..], &[0.0, 0.0, 0.0]);
        assert_eq!(
            r.d_sigma[0], 0.0,
            "T after the wall is exactly 0: thickening it changes nothing"
        );
    }
}

#[test]
fn zero_steps_contribute_nothing_and_have_a_step_gradient() {
    let sigma = [1.5, 2.0, 0.7, 3.0];
    let delta = [0.2, 0.0, 0.3, 0.0];
    let color = [0.1, 0.8, 0.4, 0.6];
    let rays = Rays::one(&sigma, &delta, &color, 1, &[0.5]);
    let r = run::<f64>(&rays, Method::Fused);
    assert_eq!((r.weights[1], r.weights[3]), (0.0, 0.0));
    assert_eq!((r.d_sigma[1], r.d_sigma[3]), (0.0, 0.0));
    // dC/ddelta_k = sigma_k dC/dtau_k, nonzero: check against a one-sided difference (a
    // central one would need a negative step, which the op rejects).
    let h = 1e-7;
    for k in [1, 3] {
        let mut moved = rays.clone();
        moved.delta[k] = h;
        let fd = (run::<f64>(&moved, Method::Fused).color[0] - r.color[0]) / h;
        assert!(r.d_delta[k] != 0.0);
        assert!(
            (r.d_delta[k] - fd).abs() <= 1e-5 * fd.abs(),
            "k={k}: {} vs {fd}",
            r.d_delta[k]
        );
    }
}

#[test]
fn empty_rays_show_the_background_and_pass_its_gradient() {
    let mut tape = Tape::<f64>::new();
    let sigma = tape.param(arr1(&[1.0, 2.0]));
    let delta = tape.constant(arr1(&[0.5, 0.5]));
    let color = tape.param(arr2(&[[0.2, 0.4], [0.6, 0.8]]));
    let bg = tape.param(arr2(&[[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]]));
    let t = tape.param(arr1(&[1.0, 2.0]));
    let op = Composite::new(&[0, 0, 2, 2])
        .unwrap()
        .background(Background::PerRay)
        .with_depth();
    let out = op
        .apply(
            &mut tape,
            &CompositeInputs {
                sigma,
                delta,
                color,
                background: Some(bg),
                t: Some(t),
            },
        )
        .unwrap();
    let c = tape.value(out.color).unwrap().to_owned();
    assert_eq!(
        c.index_axis(ndarray::Axis(0), 0).iter().copied().collect::<Vec<f64>>(),
        vec![0.1, 0.2]
    );
    assert_eq!(
        c.index_axis(ndarray::Axis(0), 2).iter().copied().collect::<Vec<f64>>(),
        vec![0.5, 0.6]
    );
    assert_eq!(tape.value(out.opacity).unwrap()[[0]], 0.0);
    assert_eq!(
        tape.value(out.depth.unwrap()).unwrap()[[0]],
        0.0,
        "an empty ray's depth is 0 (documented)"
    );
    let total = tape.sum(out.color).unwrap();
    let g = tape.backward(total).unwrap();
    let gbg = g.get(bg).unwrap();
    assert_eq!(
        gbg.index_axis(ndarray::Axis(0), 0)
            .iter()
            .copied()
            .collect::<Vec<f64>>(),
        vec![1.0, 1.0]
    );
    assert_eq!(
        gbg.index_axis(ndarray::Axis(0), 2)
            .iter()
            .copied()
            .collect::<Vec<f64>>(),
        vec![1.0, 1.0]
    );
    // dC/dbg = T_end = e^-(0.5 + 1) for the middle ray.
    assert!((gbg[[1, 0]] - (-1.5f64).exp()).abs() < 1e-16);
    // A batch of nothing but empty rays, and no samples at all.
    let mut t2 = Tape::<f32>::new();
    let s = t2.param(Array1::<f32>::zeros(0));
    let d = t2.constant(Array1::<f32>::zeros(0));
    let col = t2.param(Array2::<f32>::zeros((0, 3)));
    let b = t2.param(arr1(&[0.5f32, 0.5, 0.5]));
    let out = Composite::new(&[0, 0, 0])
        .unwrap()
        .apply(
            &mut t2,
            &CompositeInputs {
                sigma: s,
                delta: d,
                color: col,
                background: Some(b),
                t: None,
            },
        )
        .unwrap();
    assert_eq!(t2.value(out.color).unwrap().shape(), &[2, 3]);
    let total = t2.sum(out.color).unwrap();
    assert_eq!(
        t2.backward(total)
            .unwrap()
            .get(b)
            .unwrap()
            .iter()
            .copied()
            .collect::<Vec<f32>>(),
        vec![2.0, 2.0, 2.0]
    );
}

/// A long ray in f32: the fused op within 1e-5 element-wise of the f64 reference; the taped
/// twins' f32 errors on the same ray are printed (and the stable twin's f32 running sums,
/// which this design avoids, are shown to lose far more).
fn long_ray(sigma: Vec<f64>) -> (f64, f64, f64) {
    let n = sigma.len();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let rays = Rays {
        delta: vec![1e-2; n],
        color: (0..n).map(|_| rng.gen_range(0.0..1.0)).collect(),
        sigma,
        ch: 1,
        offsets: vec![0, n],
        background: vec![0.5],
    }
    .f32_representable();
    let reference = run::<f64>(&rays, Method::Fused);
    let fused = run::<f32>(&rays, Method::Fused);
    let scale = grad_scale(&rays);
    assert_close_scaled(
        "long ray C",
        &fused.color,
        &reference.color,
        &rel(&reference.color),
        1e-30,
        1e-5,
    );
    assert_close_scaled(
        "long ray dC/dsigma",
        &fused.d_sigma,
        &reference.d_sigma,
        &scale,
        1e-30,
        1e-5,
    );
    assert_close_scaled(
        "long ray w",
        &fused.weights,
        &reference.weights,
        &rel(&reference.weights),
        1e-30,
        1e-5,
    );
    let fused_err = worst_scaled(&fused.d_sigma, &reference.d_sigma, &scale, 1e-30).0;
    let stable = run::<f32>(&rays, Method::Stable);
    let naive = run::<f32>(&rays, Method::Naive);
    let stable_err = worst_scaled(&stable.d_sigma, &reference.d_sigma, &scale, 1e-30).0;
    let naive_err = worst_scaled(&naive.d_sigma, &reference.d_sigma, &scale, 1e-30).0;
    eprintln!("1e5-sample f32 ray: worst scaled dC/dsigma error fused {fused_err:.2e}, stable taped {stable_err:.2e}, naive taped {naive_err:.2e}");
    (fused_err, stable_err, naive_err)
}

#[test]
fn long_f32_rays_random_density() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    let (fused, stable, _) = long_ray((0..100_000).map(|_| rng.gen_range(0.0..2e-3)).collect());
    assert!(stable > 10.0 * fused, "f32 running sums must be visibly worse here");
}

#[test]
fn long_f32_rays_constant_density_rounds_coherently() {
    let (fused, _, naive) = long_ray(vec![1e-3; 100_000]);
    assert!(naive > 10.0 * fused, "the naive form must be visibly worse here");
}

#[test]
fn f32_transmittance_that_underflows_stays_finite_and_accurate() {
    // 4096 samples, total optical depth 200: T falls below f32's smallest subnormal (1.4e-45)
    // around depth 103, while f64 still represents it.
    let n = 4096;
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let rays = Rays {
        sigma: vec![200.0 / (n as f64 * 0.01); n],
        delta: vec![0.01; n],
        color: (0..n).map(|_| rng.gen_range(0.0..1.0)).collect(),
        ch: 1,
        offsets: vec![0, n],
        background: vec![1.0],
    }
    .f32_representable();
    let reference = run::<f64>(&rays, Method::Fused);
    let r = run::<f32>(&rays, Method::Fused);
    assert!(all_finite(&r));
    assert!(r.transmittance[n - 1] == 0.0 && reference.transmittance[n - 1] > 0.0);
    assert_close_scaled(
        "dC/dsigma",
        &r.d_sigma,
        &reference.d_sigma,
        &grad_scale(&rays),
        1e-30,
        1e-5,
    );
    assert_close_scaled("C", &r.color, &reference.color, &rel(&reference.color), 1e-30, 1e-5);
}

#[test]
fn tiny_optical_depths_keep_every_digit_where_one_minus_exp_loses_them() {
    // alpha = -expm1(-tau) = tau - tau^2/2 + ...; 1 - exp(-tau) is 0 at tau = 1e-17 in f64.
    for tau in [1e-17, 1e-12, 1e-8, 1e-5] {
        let rays = Rays::one(&[tau], &[1.0], &[0.5], 1, &[0.0]);
        // The series to four terms: exact in f64 for tau <= 1e-5.
        let series = |x: f64| x - x * x / 2.0 + x * x * x / 6.0 - x.powi(4) / 24.0;
        let exact = series(tau);
        let fused = run::<f64>(&rays, Method::Fused);
        assert!((fused.weights[0] - exact).abs() <= 1e-15 * exact, "f64 tau={tau}");
        let fused32 = run::<f32>(&rays.f32_representable(), Method::Fused);
        let exact32 = series(f64::from(tau as f32));
        assert!((fused32.weights[0] - exact32).abs() <= 1e-7 * exact32, "f32 tau={tau}");
        let naive = run::<f64>(&rays, Method::Naive);
        if tau <= 1e-12 {
            let naive_err = (naive.weights[0] - exact).abs() / exact;
            assert!(
                naive_err > 1e-5,
                "1 - exp(-tau) must visibly fail at tau = {tau}: {naive_err}"
            );
        }
    }
}

#[test]
fn faint_ray_opacity_is_not_one_minus_transmittance() {
    // Total optical depth 1e-10 in f32: 1 - T_end rounds to 0; -expm1 keeps the digits.
    let rays = Rays::one(&[1e-10], &[1.0], &[0.5], 1, &[0.0]).f32_representable();
    let r = run::<f32>(&rays, Method::Fused);
    let tau = f64::from(1e-10f32);
    let exact = -(-tau).exp_m1();
    assert!((r.opacity[0] - exact).abs() <= 1e-7 * exact);
    let t_end_f32 = (-(1e-10f32)).exp();
    assert_eq!(1.0 - t_end_f32, 0.0, "the naive form loses it all in f32");
}

#[test]
fn suffix_sum_stays_accurate_where_c_minus_prefix_cancels() {
    // f32, 4096 samples, total optical depth 50: the tail behind the opaque part.
    let n = 4096;
    let mut rng = rand::rngs::StdRng::seed_from_u64(2);
    let rays = Rays {
        sigma: (0..n)
            .map(|_| rng.gen_range(0.0..2.0 * 50.0 / (n as f64 * 0.01)))
            .collect(),
        delta: vec![0.01; n],
        color: (0..n).map(|_| rng.gen_range(0.0..1.0)).collect(),
        ch: 1,
        offsets: vec![0, n],
        background: vec![1.0],
    }
    .f32_representable();
    let reference = run::<f64>(&rays, Method::Fused);
    let fused = run::<f32>(&rays, Method::Fused);
    let scale = grad_scale(&rays);
    let fused_err = worst_scaled(&fused.d_sigma, &reference.d_sigma, &scale, 1e-30).0;
    assert!(fused_err <= 1e-5, "{fused_err}");
    // The C - prefix form in f32, written here: S_k = C - sum_{i<=k} w_i c_i.
    let (w, c) = (&fused.weights, &rays.color);
    let mut prefix = 0.0f32;
    let total_c = fused.color[0] as f32;
    let c_minus_prefix: Vec<f64> = (0..n)
        .map(|k| {
            prefix += w[k] as f32 * c[k] as f32;
            let t_next = if k + 1 < n {
                fused.transmittance[k + 1] as f32
            } else {
                1.0 - fused.opacity[0] as f32
            };
            f64::from(0.01f32 * (t_next * c[k] as f32 - (total_c - prefix)))
        })
        .collect();
    let naive_err = worst_scaled(&c_minus_prefix, &reference.d_sigma, &scale, 1e-30).0;
    eprintln!(
        "depth 50, f32: worst scaled dC/dsigma error: suffix recurrence {fused_err:.2e}, C - prefix {naive_err:.2e}"
    );
    assert!(naive_err > 1.0, "C - prefix must be far off here: {naive_err}");
}

#[test]
fn invariants_on_random_rays() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(4);
    for _ in 0..50 {
        let n = rng.gen_range(1..200);
        let rays = Rays {
            sigma: (0..n).map(|_| 10f64.powf(rng.gen_range(-3.0..3.0))).collect(),
            delta: (0..n).map(|_| rng.gen_range(0.0..0.1)).collect(),
            color: (0..n).map(|_| rng.gen_range(0.0..1.0)).collect(),
            ch: 1,
            offsets: vec![0, n],
            background: vec![rng.gen_range(0.0..1.0)],
        };
        let r = run::<f64>(&rays, Method::Fused);
        assert!((0.0..=1.0).contains(&r.opacity[0]));
        let sum_w: f64 = r.weights.iter().sum();
        assert!(sum_w <= 1.0 + 1e-14 && (sum_w - r.opacity[0]).abs() < 1e-13);
        let lo = rays
            .color
            .iter()
            .chain(&rays.background)
            .fold(f64::INFINITY, |m, &x| m.min(x));
        let hi = rays.color.iter().chain(&rays.background).fold(0.0f64, |m, &x| m.max(x));
        assert!(r.color[0] >= lo - 1e-14 && r.color[0] <= hi + 1e-14);
    }
    // 1000 empty samples then an opaque one: the weight is exactly 1 (an eps-biased cumprod
    // gives 1.0001192).
    let mut sigma = vec![0.0; 1000];
    sigma.push(1e6);
    let rays = Rays::one(&sigma, &vec![0.01; 1001], &vec![0.5; 1001], 1, &[0.0]);
    for r in [run::<f32>(&rays, Method::Fused), run::<f64>(&rays, Method::Fused)] {
        assert_eq!(r.weights[1000], 1.0);
    }
}

#[test]
fn background_variants_agree() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(6);
    let n = 10;
    let sigma: Vec<f64> = (0..n).map(|_| rng.gen_range(0.0..3.0)).collect();
    let color: Vec<f64> = (0..n * 2).map(|_| rng.gen_range(0.0..1.0)).collect();
    let run_bg = |mode: Background, bg: Option<ArrayD<f64>>| {
        let mut t = Tape::<f64>::new();
        let s = t.param(Array1::from(sigma.clone()));
        let d = t.constant(Array1::from(vec![0.1; n]));
        let c = t.param(Array2::from_shape_vec((n, 2), color.clone()).unwrap());
        let b = bg.map(|b| t.param(b));
        let out = Composite::new(&[0, 4, 10])
            .unwrap()
            .background(mode)
            .apply(
                &mut t,
                &CompositeInputs {
                    sigma: s,
                    delta: d,
                    color: c,
                    background: b,
                    t: None,
                },
            )
            .unwrap();
        let total = t.sum(out.color).unwrap();
        let g = t.backward(total).unwrap();
        (
            t.value(out.color).unwrap().to_owned(),
            g.get(s).unwrap().to_owned(),
            b.map(|b| g.get(b).unwrap().to_owned()),
            t.value(out.opacity).unwrap().to_owned(),
        )
    };
    let (c_none, ds_none, _, opacity) = run_bg(Background::None, None);
    let (c_zero, ds_zero, _, _) = run_bg(Background::Shared, Some(arr1(&[0.0, 0.0]).into_dyn()));
    assert_eq!(c_none, c_zero, "no background equals a black one");
    assert_eq!(ds_none, ds_zero);
    let per_ray = arr2(&[[0.2, 0.4], [0.6, 0.8]]).into_dyn();
    let (c_per, _, g_per, _) = run_bg(Background::PerRay, Some(per_ray));
    let g_per = g_per.unwrap();
    for r in 0..2 {
        let t_end = 1.0 - opacity[[r]];
        for ch in 0..2 {
            assert!((g_per[[r, ch]] - t_end).abs() < 1e-15, "dC/dbg = T_end");
            // The unblended colour plus T_end times the background is the blended colour.
            let bg = [[0.2, 0.4], [0.6, 0.8]][r][ch];
            assert!((c_none[[r, ch]] + t_end * bg - c_per[[r, ch]]).abs() < 1e-15);
        }
    }
}

#[test]
fn depth_is_finite_when_nothing_stops_the_ray() {
    for sigma in [0.0, 1e-30] {
        let mut t = Tape::<f64>::new();
        let s = t.param(arr1(&[sigma, sigma]));
        let d = t.constant(arr1(&[0.5, 0.5]));
        let c = t.constant(arr2(&[[1.0], [1.0]]));
        let depth_at = t.param(arr1(&[1.0, 2.0]));
        let out = Composite::new(&[0, 2])
            .unwrap()
            .background(Background::None)
            .with_depth()
            .apply(
                &mut t,
                &CompositeInputs {
                    sigma: s,
                    delta: d,
                    color: c,
                    background: None,
                    t: Some(depth_at),
                },
            )
            .unwrap();
        let depth = out.depth.unwrap();
        let value = t.value(depth).unwrap()[[0]];
        assert!(value.is_finite() && value.abs() < 1e-29);
        let sum = t.sum(depth).unwrap();
        let g = t.backward(sum).unwrap();
        // d depth / d sigma_k = delta_k (T_{k+1} t_k - sum_{i>k} w_i t_i) = 0.5 t_k at sigma = 0.
        let gs = g.get(s).unwrap();
        assert!((gs[[0]] - 0.5).abs() < 1e-12 && (gs[[1]] - 1.0).abs() < 1e-12);
    }
}

#[test]
fn early_termination_is_consistent_and_bounded() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(8);
    let n = 128;
    let rays = Rays {
        sigma: (0..n).map(|_| rng.gen_range(0.5..3.0)).collect(),
        delta: vec![0.1; n],
        color: (0..n).map(|_| rng.gen_range(0.0..1.0)).collect(),
        ch: 1,
        offsets: vec![0, n],
        background: vec![0.9],
    };
    let ones = vec![1.0];
    let exact = run_with::<f64>(&rays, Method::Fused, 0.0, &ones);
    let default = run::<f64>(&rays, Method::Fused);
    assert_eq!(
        exact.color[0].to_bits(),
        default.color[0].to_bits(),
        "threshold 0 is the exact op"
    );
    for threshold in [1e-6, 1e-4, 1e-2] {
        let cut = run_with::<f64>(&rays, Method::Fused, threshold, &ones);
        let t_stop = 1.0 - cut.opacity[0];
        let stop = cut.weights.iter().rposition(|&w| w > 0.0).unwrap() + 1;
        assert!(stop < n, "the ray must actually be cut at {threshold}");
        assert!(t_stop < threshold && t_stop > 0.0);
        let bound = t_stop * rays.color.iter().map(|c| (c - 0.9f64).abs()).fold(0.0, f64::max);
        assert!((cut.color[0] - exact.color[0]).abs() <= bound + 1e-15);
        assert!(cut.d_sigma[stop..].iter().all(|&g| g == 0.0));
        eprintln!(
            "min_transmittance {threshold:e}: stops at sample {stop} of {n}, |C - C_exact| = {:.2e} <= {bound:.2e}",
            (cut.color[0] - exact.color[0]).abs()
        );
    }
    // The backward is the derivative of the truncated function (stop index held fixed, as it
    // is under small perturbations away from the threshold).
    let offsets = [0, n];
    let inputs = [
        Array1::from(rays.sigma.clone()).into_dyn(),
        Array1::from(rays.color.clone())
            .into_shape_with_order(vec![n, 1])
            .unwrap()
            .into_dyn(),
    ];
    let report = gradcheck(
        |t, v| {
            let d = t.constant(Array1::from(vec![0.1; n]));
            let bg = t.constant(arr1(&[0.9]));
            let op = Composite::new(&offsets).unwrap().min_transmittance(1e-2).unwrap();
            let out = op.apply(
                t,
                &CompositeInputs {
                    sigma: v[0],
                    delta: d,
                    color: v[1],
                    background: Some(bg),
                    t: None,
                },
            )?;
            Ok(out.color)
        },
        &inputs,
        &GradcheckOptions::default(),
    )
    .unwrap();
    report.check(1e-8, 1e-6).unwrap();
}

#[test]
fn invalid_input_is_an_error_naming_ray_and_sample_and_changes_nothing() {
    type Case = (&'static str, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, &'static str);
    let good = || (vec![1.0, 2.0, 3.0], vec![0.1, 0.1, 0.1], vec![0.5, 0.5, 0.5], vec![0.0]);
    let mut cases: Vec<Case> = Vec::new();
    let (s, d, c, b) = good();
    let with = |i: usize, v: f64, which: usize| {
        let mut x = [s.clone(), d.clone(), c.clone(), b.clone()];
        x[which][i] = v;
        x
    };
    for (name, v, which, needle) in [
        ("NaN sigma", f64::NAN, 0, "ray 1, sample 0: sigma"),
        ("negative sigma", -1.0, 0, "ray 1, sample 0: sigma"),
        ("infinite sigma", f64::INFINITY, 0, "ray 1, sample 0: sigma"),
        ("negative delta", -0.1, 1, "ray 1, sample 0: delta"),
        ("NaN delta", f64::NAN, 1, "ray 1, sample 0: delta"),
        ("infinite colour", f64::INFINITY, 2, "ray 1, sample 0: color[0]"),
    ] {
        let [s2, d2, c2, b2] = with(1, v, which);
        cases.push((name, s2, d2, c2, b2, needle));
    }
    let [s2, d2, c2, _] = with(0, 0.0, 0);
    cases.push(("NaN background", s2, d2, c2, vec![f64::NAN], "background[0]"));
    for (name, s, d, c, b, needle) in cases {
        let mut t = Tape::<f64>::new();
        let sv = t.param(Array1::from(s));
        let dv = t.param(Array1::from(d));
        let cv = t.param(Array2::from_shape_vec((3, 1), c).unwrap());
        let bv = t.param(Array1::from(b));
        let before = t.stats();
        let err = Composite::new(&[0, 1, 3])
            .unwrap()
            .apply(
                &mut t,
                &CompositeInputs {
                    sigma: sv,
                    delta: dv,
                    color: cv,
                    background: Some(bv),
                    t: None,
                },
            )
            .unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, TapeError::Op { op: "composite", .. }), "{name}: {msg}");
        assert!(msg.contains(needle), "{name}: {msg}");
        // The composite's own error comes back whole through the tape.
        match err.downcast_ref::<OpsError>() {
            Some(OpsError::Domain {
                op: Op::Composite,
                at: At::Sample { ray, sample },
                ..
            }) => {
                assert_eq!((*ray, *sample), (1, 0), "{name}")
            }
            Some(OpsError::Domain {
                op: Op::Composite,
                at: At::Ray(_),
                what,
                ..
            }) => assert_eq!(what, "background[0]", "{name}"),
            other => panic!("{name}: {other:?}"),
        }
        assert_eq!(t.stats(), before, "{name}: the tape is unchanged");
    }
    // Shapes and packing.
    assert!(matches!(
        Composite::new(&[0, 3, 2]),
        Err(OpsError::Offsets { op: Op::Composite, .. })
    ));
    assert!(matches!(
        Composite::new(&[1, 3]),
        Err(OpsError::Offsets { op: Op::Composite, .. })
    ));
    assert!(matches!(
        Composite::new(&[]),
        Err(OpsError::Offsets { op: Op::Composite, .. })
    ));
    assert!(Composite::new(&[0, 1]).unwrap().min_transmittance(-0.1).is_err());
    assert!(Composite::new(&[0, 1]).unwrap().min_transmittance(f64::NAN).is_err());
    let mut t = Tape::<f32>::new();
    let sv = t.param(arr1(&[1.0f32, 2.0]));
    let dv = t.param(arr1(&[0.1f32, 0.1]));
    let cv = t.param(arr2(&[[0.5f32, 0.5]]));
    let bv = t.param(arr1(&[0.0f32, 0.0]));
    // The error of applying an op over `offsets`, with or without the background.
    let mut err = |offsets: &[usize], background: Option<_>| {
        let inputs = CompositeInputs {
            sigma: sv,
            delta: dv,
            color: cv,
            background,
            t: None,
        };
        let op = Composite::new(offsets).unwrap();
        op.apply(&mut t, &inputs).unwrap_err().to_string()
    };
    // Colour rows against samples, sigma against the offsets, a missing background.
    for (offsets, background, named) in [
        (&[0, 2][..], Some(bv), "color"),
        (&[0, 3][..], Some(bv), "sigma"),
        (&[0, 2][..], None, "background"),
    ] {
        let e = err(offsets, background);
        assert!(e.contains(named), "{e}");
    }
}
