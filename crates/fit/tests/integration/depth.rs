//! The depth `fogray render --depth` shows, before any colour map: an opaque ball seen from an
//! orbit of cameras renders, pixel by pixel, the distance at which each ray meets the ball
//! (closed form), within a voxel of the grid that holds it; rays that miss it are background.

use fogray_fit::dataset::camera_rays;
use fogray_fit::dense::DenseGrid;
use fogray_fit::model::RadianceField;
use fogray_fit::render::{render_picture, RenderOptions};
use fogray_fit::settings::SceneBox;
use fogray_ops::{Intrinsics, Orbit};
use ndarray::Array4;

/// The ball: centre and radius, inside the box `[-1.5, 1.5]^3`.
const CENTRE: [f64; 3] = [0.2, -0.1, 0.3];
const RADIUS: f64 = 0.6;
/// Nodes per axis: a cell of 3 / 60 = 0.05.
const NODES: usize = 61;

/// A grid whose density is 200 (raw 200 with shift 0: softplus is the identity that far out)
/// at the nodes inside the ball and softplus(-40) ~ 4e-18 at the others.
fn ball() -> DenseGrid<f64> {
    let scene_box = SceneBox {
        min: [-1.5; 3],
        max: [1.5; 3],
    };
    let mut model = DenseGrid::<f64>::new(scene_box, NODES, 0.0, 0.0).unwrap();
    let cell = 3.0 / (NODES - 1) as f64;
    let raw = Array4::from_shape_fn((NODES, NODES, NODES, 4), |(i, j, k, c)| {
        let p = [i, j, k].map(|n| -1.5 + n as f64 * cell);
        let inside = (0..3).map(|a| (p[a] - CENTRE[a]).powi(2)).sum::<f64>() < RADIUS * RADIUS;
        match (c, inside) {
            (0, true) => 200.0,
            (0, false) => -40.0,
            _ => 0.0,
        }
    });
    let id = model.grid_id();
    model.params_mut().get_mut(id).unwrap().assign(&raw.into_dyn());
    model
}

/// Where the ray `origin + t direction` (unit direction) first meets the ball, if it does,
/// and how close to the ball's centre it passes.
fn hit(origin: [f64; 3], direction: [f64; 3]) -> (Option<f64>, f64) {
    let oc: [f64; 3] = std::array::from_fn(|a| origin[a] - CENTRE[a]);
    let b: f64 = (0..3).map(|a| oc[a] * direction[a]).sum();
    let c: f64 = (0..3).map(|a| oc[a] * oc[a]).sum::<f64>() - RADIUS * RADIUS;
    let miss = (c + RADIUS * RADIUS - b * b).max(0.0).sqrt();
    let disc = b * b - c;
    ((disc >= 0.0).then(|| -b - disc.sqrt()), miss)
}

#[test]
fn an_opaque_ball_renders_its_distance_within_a_voxel() {
    let model = ball();
    let cell = 3.0 / (NODES - 1) as f64;
    let orbit = Orbit {
        centre: CENTRE,
        radius: 3.2,
        elevation: 30f64.to_radians(),
        frames: 3,
    };
    let k = Intrinsics::from_vertical_fov(40, 32, 40f64.to_radians()).unwrap();
    let options = RenderOptions {
        depth: true,
        ..RenderOptions::default()
    };
    let (mut foreground, mut background) = (0, 0);
    for camera in orbit.cameras(k).unwrap() {
        let (origins, directions) = camera_rays(&camera);
        let view = render_picture(&model, None, &origins, &directions, [32, 40], &options).unwrap();
        let depth = view.depth.unwrap();
        for ((row, col), d) in depth.indexed_iter() {
            let p = row * 40 + col;
            let (t, miss) = hit(
                std::array::from_fn(|a| origins[[p, a]]),
                std::array::from_fn(|a| directions[[p, a]]),
            );
            // The grid's surface is the ball's to within a cell; rays that graze it are
            // neither foreground nor background.
            if miss < RADIUS - 2.0 * cell {
                let t = t.unwrap();
                assert!((d - t).abs() < cell, "pixel {row}, {col}: depth {d}, the ball at {t}");
                // Nearest point of the ball: the orbit's radius less the ball's, at most.
                assert!(*d > 3.2 - RADIUS - cell);
                foreground += 1;
            } else if miss > RADIUS + 2.0 * cell {
                assert!(d.is_nan(), "pixel {row}, {col}: depth {d} beside the ball");
                background += 1;
            }
        }
    }
    // The ball (angular radius asin(0.6 / 3.2) = 10.8 degrees, 8.4 pixels at a focal length
    // of 44) leaves a disc of about 150 pixels a view inside the grazing rays (measured: 444
    // in all), and the rest of each view shows the background.
    assert!(foreground > 3 * 120, "{foreground} foreground pixels");
    assert!(background > 3 * 500, "{background} background pixels");
}
