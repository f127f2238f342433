//! A splat fit of a scene with a known answer, independent of the op: a sphere whose colour
//! is its normal (`0.5 + 0.5 n`), ray-traced analytically over white.

use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::Array3;

use super::model::{SplatArraysOwned, SplatModel};
use super::settings::SplatSettings;
use super::trainer::SplatTrainer;
use super::*;
use crate::dataset::{camera_rays, Dataset, View};

const RADIUS: f64 = 0.6;
const SIZE: usize = 32;

/// The sphere's picture from `eye`: where a ray meets it, the normal's colour; else white.
fn sphere_view(i: usize, eye: [f64; 3]) -> View {
    let k = Intrinsics::from_vertical_fov(SIZE, SIZE, 40f64.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let (o, d) = camera_rays(&camera);
    let image = Array3::from_shape_fn((SIZE, SIZE, 3), |(r, c, ch)| {
        let p = r * SIZE + c;
        let (o, d) = ([o[[p, 0]], o[[p, 1]], o[[p, 2]]], [d[[p, 0]], d[[p, 1]], d[[p, 2]]]);
        // |o + t d|² = R²: a t² + 2 b t + c = 0, nearest root.
        let a: f64 = d.iter().map(|v| v * v).sum();
        let b: f64 = (0..3).map(|k| o[k] * d[k]).sum();
        let cc: f64 = o.iter().map(|v| v * v).sum::<f64>() - RADIUS * RADIUS;
        let disc = b * b - a * cc;
        if disc < 0.0 {
            return 1.0;
        }
        let t = (-b - disc.sqrt()) / a;
        0.5 + 0.5 * (o[ch] + t * d[ch]) / RADIUS
    });
    View::new(format!("{i}"), &camera, image).unwrap()
}

/// Eight views around the sphere at two heights, and one held out between them.
fn sphere_data() -> Dataset {
    let eye = |angle: f64, z: f64| [3.0 * angle.cos(), 3.0 * angle.sin(), z];
    let train = (0..8)
        .map(|i| {
            let z = if i % 2 == 0 { 0.8 } else { -0.8 };
            sphere_view(i, eye(i as f64 * std::f64::consts::FRAC_PI_4, z))
        })
        .collect();
    let test = vec![sphere_view(8, eye(0.4, 0.3))];
    Dataset::new(train, test, [1.0; 3]).unwrap()
}

fn settings(steps: usize) -> SplatSettings {
    SplatSettings {
        budget: crate::settings::Budget::Steps(steps),
        degree: 0,
        densify_from: 0.2,
        densify_every: 100,
        densify_until: 1.0,
        reset_every: 0,
        ..SplatSettings::default()
    }
}

#[test]
fn a_fit_of_the_sphere_reaches_a_held_out_psnr() {
    let data = sphere_data();
    let model = SplatModel::<f32>::random([[-0.8; 3], [0.8; 3]], 400, 0, 3, 10_000).unwrap();
    let mut trainer = SplatTrainer::new(&data, &settings(400), model).unwrap();
    let before = trainer.evaluate().unwrap().entry.test_psnr;
    while !trainer.is_done() {
        trainer.step().unwrap();
    }
    let after = trainer.evaluate().unwrap().entry.test_psnr;
    eprintln!(
        "held-out PSNR {before:.2} -> {after:.2} dB, {} splats",
        trainer.model().len()
    );
    assert!(after > 20.0, "{before} -> {after}");
}

#[test]
fn the_loss_decreases() {
    let data = sphere_data();
    let model = SplatModel::<f64>::random([[-0.8; 3], [0.8; 3]], 200, 0, 5, 10_000).unwrap();
    let mut trainer = SplatTrainer::new(&data, &settings(160), model).unwrap();
    let losses: Vec<f64> = (0..160).map(|_| trainer.step().unwrap().loss).collect();
    let first: f64 = losses[..16].iter().sum::<f64>() / 16.0;
    let last: f64 = losses[144..].iter().sum::<f64>() / 16.0;
    assert!(last < 0.7 * first, "{first} -> {last}");
}

#[test]
fn bad_inputs_are_errors() {
    assert!(SplatModel::<f32>::random([[0.0; 3], [0.0; 3]], 10, 0, 0, 100).is_err());
    assert!(matches!(
        SplatModel::<f32>::random([[0.0; 3], [1.0; 3]], 101, 0, 0, 100),
        Err(crate::FitError::TooManySplats { count: 101, cap: 100 })
    ));
    assert!(SplatModel::<f32>::from_points(&[[0.0; 3]], &[], 0, 10).is_err());
    assert!(SplatModel::<f32>::from_points(&[[f64::NAN; 3]], &[[0.5; 3]], 0, 10).is_err());
    let data = sphere_data();
    let model = SplatModel::<f32>::random([[0.0; 3], [1.0; 3]], 20, 0, 0, 100).unwrap();
    let s = SplatSettings {
        max_splats: 10,
        degree: 0,
        ..SplatSettings::default()
    };
    assert!(SplatTrainer::new(&data, &s, model).is_err());
}

/// [`sphere_data`] with each picture's alpha: 1 where a ray meets the sphere, 0 elsewhere
/// (the white background is where the pictures are white, so the images need no change).
fn sphere_data_with_alpha() -> Dataset {
    let mut data = sphere_data();
    for view in data.train.iter_mut().chain(data.test.iter_mut()) {
        let (o, d) = camera_rays(&view.camera);
        let hit = |p: usize| {
            let (o, d) = ([o[[p, 0]], o[[p, 1]], o[[p, 2]]], [d[[p, 0]], d[[p, 1]], d[[p, 2]]]);
            let a: f64 = d.iter().map(|v| v * v).sum();
            let b: f64 = (0..3).map(|k| o[k] * d[k]).sum();
            let c: f64 = o.iter().map(|v| v * v).sum::<f64>() - RADIUS * RADIUS;
            b * b - a * c >= 0.0
        };
        view.alpha = Some(ndarray::Array2::from_shape_fn((SIZE, SIZE), |(r, c)| {
            if hit(r * SIZE + c) {
                1.0
            } else {
                0.0
            }
        }));
    }
    data
}

#[test]
fn the_visual_hull_holds_the_sphere_and_nothing_far_from_it() {
    let data = sphere_data_with_alpha();
    let bounds = [[-1.5; 3], [1.5; 3]];
    let hull = carve::visual_hull(&data, bounds, 20_000, 20_000, 7).unwrap().unwrap();
    let norm = |p: &[f64; 3]| p.iter().map(|v| v * v).sum::<f64>().sqrt();
    // Every kept point lies, for every view whose picture it falls in, on a line of sight
    // that meets the sphere (the line's distance to the centre at most the radius, with a
    // pixel's width of margin at the distance 3 cameras stand at): the silhouette's cone.
    let pixel = 2.0 * (20f64.to_radians()).tan() / SIZE as f64 * 4.0;
    for p in &hull.points {
        let mut seen = 0;
        for view in &data.train {
            let Some([x, y]) = view.camera.project(*p) else {
                continue;
            };
            if !(x >= 0.0 && y >= 0.0 && x < SIZE as f64 && y < SIZE as f64) {
                continue;
            }
            seen += 1;
            let o = view.camera.centre();
            let d = [0, 1, 2].map(|a| p[a] - o[a]);
            let len = norm(&d);
            let t = -(0..3).map(|a| o[a] * d[a]).sum::<f64>() / (len * len);
            let closest = [0, 1, 2].map(|a| o[a] + t * d[a]);
            assert!(
                norm(&closest) <= RADIUS + pixel,
                "{p:?} seen off the sphere: {}",
                norm(&closest)
            );
        }
        assert!(seen > 0, "{p:?} is seen by no view");
    }
    let kept = hull.points.len() as f64 / 20_000.0;
    assert!(kept > 0.033, "{kept}");
    // The sphere's centre region is never carved away: every candidate there is kept.
    let inner = hull.points.iter().filter(|p| norm(p) < 0.5 * RADIUS).count() as f64;
    let expected = 20_000.0 * (4.0 / 3.0 * std::f64::consts::PI * (0.5 * RADIUS).powi(3)) / 27.0;
    assert!(
        (inner - expected).abs() < 4.0 * expected.sqrt(),
        "{inner} of about {expected}"
    );
    // A point's colour is the mean of the pictures' colours where it falls: in [0, 1].
    assert!(hull.colors.iter().flatten().all(|v| (0.0..=1.0).contains(v)));
    // Without alpha, nothing to carve with.
    assert!(carve::visual_hull(&sphere_data(), bounds, 100, 100, 7)
        .unwrap()
        .is_none());
    assert!(carve::visual_hull(&data, [[0.0; 3], [0.0; 3]], 100, 100, 7).is_err());
}

#[test]
fn the_ply_file_is_what_3dgs_viewers_read() {
    use fogray_ops::sh::basis::C0;
    // Two splats of degree 1: a reader written here from the format's description (header
    // lines, then float32 records) reads back every value.
    let arrays = SplatArraysOwned {
        means: ndarray::arr2(&[[0.1, -0.2, 0.3], [1.0, 2.0, -3.0]]),
        log_scales: ndarray::arr2(&[[-3.0, -2.5, -2.0], [-1.0, -1.5, -4.0]]),
        quats: ndarray::arr2(&[[1.0, 0.0, 0.0, 0.0], [0.5, 0.5, -0.5, 0.5]]),
        opacity_logits: ndarray::arr1(&[2.0, -1.0]),
        sh: ndarray::Array2::from_shape_fn((2, 12), |(i, k)| 0.1 * (i * 12 + k) as f64 - 0.5),
    };
    let model = SplatModel::<f64>::new(arrays.clone(), 1).unwrap();
    let bytes = ply::splats_ply(&model).unwrap();
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..at]).unwrap();
    let lines: Vec<&str> = header.lines().collect();
    assert_eq!(lines[0], "ply");
    assert_eq!(lines[1], "format binary_little_endian 1.0");
    assert!(lines.contains(&"element vertex 2"));
    let names: Vec<&str> = lines.iter().filter_map(|l| l.strip_prefix("property float ")).collect();
    let expected = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "f_rest_0", "f_rest_1", "f_rest_2", "f_rest_3",
        "f_rest_4", "f_rest_5", "f_rest_6", "f_rest_7", "f_rest_8", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ];
    assert_eq!(names, expected);
    let floats: Vec<f32> = bytes[at..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    assert_eq!(floats.len(), 2 * expected.len());
    let value = |i: usize, name: &str| {
        f64::from(floats[i * expected.len() + expected.iter().position(|n| *n == name).unwrap()])
    };
    let sigmoid = |x: f64| 1.0 / (1.0 + (-x).exp());
    for i in 0..2 {
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            assert!((value(i, axis) - arrays.means[[i, a]]).abs() < 1e-6);
            assert!((value(i, &format!("scale_{a}")) - arrays.log_scales[[i, a]]).abs() < 1e-6);
        }
        for k in 0..4 {
            assert!((value(i, &format!("rot_{k}")) - arrays.quats[[i, k]]).abs() < 1e-6);
        }
        assert!((value(i, "opacity") - arrays.opacity_logits[i]).abs() < 1e-6);
        for c in 0..3 {
            // A viewer's colour seen along the view-independent term: 0.5 + C0 f_dc, which
            // is fogray's sigmoid(C0 k_0) exactly.
            let viewer = 0.5 + C0 * value(i, &format!("f_dc_{c}"));
            let ours = sigmoid(C0 * arrays.sh[[i, 4 * c]]);
            assert!((viewer - ours).abs() < 1e-6, "{viewer} {ours}");
            for b in 1..4 {
                let slope = ours * (1.0 - ours);
                let f = value(i, &format!("f_rest_{}", c * 3 + b - 1));
                assert!((f - slope * arrays.sh[[i, 4 * c + b]]).abs() < 1e-6);
            }
        }
    }
}

#[test]
fn random_splats_render_a_picture_of_the_camera_size() -> Result<(), Box<dyn std::error::Error>> {
    let model = SplatModel::<f32>::random([[-0.5; 3], [0.5; 3]], 50, 1, 7, 1000)?;
    let k = Intrinsics::from_vertical_fov(16, 16, 0.7)?;
    let camera = PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])?;
    let image = model.render(&camera, [1.0; 3])?;
    assert_eq!(image.dim(), (256, 3));
    Ok(())
}
