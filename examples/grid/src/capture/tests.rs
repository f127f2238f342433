use super::*;
use crate::scene::{Primitive, Sphere};

fn norm(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

#[test]
fn a_ray_meets_the_wall_on_the_sphere_ahead_of_it() {
    let radius = 8.0;
    let origins = [[0.0, 0.0, 0.0], [2.5, -1.0, 1.2], [7.9, 0.0, 0.0], [-3.0, 2.0, -0.5]];
    let directions = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.3, -0.8, 0.52],
        [-0.6, 0.1, -0.2],
        [0.0, 1.0, 1e-9],
    ];
    for o in origins {
        for d in directions {
            let ray = Ray {
                origin: o,
                direction: d,
            };
            let u = wall_direction(&ray, radius);
            assert!((norm(u) - 1.0).abs() < 1e-14, "{o:?} {d:?}: |u| = {}", norm(u));
            // The point lies on the ray, ahead of its origin: p - o = t d with t > 0.
            let p = u.map(|v| v * radius);
            let t = (0..3).map(|a| (p[a] - o[a]) * d[a]).sum::<f64>() / norm(d).powi(2);
            assert!(t > 0.0, "{o:?} {d:?}: t = {t}");
            for a in 0..3 {
                assert!((o[a] + t * d[a] - p[a]).abs() < 1e-12, "{o:?} {d:?}");
            }
        }
    }
}

#[test]
fn the_wall_stays_inside_0_1() {
    for i in 0..2000 {
        // A Fibonacci lattice over the sphere.
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / 2000.0;
        let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let r = (1.0 - z * z).sqrt();
        let c = wall_color([r * phi.cos(), r * phi.sin(), z]);
        assert!(c.iter().all(|v| (0.1..=0.9).contains(v)), "{c:?}");
    }
}

#[test]
fn an_empty_room_shows_its_wall_and_an_opaque_sphere_hides_it() {
    let settings = CaptureSettings {
        views: 4,
        width: 20,
        height: 15,
        ..CaptureSettings::default()
    };
    let cams = cameras(&settings).unwrap();
    let empty = Scene {
        background: [1.0; 3],
        primitives: vec![],
    };
    let picture = capture_photograph(&empty, &cams[1], settings.room_radius);
    // Each pixel is the wall's mean over the pixel: 4 x 4 rays at the quarters' centres.
    let n = crate::photographs::RAYS_PER_SIDE;
    for row in 0..15 {
        for col in 0..20 {
            let mut wall = [0.0; 3];
            for (a, b) in (0..n * n).map(|k| (k / n, k % n)) {
                let ray = Ray {
                    origin: cams[1].centre(),
                    direction: cams[1].direction_at(
                        row as f64 + (a as f64 + 0.5) / n as f64,
                        col as f64 + (b as f64 + 0.5) / n as f64,
                    ),
                };
                let w = wall_color(wall_direction(&ray, settings.room_radius));
                (0..3).for_each(|c| wall[c] += w[c] / (n * n) as f64);
            }
            for c in 0..3 {
                assert!((picture[[row, col, c]] - wall[c]).abs() < 1e-15, "({row}, {col})");
            }
        }
    }
    // An opaque sphere (optical depth 2 x 100 x 2 through its middle) filling the view.
    let red = [0.9, 0.1, 0.2];
    let opaque = Scene {
        background: [1.0; 3],
        primitives: vec![Primitive::Sphere(Sphere {
            center: [0.0; 3],
            radius: 2.0,
            density: 100.0,
            color: red,
        })],
    };
    let picture = capture_photograph(&opaque, &cams[1], settings.room_radius);
    for c in 0..3 {
        assert!((picture[[7, 10, c]] - red[c]).abs() < 1e-12);
    }
}

#[test]
fn the_walk_wanders_around_the_scene_through_the_lens() {
    let settings = CaptureSettings::default();
    let cams = cameras(&settings).unwrap();
    assert_eq!(cams.len(), 120);
    let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
    for c in &cams {
        assert_eq!(*c.distortion(), settings.distortion);
        let e = c.centre();
        let d = norm(e);
        assert!((2.7..=3.3 + 1e-12).contains(&d), "{d}");
        let elevation = (e[2] / d).asin().to_degrees();
        low = low.min(elevation);
        high = high.max(elevation);
        // Outside the box instant-ngp marches by default ([-1.515, 1.515]^3).
        assert!(e.iter().any(|v| v.abs() > 1.515), "{e:?}");
    }
    assert!(low < 11.0 && high > 39.0, "{low} {high}");
}

#[test]
fn bad_settings_are_refused() {
    let ok = CaptureSettings::default();
    for bad in [
        CaptureSettings { views: 1, ..ok },
        CaptureSettings { width: 0, ..ok },
        CaptureSettings { room_radius: 3.0, ..ok },
        CaptureSettings {
            room_radius: f64::NAN,
            ..ok
        },
    ] {
        assert!(matches!(cameras(&bad), Err(CaptureError::Settings(_))), "{bad:?}");
    }
}
