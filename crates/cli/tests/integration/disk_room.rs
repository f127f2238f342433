//! A fit whose model or report cannot fit on its disk is refused in one line before it trains
//! (the disk's free space against the fewest bytes each output takes), and the floor it checks
//! is never more than what the fit then writes.
//!
//! The full disks are small tmpfs mounts, made where this process may mount (root, or a user
//! namespace that allows it) and skipped with a message where it may not.

use std::path::{Path, PathBuf};
use std::process::Command;

use fogray_fit::checkpoint::read_info;
use fogray_fit::settings::{FitSettings, ModelKind};

use crate::common::{arg, assert_refused, fogray, tiny_fit};

/// A tmpfs of `kib` KiB mounted on a new folder, unmounted on drop.
struct TinyDisk {
    path: PathBuf,
}

impl TinyDisk {
    /// Mounts a tmpfs of `kib` KiB on `dir/disk`, filled to the last block if `filled`;
    /// `None`, said on stderr, where this process may not mount one.
    fn new(dir: &Path, kib: u64, filled: bool) -> Option<TinyDisk> {
        let path = dir.join("disk");
        std::fs::create_dir(&path).unwrap();
        let mounted = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs", arg(&path)])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !mounted {
            eprintln!("skipped: this process may not mount a tmpfs (mount -t tmpfs needs root)");
            return None;
        }
        let disk = TinyDisk { path };
        if filled {
            // Written until the disk refuses: what is left is less than a block.
            let filler = vec![0u8; 1024];
            let mut file = std::fs::File::create(disk.path.join("filler")).unwrap();
            while std::io::Write::write_all(&mut file, &filler).is_ok() {}
        }
        Some(disk)
    }

    /// The files on the disk, by name.
    fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&self.path)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
}

impl Drop for TinyDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.path).status();
    }
}

/// The ball's dataset for a fit (8 views of 8x8 pixels), in `dir/data`.
fn dataset(dir: &Path) -> PathBuf {
    tiny_fit(dir, &[]).0
}

#[test]
fn a_model_file_onto_a_full_disk_is_refused_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path());
    let Some(disk) = TinyDisk::new(dir.path(), 64, true) else {
        return;
    };
    let model = disk.path.join("m.safetensors");
    // --seconds 30: a fit that trained before failing would take that long; this one stops
    // before the first step (and says nothing of training).
    let run = fogray(&[
        "fit",
        "--data",
        arg(&data),
        "--seconds",
        "30",
        "--grid",
        "16",
        "--save-model",
        arg(&model),
    ]);
    assert_refused(&run, arg(&model), "a model onto a full disk");
    // A sparse grid of 16 grows from 4 nodes a side: its mask alone is 4^3 bytes, after the 8
    // bytes of the safetensors header's length.
    assert!(
        run.stderr
            .contains("(the model file) needs at least 72 B; its disk has 0 B free"),
        "{}",
        run.stderr
    );
    assert_eq!(disk.names(), ["filler"]);
}

#[test]
fn a_model_larger_than_an_empty_disk_is_refused_with_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path());
    let Some(disk) = TinyDisk::new(dir.path(), 200, false) else {
        return;
    };
    let model = disk.path.join("m.safetensors");
    let run = fogray(&[
        "fit",
        "--data",
        arg(&data),
        "--steps",
        "1000000",
        "--grid",
        "32",
        "--model",
        "dense",
        "--no-grow",
        "--sh-degree",
        "0",
        "--save-model",
        arg(&model),
    ]);
    assert_refused(&run, arg(&model), "a model larger than the disk");
    // 32^3 nodes of density and RGB in f32: 32768 x 4 x 4 + 8 = 524 296 bytes, against the
    // 200 KiB (204 800 bytes) of the disk.
    assert!(
        run.stderr.contains("needs at least 524 kB; its disk has 205 kB free"),
        "{}",
        run.stderr
    );
    assert_eq!(disk.names(), Vec::<String>::new());
}

#[test]
fn a_report_onto_a_full_disk_is_refused_before_training_and_leaves_no_folder() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path());
    let Some(disk) = TinyDisk::new(dir.path(), 64, true) else {
        return;
    };
    let out = disk.path.join("report");
    let run = fogray(&[
        "fit",
        "--data",
        arg(&data),
        "--steps",
        "2",
        "--grid",
        "8",
        "--out",
        arg(&out),
    ]);
    assert_refused(&run, arg(&out), "a report onto a full disk");
    // A held-out view's picture and the two plots as PNG (57 bytes each at the least), and
    // four text files of a byte at the least: 175 bytes.
    assert!(
        run.stderr.contains("(the report) needs at least 175 B"),
        "{}",
        run.stderr
    );
    assert_eq!(disk.names(), ["filler"]);
}

#[test]
fn a_fit_that_fits_its_disk_runs_and_writes_no_less_than_the_floor() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path());
    // A disk with room for the models below (the largest, a dense 8^3 grid of 13 channels
    // with Adam's moments, is about 80 kB) and little more.
    let Some(disk) = TinyDisk::new(dir.path(), 256, false) else {
        return;
    };
    for kind in ["dense", "sparse", "splats"] {
        let extension = if kind == "splats" { "ply" } else { "safetensors" };
        let model = disk.path.join(format!("{kind}.{extension}"));
        let mut args = vec!["fit", "--data", arg(&data), "--steps", "2", "--grid", "8", "--json"];
        args.extend(["--model", kind, "--sh-degree", "1", "--save-model", arg(&model)]);
        if kind == "dense" {
            args.push("--no-grow");
        }
        let run = fogray(&args);
        assert_eq!(run.code, 0, "{kind}: {}", run.stderr);
        let written = std::fs::metadata(&model).unwrap().len();
        // The splats' settings are the flags' (their PLY has no metadata); a grid's, the file's.
        let settings = match kind {
            "splats" => FitSettings {
                model: ModelKind::Splats,
                sh_degree: 1,
                ..FitSettings::default()
            },
            _ => read_info(&model).unwrap().settings,
        };
        let floor = settings.model_file_floor();
        assert!(floor > 8, "{kind}: floor {floor}");
        assert!(written >= floor, "{kind}: {written} bytes written, floor {floor}");
    }
}
