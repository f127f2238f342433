//! 3D Gaussian splatting, forward: the projection and the pixel of a round splat facing the
//! camera against their closed forms, the fused op against the plain reference renderer of
//! `splat_common` (f64 to 1e-12, f32 to 1e-6), bitwise the same image and gradients on 1 and
//! 2 threads, and the errors.

use fogray_ops::splat::{project, SplatArrays, SplatRender, SplatVars};
use fogray_ops::{Intrinsics, Op, OpsError, PinholeCamera};
use fogray_tape::{Float, Tape};
use ndarray::{arr1, arr2, Array2};

use crate::splat_common::{camera, ref_render, scene, Scene};

fn arrays<F: Float>(s: &Scene) -> [Array2<F>; 4] {
    let cast = |a: &Array2<f64>| a.mapv(F::lit);
    [cast(&s.means), cast(&s.log_scales), cast(&s.quats), cast(&s.colors)]
}

fn render<F: Float>(op: &SplatRender, s: &Scene) -> Result<Array2<F>, OpsError> {
    let [m, l, q, c] = arrays::<F>(s);
    let logits = s.logits.mapv(F::lit);
    op.render(SplatArrays {
        means: m.view(),
        log_scales: l.view(),
        quats: q.view(),
        opacity_logits: logits.view(),
        colors: c.view(),
    })
}

/// A camera at the origin looking down +z, `size` pixels square, focal length `f`.
fn axis_camera(size: usize, f: f64) -> PinholeCamera {
    let k = Intrinsics {
        fx: f,
        fy: f,
        cx: size as f64 / 2.0,
        cy: size as f64 / 2.0,
        width: size,
        height: size,
    };
    PinholeCamera::look_at(k, [0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]).unwrap()
}

#[test]
fn a_round_splat_facing_the_camera_has_its_closed_form_covariance() {
    // s = 0.1 at z = 5 through f = 40: sigma = f s / z = 0.8 px, so C = 0.64 I + 0.3 I.
    let cam = axis_camera(32, 40.0);
    let (s, z) = (0.1f64, 5.0);
    let q = arr2(&[[0.3, -0.5, 0.7, 0.2]]); // any rotation of a ball is the ball
    let p = project(
        &cam,
        arr2(&[[0.0, 0.0, z]]).view(),
        arr2(&[[s.ln(); 3]]).view(),
        q.view(),
    )
    .unwrap();
    let c = (40.0 * s / z).powi(2) + 0.3;
    let [a, b, cc] = p.conic[0];
    assert!(
        (a - 1.0 / c).abs() < 1e-14 && b.abs() < 1e-14 && (cc - 1.0 / c).abs() < 1e-14,
        "{:?}",
        p.conic[0]
    );
    assert_eq!(p.mean2d[0], [16.0, 16.0]);
    assert_eq!(p.depth[0], z);
    // 3 sqrt(0.94 + sqrt(0.1)) = 3.43, rounded up.
    assert_eq!(p.radius[0], 4);
}

#[test]
fn the_peak_pixel_is_opacity_times_colour_over_the_background() {
    // The mean on the centre of pixel (16, 16): d = 0, alpha = opacity.
    let cam = axis_camera(32, 40.0);
    let z = 5.0;
    let means = arr2(&[[0.5 * z / 40.0, 0.5 * z / 40.0, z]]);
    let bg = [0.2, 0.9, 0.4];
    let op = SplatRender::new(&cam, bg).unwrap();
    for logit in [-2.0f64, 0.0, 1.5] {
        let o = 1.0 / (1.0 + (-logit).exp());
        let s = Scene {
            means: means.clone(),
            log_scales: arr2(&[[0.1f64.ln(); 3]]),
            quats: arr2(&[[1.0, 0.0, 0.0, 0.0]]),
            logits: arr1(&[logit]),
            colors: arr2(&[[0.7, 0.1, 0.3]]),
        };
        let image = render::<f64>(&op, &s).unwrap();
        for ch in 0..3 {
            let want = o * s.colors[[0, ch]] + (1.0 - o) * bg[ch];
            assert!((image[[16 * 32 + 16, ch]] - want).abs() < 1e-15, "{logit} {ch}");
        }
        // A pixel far away sees the background alone.
        assert_eq!(image[[0, 1]], bg[1]);
    }
}

#[test]
fn the_fused_op_is_the_reference_renderer() {
    for (seed, n, w, h) in [(1, 20, 32, 32), (2, 12, 24, 17), (3, 3, 8, 8), (4, 60, 40, 33)] {
        let cam = camera(w, h);
        let s = scene(seed, n);
        let bg = [0.1, 0.5, 0.9];
        let op = SplatRender::new(&cam, bg).unwrap();
        let want = ref_render(&cam, &s, bg);
        let got64 = render::<f64>(&op, &s).unwrap();
        let got32 = render::<f32>(&op, &s).unwrap();
        let (mut e64, mut e32) = (0.0f64, 0.0f64);
        for (p, want) in want.iter().enumerate() {
            for ch in 0..3 {
                e64 = e64.max((got64[[p, ch]] - want[ch]).abs());
                e32 = e32.max((got32[[p, ch]].as_f64() - want[ch]).abs());
            }
        }
        assert!(e64 < 1e-12, "seed {seed}: f64 off by {e64}");
        assert!(e32 < 1e-6, "seed {seed}: f32 off by {e32}");
        // The scene is not empty: some pixel is not the background.
        assert!((0..w * h).any(|p| (got64[[p, 0]] - bg[0]).abs() > 0.1), "seed {seed}");
    }
}

/// The image and the five gradients of a fixed upstream, on `threads` threads.
fn image_and_grads(threads: usize, s: &Scene, op: &SplatRender) -> Vec<Vec<f64>> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let mut tape = Tape::<f64>::new();
        let vars = SplatVars {
            means: tape.param(s.means.clone()),
            log_scales: tape.param(s.log_scales.clone()),
            quats: tape.param(s.quats.clone()),
            opacity_logits: tape.param(s.logits.clone()),
            colors: tape.param(s.colors.clone()),
        };
        let image = op.apply(&mut tape, &vars).unwrap();
        let (w, h) = op.size();
        let weights = tape.constant(Array2::from_shape_fn((w * h, 3), |(p, c)| {
            ((p * 7 + c * 3) % 11) as f64 - 5.0
        }));
        let weighted = tape.mul(image, weights).unwrap();
        let loss = tape.sum(weighted).unwrap();
        let grads = tape.backward(loss).unwrap();
        let mut out = vec![tape.value(image).unwrap().iter().copied().collect()];
        for v in [
            vars.means,
            vars.log_scales,
            vars.quats,
            vars.opacity_logits,
            vars.colors,
        ] {
            out.push(grads.get(v).unwrap().iter().copied().collect());
        }
        out
    })
}

#[test]
fn one_and_two_threads_give_the_same_bits() {
    // 600 splats over 64x48 pixels: 12 tiles, many splats in several.
    let cam = camera(64, 48);
    let s = scene(7, 600);
    let op = SplatRender::new(&cam, [0.3, 0.3, 0.3]).unwrap();
    let one = image_and_grads(1, &s, &op);
    let two = image_and_grads(2, &s, &op);
    for (k, (a, b)) in one.iter().zip(&two).enumerate() {
        let same = a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "output {k} differs");
        assert!(a.iter().any(|&x| x != 0.0), "output {k} is all zeros");
    }
}

#[test]
fn bad_input_is_a_named_error() {
    let cam = camera(16, 16);
    let op = SplatRender::new(&cam, [0.0; 3]).unwrap();
    let s = scene(1, 4);
    let mut bad = s.clone();
    bad.log_scales = Array2::zeros((4, 2));
    assert!(matches!(
        render::<f64>(&op, &bad),
        Err(OpsError::Shape { what: "log-scales", .. })
    ));
    let mut bad = s.clone();
    bad.quats[[2, 0]] = f64::NAN;
    let e = render::<f64>(&op, &bad).unwrap_err();
    assert!(e.to_string().starts_with("splat: row 2, column 0: quaternion"), "{e}");
    let mut bad = s.clone();
    bad.quats.row_mut(3).fill(0.0);
    assert!(render::<f64>(&op, &bad)
        .unwrap_err()
        .to_string()
        .contains("quaternion length"));
    let mut bad = s.clone();
    bad.logits = arr1(&[0.0; 3]);
    assert!(matches!(
        render::<f64>(&op, &bad),
        Err(OpsError::Shape {
            what: "opacity logits",
            ..
        })
    ));
    let mut bad = s.clone();
    bad.colors[[1, 2]] = f64::INFINITY;
    assert!(render::<f64>(&op, &bad)
        .unwrap_err()
        .to_string()
        .contains("row 1, column 2: colour"));
    // A bound on the lists' length below what the scene makes.
    let tight = op.with_max_intersections(0);
    let e = render::<f64>(&tight, &scene(1, 20)).unwrap_err();
    assert!(
        matches!(
            e,
            OpsError::TooManyIntersections {
                op: Op::Splat,
                limit: 0,
                ..
            }
        ),
        "{e}"
    );
    assert!(SplatRender::new(&cam, [0.0, f64::NAN, 0.0]).is_err());
    let lens = cam
        .clone()
        .with_distortion(fogray_ops::LensDistortion {
            k1: 0.1,
            ..fogray_ops::LensDistortion::NONE
        })
        .unwrap();
    assert!(matches!(
        SplatRender::new(&lens, [0.0; 3]),
        Err(OpsError::Mismatch { what: "camera", .. })
    ));
    // Through a tape: the same error, typed, and the tape unchanged.
    let mut tape = Tape::<f64>::new();
    let vars = SplatVars {
        means: tape.param(s.means.clone()),
        log_scales: tape.param(Array2::zeros((4, 2))),
        quats: tape.param(s.quats.clone()),
        opacity_logits: tape.param(s.logits.clone()),
        colors: tape.param(s.colors.clone()),
    };
    let e = op.apply(&mut tape, &vars).unwrap_err();
    assert!(
        matches!(e.downcast_ref::<OpsError>(), Some(OpsError::Shape { .. })),
        "{e}"
    );
}
