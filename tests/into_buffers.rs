//! `evaluate_into` / `vjp_into` against `evaluate` / `vjp`: the same bits in buffers that held
//! garbage (so every value must be written, zeros included), and shape errors that write
//! nothing.

use fogray::ops::{Background, Composite, CompositeError};
use ndarray::{Array1, Array2, ArrayD, ArrayViewD, ArrayViewMutD, IxDyn, ShapeBuilder};
use rand::{Rng, SeedableRng};

struct Case {
    op: Composite,
    inputs: Vec<ArrayD<f32>>,
    upstream: Vec<Option<ArrayD<f32>>>,
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
    let mut inputs = vec![
        Array1::from(u(0.0, 8.0, n)).into_dyn(),
        Array1::from(u(0.01, 0.2, n)).into_dyn(),
        Array2::from_shape_vec((n, ch), u(0.0, 1.0, n * ch)).unwrap().into_dyn(),
    ];
    match background {
        Background::None => {}
        Background::Shared => inputs.push(Array1::from(u(0.0, 1.0, ch)).into_dyn()),
        Background::PerRay => inputs.push(
            Array2::from_shape_vec((rays, ch), u(0.0, 1.0, rays * ch))
                .unwrap()
                .into_dyn(),
        ),
    }
    let mut t = u(0.0, 1.0, n);
    t.sort_by(f32::total_cmp);
    inputs.push(Array1::from(t).into_dyn());
    let upstream = [vec![rays, ch], vec![rays], vec![rays], vec![n], vec![n]]
        .into_iter()
        .map(|shape| {
            let len = shape.iter().product();
            Some(ArrayD::from_shape_vec(IxDyn(&shape), u(-1.0, 1.0, len)).unwrap())
        })
        .collect();
    Case { op, inputs, upstream }
}

fn views(a: &[ArrayD<f32>]) -> Vec<ArrayViewD<'_, f32>> {
    a.iter().map(|a| a.view()).collect()
}

fn garbage(shape: &[usize]) -> ArrayD<f32> {
    ArrayD::from_elem(IxDyn(shape), f32::NAN)
}

fn same_bits(got: &ArrayD<f32>, want: &ArrayD<f32>, what: &str) {
    assert_eq!(got.shape(), want.shape(), "{what}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g.to_bits(), w.to_bits(), "{what}[{i}]: {g} vs {w}");
    }
}

#[test]
fn evaluate_into_writes_every_output_as_evaluate_does() {
    for background in [Background::None, Background::Shared, Background::PerRay] {
        let c = case(background, 7);
        let x = views(&c.inputs);
        let (want, want_res) = c.op.evaluate(&x).unwrap();
        let mut bufs: Vec<ArrayD<f32>> = want.iter().map(|w| garbage(w.shape())).collect();
        let mut out: Vec<ArrayViewMutD<'_, f32>> = bufs.iter_mut().map(|b| b.view_mut()).collect();
        let res = c.op.evaluate_into(&x, &mut out).unwrap();
        for (k, (g, w)) in bufs.iter().zip(&want).enumerate() {
            same_bits(g, w, &format!("{background:?} output {k}"));
        }
        // The residuals drive the same backward.
        let g = views_opt(&c.upstream);
        let needs = vec![true; x.len()];
        let a = c.op.vjp(&x, &res, &g, &needs).unwrap();
        let b = c.op.vjp(&x, &want_res, &g, &needs).unwrap();
        for (a, b) in a.iter().zip(&b) {
            same_bits(a.as_ref().unwrap(), b.as_ref().unwrap(), "vjp from either residuals");
        }
    }
}

fn views_opt(a: &[Option<ArrayD<f32>>]) -> Vec<Option<ArrayViewD<'_, f32>>> {
    a.iter().map(|a| a.as_ref().map(|a| a.view())).collect()
}

#[test]
fn vjp_into_writes_every_wanted_gradient_as_vjp_does_with_zeros_where_nothing_reaches() {
    for background in [Background::None, Background::Shared, Background::PerRay] {
        let c = case(background, 11);
        let x = views(&c.inputs);
        let (_, res) = c.op.evaluate(&x).unwrap();
        // All upstreams; then no colour upstream (colour and background gradients are zero);
        // then only colour (the t gradient is zero).
        let mut no_color = c.upstream.clone();
        no_color[0] = None;
        let mut only_color = c.upstream.clone();
        for g in &mut only_color[1..] {
            *g = None;
        }
        for upstream in [&c.upstream, &no_color, &only_color] {
            let g = views_opt(upstream);
            for skip in 0..x.len() {
                // Every gradient wanted but one, in turn.
                let needs: Vec<bool> = (0..x.len()).map(|i| i != skip).collect();
                let want = c.op.vjp(&x, &res, &g, &needs).unwrap();
                let mut bufs: Vec<Option<ArrayD<f32>>> =
                    (0..x.len()).map(|i| needs[i].then(|| garbage(x[i].shape()))).collect();
                let mut out: Vec<Option<ArrayViewMutD<'_, f32>>> =
                    bufs.iter_mut().map(|b| b.as_mut().map(|b| b.view_mut())).collect();
                c.op.vjp_into(&x, &res, &g, &mut out).unwrap();
                for i in 0..x.len() {
                    let what = format!("{background:?} gradient {i}, skip {skip}");
                    match (&bufs[i], &want[i]) {
                        (None, _) => assert!(!needs[i], "{what}"),
                        (Some(got), Some(w)) => same_bits(got, w, &what),
                        (Some(got), None) => assert!(got.iter().all(|&v| v.to_bits() == 0), "{what}: zeros"),
                    }
                }
            }
        }
    }
}

#[test]
fn buffers_of_the_wrong_shape_or_layout_are_refused_and_left_untouched() {
    let c = case(Background::Shared, 3);
    let x = views(&c.inputs);
    let (want, res) = c.op.evaluate(&x).unwrap();
    // One buffer too few; then a colour buffer of the wrong shape; then a strided one.
    let mut bufs: Vec<ArrayD<f32>> = want.iter().map(|w| garbage(w.shape())).collect();
    let mut out: Vec<ArrayViewMutD<'_, f32>> = bufs.iter_mut().skip(1).map(|b| b.view_mut()).collect();
    assert!(matches!(
        c.op.evaluate_into(&x, &mut out),
        Err(CompositeError::Shape { .. })
    ));
    let rays = c.op.rays();
    let mut wrong = garbage(&[rays + 1, 3]);
    let mut strided = ArrayD::from_elem(IxDyn(&[rays, 3]).f(), f32::NAN);
    for bad in [&mut wrong, &mut strided] {
        let mut out: Vec<ArrayViewMutD<'_, f32>> = vec![bad.view_mut()];
        out.extend(bufs.iter_mut().skip(1).map(|b| b.view_mut()));
        let err = c.op.evaluate_into(&x, &mut out).unwrap_err();
        assert!(matches!(err, CompositeError::Shape { .. }), "{err}");
    }
    assert!(bufs
        .iter()
        .chain([&wrong, &strided])
        .all(|b| b.iter().all(|v| v.is_nan())));
    // The backward: a sigma gradient buffer of the wrong length, and one entry too few.
    let g = views_opt(&c.upstream);
    let mut short = garbage(&[c.op.samples() - 1]);
    let mut color = garbage(x[2].shape());
    let mut out = vec![Some(short.view_mut()), None, Some(color.view_mut()), None, None];
    assert!(matches!(
        c.op.vjp_into(&x, &res, &g, &mut out),
        Err(CompositeError::Shape { .. })
    ));
    out.pop();
    assert!(matches!(
        c.op.vjp_into(&x, &res, &g, &mut out),
        Err(CompositeError::Shape { .. })
    ));
    drop(out);
    assert!(short.iter().chain(color.iter()).all(|v| v.is_nan()));
}

#[test]
fn an_invalid_value_is_named_as_by_evaluate_and_the_inputs_stay_unchanged() {
    let mut c = case(Background::Shared, 5);
    c.inputs[0][[44]] = -1.0;
    let before = c.inputs.clone();
    let x = views(&c.inputs);
    let want = c.op.evaluate(&x).unwrap_err();
    let (rays, n) = (c.op.rays(), c.op.samples());
    let mut bufs: Vec<ArrayD<f32>> = [vec![rays, 3], vec![rays], vec![rays], vec![n], vec![n]]
        .iter()
        .map(|s| garbage(s))
        .collect();
    let mut out: Vec<ArrayViewMutD<'_, f32>> = bufs.iter_mut().map(|b| b.view_mut()).collect();
    assert_eq!(c.op.evaluate_into(&x, &mut out).unwrap_err(), want);
    assert!(
        matches!(want, CompositeError::InvalidSample { ray: 2, sample: 39, .. }),
        "{want}"
    );
    assert_eq!(c.inputs, before);
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
            let x = views(&c.inputs);
            let mut rng = rand::rngs::StdRng::seed_from_u64(17);
            let len = c.op.rays() * 3;
            let loss = Photometric {
                target: (0..len).map(|_| rng.gen_range(0.0..1.0)).collect(),
                weight: (0..len).map(|_| rng.gen_range(0.5..2.0)).collect(),
                ch: 3,
            };
            // The two calls, with the upstream computed from the forward's colour.
            let (outs, res) = c.op.evaluate(&x).unwrap();
            let mut upstream = garbage(outs[0].shape());
            for (r, (row, d)) in outs[0]
                .as_slice()
                .unwrap()
                .chunks(3)
                .zip(upstream.as_slice_mut().unwrap().chunks_mut(3))
                .enumerate()
            {
                loss.grad(r, row, d);
            }
            let mut g: Vec<Option<ArrayViewD<'_, f32>>> = vec![None; outs.len()];
            g[0] = Some(upstream.view());
            for skip in 0..=x.len() {
                // Every gradient wanted, then all but one in turn.
                let needs: Vec<bool> = (0..x.len()).map(|i| i != skip).collect();
                let want = c.op.vjp(&x, &res, &g, &needs).unwrap();
                let mut out_bufs: Vec<ArrayD<f32>> = outs.iter().map(|o| garbage(o.shape())).collect();
                let mut grad_bufs: Vec<Option<ArrayD<f32>>> =
                    (0..x.len()).map(|i| needs[i].then(|| garbage(x[i].shape()))).collect();
                let mut o: Vec<ArrayViewMutD<'_, f32>> = out_bufs.iter_mut().map(|b| b.view_mut()).collect();
                let mut gb: Vec<Option<ArrayViewMutD<'_, f32>>> =
                    grad_bufs.iter_mut().map(|b| b.as_mut().map(|b| b.view_mut())).collect();
                c.op.evaluate_vjp_into(&x, |r, col, d| loss.grad(r, col, d), &mut o, &mut gb)
                    .unwrap();
                drop((o, gb));
                let what = format!("{background:?} threshold {threshold} skip {skip}");
                for (k, (got, w)) in out_bufs.iter().zip(&outs).enumerate() {
                    same_bits(got, w, &format!("{what}: output {k}"));
                }
                for i in 0..x.len() {
                    match (&grad_bufs[i], &want[i]) {
                        (None, _) => assert!(!needs[i]),
                        (Some(got), Some(w)) => same_bits(got, w, &format!("{what}: gradient {i}")),
                        // t: no upstream reaches it (depth has none here).
                        (Some(got), None) => assert!(got.iter().all(|&v| v.to_bits() == 0), "{what}: {i} zeros"),
                    }
                }
            }
        }
    }
}

#[test]
fn evaluate_vjp_into_refuses_bad_buffers_untouched_and_names_bad_values() {
    let c = case(Background::Shared, 19);
    let x = views(&c.inputs);
    let (outs, _) = c.op.evaluate(&x).unwrap();
    let never = |_: usize, _: &[f32], _: &mut [f32]| panic!("called before the shapes were checked");
    let mut out_bufs: Vec<ArrayD<f32>> = outs.iter().map(|o| garbage(o.shape())).collect();
    let mut short = garbage(&[c.op.samples() - 1]);
    {
        let mut o: Vec<ArrayViewMutD<'_, f32>> = out_bufs.iter_mut().map(|b| b.view_mut()).collect();
        let mut gb = vec![Some(short.view_mut()), None, None, None, None];
        let err = c.op.evaluate_vjp_into(&x, never, &mut o, &mut gb).unwrap_err();
        assert!(matches!(err, CompositeError::Shape { .. }), "{err}");
        let mut gb: Vec<Option<ArrayViewMutD<'_, f32>>> = (1..x.len()).map(|_| None).collect();
        let err = c.op.evaluate_vjp_into(&x, never, &mut o, &mut gb).unwrap_err();
        assert!(matches!(err, CompositeError::Shape { .. }), "{err}");
        let mut gb: Vec<Option<ArrayViewMutD<'_, f32>>> = (0..x.len()).map(|_| None).collect();
        o.pop();
        let err = c.op.evaluate_vjp_into(&x, never, &mut o, &mut gb).unwrap_err();
        assert!(matches!(err, CompositeError::Shape { .. }), "{err}");
    }
    assert!(out_bufs.iter().chain([&short]).all(|b| b.iter().all(|v| v.is_nan())));
    // An invalid value: the same error as evaluate's, the inputs unchanged.
    let mut bad = c.inputs.clone();
    bad[0][[44]] = -1.0;
    let before = bad.clone();
    let xb = views(&bad);
    let want_err = c.op.evaluate(&xb).unwrap_err().to_string();
    let mut o: Vec<ArrayViewMutD<'_, f32>> = out_bufs.iter_mut().map(|b| b.view_mut()).collect();
    let mut gb: Vec<Option<ArrayViewMutD<'_, f32>>> = (0..x.len()).map(|_| None).collect();
    let err = c.op.evaluate_vjp_into(&xb, |_, _, _| {}, &mut o, &mut gb).unwrap_err();
    assert_eq!(err.to_string(), want_err);
    assert_eq!(bad, before);
}
