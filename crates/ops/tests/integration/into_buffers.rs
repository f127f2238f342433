//! `evaluate_into` / `vjp_into` against `evaluate` / `vjp`: the same bits in buffers that held
//! garbage (so every value must be written, zeros included), shape errors that write nothing,
//! and the named wanted gradients: exactly those asked for, the bits of the full call.

use fogray_ops::{
    At, Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeGradients, CompositeOutputBuffers,
    CompositeOutputs, CompositeUpstream, CompositeWanted, Op, OpsError,
};
use ndarray::{Array1, Array2, ArrayD, IxDyn, ShapeBuilder};
use rand::{Rng, SeedableRng};

/// Upstream gradients of every output, by name.
#[derive(Clone)]
struct Upstream {
    color: Option<ArrayD<f32>>,
    opacity: Option<ArrayD<f32>>,
    depth: Option<ArrayD<f32>>,
    weights: Option<ArrayD<f32>>,
    transmittance: Option<ArrayD<f32>>,
}

impl Upstream {
    fn views(&self) -> CompositeUpstream<'_, f32> {
        CompositeUpstream {
            color: self.color.as_ref().map(ArrayD::view),
            opacity: self.opacity.as_ref().map(ArrayD::view),
            depth: self.depth.as_ref().map(ArrayD::view),
            weights: self.weights.as_ref().map(ArrayD::view),
            transmittance: self.transmittance.as_ref().map(ArrayD::view),
        }
    }
}

struct Case {
    op: Composite,
    sigma: ArrayD<f32>,
    delta: ArrayD<f32>,
    color: ArrayD<f32>,
    background: Option<ArrayD<f32>>,
    t: ArrayD<f32>,
    upstream: Upstream,
}

impl Case {
    fn arrays(&self) -> CompositeArrays<'_, f32> {
        CompositeArrays {
            sigma: self.sigma.view(),
            delta: self.delta.view(),
            color: self.color.view(),
            background: self.background.as_ref().map(ArrayD::view),
            t: Some(self.t.view()),
        }
    }

    /// Every combination of wanted gradients the op accepts (no background gradient without a
    /// background).
    fn wanted_combinations(&self) -> Vec<CompositeWanted> {
        let has_bg = self.background.is_some();
        (0..32u32)
            .map(|m| CompositeWanted {
                sigma: m & 1 != 0,
                delta: m & 2 != 0,
                color: m & 4 != 0,
                background: m & 8 != 0,
                t: m & 16 != 0,
            })
            .filter(|w| has_bg || !w.background)
            .collect()
    }

    /// Gradient buffers full of NaN for the gradients `wanted`.
    fn garbage_gradients(&self, wanted: CompositeWanted) -> CompositeGradients<f32> {
        let like = |on: bool, a: &ArrayD<f32>| on.then(|| garbage(a.shape()));
        CompositeGradients {
            sigma: like(wanted.sigma, &self.sigma),
            delta: like(wanted.delta, &self.delta),
            color: like(wanted.color, &self.color),
            background: self.background.as_ref().and_then(|b| like(wanted.background, b)),
            t: like(wanted.t, &self.t),
        }
    }
}

/// Ragged rays (one empty), early termination (so some samples are skipped), every optional
/// output on, and upstream gradients for all of them.
fn case(background: Background, seed: u64) -> Case {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let lens = [5usize, 0, 40, 1, 77, 12];
    let mut offsets = vec![0];
    for l in lens {
        offsets.push(offsets.last().unwrap() + l);
    }
    let (n, rays, ch) = (*offsets.last().unwrap(), lens.len(), 3);
    let op = Composite::new(&offsets)
        .unwrap()
        .background(background)
        .min_transmittance(1e-2)
        .unwrap()
        .with_depth()
        .with_weights()
        .with_transmittance();
    let mut u = |lo: f32, hi: f32, len: usize| -> Vec<f32> { (0..len).map(|_| rng.gen_range(lo..hi)).collect() };
    let sigma = Array1::from(u(0.0, 8.0, n)).into_dyn();
    let delta = Array1::from(u(0.01, 0.2, n)).into_dyn();
    let color = Array2::from_shape_vec((n, ch), u(0.0, 1.0, n * ch)).unwrap().into_dyn();
    let background = match background {
        Background::None => None,
        Background::Shared => Some(Array1::from(u(0.0, 1.0, ch)).into_dyn()),
        Background::PerRay => Some(
            Array2::from_shape_vec((rays, ch), u(0.0, 1.0, rays * ch))
                .unwrap()
                .into_dyn(),
        ),
    };
    let mut t = u(0.0, 1.0, n);
    t.sort_by(f32::total_cmp);
    let t = Array1::from(t).into_dyn();
    let mut random = |shape: &[usize]| {
        let len = shape.iter().product();
        Some(ArrayD::from_shape_vec(IxDyn(shape), u(-1.0, 1.0, len)).unwrap())
    };
    let upstream = Upstream {
        color: random(&[rays, ch]),
        opacity: random(&[rays]),
        depth: random(&[rays]),
        weights: random(&[n]),
        transmittance: random(&[n]),
    };
    Case {
        op,
        sigma,
        delta,
        color,
        background,
        t,
        upstream,
    }
}

fn garbage(shape: &[usize]) -> ArrayD<f32> {
    ArrayD::from_elem(IxDyn(shape), f32::NAN)
}

fn garbage_outputs(like: &CompositeOutputs<f32>) -> CompositeOutputs<f32> {
    let g = |a: &ArrayD<f32>| garbage(a.shape());
    CompositeOutputs {
        color: g(&like.color),
        opacity: g(&like.opacity),
        depth: like.depth.as_ref().map(g),
        weights: like.weights.as_ref().map(g),
        transmittance: like.transmittance.as_ref().map(g),
    }
}

fn same_bits(got: &ArrayD<f32>, want: &ArrayD<f32>, what: &str) {
    assert_eq!(got.shape(), want.shape(), "{what}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g.to_bits(), w.to_bits(), "{what}[{i}]: {g} vs {w}");
    }
}

fn output_list(o: &CompositeOutputs<f32>) -> [(&'static str, Option<&ArrayD<f32>>); 5] {
    [
        ("color", Some(&o.color)),
        ("opacity", Some(&o.opacity)),
        ("depth", o.depth.as_ref()),
        ("weights", o.weights.as_ref()),
        ("transmittance", o.transmittance.as_ref()),
    ]
}

fn gradient_list(g: &CompositeGradients<f32>) -> [(&'static str, Option<&ArrayD<f32>>); 5] {
    [
        ("sigma", g.sigma.as_ref()),
        ("delta", g.delta.as_ref()),
        ("color", g.color.as_ref()),
        ("background", g.background.as_ref()),
        ("t", g.t.as_ref()),
    ]
}

fn wanted_list(w: CompositeWanted) -> [bool; 5] {
    [w.sigma, w.delta, w.color, w.background, w.t]
}

fn same_outputs(got: &CompositeOutputs<f32>, want: &CompositeOutputs<f32>, what: &str) {
    for ((name, g), (_, w)) in output_list(got).into_iter().zip(output_list(want)) {
        match (g, w) {
            (Some(g), Some(w)) => same_bits(g, w, &format!("{what}: {name}")),
            (None, None) => {}
            _ => panic!("{what}: {name} present in one only"),
        }
    }
}

/// The buffers `got` (filled by an `_into` call) against the allocating call's `want`: the
/// same bits where `want` has a gradient, zeros where it has none (no upstream reaches it),
/// nothing where not asked for.
fn same_gradients_into(
    got: &CompositeGradients<f32>,
    want: &CompositeGradients<f32>,
    asked: CompositeWanted,
    what: &str,
) {
    let lists = gradient_list(got).into_iter().zip(gradient_list(want));
    for (((name, g), (_, w)), asked) in lists.zip(wanted_list(asked)) {
        let what = format!("{what}: {name}");
        match (g, w) {
            (None, _) => assert!(!asked, "{what}"),
            (Some(g), Some(w)) => same_bits(g, w, &what),
            (Some(g), None) => assert!(g.iter().all(|&v| v.to_bits() == 0), "{what}: zeros"),
        }
    }
}

#[test]
fn evaluate_into_writes_every_output_as_evaluate_does() {
    for background in [Background::None, Background::Shared, Background::PerRay] {
        let c = case(background, 7);
        let x = c.arrays();
        let (want, want_res) = c.op.evaluate(&x).unwrap();
        let mut bufs = garbage_outputs(&want);
        let res = c.op.evaluate_into(&x, &mut bufs.buffers()).unwrap();
        same_outputs(&bufs, &want, &format!("{background:?}"));
        // The residuals drive the same backward.
        let all = CompositeWanted {
            sigma: true,
            delta: true,
            color: true,
            background: c.background.is_some(),
            t: true,
        };
        let up = c.upstream.views();
        let a = c.op.vjp(&x, &res, &up, all).unwrap();
        let b = c.op.vjp(&x, &want_res, &up, all).unwrap();
        assert_eq!(a, b, "vjp from either residuals");
    }
}

#[test]
fn each_wanted_combination_gives_exactly_the_gradients_asked_for_with_the_bits_of_the_full_call() {
    for background in [Background::None, Background::Shared, Background::PerRay] {
        let c = case(background, 23);
        let x = c.arrays();
        let (_, res) = c.op.evaluate(&x).unwrap();
        let up = c.upstream.views();
        let combinations = c.wanted_combinations();
        let full = c.op.vjp(&x, &res, &up, *combinations.last().unwrap()).unwrap();
        assert!(gradient_list(&full)
            .iter()
            .all(|(name, g)| g.is_some() || (*name == "background" && c.background.is_none())));
        for wanted in combinations {
            let what = format!("{background:?} {wanted:?}");
            let g = c.op.vjp(&x, &res, &up, wanted).unwrap();
            for (((name, g), (_, f)), asked) in gradient_list(&g)
                .into_iter()
                .zip(gradient_list(&full))
                .zip(wanted_list(wanted))
            {
                match (asked, g, f) {
                    (true, Some(g), Some(f)) => same_bits(g, f, &format!("{what}: {name}")),
                    (false, None, _) => {}
                    _ => panic!("{what}: {name} asked {asked}, returned {}", g.is_some()),
                }
            }
            // The same through buffers.
            let mut bufs = c.garbage_gradients(wanted);
            c.op.vjp_into(&x, &res, &up, &mut bufs.buffers()).unwrap();
            assert_eq!(bufs, g, "{what}: into buffers");
        }
    }
}

#[test]
fn vjp_into_writes_every_wanted_gradient_as_vjp_does_with_zeros_where_nothing_reaches() {
    for background in [Background::None, Background::Shared, Background::PerRay] {
        let c = case(background, 11);
        let x = c.arrays();
        let (_, res) = c.op.evaluate(&x).unwrap();
        // All upstreams; then no colour upstream (colour and background gradients are zero);
        // then only colour (the t gradient is zero).
        let no_color = Upstream {
            color: None,
            ..c.upstream.clone()
        };
        let only_color = Upstream {
            color: c.upstream.color.clone(),
            opacity: None,
            depth: None,
            weights: None,
            transmittance: None,
        };
        for upstream in [&c.upstream, &no_color, &only_color] {
            let up = upstream.views();
            for wanted in c.wanted_combinations() {
                let want = c.op.vjp(&x, &res, &up, wanted).unwrap();
                if upstream.color.is_none() {
                    assert!(want.color.is_none() && want.background.is_none());
                }
                if upstream.depth.is_none() {
                    assert!(want.t.is_none());
                }
                let mut bufs = c.garbage_gradients(wanted);
                c.op.vjp_into(&x, &res, &up, &mut bufs.buffers()).unwrap();
                same_gradients_into(&bufs, &want, wanted, &format!("{background:?} {wanted:?}"));
            }
        }
    }
}

#[test]
fn buffers_of_the_wrong_shape_or_layout_are_refused_and_left_untouched() {
    let c = case(Background::Shared, 3);
    let x = c.arrays();
    let (want, res) = c.op.evaluate(&x).unwrap();
    // A buffer missing for a configured output; then a colour buffer of the wrong shape; then
    // a strided one.
    let mut bufs = garbage_outputs(&want);
    {
        let mut b = bufs.buffers();
        b.depth = None;
        let err = c.op.evaluate_into(&x, &mut b).unwrap_err();
        assert!(
            matches!(
                err,
                OpsError::Mismatch {
                    op: Op::Composite,
                    what: "depth buffer",
                    ..
                }
            ),
            "{err}"
        );
    }
    let rays = c.op.rays();
    let mut wrong = garbage(&[rays + 1, 3]);
    let mut strided = ArrayD::from_elem(IxDyn(&[rays, 3]).f(), f32::NAN);
    for bad in [&mut wrong, &mut strided] {
        let mut b = bufs.buffers();
        b.color = bad.view_mut();
        let err = c.op.evaluate_into(&x, &mut b).unwrap_err();
        assert!(matches!(err, OpsError::Shape { op: Op::Composite, .. }), "{err}");
    }
    assert!(output_list(&bufs)
        .into_iter()
        .filter_map(|(_, b)| b)
        .chain([&wrong, &strided])
        .all(|b| b.iter().all(|v| v.is_nan())));
    // The backward: a sigma gradient buffer of the wrong length.
    let up = c.upstream.views();
    let mut short = garbage(&[c.op.samples() - 1]);
    let mut color = garbage(c.color.shape());
    let mut out = CompositeGradientBuffers {
        sigma: Some(short.view_mut()),
        color: Some(color.view_mut()),
        ..Default::default()
    };
    assert!(matches!(
        c.op.vjp_into(&x, &res, &up, &mut out),
        Err(OpsError::Shape { op: Op::Composite, .. })
    ));
    drop(out);
    assert!(short.iter().chain(color.iter()).all(|v| v.is_nan()));
}

/// The argument a `Mismatch` error names.
fn mismatch<T>(r: Result<T, OpsError>) -> &'static str {
    match r {
        Err(OpsError::Mismatch {
            op: Op::Composite,
            what,
            ..
        }) => what,
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("accepted"),
    }
}

#[test]
fn arguments_the_configuration_does_not_have_or_needs_are_refused_by_name() {
    let plain = case(Background::None, 29);
    let (sigma, delta, color) = (plain.sigma.view(), plain.delta.view(), plain.color.view());
    let bg = Array1::from(vec![0.5f32; 3]).into_dyn();
    // The op has depth and no background: a background given, t missing.
    let with_bg = plain.arrays().with_background(bg.view());
    assert_eq!(mismatch(plain.op.evaluate(&with_bg)), "background");
    let no_t = CompositeArrays::new(sigma.clone(), delta.clone(), color.clone());
    assert_eq!(mismatch(plain.op.evaluate(&no_t)), "t");
    let x = plain.arrays();
    let (outs, res) = plain.op.evaluate(&x).unwrap();
    let bg_wanted = CompositeWanted {
        background: true,
        ..Default::default()
    };
    let up = plain.upstream.views();
    assert_eq!(mismatch(plain.op.vjp(&x, &res, &up, bg_wanted)), "background gradient");
    let mut bg_buf = garbage(&[3]);
    let mut out = CompositeGradientBuffers {
        background: Some(bg_buf.view_mut()),
        ..Default::default()
    };
    assert_eq!(
        mismatch(plain.op.vjp_into(&x, &res, &up, &mut out)),
        "background gradient"
    );
    // An op without depth nor weights: a depth upstream, a t gradient, a weights buffer.
    let bare = Composite::new(plain.op.offsets()).unwrap().background(Background::None);
    let xb = CompositeArrays::new(sigma, delta, color);
    let (_, res_b) = bare.evaluate(&xb).unwrap();
    let depth_up = CompositeUpstream {
        depth: Some(outs.opacity.view()),
        ..Default::default()
    };
    assert_eq!(
        mismatch(bare.vjp(&xb, &res_b, &depth_up, CompositeWanted::default())),
        "depth upstream gradient"
    );
    let t_wanted = CompositeWanted {
        t: true,
        ..Default::default()
    };
    assert_eq!(
        mismatch(bare.vjp(&xb, &res_b, &CompositeUpstream::default(), t_wanted)),
        "t gradient"
    );
    let (mut c, mut o, mut w) = (
        garbage(outs.color.shape()),
        garbage(outs.opacity.shape()),
        garbage(&[bare.samples()]),
    );
    let mut b = CompositeOutputBuffers::new(c.view_mut(), o.view_mut());
    b.weights = Some(w.view_mut());
    assert_eq!(mismatch(bare.evaluate_into(&xb, &mut b)), "weights buffer");
    assert!(c.iter().chain(o.iter()).chain(w.iter()).all(|v| v.is_nan()));
}

#[test]
fn an_invalid_value_is_named_as_by_evaluate_and_the_inputs_stay_unchanged() {
    let mut c = case(Background::Shared, 5);
    c.sigma[[44]] = -1.0;
    let before = c.sigma.clone();
    let x = c.arrays();
    let want = c.op.evaluate(&x).unwrap_err();
    let (rays, n) = (c.op.rays(), c.op.samples());
    let mut bufs = CompositeOutputs {
        color: garbage(&[rays, 3]),
        opacity: garbage(&[rays]),
        depth: Some(garbage(&[rays])),
        weights: Some(garbage(&[n])),
        transmittance: Some(garbage(&[n])),
    };
    assert_eq!(c.op.evaluate_into(&x, &mut bufs.buffers()).unwrap_err(), want);
    assert!(
        matches!(
            want,
            OpsError::Domain {
                op: Op::Composite,
                at: At::Sample { ray: 2, sample: 39 },
                ..
            }
        ),
        "{want}"
    );
    assert_eq!(c.sigma, before);
}

/// `L = sum over rays and channels of w_rc (C_rc - p_rc)^2`: each ray's gradient depends on
/// its own colour only, as `evaluate_vjp_into` requires.
struct Photometric {
    target: Vec<f32>,
    weight: Vec<f32>,
    ch: usize,
}

impl Photometric {
    fn grad(&self, ray: usize, c: &[f32], d: &mut [f32]) {
        for (k, (d, &c)) in d.iter_mut().zip(c).enumerate() {
            let i = ray * self.ch + k;
            *d = 2.0 * self.weight[i] * (c - self.target[i]);
        }
    }
}

#[test]
fn evaluate_vjp_into_gives_the_bits_of_evaluate_into_then_vjp_into() {
    for background in [Background::None, Background::Shared, Background::PerRay] {
        for threshold in [0.0, 1e-2] {
            let mut c = case(background, 13);
            c.op = c.op.clone().min_transmittance(threshold).unwrap();
            let x = c.arrays();
            let mut rng = rand::rngs::StdRng::seed_from_u64(17);
            let len = c.op.rays() * 3;
            let loss = Photometric {
                target: (0..len).map(|_| rng.gen_range(0.0..1.0)).collect(),
                weight: (0..len).map(|_| rng.gen_range(0.5..2.0)).collect(),
                ch: 3,
            };
            // The two calls, with the upstream computed from the forward's colour.
            let (outs, res) = c.op.evaluate(&x).unwrap();
            let mut upstream = garbage(outs.color.shape());
            for (r, (row, d)) in outs
                .color
                .as_slice()
                .unwrap()
                .chunks(3)
                .zip(upstream.as_slice_mut().unwrap().chunks_mut(3))
                .enumerate()
            {
                loss.grad(r, row, d);
            }
            let up = CompositeUpstream::color(upstream.view());
            for wanted in c.wanted_combinations() {
                let want = c.op.vjp(&x, &res, &up, wanted).unwrap();
                let mut out_bufs = garbage_outputs(&outs);
                let mut grad_bufs = c.garbage_gradients(wanted);
                c.op.evaluate_vjp_into(
                    &x,
                    |r, col, d| loss.grad(r, col, d),
                    &mut out_bufs.buffers(),
                    &mut grad_bufs.buffers(),
                )
                .unwrap();
                let what = format!("{background:?} threshold {threshold} {wanted:?}");
                same_outputs(&out_bufs, &outs, &what);
                // t: no upstream reaches it (depth has none here), so zeros.
                same_gradients_into(&grad_bufs, &want, wanted, &what);
            }
        }
    }
}

#[test]
fn evaluate_vjp_into_refuses_bad_buffers_untouched_and_names_bad_values() {
    let c = case(Background::Shared, 19);
    let x = c.arrays();
    let (outs, _) = c.op.evaluate(&x).unwrap();
    let never = |_: usize, _: &[f32], _: &mut [f32]| panic!("called before the shapes were checked");
    let mut out_bufs = garbage_outputs(&outs);
    let mut short = garbage(&[c.op.samples() - 1]);
    {
        let mut o = out_bufs.buffers();
        let mut gb = CompositeGradientBuffers {
            sigma: Some(short.view_mut()),
            ..Default::default()
        };
        let err = c.op.evaluate_vjp_into(&x, never, &mut o, &mut gb).unwrap_err();
        assert!(matches!(err, OpsError::Shape { op: Op::Composite, .. }), "{err}");
        o.transmittance = None;
        let err =
            c.op.evaluate_vjp_into(&x, never, &mut o, &mut CompositeGradientBuffers::default())
                .unwrap_err();
        assert!(matches!(err, OpsError::Mismatch { op: Op::Composite, .. }), "{err}");
    }
    assert!(output_list(&out_bufs)
        .into_iter()
        .filter_map(|(_, b)| b)
        .chain([&short])
        .all(|b| b.iter().all(|v| v.is_nan())));
    // An invalid value: the same error as evaluate's, the inputs unchanged.
    let mut bad = c.sigma.clone();
    bad[[44]] = -1.0;
    let before = bad.clone();
    let xb = CompositeArrays {
        sigma: bad.view(),
        ..c.arrays()
    };
    let want_err = c.op.evaluate(&xb).unwrap_err().to_string();
    let err =
        c.op.evaluate_vjp_into(
            &xb,
            |_, _, _| {},
            &mut out_bufs.buffers(),
            &mut CompositeGradientBuffers::default(),
        )
        .unwrap_err();
    assert_eq!(err.to_string(), want_err);
    assert_eq!(bad, before);
}
