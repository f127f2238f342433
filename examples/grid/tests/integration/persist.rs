//! Saving, reloading and continuing a fit, and rendering from a saved model: a reloaded model
//! renders bit for bit as the fit's; a fit stopped at step k and continued from its file takes
//! the same steps, bit for bit, as one never stopped; the depth of a homogeneous box against
//! its closed form; and every kind of bad file refused with a typed error.

use crate::common::default_scene_data;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use fogray::tape::Float;
use fogray_grid::checkpoint::{load, read_info, save, Cameras, CheckpointError, Precision, SavedFit};
use fogray_grid::dataset::Dataset;
use fogray_grid::fit::{
    fit_from, render_test_views, Budget, FitConfig, FitResult, Sampling, OCCUPANCY_EVERY, OCCUPANCY_WARMUP,
};
use fogray_grid::model::{GridModel, Method};
use fogray_grid::render::{render_view, BACKGROUND_OPACITY};
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_grid::state::Start;
use ndarray::Array4;
use safetensors::tensor::TensorView;
use safetensors::SafeTensors;

const CAMERAS: Cameras = Cameras {
    views: 8,
    test_views: 2,
    size: 10,
};

fn data() -> Dataset {
    default_scene_data(&CAMERAS.ring().unwrap())
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogray-grid-persist-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn saved<F: Float>(config: FitConfig) -> SavedFit {
    SavedFit {
        precision: Precision::of::<F>(),
        config,
        cameras: CAMERAS,
        scene: Scene::default(),
    }
}

fn grid_bits<F: Float>(model: &GridModel<F>) -> Vec<u64> {
    let grid = model.params().get(model.grid_id()).unwrap();
    grid.iter().map(|v| v.as_f64().to_bits()).collect()
}

fn image_bits(images: &[ndarray::Array3<f64>]) -> Vec<u64> {
    images.iter().flat_map(|im| im.iter().map(|v| v.to_bits())).collect()
}

fn run<F: Float>(
    data: &Dataset,
    config: &FitConfig,
    start: Option<Start<F>>,
    stop_after: Option<usize>,
) -> FitResult<F> {
    let stop = AtomicBool::new(false);
    let mut progress = |p: fogray_grid::fit::Progress| {
        if Some(p.step) == stop_after {
            stop.store(true, Ordering::Relaxed);
        }
    };
    fit_from(data, config, start, Some(&stop), &mut progress).unwrap()
}

/// A fit of `total` steps against one of `k` steps saved to a file, reloaded and continued
/// to `total`: the first part is a fit with a budget of `k` steps, or (`stopped`) a fit to
/// `total` stopped by its flag after step `k`.
fn split_equals_whole<F: Float>(config: FitConfig, total: usize, k: usize, stopped: bool, name: &str) {
    let data = data();
    let whole_config = FitConfig {
        budget: Budget::Steps(total),
        ..config
    };
    let whole = run::<F>(&data, &whole_config, None, None);
    let first_config = if stopped {
        whole_config
    } else {
        FitConfig {
            budget: Budget::Steps(k),
            ..config
        }
    };
    let first = run::<F>(&data, &first_config, None, stopped.then_some(k));
    assert_eq!(first.training.step, k);
    assert_eq!(first.interrupted, stopped);
    let file = temp(name);
    save(&file, &first.model, &first.training, &saved::<F>(first_config)).unwrap();
    let back = load::<F>(&file).unwrap();
    assert_eq!(back.start.training, first.training);
    let second = run::<F>(&data, &whole_config, Some(back.start), None);
    assert_eq!(second.training.step, total);
    assert_eq!(second.model.nodes(), whole.model.nodes());
    assert_eq!(grid_bits(&second.model), grid_bits(&whole.model), "{name}");
    // Everything but the training seconds, which are the clock's.
    let (a, b) = (&second.training, &whole.training);
    assert_eq!(
        (a.step, a.stage, a.batch_stream),
        (b.step, b.stage, b.batch_stream),
        "{name}"
    );
    assert_eq!(a.adam, b.adam, "{name}");
    assert_eq!(a.occupancy, b.occupancy, "{name}");
    assert!(a.seconds > first.training.seconds);
    assert_eq!(image_bits(&second.renders), image_bits(&whole.renders));
    assert_eq!(second.log[0].step, k);
    assert_eq!(
        second.log.last().unwrap().test_psnr.to_bits(),
        whole.log.last().unwrap().test_psnr.to_bits()
    );
    // A fresh Adam and the stream restarted would differ: the comparison can fail.
    let mut forgetful = load::<F>(&file).unwrap().start;
    forgetful.training.adam = None;
    forgetful.training.batch_stream = 0;
    let differs = run::<F>(&data, &whole_config, Some(forgetful), None);
    assert_ne!(grid_bits(&differs.model), grid_bits(&whole.model));
}

#[test]
fn k_steps_saved_and_continued_equal_2k_steps_bitwise() {
    // A constant rate and no growth: the first part's budget of k steps does what the first k
    // steps of the whole's do.
    let base = FitConfig {
        grid: 6,
        batch: 128,
        lr: 0.2,
        lr_final: 0.2,
        grow: false,
        sampling: Sampling::Uniform,
        ..FitConfig::default()
    };
    split_equals_whole::<f32>(base, 12, 6, false, "split-f32.safetensors");
    split_equals_whole::<f64>(base, 12, 6, false, "split-f64.safetensors");
    // A growing grid (3, 5 then 10 nodes from steps 2 and 6 of 20) with an annealed rate,
    // stopped between stages after step 4 and continued through the growth and the anneal.
    let growing = FitConfig {
        grid: 10,
        grow: true,
        lr_final: 0.02,
        ..base
    };
    split_equals_whole::<f32>(growing, 20, 4, true, "split-grow.safetensors");
    split_equals_whole::<f32>(base, 8, 3, true, "split-stop.safetensors");
}

#[test]
fn an_occupancy_fit_saved_and_continued_equals_the_whole_bitwise() {
    // The occupancy grid is first refreshed at step 64, then every 16 steps: saved at step 72
    // (one refresh in), continued through the refreshes at 80 and 96.
    let occupancy = FitConfig {
        grid: 6,
        batch: 64,
        lr: 0.2,
        lr_final: 0.2,
        grow: false,
        sampling: Sampling::Occupancy,
        ..FitConfig::default()
    };
    const { assert!(OCCUPANCY_WARMUP < 72 && 72 < OCCUPANCY_WARMUP + 2 * OCCUPANCY_EVERY) };
    split_equals_whole::<f32>(occupancy, 100, 72, false, "split-occupancy.safetensors");
    // The grid in the file is the one the fit had, and it is not the fresh grid a file
    // without one would give.
    let data = data();
    let first = run::<f32>(
        &data,
        &FitConfig {
            budget: Budget::Steps(72),
            ..occupancy
        },
        None,
        None,
    );
    let fraction = first.occupancy.as_ref().unwrap().occupied_fraction();
    assert!(fraction < 1.0, "{fraction}");
    let file = temp("occupancy.safetensors");
    save(&file, &first.model, &first.training, &saved::<f32>(occupancy)).unwrap();
    let back = load::<f32>(&file).unwrap().start.training.occupancy.unwrap();
    assert_eq!(Some(back), first.occupancy.map(|g| g.state()));
}

#[test]
fn a_reloaded_model_renders_bitwise_as_the_fit_and_as_render_view() {
    let data = data();
    let config = FitConfig {
        grid: 8,
        batch: 128,
        budget: Budget::Steps(5),
        grow: false,
        sampling: Sampling::Uniform,
        ..FitConfig::default()
    };
    let result = run::<f32>(&data, &config, None, None);
    let file = temp("render.safetensors");
    save(&file, &result.model, &result.training, &saved::<f32>(config)).unwrap();
    let back = load::<f32>(&file).unwrap();
    assert_eq!(grid_bits(&back.start.model), grid_bits(&result.model));
    let again = render_test_views(&back.start.model, &data, Method::Fused, None).unwrap();
    assert_eq!(image_bits(&again), image_bits(&result.renders));
    // The render subcommand's renderer, with depth, gives the same colours.
    let ring = CAMERAS.ring().unwrap();
    for (t, want) in data.test.iter().zip(&result.renders) {
        let r = render_view(&back.start.model, &ring, t.view, data.background, None).unwrap();
        assert_eq!(image_bits(&[r.color]), image_bits(std::slice::from_ref(want)));
    }
    let info = read_info(&file).unwrap();
    assert_eq!((info.nodes, info.step), (8, 5));
    assert_eq!(info.seconds.to_bits(), result.training.seconds.to_bits());
    assert_eq!(info.fit, saved::<f32>(config));
}

#[test]
fn the_depth_of_a_homogeneous_box_is_its_closed_form() {
    // Density 1 everywhere in [-1, 1]^3 (raw = softplus^-1(1) - shift). A ray entering at t0
    // and leaving at t1 = t0 + L stops at t0 + s with density e^-s on [0, L], so its expected
    // depth given that it stops is t0 + 1 - L e^-L / (1 - e^-L).
    let shift = -4.0;
    let mut model = GridModel::<f64>::new(41, shift).unwrap();
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
    let ring = Ring::new(3, 1, 24).unwrap();
    let mut checked = (0, 0);
    for view in 0..ring.len() {
        let r = render_view(&model, &ring, view, [1.0, 1.0, 1.0], None).unwrap();
        for (p, ray) in ring.rays(view).iter().enumerate() {
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
            let depth = r.depth[[a, b]];
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

/// The tensors and metadata of a good file, rewritten with `edit` applied.
fn rewrite(good: &Path, bad: &Path, edit: impl FnOnce(&mut Vec<(String, TensorData)>, &mut HashMap<String, String>)) {
    let bytes = std::fs::read(good).unwrap();
    let (_, header) = SafeTensors::read_metadata(&bytes).unwrap();
    let mut meta = header.metadata().clone().unwrap();
    let parsed = SafeTensors::deserialize(&bytes).unwrap();
    let mut tensors: Vec<(String, TensorData)> = parsed
        .tensors()
        .into_iter()
        .map(|(name, v)| {
            (
                name,
                TensorData {
                    dtype: v.dtype(),
                    shape: v.shape().to_vec(),
                    bytes: v.data().to_vec(),
                },
            )
        })
        .collect();
    edit(&mut tensors, &mut meta);
    let views: Vec<(String, TensorView<'_>)> = tensors
        .iter()
        .map(|(n, t)| (n.clone(), TensorView::new(t.dtype, t.shape.clone(), &t.bytes).unwrap()))
        .collect();
    safetensors::serialize_to_file(views, Some(meta), bad).unwrap();
}

/// A change to a file's tensors and metadata.
type Edit = dyn FnOnce(&mut Vec<(String, TensorData)>, &mut HashMap<String, String>);

struct TensorData {
    dtype: safetensors::tensor::Dtype,
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

/// A 2-step fit of a 4^3 grid with `sampling`, saved to the temporary file `name`.
fn small_saved_fit(sampling: Sampling, name: &str) -> PathBuf {
    let config = FitConfig {
        grid: 4,
        batch: 64,
        budget: Budget::Steps(2),
        sampling,
        grow: false,
        ..FitConfig::default()
    };
    let result = run::<f32>(&data(), &config, None, None);
    let file = temp(name);
    save(&file, &result.model, &result.training, &saved::<f32>(config)).unwrap();
    file
}

/// `e` is a format error whose message holds `what`.
fn assert_format(e: CheckpointError, what: &str) {
    match e {
        CheckpointError::Format { message, .. } => assert!(message.contains(what), "{message} / {what}"),
        other => panic!("{other:?} for {what}"),
    }
}

/// Each edit of `good`, written to `bad`, is refused with a format error whose message holds
/// the case's text.
fn each_edit_is_refused(good: &Path, bad: &Path, cases: Vec<(&str, Box<Edit>)>) {
    for (what, edit) in cases {
        rewrite(good, bad, edit);
        assert_format(load::<f32>(bad).unwrap_err(), what);
    }
}

#[test]
fn bad_files_are_refused_with_a_typed_error() {
    let good = small_saved_fit(Sampling::Uniform, "good.safetensors");
    load::<f32>(&good).unwrap();

    assert!(matches!(
        load::<f32>(Path::new("/nonexistent/model.safetensors")),
        Err(CheckpointError::Read { .. })
    ));
    let junk = temp("junk.safetensors");
    std::fs::write(&junk, b"not a model at all").unwrap();
    assert_format(load::<f32>(&junk).unwrap_err(), "not a safetensors file");
    let truncated = temp("truncated.safetensors");
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() - 8]).unwrap();
    assert!(matches!(load::<f32>(&truncated), Err(CheckpointError::Format { .. })));
    match load::<f64>(&good).unwrap_err() {
        CheckpointError::Mismatch {
            setting, file, asked, ..
        } => {
            assert_eq!((setting, file.as_str(), asked.as_str()), ("--precision", "f32", "f64"))
        }
        other => panic!("{other:?}"),
    }
    let info = read_info(&good).unwrap();
    assert!(info.check_matches(&good, Precision::F32, 4).is_ok());
    assert!(matches!(
        info.check_matches(&good, Precision::F32, 5),
        Err(CheckpointError::Mismatch { setting: "--grid", .. })
    ));

    let bad = temp("bad.safetensors");
    let cases: Vec<(&str, Box<Edit>)> = vec![
        (
            "\"grid\" holds NaN",
            Box::new(|t, _| {
                t.iter_mut().find(|(n, _)| n == "grid").unwrap().1.bytes[4..8].copy_from_slice(&f32::NAN.to_le_bytes())
            }),
        ),
        (
            "tensor \"grid\" is F32 [4, 4, 4, 4]",
            Box::new(|_, m| {
                m.insert("nodes".into(), "5".into());
            }),
        ),
        (
            "no metadata entry \"lr\"",
            Box::new(|_, m| {
                m.remove("lr");
            }),
        ),
        (
            "format \"something else\"",
            Box::new(|_, m| {
                m.insert("format".into(), "something else".into());
            }),
        ),
        (
            "second moment",
            Box::new(|t, _| {
                let v = &mut t.iter_mut().find(|(n, _)| n == "adam.second_moment").unwrap().1;
                v.bytes[0..4].copy_from_slice(&(-1.0f32).to_le_bytes());
            }),
        ),
        (
            "tensor \"adam.first_moment\"",
            Box::new(|t, _| t.retain(|(n, _)| n != "adam.first_moment")),
        ),
        (
            "scene",
            Box::new(|_, m| {
                m.insert("scene".into(), "{".into());
            }),
        ),
    ];
    each_edit_is_refused(&good, &bad, cases);
}

#[test]
fn bad_occupancy_tensors_are_refused_with_a_typed_error() {
    let good = small_saved_fit(Sampling::Occupancy, "good-occupancy.safetensors");
    // Before its first refresh every cell of the grid is occupied, and so after loading.
    let state = load::<f32>(&good).unwrap().start.training.occupancy.unwrap();
    assert!(state.occupied.iter().all(|&o| o) && state.occupied.shape() == [3, 3, 3]);
    let bad = temp("bad-occupancy.safetensors");
    let cases: Vec<(&str, Box<Edit>)> = vec![
        (
            "holds the byte 2",
            Box::new(|t, _| t.iter_mut().find(|(n, _)| n == "occupancy.occupied").unwrap().1.bytes[5] = 2),
        ),
        (
            "must be finite and non-negative",
            Box::new(|t, _| {
                let v = &mut t.iter_mut().find(|(n, _)| n == "occupancy.estimate").unwrap().1;
                v.bytes[8..12].copy_from_slice(&(-2.0f32).to_le_bytes());
            }),
        ),
        (
            "tensor \"occupancy.estimate\"",
            Box::new(|t, _| t.retain(|(n, _)| n != "occupancy.estimate")),
        ),
        (
            "expected BOOL [3, 3, 3]",
            Box::new(|t, _| {
                let v = &mut t.iter_mut().find(|(n, _)| n == "occupancy.occupied").unwrap().1;
                v.shape = vec![27];
            }),
        ),
    ];
    each_edit_is_refused(&good, &bad, cases);
    // Without both tensors (a file from before grids were saved) there is no state to restore.
    rewrite(&good, &bad, |t, _| t.retain(|(n, _)| !n.starts_with("occupancy.")));
    assert_eq!(load::<f32>(&bad).unwrap().start.training.occupancy, None);
}
