//! `fogray export --mesh` on saved models (a ball built directly, dense in f32 and sparse in
//! f64, so both dispatches run): a closed PLY mesh of the ball's colour, and refusals of bad
//! arguments with exit status 2 and one line.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use fogray_fit::checkpoint::save;
use fogray_fit::dense::DenseGrid;
use fogray_fit::model::RadianceField;
use fogray_fit::settings::{FitSettings, ModelKind, Precision};
use fogray_fit::sparse::SparseGrid;
use fogray_fit::state::TrainingState;
use fogray_tape::Float;
use ndarray::Array2;

use crate::common::{arg, assert_refused, fogray};

const NODES: usize = 20;
const RADIUS: f64 = 0.5;
/// Raw colour channels (view-independent) everywhere.
const RAW_COLOR: [f64; 3] = [1.0, 0.0, -2.0];

fn settings(model: ModelKind, precision: Precision) -> FitSettings {
    FitSettings {
        grid: NODES,
        grow: false,
        sh_degree: 0,
        shift: 0.0,
        model,
        precision,
        ..FitSettings::default()
    }
}

/// Every node's raw values `[NODES^3, 4]` in linear order: density 50 within the ball of
/// [`RADIUS`] at the origin (raw 50), about 0 outside (raw -20).
fn ball_rows<F: Float>() -> Array2<F> {
    Array2::from_shape_fn((NODES * NODES * NODES, 4), |(l, c)| {
        if c > 0 {
            return F::lit(RAW_COLOR[c - 1]);
        }
        let i = [l / (NODES * NODES), l / NODES % NODES, l % NODES];
        let r2: f64 = i
            .iter()
            .map(|&x| (-1.0 + 2.0 * x as f64 / (NODES - 1) as f64).powi(2))
            .sum();
        F::lit(if r2 < RADIUS * RADIUS { 50.0 } else { -20.0 })
    })
}

/// Saves a ball model of kind `M` in `F` to `path`.
fn save_ball<F: Float, M: RadianceField<F>>(path: &Path, settings: &FitSettings) {
    let mut model = M::fresh(settings, NODES).unwrap();
    let id = model.params().ids().next().unwrap();
    let rows = ball_rows::<F>();
    let mut values = model.params_mut().get_mut(id).unwrap();
    let shape = values.shape().to_vec();
    values.assign(&rows.into_shape_with_order(shape).unwrap());
    save(path, &model, &TrainingState::default(), settings, &BTreeMap::new()).unwrap();
}

/// The counts, colours and faces of a binary PLY written by `fogray export`.
fn read_ply(path: &Path) -> (usize, Vec<[u8; 3]>, Vec<[i32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..at]).unwrap();
    assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"), "{header}");
    let count = |e: &str| -> usize {
        let line = header
            .lines()
            .find(|l| l.starts_with(&format!("element {e} ")))
            .unwrap();
        line.rsplit(' ').next().unwrap().parse().unwrap()
    };
    let (v, f) = (count("vertex"), count("face"));
    assert_eq!(bytes.len(), at + 15 * v + 13 * f);
    let colors = (0..v).map(|i| {
        let b = &bytes[at + 15 * i + 12..];
        [b[0], b[1], b[2]]
    });
    let faces = (0..f).map(|i| {
        let b = &bytes[at + 15 * v + 13 * i..];
        assert_eq!(b[0], 3);
        std::array::from_fn(|k| i32::from_le_bytes(b[1 + 4 * k..5 + 4 * k].try_into().unwrap()))
    });
    (v, colors.collect(), faces.collect())
}

#[test]
fn export_writes_a_closed_mesh_of_a_saved_ball_in_its_colour() {
    let dir = tempfile::tempdir().unwrap();
    let dense = dir.path().join("dense.safetensors");
    let sparse = dir.path().join("sparse.safetensors");
    save_ball::<f32, DenseGrid<f32>>(&dense, &settings(ModelKind::Dense, Precision::F32));
    save_ball::<f64, SparseGrid<f64>>(&sparse, &settings(ModelKind::Sparse, Precision::F64));
    let sigmoid = |x: f64| 1.0 / (1.0 + (-x).exp());
    let want = RAW_COLOR.map(|x| (255.0 * sigmoid(x)).round() as u8);
    let mut counts = Vec::new();
    for model in [&dense, &sparse] {
        let out = dir.path().join("ball.ply");
        let run = fogray(&["export", "--model", arg(model), "--mesh", arg(&out)]);
        assert_eq!(run.code, 0, "{}", run.stderr);
        let (v, colors, faces) = read_ply(&out);
        let summary = format!(
            "{}: {v} vertices, {} triangles, density level ",
            out.display(),
            faces.len()
        );
        let level = run
            .stdout
            .trim()
            .strip_prefix(&summary)
            .unwrap_or_else(|| panic!("{}", run.stdout));
        let level: f64 = level
            .strip_suffix(&format!(" on a {NODES}^3 lattice"))
            .unwrap()
            .parse()
            .unwrap();
        // The default level: opacity 0.1 over one step, half a node spacing.
        let step = 1.0 / (NODES - 1) as f64;
        assert!((1.0 - (-level * step).exp() - 0.1).abs() < 1e-12, "{level}");
        assert!(faces.len() > 100);
        assert!(colors.iter().all(|&c| c == want), "{:?} != {want:?}", colors[0]);
        // Closed: each undirected edge in exactly two faces.
        let mut edges: HashMap<(i32, i32), usize> = HashMap::new();
        for f in &faces {
            assert!(f.iter().all(|&i| i >= 0 && (i as usize) < v));
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2));
        // No partial file is left beside it.
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left.len(), 3, "{left:?}");
        counts.push((v, faces.len()));
    }
    // The same values give the same mesh whatever the model's kind and precision.
    assert_eq!(counts[0], counts[1]);
    // A finer lattice and an explicit level.
    let out = dir.path().join("fine.ply");
    let run = fogray(&[
        "export",
        "--model",
        arg(&dense),
        "--mesh",
        arg(&out),
        "--level",
        "25",
        "--resolution",
        "31",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(
        run.stdout.contains("density level 25 on a 31^3 lattice"),
        "{}",
        run.stdout
    );
    assert!(read_ply(&out).0 > counts[0].0);
}

/// The good model's file with its metadata entry `model` set to `kind`.
fn with_kind(good: &Path, bad: &Path, kind: &str) {
    let bytes = std::fs::read(good).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let mut header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    header["__metadata__"]["model"] = serde_json::Value::String(kind.into());
    let mut text = serde_json::to_string(&header).unwrap();
    while text.len() % 8 != 0 {
        text.push(' ');
    }
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend(text.as_bytes());
    out.extend(&bytes[8 + n..]);
    std::fs::write(bad, out).unwrap();
}

#[test]
fn export_refuses_bad_arguments_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("ball.safetensors");
    save_ball::<f32, DenseGrid<f32>>(&model, &settings(ModelKind::Dense, Precision::F32));
    let out = dir.path().join("out.ply");
    let export = |extra: &[&str], model: &Path| {
        let mut args = vec!["export", "--model", arg(model), "--mesh", arg(&out)];
        args.extend(extra);
        fogray(&args)
    };
    let not_a_model = dir.path().join("notes.safetensors");
    std::fs::write(&not_a_model, "{\"frames\": []}").unwrap();
    assert_refused(&export(&[], &not_a_model), "notes.safetensors", "not safetensors");
    let unknown = dir.path().join("mlp.safetensors");
    with_kind(&model, &unknown, "mlp");
    assert_refused(&export(&[], &unknown), "\"mlp\" model", "an unknown kind");
    // The density on the lattice runs from softplus(-20) = 2.061e-9 to softplus(50) = 50.
    let run = export(&["--level", "60"], &model);
    assert_refused(&run, "range [", "a level above the range");
    assert!(run.stderr.contains(", 50.00] on the lattice"), "{}", run.stderr);
    assert_refused(
        &export(&["--level", "1e-12"], &model),
        "range [",
        "a level below the range",
    );
    assert_refused(&export(&["--level", "-1"], &model), "range [", "a negative level");
    for a in ["0", "1", "1.5", "-0.2"] {
        assert_refused(
            &export(&["--opacity", a], &model),
            "--opacity",
            "an opacity outside (0, 1)",
        );
    }
    assert_refused(
        &export(&["--opacity", "0.999999"], &model),
        "range [",
        "an opacity above the range",
    );
    for n in ["0", "1"] {
        assert_refused(
            &export(&["--resolution", n], &model),
            "--resolution",
            "a resolution below 2",
        );
    }
    assert_refused(
        &export(&["--level", "5", "--opacity", "0.5"], &model),
        "--level and --opacity",
        "both levels",
    );
    assert!(!out.exists(), "a refused export wrote {}", out.display());
    let nowhere = dir.path().join("no-such-dir").join("out.ply");
    let run = fogray(&["export", "--model", arg(&model), "--mesh", arg(&nowhere)]);
    assert_refused(&run, "no-such-dir", "an unwritable output");
    // A directory as the output: refused, and nothing left beside it.
    let run = fogray(&["export", "--model", arg(&model), "--mesh", arg(dir.path())]);
    assert_refused(
        &run,
        "it is a folder, where a file is expected",
        "a directory as the output",
    );
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 3, "{left:?}");
}
