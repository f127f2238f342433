//! The fused composite against its stable taped twin (f64, 1e-12 element by element), against
//! itself in f32 (1e-5 element by element), and against central finite differences; results
//! independent of the thread count.

// Index loops mirror the formulas' subscripts in these tests.
#![allow(clippy::needless_range_loop)]

use crate::composite_common;

use composite_common::{assert_close_scaled, grad_scale, run, worst_scaled, Method, Rays};
use fogray::ops::{twins, Background, Composite, CompositeInputs};
use fogray::tape::{gradcheck, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{Array1, ArrayD};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};

/// Random packed rays: lengths in 0..max_len, densities either exactly 0 or log-uniform in
/// [1e-3, 1e3], steps log-uniform in [1e-3, 1e-1], colours in [0, 1], f32-representable.
fn random_rays(seed: u64, rays: usize, max_len: usize, ch: usize) -> Rays {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut offsets = vec![0];
    for _ in 0..rays {
        let len = rng.gen_range(0..max_len);
        offsets.push(offsets.last().unwrap() + len);
    }
    let n = *offsets.last().unwrap();
    let sigma = (0..n)
        .map(|_| {
            if rng.gen_bool(0.2) {
                0.0
            } else {
                10f64.powf(rng.gen_range(-3.0..3.0))
            }
        })
        .collect();
    let delta = (0..n).map(|_| 10f64.powf(rng.gen_range(-3.0..-1.0))).collect();
    let color = (0..n * ch).map(|_| rng.gen_range(0.0..1.0)).collect();
    let background = (0..ch).map(|_| rng.gen_range(0.0..1.0)).collect();
    Rays {
        sigma,
        delta,
        color,
        ch,
        offsets,
        background,
    }
    .f32_representable()
}

/// Relative scale floored so that f32's subnormal range does not count.
fn rel_scale(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x.abs()).collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    #[test]
    fn fused_matches_stable_in_f64_and_itself_in_f32(seed in any::<u64>(), ch_pick in 0usize..3, rays in 1usize..6) {
        let ch = [1, 3, 4][ch_pick];
        let r = random_rays(seed, rays, 300, ch);
        let fused = run::<f64>(&r, Method::Fused);
        let stable = run::<f64>(&r, Method::Stable);
        let g_scale = grad_scale(&r);
        let c_scale = rel_scale(&fused.color);
        // f64: fused vs stable, element by element.
        assert_close_scaled("color f64", &fused.color, &stable.color, &c_scale, 1e-300, 1e-12);
        assert_close_scaled("weights f64", &fused.weights, &stable.weights, &rel_scale(&fused.weights), 1e-300, 1e-12);
        assert_close_scaled("T f64", &fused.transmittance, &stable.transmittance, &rel_scale(&fused.transmittance), 1e-300, 1e-12);
        assert_close_scaled("opacity f64", &fused.opacity, &stable.opacity, &rel_scale(&fused.opacity), 1e-300, 1e-12);
        assert_close_scaled("dC/dsigma f64", &fused.d_sigma, &stable.d_sigma, &g_scale, 1e-300, 1e-12);
        let dd_scale: Vec<f64> = g_scale.iter().zip(&r.sigma).zip(&r.delta).map(|((s, sig), d)| s * sig / d).collect();
        assert_close_scaled("dC/ddelta f64", &fused.d_delta, &stable.d_delta, &dd_scale, 1e-300, 1e-12);
        assert_close_scaled("dC/dc f64", &fused.d_color, &stable.d_color, &rel_scale(&fused.d_color), 1e-300, 1e-12);
        assert_close_scaled("dC/dbg f64", &fused.d_background, &stable.d_background, &rel_scale(&fused.d_background), 1e-300, 1e-12);
        // f32 fused vs f64 fused on the same inputs, element by element.
        let f32r = run::<f32>(&r, Method::Fused);
        assert_close_scaled("color f32", &f32r.color, &fused.color, &c_scale, 1e-30, 1e-5);
        assert_close_scaled("weights f32", &f32r.weights, &fused.weights, &rel_scale(&fused.weights), 1e-30, 1e-5);
        assert_close_scaled("T f32", &f32r.transmittance, &fused.transmittance, &rel_scale(&fused.transmittance), 1e-30, 1e-5);
        assert_close_scaled("dC/dsigma f32", &f32r.d_sigma, &fused.d_sigma, &g_scale, 1e-30, 1e-5);
        assert_close_scaled("dC/dc f32", &f32r.d_color, &fused.d_color, &rel_scale(&fused.d_color), 1e-30, 1e-5);
    }
}

#[test]
fn naive_twin_f32_error_is_reported() {
    // Reported, not required: the naive form's f32 error on the same random rays.
    let mut worst = (0.0f64, 0.0f64);
    for seed in 0..8 {
        let r = random_rays(seed, 4, 300, 3);
        let reference = run::<f64>(&r, Method::Fused);
        let naive = run::<f32>(&r, Method::Naive);
        let g = worst_scaled(&naive.d_sigma, &reference.d_sigma, &grad_scale(&r), 1e-30).0;
        let c = worst_scaled(&naive.color, &reference.color, &rel_scale(&reference.color), 1e-30).0;
        worst = (worst.0.max(c), worst.1.max(g));
    }
    eprintln!(
        "naive taped f32 on random rays: worst colour error {:.2e}, worst scaled dC/dsigma error {:.2e}",
        worst.0, worst.1
    );
    assert!(worst.0.is_finite());
}

/// Every output of the composite in one vector, so that gradcheck's random projection
/// exercises all of them (and all the backward's upstream-gradient paths) at once.
fn all_outputs(
    t: &mut Tape<f64>,
    v: &[Var],
    offsets: &[usize],
    fused: bool,
    background: Background,
) -> Result<Var, TapeError> {
    let op = Composite::new(offsets)
        .unwrap()
        .background(background)
        .with_depth()
        .with_weights()
        .with_transmittance();
    let inputs = CompositeInputs {
        sigma: v[0],
        delta: v[1],
        color: v[2],
        background: (background != Background::None).then(|| v[3]),
        t: Some(v[4]),
    };
    let out = if fused {
        op.apply(t, &inputs)?
    } else {
        twins::stable(t, &op, &inputs)?
    };
    let rays = offsets.len() - 1;
    let ch = t.shape(out.color)?[1];
    let color = t.reshape(out.color, &[rays * ch])?;
    t.concat(
        &[
            color,
            out.opacity,
            out.depth.unwrap(),
            out.weights.unwrap(),
            out.transmittance.unwrap(),
        ],
        0,
    )
}

#[test]
fn fused_and_stable_pass_gradcheck_for_every_input_and_output() {
    let offsets = [0, 3, 3, 7, 8];
    let n = 8;
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut rand_vec = |len: usize, lo: f64, hi: f64| -> ArrayD<f64> {
        Array1::from_shape_fn(len, |_| rng.gen_range(lo..hi)).into_dyn()
    };
    let sigma = rand_vec(n, 0.1, 6.0);
    let delta = rand_vec(n, 0.05, 0.5);
    let color = rand_vec(n * 3, 0.0, 1.0).into_shape_with_order(vec![n, 3]).unwrap();
    let t = rand_vec(n, 1.0, 5.0);
    for (background, bg) in [
        (Background::Shared, rand_vec(3, 0.0, 1.0)),
        (
            Background::PerRay,
            rand_vec(12, 0.0, 1.0).into_shape_with_order(vec![4, 3]).unwrap(),
        ),
        (Background::None, rand_vec(3, 0.0, 1.0)),
    ] {
        for fused in [true, false] {
            let inputs = [sigma.clone(), delta.clone(), color.clone(), bg.clone(), t.clone()];
            let report = gradcheck(
                |tp, v| all_outputs(tp, v, &offsets, fused, background),
                &inputs,
                &GradcheckOptions::default(),
            )
            .unwrap();
            if let Err(r) = report.check(1e-7, 1e-6) {
                panic!("fused={fused} {background:?}: {r}");
            }
        }
    }
}

#[test]
fn results_are_bitwise_identical_whatever_the_thread_count() {
    let r = random_rays(42, 300, 100, 3);
    let in_pool = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| (run::<f32>(&r, Method::Fused), run::<f64>(&r, Method::Fused)))
    };
    let (a32, a64) = in_pool(1);
    for threads in [2, 3] {
        let (b32, b64) = in_pool(threads);
        for (x, y) in [(&a32, &b32), (&a64, &b64)] {
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&x.color), bits(&y.color));
            assert_eq!(bits(&x.weights), bits(&y.weights));
            assert_eq!(bits(&x.d_sigma), bits(&y.d_sigma));
            assert_eq!(bits(&x.d_delta), bits(&y.d_delta));
            assert_eq!(bits(&x.d_color), bits(&y.d_color));
            assert_eq!(bits(&x.d_background), bits(&y.d_background));
        }
    }
}

#[test]
fn each_ray_in_a_packed_batch_equals_the_ray_rendered_alone() {
    // Lengths {0, 1, 2, 64, 1e5}: each ray's outputs bitwise equal to rendering it alone.
    let lengths = [0usize, 1, 2, 64, 100_000];
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let n: usize = lengths.iter().sum();
    let mut offsets = vec![0];
    for l in lengths {
        offsets.push(offsets.last().unwrap() + l);
    }
    let batch = Rays {
        sigma: (0..n).map(|_| rng.gen_range(0.0..2.0)).collect(),
        delta: vec![1e-3; n],
        color: (0..n).map(|_| rng.gen_range(0.0..1.0)).collect(),
        ch: 1,
        offsets: offsets.clone(),
        background: vec![0.25],
    }
    .f32_representable();
    let all = run::<f32>(&batch, Method::Fused);
    for (r, w) in offsets.windows(2).enumerate() {
        let alone = Rays {
            sigma: batch.sigma[w[0]..w[1]].to_vec(),
            delta: batch.delta[w[0]..w[1]].to_vec(),
            color: batch.color[w[0]..w[1]].to_vec(),
            ch: 1,
            offsets: vec![0, w[1] - w[0]],
            background: vec![0.25],
        };
        let one = run::<f32>(&alone, Method::Fused);
        assert_eq!(one.color[0].to_bits(), all.color[r].to_bits(), "ray {r}");
        assert_eq!(one.opacity[0].to_bits(), all.opacity[r].to_bits(), "ray {r}");
        assert_eq!(one.d_sigma, all.d_sigma[w[0]..w[1]], "ray {r}");
        assert_eq!(one.weights, all.weights[w[0]..w[1]], "ray {r}");
    }
}

#[test]
fn multi_channel_equals_separate_single_channel_runs() {
    for ch in [1usize, 3, 8] {
        let r = random_rays(11 + ch as u64, 3, 50, ch);
        let all = run::<f64>(&r, Method::Fused);
        // dC/dsigma is linear in the upstream gradient: with ones, the sum over channels.
        let mut summed = vec![0.0; r.n()];
        for c in 0..ch {
            let single = Rays {
                color: r.color.iter().skip(c).step_by(ch).copied().collect(),
                ch: 1,
                background: vec![r.background[c]],
                ..r.clone()
            };
            let one = run::<f64>(&single, Method::Fused);
            for ray in 0..r.rays() {
                assert_eq!(one.color[ray], all.color[ray * ch + c]);
            }
            for k in 0..r.n() {
                assert_eq!(one.d_color[k], all.d_color[k * ch + c]);
                summed[k] += one.d_sigma[k];
            }
        }
        assert_close_scaled(
            "dC/dsigma summed over channels",
            &all.d_sigma,
            &summed,
            &grad_scale(&r),
            1e-300,
            1e-13,
        );
    }
}
