//! Sizes and budgets that cannot be met are refused by the settings' check, in one line
//! naming the flag and the bytes, before anything is allocated; a model file whose metadata
//! disagrees with itself is refused naming the file.

use std::collections::{BTreeMap, HashMap};

use crate::checkpoint::{load, read_info, save, CheckpointError};
use crate::dense::DenseGrid;
use crate::settings::{Budget, FitSettings, ModelKind, Sampling};
use crate::FitError;
use fogray_ops::limits::Bytes;
use safetensors::tensor::TensorView;
use safetensors::SafeTensors;

use crate::testing::{ball_dataset, run, temp};

/// The one-line message of a refused size.
fn too_large(settings: &FitSettings, available: Option<Bytes>) -> String {
    let result = match available {
        Some(bytes) => settings.check_memory(bytes),
        None => settings.check(),
    };
    match result {
        Err(e @ FitError::TooLarge(_)) => e.to_string(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_grid_the_machine_cannot_hold_is_refused_with_its_bytes() {
    // 100000^3 nodes of density and RGB (4 f32) in 5 copies (values, two gradients, Adam's
    // two moments): 8e16 bytes, and the stage before it, 50000^3 nodes, 1e16 more.
    let settings = FitSettings {
        grid: 100_000,
        ..FitSettings::DEFAULT
    };
    let e = too_large(&settings, None);
    assert!(
        e.starts_with("--grid 100000 would need 90.0 PB for the dense grid (f32, 4 channels a node); "),
        "{e}"
    );
    assert!(e.ends_with(" available") && !e.contains('\n'), "{e}");
    // Without growth, 1000^3 nodes: 8e10 bytes, against the 24 GB machine of the report.
    let fixed = FitSettings {
        grid: 1000,
        grow: false,
        ..FitSettings::DEFAULT
    };
    assert_eq!(
        too_large(&fixed, Some(Bytes(24_000_000_000))),
        "--grid 1000 would need 80.0 GB for the dense grid (f32, 4 channels a node); 24.0 GB available"
    );
    // A sparse grid is checked as if it kept every node (as it may): 5 bytes a node more for
    // its index and keep mask.
    let sparse = FitSettings {
        model: ModelKind::Sparse,
        ..fixed
    };
    assert!(too_large(&sparse, Some(Bytes(24_000_000_000))).contains("would need 85.0 GB for the sparse grid"));
}

#[test]
fn a_batch_the_machine_cannot_hold_is_refused_with_its_bytes() {
    // At 64 nodes a ray takes 2 * 63 = 126 samples of (15 + 2 * 4) f32 and an 8-byte index
    // (100 bytes), and holds 29 f32 and an 8-byte row of its own (124): 12724 bytes a ray.
    let settings = FitSettings {
        batch: 4_000_000_000,
        ..FitSettings::DEFAULT
    };
    let e = too_large(&settings, None);
    assert!(
        e.starts_with("--batch 4000000000 would need 50.9 TB for a step's rays at --grid 64; "),
        "{e}"
    );
    let hundred_million = FitSettings {
        batch: 100_000_000,
        ..FitSettings::DEFAULT
    };
    assert_eq!(
        too_large(&hundred_million, Some(Bytes(24_000_000_000))),
        "--batch 100000000 would need 1.27 TB for a step's rays at --grid 64; 24.0 GB available"
    );
}

#[test]
fn a_long_fit_of_real_photographs_fits_a_modest_machine() {
    // The lattice, model and colour of `fogray fit`'s long fits: a sparse 192^3 grid with
    // colour of degree 1 (13 channels), 8192 rays a step.
    let settings = FitSettings {
        grid: 192,
        model: ModelKind::Sparse,
        sh_degree: 1,
        ..FitSettings::DEFAULT
    };
    settings.check_memory(Bytes(8_000_000_000)).unwrap();
}

#[test]
fn budgets_that_cannot_end_are_refused() {
    for (settings, flag) in [
        (
            FitSettings::DEFAULT.with_budget(Budget::Seconds(1e308)),
            "--seconds 1e308: at most 604800",
        ),
        (
            FitSettings::DEFAULT.with_budget(Budget::Steps(usize::MAX)),
            "--steps 18446744073709551615: at most",
        ),
    ] {
        let e = settings.check().unwrap_err().to_string();
        assert!(e.starts_with(flag) && !e.contains('\n'), "{e}");
    }
    FitSettings::DEFAULT
        .with_budget(Budget::Seconds(604_800.0))
        .check()
        .unwrap();
    FitSettings::DEFAULT
        .with_budget(Budget::Steps(100_000_000))
        .check()
        .unwrap();
}

#[test]
fn a_model_whose_precision_entry_disagrees_with_its_settings_is_refused() {
    let settings = FitSettings {
        grid: 4,
        batch: 64,
        grow: false,
        sampling: Sampling::Uniform,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(1));
    let result = run::<f32>(&ball_dataset(8, 2, 10), &settings, None, None);
    let good = temp("precision-good.safetensors");
    save(&good, &result.model, &result.training, &settings, &BTreeMap::new()).unwrap();
    // The same f32 tensors and settings, the metadata's precision entry rewritten to f64.
    let bytes = std::fs::read(&good).unwrap();
    let (_, header) = SafeTensors::read_metadata(&bytes).unwrap();
    let mut meta: HashMap<String, String> = header.metadata().clone().unwrap();
    assert_eq!(meta.insert("precision".into(), "f64".into()).as_deref(), Some("f32"));
    let parsed = SafeTensors::deserialize(&bytes).unwrap();
    let tensors: Vec<(String, TensorView<'_>)> = parsed.tensors();
    let bad = temp("precision-f64-over-f32.safetensors");
    safetensors::serialize_to_file(tensors, Some(meta), &bad).unwrap();
    for e in [
        read_info(&bad).unwrap_err(),
        load::<f32, DenseGrid<f32>>(&bad).unwrap_err(),
    ] {
        match &e {
            CheckpointError::Format { path, message } => {
                assert_eq!(path, &bad);
                assert!(
                    message.contains("\"precision\" is \"f64\" but its settings say \"f32\""),
                    "{message}"
                );
            }
            other => panic!("{other:?}"),
        }
        assert!(e.to_string().contains(&*bad.to_string_lossy()));
    }
    let _ = std::fs::remove_file(&good);
    let _ = std::fs::remove_file(&bad);
}
