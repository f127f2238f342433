//! Rays composited eight at a time across the vector lanes (`Composite::pack_rays`, the
//! default) against the same op one ray at a time: every output and every gradient bitwise
//! equal, over ragged packs, empty rays, packs across block boundaries, each kind of
//! background, early termination, channel counts, both precisions and thread counts; and the
//! packed path against a closed form, so that agreement is not agreement in error.

use fogray_ops::{
    Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeOutputBuffers, CompositeUpstream,
    CompositeWanted,
};
use fogray_tape::Float;
use ndarray::{Array1, Array2, ArrayD};
use rand::{Rng, SeedableRng};

/// Ray lengths: runs of equal lengths (packs, some crossing the 64-ray blocks), ragged
/// stretches, empty rays inside a would-be pack, and lengths around the groups of four.
fn lengths() -> Vec<usize> {
    let mut l = Vec::new();
    for (len, count) in [(64, 8), (5, 3), (1, 9), (0, 1), (3, 8), (17, 16), (4, 7), (2, 1)] {
        l.extend(std::iter::repeat_n(len, count));
    }
    // Rays 60..76 have one length: a pack straddles the block boundary at ray 64.
    l.resize(60, 6);
    l.extend(std::iter::repeat_n(33, 16));
    l.extend([7, 7, 7, 7, 0, 7, 7, 7, 7, 7, 31, 32, 9, 9, 9, 9, 9, 9, 9, 9]);
    l
}

/// Random inputs: densities from 0 to opaque (some exactly 0), steps, colours of both signs,
/// depths; upstream gradients for every output.
struct Case<F: Float> {
    offsets: Vec<usize>,
    sigma: ArrayD<F>,
    delta: ArrayD<F>,
    color: ArrayD<F>,
    shared_bg: ArrayD<F>,
    per_ray_bg: ArrayD<F>,
    t: ArrayD<F>,
    g_color: ArrayD<F>,
    g_opacity: ArrayD<F>,
    g_depth: ArrayD<F>,
    g_weights: ArrayD<F>,
    g_trans: ArrayD<F>,
}

fn case<F: Float>(ch: usize, seed: u64) -> Case<F> {
    let lengths = lengths();
    let mut offsets = vec![0];
    for l in &lengths {
        offsets.push(offsets[offsets.len() - 1] + l);
    }
    let (n, rays) = (offsets[rays_of(&offsets)], rays_of(&offsets));
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut v = |len: usize, lo: f64, hi: f64| -> Vec<F> { (0..len).map(|_| F::lit(rng.gen_range(lo..hi))).collect() };
    let mut sigma = v(n, 0.0, 6.0);
    for (i, s) in sigma.iter_mut().enumerate() {
        match i % 13 {
            0 => *s = F::zero(),
            1 => *s = F::lit(400.0),
            2 => *s = F::lit(1e-7),
            _ => {}
        }
    }
    let arr = |shape: Vec<usize>, data: Vec<F>| ArrayD::from_shape_vec(shape, data).unwrap();
    Case {
        sigma: arr(vec![n], sigma),
        delta: arr(vec![n], v(n, 0.0, 0.2)),
        color: arr(vec![n, ch], v(n * ch, -0.5, 1.5)),
        shared_bg: arr(vec![ch], v(ch, 0.0, 1.0)),
        per_ray_bg: arr(vec![rays, ch], v(rays * ch, 0.0, 1.0)),
        t: arr(vec![n], v(n, 0.0, 4.0)),
        g_color: arr(vec![rays, ch], v(rays * ch, -1.0, 1.0)),
        g_opacity: arr(vec![rays], v(rays, -1.0, 1.0)),
        g_depth: arr(vec![rays], v(rays, -1.0, 1.0)),
        g_weights: arr(vec![n], v(n, -1.0, 1.0)),
        g_trans: arr(vec![n], v(n, -1.0, 1.0)),
        offsets,
    }
}

fn rays_of(offsets: &[usize]) -> usize {
    offsets.len() - 1
}

fn bits<F: Float>(a: &ArrayD<F>) -> Vec<u64> {
    a.iter().map(|x| x.as_f64().to_bits()).collect()
}

/// Every output and gradient of `op` on `c`, as bit patterns: the forward with every output,
/// the backward with every upstream gradient and every input gradient, and the one-pass call.
fn everything<F: Float>(op: &Composite, c: &Case<F>, background: Background) -> Vec<(String, Vec<u64>)> {
    let mut inputs = CompositeArrays::new(c.sigma.view(), c.delta.view(), c.color.view()).with_t(c.t.view());
    inputs = match background {
        Background::None => inputs,
        Background::Shared => inputs.with_background(c.shared_bg.view()),
        Background::PerRay => inputs.with_background(c.per_ray_bg.view()),
    };
    let mut all = Vec::new();
    let (outs, res) = op.evaluate(&inputs).unwrap();
    all.push(("colour".to_string(), bits(&outs.color)));
    all.push(("opacity".to_string(), bits(&outs.opacity)));
    for (name, o) in [
        ("depth", &outs.depth),
        ("weights", &outs.weights),
        ("T", &outs.transmittance),
    ] {
        all.push((name.to_string(), bits(o.as_ref().unwrap())));
    }
    let upstream = CompositeUpstream {
        color: Some(c.g_color.view()),
        opacity: Some(c.g_opacity.view()),
        depth: Some(c.g_depth.view()),
        weights: Some(c.g_weights.view()),
        transmittance: Some(c.g_trans.view()),
    };
    let wanted = CompositeWanted {
        sigma: true,
        delta: true,
        color: true,
        background: background != Background::None,
        t: true,
    };
    let g = op.vjp(&inputs, &res, &upstream, wanted).unwrap();
    for (name, x) in [
        ("d sigma", &g.sigma),
        ("d delta", &g.delta),
        ("d colour", &g.color),
        ("d background", &g.background),
        ("d t", &g.t),
    ] {
        all.push((name.to_string(), x.as_ref().map_or(vec![], bits)));
    }
    // One pass with dL/dC = C - 0.3 (a function of the colour just composited).
    let (rays, ch, n) = (rays_of(&c.offsets), c.color.shape()[1], c.sigma.len());
    let mut color = ArrayD::zeros(vec![rays, ch]);
    let mut opacity = ArrayD::zeros(vec![rays]);
    let mut depth = ArrayD::zeros(vec![rays]);
    let mut weights = ArrayD::zeros(vec![n]);
    let mut trans = ArrayD::zeros(vec![n]);
    let mut gs = ArrayD::zeros(vec![n]);
    let mut gd = ArrayD::zeros(vec![n]);
    let mut gc = ArrayD::zeros(vec![n, ch]);
    op.evaluate_vjp_into(
        &inputs,
        |_, col: &[F], d: &mut [F]| {
            for (d, &c) in d.iter_mut().zip(col) {
                *d = c - F::lit(0.3);
            }
        },
        &mut CompositeOutputBuffers {
            color: color.view_mut(),
            opacity: opacity.view_mut(),
            depth: Some(depth.view_mut()),
            weights: Some(weights.view_mut()),
            transmittance: Some(trans.view_mut()),
        },
        &mut CompositeGradientBuffers {
            sigma: Some(gs.view_mut()),
            delta: Some(gd.view_mut()),
            color: Some(gc.view_mut()),
            ..Default::default()
        },
    )
    .unwrap();
    for (name, x) in [
        ("1-pass colour", &color),
        ("1-pass opacity", &opacity),
        ("1-pass depth", &depth),
        ("1-pass weights", &weights),
        ("1-pass T", &trans),
        ("1-pass d sigma", &gs),
        ("1-pass d delta", &gd),
        ("1-pass d colour", &gc),
    ] {
        all.push((name.to_string(), bits(x)));
    }
    all
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

fn packed_equals_per_ray<F: Float>() {
    for ch in [1, 3, 5] {
        let c = case::<F>(ch, 7 + ch as u64);
        for background in [Background::None, Background::Shared, Background::PerRay] {
            for threshold in [0.0, 1e-3, 0.3] {
                let op = Composite::new(&c.offsets)
                    .unwrap()
                    .background(background)
                    .min_transmittance(threshold)
                    .unwrap()
                    .with_depth()
                    .with_weights()
                    .with_transmittance();
                let want = pool(1).install(|| everything(&op.clone().pack_rays(false), &c, background));
                for threads in [1, 2, 3] {
                    let got = pool(threads).install(|| everything(&op.clone().pack_rays(true), &c, background));
                    for ((name, g), (_, w)) in got.iter().zip(&want) {
                        assert!(!w.is_empty() || name == "d background", "{name} missing");
                        assert_eq!(
                            g,
                            w,
                            "{} ch {ch} {background:?} threshold {threshold} threads {threads}: {name}",
                            F::NAME
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn packed_rays_give_the_per_ray_bits_in_f32() {
    packed_equals_per_ray::<f32>();
}

#[test]
fn packed_rays_give_the_per_ray_bits_in_f64() {
    packed_equals_per_ray::<f64>();
}

/// Sixteen rays (two packs) of constant density through two colours: the colour has a closed
/// form, `C = (1 - e^-a) c1 + e^-a (1 - e^-b) c2 + e^-(a+b) bg` with `a`, `b` the optical
/// depths of the two halves.
#[test]
fn packed_rays_match_the_closed_form_of_two_uniform_slabs() {
    let (rays, len) = (16usize, 40usize);
    let offsets: Vec<usize> = (0..=rays).map(|r| r * len).collect();
    let sigma = Array1::from_shape_fn(rays * len, |i| 0.5 + (i / len) as f64 * 0.25);
    let delta = Array1::from_elem(rays * len, 0.05);
    let color = Array2::from_shape_fn((rays * len, 1), |(i, _)| if i % len < len / 2 { 0.9 } else { 0.2 });
    let bg = Array1::from_elem(1, 0.6);
    let op = Composite::new(&offsets).unwrap();
    let inputs = CompositeArrays::new(
        sigma.view().into_dyn(),
        delta.view().into_dyn(),
        color.view().into_dyn(),
    )
    .with_background(bg.view().into_dyn());
    let (outs, _) = op.evaluate(&inputs).unwrap();
    for r in 0..rays {
        let half = (0.5 + r as f64 * 0.25) * 0.05 * (len / 2) as f64;
        let (ea, eb) = ((-half).exp(), (-half).exp());
        let want = (1.0 - ea) * 0.9 + ea * (1.0 - eb) * 0.2 + ea * eb * 0.6;
        assert!(
            (outs.color[[r, 0]] - want).abs() < 1e-14,
            "ray {r}: {} vs {want}",
            outs.color[[r, 0]]
        );
        assert!((outs.opacity[r] - (1.0 - ea * eb)).abs() < 1e-14);
    }
}
