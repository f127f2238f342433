//! What `fogray` does to a user's files: an output that would land on the command's own
//! input is refused before any work (exit status 2, one line naming it) and every input is
//! left byte for byte; a link planted in the output folder is never written through; a write
//! that fails half way (a full disk) or Ctrl-C leaves no temporary behind.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fogray_data::write_blender;
use fogray_fit::checkpoint::save;
use fogray_fit::dense::DenseGrid;
use fogray_fit::model::RadianceField;
use fogray_fit::settings::{FitSettings, ModelKind, Precision};
use fogray_fit::state::TrainingState;
use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::Array3;

use crate::common::{arg, assert_refused, fogray, render_cameras, run_output, TINY_FIT};

/// A Blender dataset `dir/data` of four 8x8 views (`transforms_train.json`, `train/v0.png`
/// ...) and a fresh 8^3 dense model `dir/model.safetensors` (a render of it is grey haze,
/// which is all these tests need).
fn scene(dir: &Path) -> (PathBuf, PathBuf) {
    let data = dir.join("data");
    let k = Intrinsics::from_vertical_fov(8, 8, 0.8).unwrap();
    let eyes = [[3.0, 0.0, 0.5], [0.0, 3.0, 0.5], [-3.0, 0.0, 0.5], [0.0, -3.0, 0.5]];
    let cameras: Vec<PinholeCamera> = eyes
        .iter()
        .map(|&eye| PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap())
        .collect();
    let images: Vec<Array3<f64>> = (0..eyes.len())
        .map(|i| Array3::from_shape_fn((8, 8, 3), |(a, b, c)| ((a + 2 * b + 3 * c + i) % 7) as f64 / 6.0))
        .collect();
    let names: Vec<String> = (0..eyes.len()).map(|i| format!("v{i}")).collect();
    let frames: Vec<_> = names
        .iter()
        .zip(&cameras)
        .zip(&images)
        .map(|((n, c), p)| (n.as_str(), c, p))
        .collect();
    write_blender(&data, &frames).unwrap();
    let model = dir.join("model.safetensors");
    write_model(&model);
    (data, model)
}

/// A dense model of 8^3 nodes in f32 over the box [-1.5, 1.5]^3: a dense ball of radius 1 at
/// the origin (raw density 50 inside, -20 outside), so that it renders and has a surface.
pub fn write_model(path: &Path) {
    const NODES: usize = 8;
    let settings = FitSettings {
        grid: NODES,
        grow: false,
        sh_degree: 0,
        model: ModelKind::Dense,
        precision: Precision::F32,
        ..FitSettings::default()
    };
    let mut model = DenseGrid::<f32>::fresh(&settings, NODES).unwrap();
    let id = model.params().ids().next().unwrap();
    let mut values = model.params_mut().get_mut(id).unwrap();
    let shape = values.shape().to_vec();
    let rows = ndarray::Array2::from_shape_fn((NODES * NODES * NODES, 4), |(l, c)| {
        let i = [l / (NODES * NODES), l / NODES % NODES, l % NODES];
        let r2: f32 = i
            .iter()
            .map(|&x| (-1.5 + 3.0 * x as f32 / (NODES - 1) as f32).powi(2))
            .sum();
        match c {
            0 if r2 < 1.0 => 50.0,
            0 => -20.0,
            _ => 0.5,
        }
    });
    values.assign(&rows.into_shape_with_order(shape).unwrap());
    save(path, &model, &TrainingState::default(), &settings, &BTreeMap::new()).unwrap();
}

/// Every file under `dir` (recursively) and its bytes; links as the path they name.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            if meta.is_symlink() {
                let target = std::fs::read_link(&path).unwrap();
                files.insert(path, target.into_os_string().into_encoded_bytes());
            } else if meta.is_dir() {
                stack.push(path);
            } else {
                files.insert(path.clone(), std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// The names under `dir` (recursively) that look like a temporary or partial file; entries
/// that vanish while it looks (a running command renaming its files) are passed over.
fn leftovers(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(entry.path());
            } else if name.starts_with('.') || name.contains("partial") || name.ends_with(".tmp") {
                found.push(name);
            }
        }
    }
    found
}

#[test]
fn a_render_into_its_own_dataset_is_refused_and_the_dataset_is_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let (data, model) = scene(dir.path());
    let before = snapshot(dir.path());
    let train = data.join("train");
    let roundabout = data.join("train/../train");
    for (out, why) in [
        (&data, "the dataset's folder"),
        (&train, "its pictures' folder"),
        (&roundabout, "the same through .."),
    ] {
        let run = render_cameras(&model, &data, out, &[]);
        assert_refused(&run, "refused as an output", why);
        assert!(run.stderr.contains(arg(out)), "{why}: {}", run.stderr);
        assert_eq!(snapshot(dir.path()), before, "{why}: a file changed");
    }
    // A transforms file given alone protects its pictures: a frame's PNG may not land on one.
    let transforms = data.join("transforms_train.json");
    let run = render_cameras(&model, &transforms, &train, &[]);
    assert_refused(&run, "it is the input", "a picture of the transforms file");
    assert_eq!(snapshot(dir.path()), before);
    // Beside the dataset, the render runs.
    let out = dir.path().join("renders");
    let run = render_cameras(&model, &data, &out, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(run.stdout.lines().count(), 4);
}

#[test]
fn an_export_onto_its_model_and_a_gif_onto_a_folder_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = scene(dir.path());
    let before = snapshot(dir.path());
    let run = fogray(&["export", "--model", arg(&model), "--mesh", arg(&model)]);
    assert_refused(&run, "it is the input", "the mesh onto the model");
    assert_eq!(snapshot(dir.path()), before);
    // The model has a surface: beside it, the same export writes a mesh.
    let mesh = dir.path().join("mesh.ply");
    let run = fogray(&["export", "--model", arg(&model), "--mesh", arg(&mesh)]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(std::fs::read(&mesh).unwrap().starts_with(b"ply\n"));
    // A GIF named after a folder: refused before the first frame (none is written).
    let out = dir.path().join("orbit");
    let folder = dir.path().join("a-folder");
    std::fs::create_dir(&folder).unwrap();
    let run = fogray(&[
        "render",
        "--model",
        arg(&model),
        "--orbit",
        "3",
        "--size",
        "8x8",
        "--out",
        arg(&out),
        "--gif",
        arg(&folder),
    ]);
    assert_refused(&run, "it is a folder, where a file is expected", "--gif onto a folder");
    assert!(!out.exists(), "no frame rendered");
}

#[test]
fn a_fit_saving_onto_its_transforms_or_reporting_into_its_dataset_is_refused_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = scene(dir.path());
    let before = snapshot(&data);
    let transforms = data.join("transforms_train.json");
    let mut args = vec!["fit", "--data", arg(&data), "--save-model", arg(&transforms)];
    args.extend(TINY_FIT);
    assert_refused(
        &fogray(&args),
        "refused as an output",
        "--save-model onto the transforms file",
    );
    let mut args = vec!["fit", "--data", arg(&data), "--out", arg(&data)];
    args.extend(TINY_FIT);
    assert_refused(&fogray(&args), "refused as an output", "--out into the dataset");
    // A folder where the model goes: refused before training, not after.
    let mut args = vec!["fit", "--data", arg(&data), "--save-model", arg(dir.path())];
    args.extend(TINY_FIT);
    assert_refused(
        &fogray(&args),
        "it is a folder, where a file is expected",
        "--save-model a folder",
    );
    // A report folder whose test/ links into the dataset: its held-out pictures would be
    // overwritten by the report's panels.
    #[cfg(unix)]
    {
        let report = dir.path().join("report");
        std::fs::create_dir(&report).unwrap();
        std::os::unix::fs::symlink(&data, report.join("test")).unwrap();
        let mut args = vec!["fit", "--data", arg(&data), "--out", arg(&report)];
        args.extend(TINY_FIT);
        assert_refused(
            &fogray(&args),
            "lies inside the input dataset folder",
            "--out whose test/ links into the dataset",
        );
    }
    assert_eq!(snapshot(&data), before);
}

#[cfg(unix)]
#[test]
fn links_planted_in_the_output_folder_are_never_written_through() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = scene(dir.path());
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, "the user's own file").unwrap();
    let out = dir.path().join("orbit");
    std::fs::create_dir(&out).unwrap();
    // The names fogray used to write through before renaming, each a link to the victim.
    let planted = [
        out.join(".frame-000.png.partial.png"),
        out.join(".frame-000-depth.png.partial.png"),
        dir.path().join(".orbit.gif.partial"),
    ];
    for link in &planted {
        std::os::unix::fs::symlink(&victim, link).unwrap();
    }
    let gif = dir.path().join("orbit.gif");
    let run = fogray(&[
        "render",
        "--model",
        arg(&model),
        "--orbit",
        "1",
        "--size",
        "8x8",
        "--depth",
        "--out",
        arg(&out),
        "--gif",
        arg(&gif),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "the user's own file");
    for link in &planted {
        assert_eq!(std::fs::read_link(link).unwrap(), victim, "{link:?} moved or replaced");
    }
    for file in [out.join("frame-000.png"), out.join("frame-000-depth.png")] {
        let meta = std::fs::symlink_metadata(&file).unwrap();
        assert!(meta.is_file(), "{file:?} is not a plain file");
        image::open(&file).unwrap_or_else(|e| panic!("{file:?}: {e}"));
    }
    assert!(std::fs::read(&gif).unwrap().starts_with(b"GIF89a"));
}

/// Runs `fogray` with `args` under a file size limit of 512 bytes (`ulimit -f 1` in POSIX
/// blocks), SIGXFSZ ignored, so that a write past the limit fails as on a full disk; `None`,
/// said on stderr, where the shell cannot limit a file's size.
fn fogray_on_a_full_disk(args: &[&str]) -> Option<crate::common::Run> {
    let script = r#"trap '' XFSZ; ulimit -f 1 || exit 99; exec "$@""#;
    let out = std::process::Command::new("sh")
        .args(["-c", script, "sh", env!("CARGO_BIN_EXE_fogray")])
        .args(args)
        .output()
        .unwrap();
    if out.status.code() == Some(99) {
        eprintln!("skipped: this shell cannot limit the size of a file (ulimit -f)");
        return None;
    }
    Some(run_output(out))
}

#[cfg(unix)]
#[test]
fn a_write_that_fails_half_way_leaves_no_temporary_and_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = scene(dir.path());
    let out = dir.path().join("orbit");
    // A depth map is a few kilobytes (its colour bar and labels): past the limit.
    let Some(run) = fogray_on_a_full_disk(&[
        "render",
        "--model",
        arg(&model),
        "--orbit",
        "1",
        "--size",
        "8x8",
        "--depth",
        "--out",
        arg(&out),
    ]) else {
        return;
    };
    assert_refused(&run, "frame-000-depth.png", "a depth map past the size limit");
    assert!(!out.join("frame-000-depth.png").exists());
    assert_eq!(leftovers(dir.path()), Vec::<String>::new());
}

#[cfg(unix)]
#[test]
fn a_fit_report_past_a_full_disk_leaves_only_whole_files_and_says_so_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = scene(dir.path());
    let out = dir.path().join("report");
    let mut args = vec!["fit", "--data", arg(&data), "--out", arg(&out)];
    args.extend(TINY_FIT);
    let Some(run) = fogray_on_a_full_disk(&args) else {
        return;
    };
    // The error names the report's file that did not fit; --json's summary is not printed.
    assert_refused(&run, arg(&out), "a fit report past the size limit");
    // What the report wrote before the disk filled is whole; the rest is absent (and the
    // report's folders are gone if nothing was written into them).
    let written = if out.exists() { snapshot(&out) } else { BTreeMap::new() };
    for (path, bytes) in written {
        match path.extension().and_then(|e| e.to_str()) {
            Some("png") => {
                image::load_from_memory(&bytes).unwrap_or_else(|e| panic!("{path:?} is not whole: {e}"));
            }
            Some("json") => {
                serde_json::from_slice::<serde_json::Value>(&bytes)
                    .unwrap_or_else(|e| panic!("{path:?} is not whole: {e}"));
            }
            _ => {}
        }
    }
    assert!(!out.join("report.md").exists(), "the report was written past the limit");
    assert_eq!(leftovers(dir.path()), Vec::<String>::new());
}

/// A folder made read-only for this process, made writable again on drop: by its permissions
/// (0o555), or where those do not bind (root), by the immutable attribute (`chattr +i`).
#[cfg(unix)]
struct Locked {
    path: PathBuf,
    immutable: bool,
}

#[cfg(unix)]
impl Locked {
    /// Locks `path` (a new folder), or `None` if neither way keeps this process from writing.
    fn new(path: PathBuf) -> Option<Locked> {
        use std::os::unix::fs::PermissionsExt;
        std::fs::create_dir(&path).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o555)).unwrap();
        let mut locked = Locked { path, immutable: false };
        if locked.binds() {
            return Some(locked);
        }
        let chattr = std::process::Command::new("chattr")
            .arg("+i")
            .arg(&locked.path)
            .output();
        locked.immutable = chattr.is_ok_and(|o| o.status.success());
        locked.binds().then_some(locked)
    }

    fn binds(&self) -> bool {
        let probe = self.path.join("probe");
        let refused = std::fs::write(&probe, "x").is_err();
        std::fs::remove_file(&probe).ok();
        refused
    }
}

#[cfg(unix)]
impl Drop for Locked {
    fn drop(&mut self) {
        use std::os::unix::fs::PermissionsExt;
        if self.immutable {
            std::process::Command::new("chattr")
                .arg("-i")
                .arg(&self.path)
                .status()
                .ok();
        }
        std::fs::set_permissions(&self.path, std::fs::Permissions::from_mode(0o755)).ok();
    }
}

#[cfg(unix)]
#[test]
fn a_read_only_output_folder_is_refused_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = scene(dir.path());
    let Some(locked) = Locked::new(dir.path().join("locked")) else {
        eprintln!("skipped: neither permissions nor chattr +i keep this user out of a folder");
        return;
    };
    let mesh = locked.path.join("mesh.ply");
    let export = fogray(&["export", "--model", arg(&model), "--mesh", arg(&mesh)]);
    let render = |out: &Path, gif: &Path| {
        let args = ["--orbit", "2", "--size", "8x8", "--out", arg(out), "--gif", arg(gif)];
        fogray(&[&["render", "--model", arg(&model)][..], &args].concat())
    };
    // Frames into the locked folder, the GIF beside it (started before the first frame).
    let (out, gif) = (dir.path().join("orbit"), dir.path().join("orbit.gif"));
    let frames = render(&locked.path, &gif);
    let gif_there = render(&out, &locked.path.join("orbit.gif"));
    drop(locked);
    assert_refused(&export, "cannot be written", "a mesh in a read-only folder");
    assert_refused(&frames, "cannot be written", "frames in a read-only folder");
    assert_refused(&gif_there, "cannot be written", "a GIF in a read-only folder");
    assert!(!out.exists() && !gif.exists(), "nothing rendered");
    // Not even the GIF's temporary.
    assert_eq!(leftovers(dir.path()), Vec::<String>::new());
}

#[cfg(unix)]
#[test]
fn ctrl_c_during_a_gif_leaves_no_temporary() {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = scene(dir.path());
    let out = dir.path().join("orbit");
    let gif = dir.path().join("orbit.gif");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_fogray"))
        .args([
            "render",
            "--model",
            arg(&model),
            "--orbit",
            "20000",
            "--size",
            "8x8",
            "--out",
            arg(&out),
            "--gif",
            arg(&gif),
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // The GIF's temporary exists from before the first frame to the last: wait for it.
    let start = Instant::now();
    while leftovers(dir.path()).is_empty() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the render ended before its GIF started"
        );
        assert!(start.elapsed() < Duration::from_secs(60), "no temporary appeared");
        std::thread::sleep(Duration::from_millis(10));
    }
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{status:?}");
    assert_eq!(leftovers(dir.path()), Vec::<String>::new());
    assert!(!gif.exists());
}
