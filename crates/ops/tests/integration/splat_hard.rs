//! 3D Gaussian splatting, hard cases: splats behind the camera, a splat of scale `e^-30`, a
//! pixel behind 10,000 splats (the transmittance floor is reached and the backward stops where
//! the forward did), and opacity 1 (alpha clamped at 0.99).

use fogray_ops::splat::{bin, project, rasterize, SplatArrays, SplatGradients, SplatRender, ALPHA_MAX, T_MIN};
use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::{arr1, arr2, concatenate, Array1, Array2, Axis};
use rand::{Rng, SeedableRng};

use crate::splat_common::{camera, scene, Scene};

fn view(s: &Scene) -> SplatArrays<'_, f64> {
    SplatArrays {
        means: s.means.view(),
        log_scales: s.log_scales.view(),
        quats: s.quats.view(),
        opacity_logits: s.logits.view(),
        colors: s.colors.view(),
    }
}

/// The image and the gradients of `sum(weights * image)`.
fn run(op: &SplatRender, s: &Scene) -> (Array2<f64>, SplatGradients<f64>) {
    let image = op.render(view(s)).unwrap();
    let weights = Array2::from_shape_fn(image.dim(), |(p, c)| 1.0 + ((p + c) % 3) as f64);
    (image, op.vjp(view(s), weights.view()).unwrap())
}

fn all_finite(g: &SplatGradients<f64>) -> bool {
    [&g.means, &g.log_scales, &g.quats, &g.colors]
        .iter()
        .all(|a| a.iter().all(|v| v.is_finite()))
        && g.opacity_logits.iter().all(|v| v.is_finite())
}

fn join(a: &Scene, b: &Scene) -> Scene {
    let cat = |x: &Array2<f64>, y: &Array2<f64>| concatenate(Axis(0), &[x.view(), y.view()]).unwrap();
    Scene {
        means: cat(&a.means, &b.means),
        log_scales: cat(&a.log_scales, &b.log_scales),
        quats: cat(&a.quats, &b.quats),
        logits: concatenate(Axis(0), &[a.logits.view(), b.logits.view()]).unwrap(),
        colors: cat(&a.colors, &b.colors),
    }
}

#[test]
fn splats_behind_the_camera_change_nothing_and_get_no_gradient() {
    let cam = camera(24, 24);
    let op = SplatRender::new(&cam, [0.5; 3]).unwrap();
    let front = scene(41, 10);
    // The camera is at z = -4 looking at +z: these are behind it, or on its plane.
    let mut behind = scene(42, 3);
    for (i, z) in [-6.0, -4.0, -3.995].into_iter().enumerate() {
        behind.means[[i, 2]] = z;
        behind.means[[i, 0]] = 0.4;
        behind.means[[i, 1]] = -0.3;
        behind.logits[i] = 5.0;
    }
    let (alone, g_alone) = run(&op, &front);
    let (with, g_with) = run(&op, &join(&front, &behind));
    assert_eq!(alone, with);
    assert_eq!(g_alone.means, g_with.means.slice(ndarray::s![..10, ..]));
    for g in [&g_with.means, &g_with.log_scales, &g_with.quats, &g_with.colors] {
        assert!(g.slice(ndarray::s![10.., ..]).iter().all(|&v| v == 0.0));
    }
    assert!(g_with.opacity_logits.slice(ndarray::s![10..]).iter().all(|&v| v == 0.0));
}

#[test]
fn a_splat_of_scale_e_minus_30_is_the_dilation_alone() {
    let k = Intrinsics {
        fx: 30.0,
        fy: 30.0,
        cx: 8.0,
        cy: 8.0,
        width: 16,
        height: 16,
    };
    let cam = PinholeCamera::look_at(k, [0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]).unwrap();
    let s = Scene {
        means: arr2(&[[0.01, -0.02, 3.0]]),
        log_scales: arr2(&[[-30.0, -30.0, -30.0]]),
        quats: arr2(&[[0.2, 0.9, -0.1, 0.3]]),
        logits: arr1(&[2.0]),
        colors: arr2(&[[1.0, 0.5, 0.0]]),
    };
    let p = project(&cam, s.means.view(), s.log_scales.view(), s.quats.view()).unwrap();
    // C = 0.3 I (the splat's own variance is 1e-26 px^2).
    assert!((p.conic[0][0] - 1.0 / 0.3).abs() < 1e-12 && p.conic[0][1].abs() < 1e-12);
    let op = SplatRender::new(&cam, [0.0; 3]).unwrap();
    let (image, g) = run(&op, &s);
    assert!(image.iter().all(|v| v.is_finite()) && image.iter().any(|&v| v > 0.1));
    assert!(all_finite(&g));
    // Its size no longer matters: the log-scale's gradient is s^2-small.
    assert!(g.log_scales.iter().all(|v| v.abs() < 1e-20), "{:?}", g.log_scales);
    assert!(g.means.iter().any(|v| v.abs() > 1e-3));
}

/// `n` splats strung along the ray through the centre of pixel (8, 8) of a 16x16 camera at
/// the origin, from depth 2 to 6, with opacities about 0.5.
fn string_of_splats(n: usize) -> (PinholeCamera, Scene) {
    let k = Intrinsics {
        fx: 30.0,
        fy: 30.0,
        cx: 8.0,
        cy: 8.0,
        width: 16,
        height: 16,
    };
    let cam = PinholeCamera::look_at(k, [0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let d = [0.5 / 30.0, 0.5 / 30.0, 1.0];
    let means = Array2::from_shape_fn((n, 3), |(i, c)| d[c] * (2.0 + 4.0 * i as f64 / n as f64));
    let s = Scene {
        means,
        log_scales: Array2::from_shape_fn((n, 3), |_| rng.gen_range(-3.0..-2.0)),
        quats: Array2::from_shape_fn((n, 4), |_| rng.gen_range(-1.0..1.0)),
        logits: Array1::from_shape_fn(n, |_| rng.gen_range(-0.3..0.3)),
        colors: Array2::from_shape_fn((n, 3), |_| rng.gen_range(0.0..1.0)),
    };
    (cam, s)
}

#[test]
fn a_pixel_behind_ten_thousand_splats_stops_at_the_floor_and_so_does_its_backward() {
    let n = 10_000;
    let (cam, s) = string_of_splats(n);
    let proj = project(&cam, s.means.view(), s.log_scales.view(), s.quats.view()).unwrap();
    let tiles = bin(&proj, 16, 16, 1 << 20).unwrap();
    let opacity: Vec<f64> = s.logits.iter().map(|x| 1.0 / (1.0 + (-x).exp())).collect();
    let colors: Vec<[f64; 3]> = (0..n).map(|i| [0, 1, 2].map(|c| s.colors[[i, c]])).collect();
    let raster = rasterize(&proj, &tiles, &opacity, &colors, [0.0; 3]).unwrap();
    let p = 8 * 16 + 8;
    let count = raster.count[p] as usize;
    // Alphas near 0.5: the floor is reached after about a dozen splats.
    assert!(count > 5 && count < 40, "{count}");
    assert!(raster.transmittance[p] >= T_MIN && raster.transmittance[p] < 2e-2);

    let op = SplatRender::new(&cam, [0.0; 3]).unwrap();
    let mut up = Array2::zeros((256, 3));
    up.row_mut(p).fill(1.0);
    let g = op.vjp(view(&s), up.view()).unwrap();
    assert!(all_finite(&g));
    // The splats are in depth order: those past the stop get nothing.
    assert!(g.opacity_logits.iter().skip(count).all(|&v| v == 0.0));
    assert!(g
        .colors
        .rows()
        .into_iter()
        .skip(count)
        .all(|r| r.iter().all(|&v| v == 0.0)));
    assert!(g.opacity_logits[0] != 0.0 && g.opacity_logits[count - 1] != 0.0);
    // And where it is nonzero it is the finite difference of the pixel (which reads the same
    // splats on either side of the step).
    let pixel = |s: &Scene| op.render(view(s)).unwrap().row(p).sum();
    for i in [0, 3, count - 1, count, count + 10] {
        let mut plus = s.clone();
        plus.logits[i] += 1e-6;
        let mut minus = s.clone();
        minus.logits[i] -= 1e-6;
        let fd = (pixel(&plus) - pixel(&minus)) / 2e-6;
        let a = g.opacity_logits[i];
        assert!((a - fd).abs() < 1e-7 + 1e-6 * fd.abs(), "splat {i}: {a} vs {fd}");
    }
}

#[test]
fn opacity_one_is_clamped_at_alpha_0_99_with_a_finite_gradient() {
    let k = Intrinsics {
        fx: 30.0,
        fy: 30.0,
        cx: 8.0,
        cy: 8.0,
        width: 16,
        height: 16,
    };
    let cam = PinholeCamera::look_at(k, [0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]).unwrap();
    let z = 3.0;
    let s = Scene {
        // On the centre of pixel (8, 8).
        means: arr2(&[[0.5 * z / 30.0, 0.5 * z / 30.0, z]]),
        log_scales: arr2(&[[0.05f64.ln(); 3]]),
        quats: arr2(&[[1.0, 0.0, 0.0, 0.0]]),
        logits: arr1(&[40.0]), // sigmoid(40) rounds to 1
        colors: arr2(&[[1.0, 0.0, 0.5]]),
    };
    let bg = [0.0, 1.0, 1.0];
    let op = SplatRender::new(&cam, bg).unwrap();
    let (image, g) = run(&op, &s);
    let p = 8 * 16 + 8;
    for ch in 0..3 {
        let want = ALPHA_MAX * s.colors[[0, ch]] + (1.0 - ALPHA_MAX) * bg[ch];
        assert!((image[[p, ch]] - want).abs() < 1e-15);
    }
    assert!(all_finite(&g));
    // sigmoid'(40) = e^-40: only pixels off the clamp contribute, through that slope.
    assert!(g.opacity_logits[0].abs() < 1e-16);
    // A pixel where the clamp does not hold still moves the mean.
    assert!(g.means.iter().any(|v| v.abs() > 1e-6));
    // At opacity sigmoid(6) = 0.9975 the centre pixels are clamped and the rest are not: the
    // gradient is still the finite difference of the (piecewise smooth) image.
    let mut s6 = s.clone();
    s6.logits[0] = 6.0;
    let (_, g6) = run(&op, &s6);
    let weighted = |s: &Scene| {
        let image = op.render(view(s)).unwrap();
        image
            .indexed_iter()
            .map(|((p, c), v)| v * (1.0 + ((p + c) % 3) as f64))
            .sum::<f64>()
    };
    let mut fds = Vec::new();
    for (which, idx) in [(0, 0), (1, 0), (1, 1), (2, 2)] {
        let (mut plus, mut minus) = (s6.clone(), s6.clone());
        match which {
            0 => (plus.logits[0] += 1e-6, minus.logits[0] -= 1e-6),
            1 => (plus.means[[0, idx]] += 1e-6, minus.means[[0, idx]] -= 1e-6),
            _ => (plus.log_scales[[0, idx]] += 1e-6, minus.log_scales[[0, idx]] -= 1e-6),
        };
        let fd = (weighted(&plus) - weighted(&minus)) / 2e-6;
        let a = [g6.opacity_logits[0], g6.means[[0, idx]], g6.log_scales[[0, idx]]][which];
        assert!((a - fd).abs() < 1e-6 + 1e-5 * fd.abs(), "{which} {idx}: {a} vs {fd}");
        fds.push(fd);
    }
    assert!(fds[0] != 0.0);
}

#[test]
fn an_image_too_large_for_memory_is_refused_before_allocation() {
    let (cam, s) = string_of_splats(3);
    let proj = project(&cam, s.means.view(), s.log_scales.view(), s.quats.view()).unwrap();
    let e = bin(&proj, 1 << 30, 1 << 30, 1 << 20).unwrap_err();
    assert!(
        matches!(
            e,
            fogray_ops::OpsError::Config {
                what: "image size (pixels)",
                ..
            }
        ),
        "{e}"
    );
    assert!(bin(&proj, 0, 16, 1 << 20).is_err());
}
