//! `fogray prepare`: its refusals before any work, its handling of COLMAP through a stand-in
//! `colmap` script (the option names of the version it claims, a failing step, a mapper that
//! makes nothing or two models, Ctrl-C), and, where COLMAP is installed, a real run on a
//! rendered capture that fogray-data then loads.
#![cfg(unix)]

mod fake;
mod scene;

use std::path::Path;
use std::process::Command;

use crate::common::{arg, assert_refused, Run};

/// Runs `fogray prepare ARGS` with `PATH` set to `path` and the environment `env`.
fn prepare(args: &[&str], path: &str, env: &[(&str, &Path)]) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_fogray"))
        .arg("prepare")
        .args(args)
        .env("PATH", path)
        .envs(env.iter().map(|(k, v)| (k, v.as_os_str())))
        .output()
        .unwrap();
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8(out.stdout).unwrap(),
        stderr: String::from_utf8(out.stderr).unwrap(),
    }
}

/// A folder `dir/photos` of `names`, each file holding its own name (COLMAP is not run on
/// them by these tests).
fn photos(dir: &Path, names: &[&str]) -> std::path::PathBuf {
    let photos = dir.join("photos");
    std::fs::create_dir(&photos).unwrap();
    for name in names {
        std::fs::write(photos.join(name), name.as_bytes()).unwrap();
    }
    photos
}

#[test]
fn without_colmap_on_path_it_says_how_to_get_it_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let photos = photos(dir.path(), &["a.jpg", "b.JPG"]);
    let empty = dir.path().join("no-programs");
    std::fs::create_dir(&empty).unwrap();
    let out = dir.path().join("out");
    let run = prepare(&[arg(&photos), "--out", arg(&out)], arg(&empty), &[]);
    assert_refused(&run, "no colmap on PATH", "no colmap");
    assert!(run.stderr.contains("apt install colmap") && run.stderr.contains("colmap.github.io"));
    assert!(!out.exists());
}

#[test]
fn bad_folders_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let path = std::env::var("PATH").unwrap_or_default();
    let missing = dir.path().join("missing");
    let out = dir.path().join("out");
    let run = prepare(&[arg(&missing), "--out", arg(&out)], &path, &[]);
    assert_refused(&run, "missing is not a folder", "missing folder");

    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::write(empty.join("notes.txt"), b"x").unwrap();
    let run = prepare(&[arg(&empty), "--out", arg(&out)], &path, &[]);
    assert_refused(&run, "holds no photograph", "no photographs");

    let photos = photos(dir.path(), &["a.png"]);
    for inside in [photos.clone(), photos.join("prepared")] {
        let run = prepare(&[arg(&photos), "--out", arg(&inside)], &path, &[]);
        assert_refused(&run, "lies inside the photographs' folder", "--out inside");
    }
    // A flag error is one line too (clap's message).
    let run = prepare(&[arg(&photos)], &path, &[]);
    assert_refused(&run, "fogray prepare: error: ", "no --out");
    assert!(run.stderr.contains("--out"), "{}", run.stderr);
    let run = prepare(&[arg(&photos), "--out", arg(&empty)], &path, &[]);
    assert_refused(&run, "not an empty folder", "--out not empty");
    assert!(!out.exists() && !photos.join("prepared").exists());
    assert_eq!(std::fs::read_dir(&photos).unwrap().count(), 1);
}

#[test]
fn the_largest_model_becomes_sparse_0_and_the_summary_names_the_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let photos = photos(dir.path(), &["a.png", "b.png", "c.png", "d.png"]);
    // COLMAP's model 0 registers one photograph, its model 1 three.
    let models = dir.path().join("models");
    fake::model(&models.join("0"), &["d.png"], 640);
    fake::model(&models.join("1"), &["c.png", "a.png", "b.png"], 1920);
    let fake = fake::Colmap::new(dir.path());
    let out = dir.path().join("out");
    let run = fake.prepare(&[arg(&photos), "--out", arg(&out)], &[("FAKE_MODELS", &models)]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let lines: Vec<&str> = run.stdout.lines().collect();
    let model = out.join("sparse").join("0");
    assert_eq!(
        lines[0],
        format!(
            "registered 3 of 4 photographs into {}; left out: d.png",
            model.display()
        )
    );
    assert!(lines[1].contains("numbered 1, is moved to sparse/0"), "{}", run.stdout);
    // 1920 pixels wide: 1920 / 640 = 3.
    assert_eq!(
        lines[2],
        format!("fit it: fogray fit --data {} --downscale 3", out.display())
    );
    let bytes = |p: &Path| std::fs::read(p).unwrap();
    assert_eq!(
        bytes(&model.join("images.bin")),
        bytes(&models.join("1").join("images.bin"))
    );
    let other = out.join("sparse").join("1").join("images.bin");
    assert_eq!(bytes(&other), bytes(&models.join("0").join("images.bin")));
    assert!(!out.join(".sparse-partial").exists());
    for name in ["a.png", "b.png", "c.png", "d.png"] {
        assert_eq!(bytes(&out.join("images").join(name)), name.as_bytes());
        assert_eq!(bytes(&photos.join(name)), name.as_bytes());
    }
    // The option names of the version the script claims (4.x), COLMAP run on DIR/images.
    let calls = fake.calls();
    assert_eq!(calls.len(), 3, "{calls:?}");
    assert!(calls[0].starts_with("feature_extractor ") && calls[0].contains("--FeatureExtraction.use_gpu 0"));
    assert!(
        calls[0].contains("--ImageReader.camera_model OPENCV --"),
        "{}",
        calls[0]
    );
    assert!(calls[0].contains(&format!("--image_path {}", out.join("images").display())));
    assert!(calls[1].starts_with("exhaustive_matcher ") && calls[1].contains("--FeatureMatching.use_gpu 0"));
    assert!(calls[2].starts_with("mapper ") && calls[2].contains("--output_path"));
    let log = std::fs::read_to_string(out.join("colmap.log")).unwrap();
    assert!(
        log.contains("$ colmap feature_extractor") && log.contains("Processed file [4/4]"),
        "{log}"
    );
}

/// Asserts a failure after work began: exit status 2, nothing on stdout, the error the last
/// line of stderr, starting with `start`, every line before it a step done.
fn assert_failed(run: &Run, start: &str) {
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stdout.is_empty(), "{}", run.stdout);
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert!(lines.last().unwrap().starts_with(start), "{}", run.stderr);
    let done = &lines[1..lines.len() - 1];
    assert!(
        lines[0].starts_with("fogray prepare: COLMAP 4.0.0, 2 photographs"),
        "{}",
        run.stderr
    );
    assert!(done.iter().all(|l| l.contains(": done in ")), "{}", run.stderr);
}

#[test]
fn a_failing_step_or_an_empty_mapping_is_one_line_pointing_at_the_log() {
    let dir = tempfile::tempdir().unwrap();
    let photos = photos(dir.path(), &["a.jpg", "b.jpg"]);
    let fake = fake::Colmap::new(dir.path());
    let out = dir.path().join("out");
    let flag = dir.path().join("flag");
    let args = [arg(&photos), "--out", arg(&out), "--matching", "sequential"];
    let run = fake.prepare(&args, &[("FAKE_FAIL_MATCHING", &flag)]);
    let log = out.join("colmap.log");
    // The steps done are on stderr before it; the error is its last line.
    let expected = format!(
        "fogray prepare: error: COLMAP's sequential matching failed (exit status 3): see {}",
        log.display()
    );
    assert_failed(&run, &expected);
    assert!(std::fs::read_to_string(&log).unwrap().contains("matching broke"));
    assert!(!out.join("sparse").exists() && !out.join(".sparse-partial").exists());

    // A mapper that ends well but writes no model.
    let out = dir.path().join("out2");
    let empty = dir.path().join("no-models");
    std::fs::create_dir(&empty).unwrap();
    let run = fake.prepare(&[arg(&photos), "--out", arg(&out)], &[("FAKE_MODELS", &empty)]);
    assert_failed(&run, "fogray prepare: error: COLMAP's mapping reconstructed nothing");
    assert!(!out.join("sparse").exists() && !out.join(".sparse-partial").exists());
}

#[test]
fn ctrl_c_kills_colmap_and_leaves_no_model() {
    let dir = tempfile::tempdir().unwrap();
    let photos = photos(dir.path(), &["a.jpg", "b.jpg"]);
    let fake = fake::Colmap::new(dir.path());
    let out = dir.path().join("out");
    let started = dir.path().join("started");
    let (code, stderr) = fake.prepare_then_ctrl_c(&[arg(&photos), "--out", arg(&out)], &started);
    assert_eq!(code, 130, "{stderr}");
    let line = stderr.lines().last().unwrap();
    assert!(line.contains("interrupted during feature extraction"), "{stderr}");
    assert!(!out.join("sparse").exists() && !out.join(".sparse-partial").exists());
    // The stand-in (its pid in the file it wrote on starting) is gone.
    let pid = std::fs::read_to_string(&started).unwrap();
    assert!(!Path::new("/proc").join(pid.trim()).exists(), "colmap {pid} still runs");
}

/// A real COLMAP on twelve rendered views: skipped (with a message) where `colmap` is not on
/// `PATH`; CI does not install it.
#[test]
fn colmap_poses_a_rendered_capture_that_fogray_data_loads() {
    if Command::new("colmap").arg("-h").output().is_err() {
        eprintln!("skipped: no colmap on PATH (apt install colmap to run this test)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    scene::write_capture(&photos);
    let out = dir.path().join("out");
    let path = std::env::var("PATH").unwrap_or_default();
    let run = prepare(&[arg(&photos), "--out", arg(&out)], &path, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let first = run.stdout.lines().next().unwrap();
    let registered: usize = first
        .strip_prefix("registered ")
        .and_then(|r| r.split_once(' '))
        .and_then(|(n, _)| n.parse().ok())
        .unwrap_or_else(|| panic!("{first}"));
    assert!(first.contains(&format!("of {} photographs", scene::VIEWS)), "{first}");
    assert!(registered >= scene::VIEWS - 2, "{}", run.stdout);
    let data = fogray_data::load(&out, &fogray_data::LoadOptions::default()).unwrap();
    assert_eq!(data.format, fogray_data::Format::Colmap);
    assert_eq!(data.train.len() + data.test.len(), registered);
    assert_eq!(data.unregistered, scene::VIEWS - registered);
}
