//! The exact render against hand-derived values and brute-force quadrature.

use fogray_grid::exact::*;
use fogray_grid::scene::{Cuboid, Primitive, Scene, Sphere};

fn sphere(center: [f64; 3], radius: f64, density: f64, color: [f64; 3]) -> Primitive {
    Primitive::Sphere(Sphere {
        center,
        radius,
        density,
        color,
    })
}

fn cuboid(min: [f64; 3], max: [f64; 3], density: f64, color: [f64; 3]) -> Primitive {
    Primitive::Box(Cuboid {
        min,
        max,
        density,
        color,
    })
}

fn scene(background: [f64; 3], primitives: Vec<Primitive>) -> Scene {
    Scene { background, primitives }
}

fn close(got: f64, want: f64, tol: f64) {
    assert!(
        (got - want).abs() <= tol * want.abs().max(1.0),
        "got {got}, want {want}"
    );
}

#[test]
fn a_sphere_through_its_centre_transmits_exp_minus_2_r_s() {
    let (r, s, c, bg) = (0.45, 40.0, [0.85, 0.3, 0.2], [1.0, 0.5, 0.0]);
    let sc = scene(bg, vec![sphere([0.1, -0.2, 0.3], r, s, c)]);
    // From (0.1, -0.2, -2.7) straight up the z axis through the centre: a chord of 2r.
    let px = render_ray(
        &sc,
        &Ray {
            origin: [0.1, -0.2, -2.7],
            direction: [0.0, 0.0, 1.0],
        },
    );
    let t = (-2.0 * r * s).exp();
    close(px.transmittance, t, 1e-13);
    for k in 0..3 {
        close(px.color[k], c[k] * (1.0 - t) + bg[k] * t, 1e-15);
    }
}

#[test]
fn the_expected_depth_of_a_slab_is_2_minus_3_over_e() {
    // Density 1 on depths [1, 2]: the integral of t e^-(t - 1) over [1, 2] is
    // [-t e^-(t - 1)] + [-e^-(t - 1)] from 1 to 2 = (1 - 2/e) + (1 - 1/e) = 2 - 3/e.
    let sc = scene([0.0; 3], vec![cuboid([-1.0; 3], [1.0, 1.0, 0.0], 1.0, [1.0; 3])]);
    let px = render_ray(
        &sc,
        &Ray {
            origin: [0.5, 0.5, -2.0],
            direction: [0.0, 0.0, 1.0],
        },
    );
    close(px.depth, 2.0 - 3.0 / std::f64::consts::E, 1e-15);
    let sc = scene(
        [0.0; 3],
        vec![cuboid([-1.0, -1.0, -1.5], [1.0, 1.0, -1.0], 2.0, [1.0; 3])],
    );
    let px = render_ray(
        &sc,
        &Ray {
            origin: [0.5, 0.5, -2.0],
            direction: [0.0, 0.0, 1.0],
        },
    );
    // Density 2 on [0.5, 1]: alpha = 1 - e^-1, so 0.5 alpha + alpha / 2 - 0.5 e^-1 = 1 - 1.5/e.
    close(px.depth, 1.0 - 1.5 / std::f64::consts::E, 1e-15);
}

#[test]
fn an_off_centre_chord_and_a_diagonal_through_a_box() {
    // Distance 0.3 from the centre of a sphere of radius 0.5: chord 2 sqrt(0.25 - 0.09) = 0.8.
    let sc = scene([0.0; 3], vec![sphere([0.0; 3], 0.5, 3.0, [1.0; 3])]);
    let px = render_ray(
        &sc,
        &Ray {
            origin: [0.3, -5.0, 0.0],
            direction: [0.0, 1.0, 0.0],
        },
    );
    close(px.transmittance, (-0.8f64 * 3.0).exp(), 1e-14);
    // The unit cube's main diagonal has length sqrt 3; the direction here is not unit, so
    // depth is measured in units of |direction| = sqrt 3 and the cube spans one unit.
    let sc = scene([0.0; 3], vec![cuboid([0.0; 3], [1.0; 3], 2.0, [1.0; 3])]);
    let px = render_ray(
        &sc,
        &Ray {
            origin: [-1.0; 3],
            direction: [1.0; 3],
        },
    );
    close(px.transmittance, (-2.0f64).exp(), 1e-14);
    // Parallel to the x faces and outside them: a miss (no 0 * inf = NaN).
    let miss = Ray {
        origin: [1.5, 0.5, -3.0],
        direction: [0.0, 0.0, 1.0],
    };
    assert_eq!(render_ray(&sc, &miss).transmittance, 1.0);
    // Starting inside: only the part ahead counts, 0.75 of the cube's height.
    let inside = Ray {
        origin: [0.5, 0.5, 0.25],
        direction: [0.0, 0.0, 1.0],
    };
    close(render_ray(&sc, &inside).transmittance, (-1.5f64).exp(), 1e-14);
    // A cube behind the ray is not seen.
    let away = Ray {
        origin: [0.5, 0.5, 2.0],
        direction: [0.0, 0.0, 1.0],
    };
    assert_eq!(render_ray(&sc, &away).transmittance, 1.0);
}

#[test]
fn overlapping_densities_add_and_colours_mix_by_density() {
    // Along x: A on [-0.5, 0.5] (density 2, red), B on [0, 1] (density 3, blue). The pieces
    // are [-0.5, 0] (2, red), [0, 0.5] (5, (2 red + 3 blue) / 5) and [0.5, 1] (3, blue), of
    // optical depth 1, 2.5 and 1.5, so with background g
    // C = (1 - e^-1) red + e^-1 (1 - e^-2.5) mix + e^-3.5 (1 - e^-1.5) blue + e^-5 g.
    let (red, blue, g) = ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]);
    let a = cuboid([-0.5, -1.0, -1.0], [0.5, 1.0, 1.0], 2.0, red);
    let b = cuboid([0.0, -1.0, -1.0], [1.0, 1.0, 1.0], 3.0, blue);
    let ray = Ray {
        origin: [-3.0, 0.1, 0.2],
        direction: [1.0, 0.0, 0.0],
    };
    let e = |x: f64| (-x).exp();
    let (w_red, w_mix, w_blue) = (1.0 - e(1.0), e(1.0) * (1.0 - e(2.5)), e(3.5) * (1.0 - e(1.5)));
    let want = [w_red + w_mix * 0.4, e(5.0), w_mix * 0.6 + w_blue];
    for order in [vec![a.clone(), b.clone()], vec![b, a]] {
        let px = render_ray(&scene(g, order), &ray);
        for (got, want) in px.color.iter().zip(want) {
            close(*got, want, 1e-15);
        }
        close(px.transmittance, e(5.0), 1e-15);
    }
}

#[test]
fn thin_media_keep_their_opacity_where_one_minus_exp_cancels() {
    // Optical depth 1e-12 across the sphere: C = -expm1(-1e-12) = 1e-12 (1 - 5e-13).
    let sc = scene([0.0; 3], vec![sphere([0.0; 3], 0.5, 1e-12, [1.0; 3])]);
    let px = render_ray(
        &sc,
        &Ray {
            origin: [0.0, 0.0, -2.0],
            direction: [0.0, 0.0, 1.0],
        },
    );
    let want = 1e-12 * (1.0 - 5e-13);
    assert!((px.color[0] - want).abs() < 1e-12 * want, "{}", px.color[0]);
    // The textbook 1 - exp(-tau) loses a good part of its digits here.
    let naive = 1.0 - (-1e-12f64).exp();
    assert!((naive - want).abs() > 1e-6 * want);
}

#[test]
fn a_small_far_sphere_keeps_its_chord() {
    // A sphere of radius 1e-4 at distance 1e4 along an oblique direction, passed at 0.6 r from
    // its centre: the chord is 2 sqrt(r^2 - (0.6 r)^2) = 1.6 r.
    let n = 14f64.sqrt();
    let d = [1.0 / n, 2.0 / n, 3.0 / n];
    let perp = [2.0 / 5f64.sqrt(), -1.0 / 5f64.sqrt(), 0.0]; // d . perp = 0
    let (r, h, far) = (1e-4, 0.6e-4, 1e4);
    let center = [0, 1, 2].map(|k| far * d[k] + h * perp[k]);
    let s = Sphere {
        center,
        radius: r,
        density: 1.0,
        color: [1.0; 3],
    };
    let ray = Ray {
        origin: [0.0; 3],
        direction: d,
    };
    let span = sphere_span(&s, &ray).unwrap();
    close((span.exit - span.enter) / (1.6 * r), 1.0, 1e-6);
    // The textbook discriminant b^2 - c (|d| = 1) is lost to cancellation here.
    let b = -(0..3).map(|k| center[k] * d[k]).sum::<f64>();
    let c = (0..3).map(|k| center[k] * center[k]).sum::<f64>() - r * r;
    let naive_chord = 2.0 * (b * b - c).max(0.0).sqrt();
    assert!((naive_chord / (1.6 * r) - 1.0).abs() > 1e-2, "{naive_chord}");
}

/// The medium at a point, by point-in-primitive tests alone (independent of the spans).
fn medium_at(scene: &Scene, p: [f64; 3]) -> (f64, [f64; 3]) {
    let (mut sigma, mut weighted) = (0.0, [0.0; 3]);
    for prim in &scene.primitives {
        let inside = match prim {
            Primitive::Sphere(s) => (0..3).map(|k| (p[k] - s.center[k]).powi(2)).sum::<f64>() <= s.radius * s.radius,
            Primitive::Box(b) => (0..3).all(|k| b.min[k] <= p[k] && p[k] <= b.max[k]),
        };
        if inside {
            sigma += prim.density();
            for (acc, c) in weighted.iter_mut().zip(prim.color()) {
                *acc += prim.density() * c;
            }
        }
    }
    (sigma, weighted)
}

/// Midpoint quadrature over `t in [0, far]` with `n` steps: colour, transmittance and
/// unnormalised expected depth.
fn quadrature(scene: &Scene, ray: &Ray, far: f64, n: usize) -> [f64; 5] {
    let h = far / n as f64;
    let (mut color, mut t_through, mut depth) = ([0.0; 3], 1.0, 0.0);
    for i in 0..n {
        let t = (i as f64 + 0.5) * h;
        let p = [0, 1, 2].map(|k| ray.origin[k] + t * ray.direction[k]);
        let (sigma, weighted) = medium_at(scene, p);
        if sigma > 0.0 {
            let alpha = 1.0 - (-sigma * h).exp();
            for (acc, w) in color.iter_mut().zip(weighted) {
                *acc += t_through * alpha * w / sigma;
            }
            depth += t_through * alpha * t;
            t_through *= 1.0 - alpha;
        }
    }
    let bg = scene.background;
    [0, 1, 2, 3, 4].map(|k| match k {
        0..=2 => color[k] + t_through * bg[k],
        3 => t_through,
        _ => depth,
    })
}

#[test]
fn brute_force_quadrature_converges_to_the_exact_render() {
    // The default scene's primitives at a twentieth of their density, so that every boundary
    // moves the result (through a fully opaque sphere the colour hardly depends on where it
    // starts, and the quadrature would look better than it is).
    let mut sc = Scene::default();
    for p in &mut sc.primitives {
        match p {
            Primitive::Sphere(s) => s.density /= 20.0,
            Primitive::Box(b) => b.density /= 20.0,
        }
    }
    let eye = [2.1, -1.6, 1.3];
    // 27 rays through a lattice of points spread over the scene.
    let targets: Vec<[f64; 3]> = (0..27)
        .map(|i| [i % 3, i / 3 % 3, i / 9].map(|k| -0.6 + 0.55 * k as f64 + 0.05 * (i % 4) as f64))
        .collect();
    let rays: Vec<Ray> = targets
        .iter()
        .map(|t| {
            let d = [0, 1, 2].map(|k| t[k] - eye[k]);
            let n = (0..3).map(|k| d[k] * d[k]).sum::<f64>().sqrt();
            Ray {
                origin: eye,
                direction: d.map(|x| x / n),
            }
        })
        .collect();
    // |eye| < 3 and the scene lies within sqrt 3 of the origin: depth 5 covers it.
    let far = 5.0;
    let errors: Vec<f64> = [1_000, 10_000, 100_000]
        .iter()
        .map(|&n| {
            rays.iter()
                .map(|ray| {
                    let exact = render_ray(&sc, ray);
                    let q = quadrature(&sc, ray, far, n);
                    let want = [
                        exact.color[0],
                        exact.color[1],
                        exact.color[2],
                        exact.transmittance,
                        exact.depth,
                    ];
                    (0..5).map(|k| (q[k] - want[k]).abs()).fold(0.0, f64::max)
                })
                .sum::<f64>()
                / rays.len() as f64
        })
        .collect();
    // Midpoint quadrature of a piecewise-constant medium errs only in the steps that straddle
    // a boundary, so its error (here the mean over the rays of the worst channel) falls like
    // the step, by about 10 per decade of samples.
    assert!(errors[0] > 5.0 * errors[1] && errors[1] > 5.0 * errors[2], "{errors:?}");
    assert!(errors[2] < 5e-5, "{errors:?}");
}
