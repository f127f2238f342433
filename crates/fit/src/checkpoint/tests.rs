//! Model files: a reloaded model renders bit for bit as the fit did, its metadata reads back,
//! and every kind of bad file is refused with a typed error.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use crate::checkpoint::{load, read_info, save, CheckpointError};
use crate::dense::DenseGrid;
use crate::render::{render_picture, RenderOptions};
use crate::settings::{Budget, FitSettings, Precision, Sampling};
use crate::train::render_test_views;
use safetensors::tensor::TensorView;
use safetensors::SafeTensors;

use crate::testing::{ball_dataset, grid_bits, image_bits, run, temp};

#[test]
fn a_reloaded_model_renders_bitwise_as_the_fit_and_as_render_picture() {
    let data = ball_dataset(8, 2, 10);
    let settings = FitSettings {
        grid: 8,
        batch: 128,
        grow: false,
        sampling: Sampling::Uniform,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(5));
    let result = run::<f32>(&data, &settings, None, None);
    let file = temp("render.safetensors");
    let extra = BTreeMap::from([
        ("views".to_string(), "8".to_string()),
        ("note".to_string(), "any text, \"quoted\"\nor not".to_string()),
    ]);
    save(&file, &result.model, &result.training, &settings, &extra).unwrap();
    let back = load::<f32, DenseGrid<f32>>(&file).unwrap();
    assert_eq!(grid_bits(&back.start.model), grid_bits(&result.model));
    assert_eq!((back.settings, &back.extra), (settings, &extra));
    let again = render_test_views(&back.start.model, &data, &settings, None).unwrap();
    assert_eq!(image_bits(&again), image_bits(&result.renders));
    // Any picture's renderer, with depth, gives the same colours.
    let options = RenderOptions {
        background: data.background,
        depth: true,
        ..RenderOptions::default()
    };
    for (t, want) in data.test.iter().zip(&result.renders) {
        let (origins, directions) = t.rays();
        let r = render_picture(&back.start.model, None, &origins, &directions, t.size(), &options).unwrap();
        assert_eq!(image_bits(&[r.color]), image_bits(std::slice::from_ref(want)));
        assert_eq!(r.depth.unwrap().dim(), (10, 10));
    }
    let info = read_info(&file).unwrap();
    assert_eq!((info.nodes, info.step), (8, 5));
    assert_eq!(info.seconds.to_bits(), result.training.seconds.to_bits());
    assert_eq!(info.kind, "dense-grid");
    assert_eq!((info.settings, info.extra), (settings, extra));
    let _ = std::fs::remove_file(&file);
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

/// The tensor `name` of a file being edited.
fn tensor<'a>(tensors: &'a mut [(String, TensorData)], name: &str) -> &'a mut TensorData {
    &mut tensors.iter_mut().find(|(n, _)| n == name).unwrap().1
}

/// A 2-step fit of a 4^3 grid with `sampling`, saved to the temporary file `name`.
fn small_saved_fit(sampling: Sampling, name: &str) -> PathBuf {
    let settings = FitSettings {
        grid: 4,
        batch: 64,
        sampling,
        grow: false,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(2));
    let result = run::<f32>(&ball_dataset(8, 2, 10), &settings, None, None);
    let file = temp(name);
    save(&file, &result.model, &result.training, &settings, &BTreeMap::new()).unwrap();
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
        assert_format(load::<f32, DenseGrid<f32>>(bad).unwrap_err(), what);
    }
}

#[test]
fn bad_files_are_refused_with_a_typed_error() {
    let good = small_saved_fit(Sampling::Uniform, "good.safetensors");
    load::<f32, DenseGrid<f32>>(&good).unwrap();

    assert!(matches!(
        load::<f32, DenseGrid<f32>>(Path::new("/nonexistent/model.safetensors")),
        Err(CheckpointError::Read { .. })
    ));
    let junk = temp("junk.safetensors");
    std::fs::write(&junk, b"not a model at all").unwrap();
    assert_format(
        load::<f32, DenseGrid<f32>>(&junk).unwrap_err(),
        "not a safetensors file",
    );
    let truncated = temp("truncated.safetensors");
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() - 8]).unwrap();
    assert!(matches!(
        load::<f32, DenseGrid<f32>>(&truncated),
        Err(CheckpointError::Format { .. })
    ));
    match load::<f64, DenseGrid<f64>>(&good).unwrap_err() {
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
            Box::new(|t, _| tensor(t, "grid").bytes[4..8].copy_from_slice(&f32::NAN.to_le_bytes())),
        ),
        (
            "tensor \"grid\" is F32 [4, 4, 4, 4]",
            Box::new(|_, m| {
                m.insert("nodes".into(), "3".into());
            }),
        ),
        // A node count that would have a reader allocate without bound is refused first.
        (
            "metadata entry \"nodes\" is 100000, outside 2 to the settings' grid of 4",
            Box::new(|_, m| {
                m.insert("nodes".into(), "100000".into());
            }),
        ),
        (
            "would need",
            Box::new(|_, m| {
                let s = m["settings"].replace("\"grid\":4", "\"grid\":100000");
                m.insert("settings".into(), s);
                m.insert("nodes".into(), "100000".into());
            }),
        ),
        // The settings are one entry (JSON); a setting missing from it reads its default.
        (
            "no metadata entry \"settings\"",
            Box::new(|_, m| {
                m.remove("settings");
            }),
        ),
        (
            "no metadata entry \"step\"",
            Box::new(|_, m| {
                m.remove("step");
            }),
        ),
        (
            "settings: --grid must be at least 2",
            Box::new(|_, m| {
                let s = m["settings"].replace("\"grid\":4", "\"grid\":1");
                m.insert("settings".into(), s);
            }),
        ),
        (
            "format \"something else\"",
            Box::new(|_, m| {
                m.insert("format".into(), "something else".into());
            }),
        ),
        (
            "version \"1\"",
            Box::new(|_, m| {
                m.insert("version".into(), "1".into());
            }),
        ),
        (
            "model \"another\", not \"dense-grid\"",
            Box::new(|_, m| {
                m.insert("model".into(), "another".into());
            }),
        ),
        (
            "second moment",
            Box::new(|t, _| tensor(t, "adam.grid.second_moment").bytes[0..4].copy_from_slice(&(-1.0f32).to_le_bytes())),
        ),
        (
            "tensor \"adam.grid.first_moment\"",
            Box::new(|t, _| t.retain(|(n, _)| n != "adam.grid.first_moment")),
        ),
    ];
    each_edit_is_refused(&good, &bad, cases);
}

#[test]
fn bad_occupancy_tensors_are_refused_with_a_typed_error() {
    let good = small_saved_fit(Sampling::Occupancy, "good-occupancy.safetensors");
    // Before its first refresh every cell of the grid is occupied, and so after loading.
    let state = load::<f32, DenseGrid<f32>>(&good)
        .unwrap()
        .start
        .training
        .occupancy
        .unwrap();
    assert!(state.occupied.iter().all(|&o| o) && state.occupied.shape() == [3, 3, 3]);
    let bad = temp("bad-occupancy.safetensors");
    let cases: Vec<(&str, Box<Edit>)> = vec![
        (
            "holds the byte 2",
            Box::new(|t, _| tensor(t, "occupancy.occupied").bytes[5] = 2),
        ),
        (
            "must be finite and non-negative",
            Box::new(|t, _| tensor(t, "occupancy.estimate").bytes[8..12].copy_from_slice(&(-2.0f32).to_le_bytes())),
        ),
        (
            "tensor \"occupancy.estimate\"",
            Box::new(|t, _| t.retain(|(n, _)| n != "occupancy.estimate")),
        ),
        (
            "expected BOOL [3, 3, 3]",
            Box::new(|t, _| tensor(t, "occupancy.occupied").shape = vec![27]),
        ),
    ];
    each_edit_is_refused(&good, &bad, cases);
    // Without both tensors (a file from before grids were saved) there is no state to restore.
    rewrite(&good, &bad, |t, _| t.retain(|(n, _)| !n.starts_with("occupancy.")));
    assert_eq!(
        load::<f32, DenseGrid<f32>>(&bad).unwrap().start.training.occupancy,
        None
    );
}
