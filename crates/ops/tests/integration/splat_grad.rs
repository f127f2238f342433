//! 3D Gaussian splatting, backward: the projection's and the rasteriser's hand-written
//! backwards against central finite differences of their own forwards (f64), and the fused op
//! on the tape against the tape's gradcheck.

use fogray_ops::splat::{bin, project, project_vjp, rasterize, rasterize_vjp, Projection, SplatRender, SplatVars};
use fogray_tape::{gradcheck, GradcheckOptions, Tape};
use ndarray::{Array2, ArrayD};
use rand::{Rng, SeedableRng};

use crate::splat_common::{camera, scene};

const EPS: f64 = 1e-6;

/// `|a - b| <= atol + rtol |b|`, or a message naming `what`.
fn close(what: &str, a: f64, b: f64) {
    assert!(
        (a - b).abs() <= 1e-6 + 1e-5 * b.abs(),
        "{what}: analytic {a}, finite differences {b}"
    );
}

#[test]
fn the_projection_backward_is_the_finite_differences_of_its_forward() {
    for (seed, n) in [(11, 8), (12, 20)] {
        let cam = camera(24, 20);
        let s = scene(seed, n);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let gm: Vec<[f64; 2]> = (0..n)
            .map(|_| [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)])
            .collect();
        let gk: Vec<[f64; 3]> = (0..n)
            .map(|_| std::array::from_fn(|_| rng.gen_range(-30.0..30.0)))
            .collect();
        let gd: Vec<f64> = (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        // L = sum of the outputs weighted by the upstream gradients.
        let loss = |m: &Array2<f64>, l: &Array2<f64>, q: &Array2<f64>| -> f64 {
            let p: Projection = project(&cam, m.view(), l.view(), q.view()).unwrap();
            (0..n)
                .filter(|&i| p.radius[i] > 0)
                .map(|i| {
                    gm[i][0] * p.mean2d[i][0]
                        + gm[i][1] * p.mean2d[i][1]
                        + (0..3).map(|k| gk[i][k] * p.conic[i][k]).sum::<f64>()
                        + gd[i] * p.depth[i]
                })
                .sum()
        };
        let g = project_vjp(&cam, s.means.view(), s.log_scales.view(), s.quats.view(), &gm, &gk, &gd).unwrap();
        let mut arrays = [s.means.clone(), s.log_scales.clone(), s.quats.clone()];
        for which in 0..3 {
            for idx in ndarray::indices(arrays[which].dim()) {
                let x = arrays[which][idx];
                arrays[which][idx] = x + EPS;
                let up = loss(&arrays[0], &arrays[1], &arrays[2]);
                arrays[which][idx] = x - EPS;
                let down = loss(&arrays[0], &arrays[1], &arrays[2]);
                arrays[which][idx] = x;
                let fd = (up - down) / (2.0 * EPS);
                let (i, k) = idx;
                let analytic = [g.means[i].get(k), g.log_scales[i].get(k), Some(&g.quats[i][k])][which];
                close(
                    &format!("seed {seed}, input {which} at {idx:?}"),
                    *analytic.unwrap(),
                    fd,
                );
            }
        }
    }
}

#[test]
fn the_rasteriser_backward_is_the_finite_differences_of_its_forward() {
    for (seed, n, w, h) in [(21, 5, 8, 8), (22, 15, 20, 18)] {
        let cam = camera(w, h);
        let s = scene(seed, n);
        let proj = project(&cam, s.means.view(), s.log_scales.view(), s.quats.view()).unwrap();
        let tiles = bin(&proj, w, h, 1 << 20).unwrap();
        let opacity: Vec<f64> = s.logits.iter().map(|x| 1.0 / (1.0 + (-x).exp())).collect();
        let colors: Vec<[f64; 3]> = (0..n).map(|i| [0, 1, 2].map(|c| s.colors[[i, c]])).collect();
        let bg = [0.3, 0.6, 0.1];
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let up: Vec<[f64; 3]> = (0..w * h)
            .map(|_| std::array::from_fn(|_| rng.gen_range(-1.0..1.0)))
            .collect();
        let loss = |p: &Projection, o: &[f64], c: &[[f64; 3]], bg: [f64; 3]| -> f64 {
            let r = rasterize(p, &tiles, o, c, bg).unwrap();
            r.color
                .iter()
                .zip(&up)
                .map(|(a, b)| (0..3).map(|k| a[k] * b[k]).sum::<f64>())
                .sum()
        };
        let raster = rasterize(&proj, &tiles, &opacity, &colors, bg).unwrap();
        let g = rasterize_vjp(&proj, &tiles, &opacity, &colors, bg, &raster, &up).unwrap();
        let fd = |f: &dyn Fn(f64) -> f64| (f(EPS) - f(-EPS)) / (2.0 * EPS);
        for i in 0..n {
            for k in 0..2 {
                let d = fd(&|e| {
                    let mut p = proj.clone();
                    p.mean2d[i][k] += e;
                    loss(&p, &opacity, &colors, bg)
                });
                close(&format!("mean2d[{i}][{k}]"), g.mean2d[i][k], d);
            }
            for k in 0..3 {
                let d = fd(&|e| {
                    let mut p = proj.clone();
                    p.conic[i][k] += e;
                    loss(&p, &opacity, &colors, bg)
                });
                close(&format!("conic[{i}][{k}]"), g.conic[i][k], d);
                let d = fd(&|e| {
                    let mut c = colors.clone();
                    c[i][k] += e;
                    loss(&proj, &opacity, &c, bg)
                });
                close(&format!("color[{i}][{k}]"), g.color[i][k], d);
            }
            let d = fd(&|e| {
                let mut o = opacity.clone();
                o[i] += e;
                loss(&proj, &o, &colors, bg)
            });
            close(&format!("opacity[{i}]"), g.opacity[i], d);
        }
        for k in 0..3 {
            let d = fd(&|e| {
                let mut b = bg;
                b[k] += e;
                loss(&proj, &opacity, &colors, b)
            });
            close(&format!("background[{k}]"), g.background[k], d);
        }
        assert!(g.opacity.iter().any(|&x| x != 0.0));
    }
}

#[test]
fn the_fused_op_passes_gradcheck() {
    for (seed, n, w, h) in [(31, 6, 16, 16), (32, 12, 24, 20)] {
        let cam = camera(w, h);
        let s = scene(seed, n);
        let op = SplatRender::new(&cam, [0.2, 0.4, 0.8]).unwrap();
        let f = |tape: &mut Tape<f64>, v: &[fogray_tape::Var]| {
            let vars = SplatVars {
                means: v[0],
                log_scales: v[1],
                quats: v[2],
                opacity_logits: v[3],
                colors: v[4],
            };
            op.apply(tape, &vars)
        };
        let inputs: Vec<ArrayD<f64>> = vec![
            s.means.clone().into_dyn(),
            s.log_scales.clone().into_dyn(),
            s.quats.clone().into_dyn(),
            s.logits.clone().into_dyn(),
            s.colors.clone().into_dyn(),
        ];
        let opts = GradcheckOptions {
            names: ["means", "log_scales", "quats", "opacity_logits", "colors"]
                .map(String::from)
                .to_vec(),
            ..GradcheckOptions::default()
        };
        let report = gradcheck(f, &inputs, &opts).unwrap();
        if let Err(r) = report.check(1e-6, 1e-5) {
            panic!("seed {seed}: {r}");
        }
    }
}

#[test]
fn the_projection_backward_is_the_taped_twins_to_rounding() {
    use fogray_ops::splat::twin;
    let cam = camera(24, 20);
    for (seed, n) in [(51, 10), (52, 30)] {
        let mut s = scene(seed, n);
        // One splat behind the camera and one beyond the frustum's clamp (far to the side).
        s.means.row_mut(0).assign(&ndarray::arr1(&[0.1, 0.2, -6.0]));
        s.means.row_mut(1).assign(&ndarray::arr1(&[9.0, -7.0, 1.0]));
        let p = project(&cam, s.means.view(), s.log_scales.view(), s.quats.view()).unwrap();
        assert_eq!(p.radius[0], 0);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let gm = Array2::from_shape_fn((n, 2), |_| rng.gen_range(-1.0..1.0));
        let gk = Array2::from_shape_fn((n, 3), |_| rng.gen_range(-30.0..30.0));
        // Culled splats get no depth gradient from the fused backward.
        let gd = ndarray::Array1::from_shape_fn(n, |i| if p.radius[i] > 0 { rng.gen_range(-1.0..1.0) } else { 0.0 });

        let mut tape = Tape::<f64>::new();
        let (m, l, q) = (
            tape.param(s.means.clone()),
            tape.param(s.log_scales.clone()),
            tape.param(s.quats.clone()),
        );
        let out = twin::projection(&mut tape, &cam, m, l, q).unwrap();
        let (wm, wk, wd) = (
            tape.constant(gm.clone()),
            tape.constant(gk.clone()),
            tape.constant(gd.clone()),
        );
        let terms = [
            tape.mul(out.mean2d, wm).unwrap(),
            tape.mul(out.conic, wk).unwrap(),
            tape.mul(out.depth, wd).unwrap(),
        ];
        let sums: Vec<_> = terms.iter().map(|&t| tape.sum(t).unwrap()).collect();
        let a = tape.add(sums[0], sums[1]).unwrap();
        let loss = tape.add(a, sums[2]).unwrap();
        let grads = tape.backward(loss).unwrap();

        let mean2d = tape.value(out.mean2d).unwrap().to_owned();
        let conic = tape.value(out.conic).unwrap().to_owned();
        for i in 0..n {
            for k in 0..2 {
                assert!((mean2d[[i, k]] - p.mean2d[i][k]).abs() < 1e-12, "mean2d {i} {k}");
            }
            for k in 0..3 {
                let (a, b) = (conic[[i, k]], p.conic[i][k]);
                assert!((a - b).abs() < 1e-12 * (1.0 + b.abs()), "conic {i} {k}: {a} vs {b}");
            }
        }
        let gm_rows: Vec<[f64; 2]> = gm.rows().into_iter().map(|r| [r[0], r[1]]).collect();
        let gk_rows: Vec<[f64; 3]> = gk.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
        let fused = project_vjp(
            &cam,
            s.means.view(),
            s.log_scales.view(),
            s.quats.view(),
            &gm_rows,
            &gk_rows,
            gd.as_slice().unwrap(),
        )
        .unwrap();
        let check = |what: &str, taped: ndarray::ArrayViewD<f64>, fused: Vec<f64>| {
            let scale = fused.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (j, (a, b)) in taped.iter().zip(&fused).enumerate() {
                assert!((a - b).abs() <= 1e-11 * scale, "{what}[{j}]: taped {a}, fused {b}");
            }
        };
        check("means", grads.get(m).unwrap().view(), fused.means.concat());
        check("log_scales", grads.get(l).unwrap().view(), fused.log_scales.concat());
        check("quats", grads.get(q).unwrap().view(), fused.quats.concat());
    }
}
