//! A fit of the built-in scene saved with its cameras and scene, as the binary saves one: the
//! file gives them back, and the ring's views rendered from the reloaded model are the fit's
//! test renders bit for bit; a saved scene that does not parse is refused; and the depth of a
//! homogeneous box against its closed form. (Checkpoint round trips, bad files and a resumed
//! fit against an unbroken one are fogray-fit's own tests: crates/fit/tests/integration.)

use std::collections::BTreeMap;

use crate::common::{default_scene_data, grid, temp_dir};
use fogray::fit::checkpoint::{load, read_info, save};
use fogray::fit::dense::DenseGrid;
use fogray::fit::model::RadianceField;
use fogray::fit::render::{render_picture, RenderOptions, BACKGROUND_OPACITY};
use fogray::fit::settings::{Budget, FitSettings, Method, Sampling, SceneBox};
use fogray::fit::state::TrainingState;
use fogray::fit::train::fit;
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_grid::views::view;
use ndarray::{Array2, Array4};

fn image_bits(images: &[ndarray::Array3<f64>]) -> Vec<u64> {
    images.iter().flat_map(|im| im.iter().map(|v| v.to_bits())).collect()
}

/// The binary's checkpoint entries for `views`, `test_views`, `size` and `scene` (its
/// `Problem::entries`).
fn entries(views: usize, test_views: usize, size: usize, scene: &str) -> BTreeMap<String, String> {
    [
        ("views", views.to_string()),
        ("test_views", test_views.to_string()),
        ("size", size.to_string()),
        ("scene", scene.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

#[test]
fn a_saved_fit_gives_back_its_cameras_and_scene_and_renders_from_the_ring_as_the_fit() {
    let (views, test_views, size) = (8, 2, 10);
    let data = default_scene_data(&Ring::new(views, test_views, size).unwrap());
    let settings = FitSettings {
        grid: 8,
        batch: 128,
        grow: false,
        sampling: Sampling::Uniform,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(5));
    let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
    let dir = temp_dir("persist-ring");
    let file = dir.join("m.safetensors");
    let extra = entries(views, test_views, size, &Scene::default().to_json_pretty());
    save(&file, &result.model, &result.training, &settings, &extra).unwrap();

    let info = read_info(&file).unwrap();
    assert_eq!((info.nodes, info.step), (8, 5));
    assert_eq!(info.settings, settings);
    assert_eq!(info.extra, extra);
    // The cameras and the scene, as the render subcommand reads them back.
    let number = |key: &str| info.extra[key].parse::<usize>().unwrap();
    let ring = Ring::new(number("views"), number("test_views"), number("size")).unwrap();
    let scene = Scene::from_json(&info.extra["scene"]).unwrap();
    assert_eq!(scene, Scene::default());

    // The render subcommand's path: each test view of the ring, its camera's rays rendered
    // from the reloaded model (with depth), gives the fit's test renders bit for bit.
    let back = load::<f32, DenseGrid<f32>>(&file).unwrap();
    let options = RenderOptions {
        background: scene.background,
        method: Method::Fused,
        depth: true,
    };
    assert_eq!(ring.test_views().len(), result.renders.len());
    for ((i, want), test) in ring.test_views().into_iter().zip(&result.renders).zip(&data.test) {
        let v = view(&scene, &ring, i).unwrap();
        assert_eq!((&v.name, &v.image), (&test.name, &test.image), "view {i}");
        let (origins, directions) = v.rays();
        let r = render_picture(&back.start.model, None, &origins, &directions, v.size(), &options).unwrap();
        assert_eq!(
            image_bits(&[r.color]),
            image_bits(std::slice::from_ref(want)),
            "view {i}"
        );
        assert_eq!(r.depth.unwrap().dim(), (size, size));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_saved_scene_that_does_not_parse_is_refused_with_one_line() {
    // The library saves the application's entries as they are; the binary reads the scene back
    // and refuses one that does not parse, naming it.
    let dir = temp_dir("persist-bad-scene");
    let settings = FitSettings {
        grid: 4,
        ..FitSettings::default()
    };
    let model = DenseGrid::<f32>::fresh(&settings, 4).unwrap();
    let training = TrainingState::default();
    let good = dir.join("good.safetensors");
    let bad = dir.join("bad.safetensors");
    let scene = Scene::default().to_json_pretty();
    save(&good, &model, &training, &settings, &entries(3, 1, 4, &scene)).unwrap();
    save(&bad, &model, &training, &settings, &entries(3, 1, 4, "{")).unwrap();
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    let (code, _, err) = grid(&["render", "--model", good.to_str().unwrap(), "--out", out]);
    assert_eq!(code, 0, "{err}");
    let (code, stdout, err) = grid(&["render", "--model", bad.to_str().unwrap(), "--out", out]);
    assert_eq!(code, 2, "{err}");
    assert!(stdout.is_empty(), "{stdout}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("the saved scene"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_depth_of_a_homogeneous_box_is_its_closed_form() {
    // Density 1 everywhere in [-1, 1]^3 (raw = softplus^-1(1) - shift). A ray entering at t0
    // and leaving at t1 = t0 + L stops at t0 + s with density e^-s on [0, L], so its expected
    // depth given that it stops is t0 + 1 - L e^-L / (1 - e^-L).
    let shift = -4.0;
    let mut model = DenseGrid::<f64>::new(SceneBox::UNIT, 41, shift, 0.0).unwrap();
    let raw = (1f64.exp() - 1.0).ln() - shift;
    let id = model.grid_id();
    model
        .params_mut()
        .get_mut(id)
        .unwrap()
        .assign(&Array4::from_shape_fn(
            (41, 41, 41, 4),
            |(.., c)| if c == 0 { raw } else { 0.0 },
        ));
    let options = RenderOptions {
        background: [1.0; 3],
        method: Method::Fused,
        depth: true,
    };
    let ring = Ring::new(3, 1, 24).unwrap();
    let mut checked = (0, 0);
    for view in 0..ring.len() {
        let rays = ring.rays(view).unwrap();
        let origins = Array2::from_shape_fn((rays.len(), 3), |(p, a)| rays[p].origin[a]);
        let directions = Array2::from_shape_fn((rays.len(), 3), |(p, a)| rays[p].direction[a]);
        let r = render_picture(&model, None, &origins, &directions, [24, 24], &options).unwrap();
        let depths = r.depth.unwrap();
        for (p, ray) in rays.iter().enumerate() {
            let (a, b) = (p / 24, p % 24);
            // Slab clipping of the unit ray against the box, by hand.
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for k in 0..3 {
                let (u, v) = (
                    (-1.0 - ray.origin[k]) / ray.direction[k],
                    (1.0 - ray.origin[k]) / ray.direction[k],
                );
                t0 = t0.max(u.min(v));
                t1 = t1.min(u.max(v));
            }
            let length = (t1 - t0).max(0.0);
            let opacity = -(-length).exp_m1();
            assert!((r.opacity[[a, b]] - opacity).abs() < 2e-3, "view {view} ({a}, {b})");
            let depth = depths[[a, b]];
            if opacity < BACKGROUND_OPACITY - 0.01 {
                assert!(depth.is_nan(), "view {view} ({a}, {b}): {depth}");
                checked.1 += 1;
            } else if opacity > BACKGROUND_OPACITY + 0.01 {
                let want = t0 + 1.0 - length * (-length).exp() / opacity;
                // Samples every 0.025 along the ray: the quadrature's error is a fraction of that.
                assert!((depth - want).abs() < 0.01, "view {view} ({a}, {b}): {depth} vs {want}");
                // Unnormalised (sum w t), the depth would be off by (1 - opacity) t.
                assert!((depth * r.opacity[[a, b]] - want).abs() > 0.01 || opacity > 0.99);
                checked.0 += 1;
            }
        }
    }
    assert!(checked.0 > 1000 && checked.1 > 20, "{checked:?}");
}
