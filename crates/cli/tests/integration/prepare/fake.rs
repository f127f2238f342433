//! A stand-in `colmap`: a shell script that answers `-h` as COLMAP 4.x does (the
//! `FeatureExtraction` / `FeatureMatching` option names), records each step's arguments,
//! prints feature extraction's progress, and copies the models of `$FAKE_MODELS` into the
//! mapper's output. `$FAKE_FAIL_MATCHING` makes matching fail; `$FAKE_STARTED` makes feature
//! extraction write its pid there and wait to be killed.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::Run;

const SCRIPT: &str = r#"#!/bin/sh
if [ "$1" = "-h" ]; then echo "COLMAP 4.0.0 -- Structure-from-Motion (a stand-in)"; exit 0; fi
if [ "$2" = "-h" ]; then
  echo "  --log_to_stderr arg (=1)"
  echo "  --FeatureExtraction.use_gpu arg (=1)"
  echo "  --FeatureMatching.use_gpu arg (=1)"
  exit 0
fi
echo "$*" >> "$FAKE_CALLS"
case "$1" in
  feature_extractor)
    if [ -n "$FAKE_STARTED" ]; then echo $$ > "$FAKE_STARTED"; exec sleep 30; fi
    for i in 1 2 3 4; do echo "Processed file [$i/4]"; done ;;
  *_matcher)
    if [ -n "$FAKE_FAIL_MATCHING" ]; then echo "matching broke" >&2; exit 3; fi ;;
  mapper)
    while [ $# -gt 0 ]; do if [ "$1" = "--output_path" ]; then out="$2"; fi; shift; done
    cp -R "$FAKE_MODELS"/. "$out"/ ;;
esac
"#;

/// The stand-in, installed in a folder of its own.
pub struct Colmap {
    bin: PathBuf,
    calls: PathBuf,
}

impl Colmap {
    /// Writes the script as `dir/fake-bin/colmap`.
    pub fn new(dir: &Path) -> Colmap {
        use std::os::unix::fs::PermissionsExt;
        let bin = dir.join("fake-bin");
        std::fs::create_dir(&bin).unwrap();
        let script = bin.join("colmap");
        std::fs::write(&script, SCRIPT).unwrap();
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
        Colmap {
            calls: dir.join("calls.txt"),
            bin,
        }
    }

    /// `fogray prepare ARGS` with the stand-in first on `PATH`.
    fn command(&self, args: &[&str], env: &[(&str, &Path)]) -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_fogray"));
        command
            .arg("prepare")
            .args(args)
            .env("PATH", format!("{}:/usr/bin:/bin", self.bin.display()))
            .env("FAKE_CALLS", &self.calls)
            .envs(env.iter().map(|(k, v)| (k, v.as_os_str())));
        command
    }

    /// Runs `fogray prepare ARGS` to its end.
    pub fn prepare(&self, args: &[&str], env: &[(&str, &Path)]) -> Run {
        let out = self.command(args, env).output().unwrap();
        Run {
            code: out.status.code().unwrap_or(-1),
            stdout: String::from_utf8(out.stdout).unwrap(),
            stderr: String::from_utf8(out.stderr).unwrap(),
        }
    }

    /// Starts `fogray prepare ARGS`, sends it SIGINT once feature extraction has started
    /// (the stand-in wrote `started`), and returns its exit status and stderr.
    pub fn prepare_then_ctrl_c(&self, args: &[&str], started: &Path) -> (i32, String) {
        let mut child = self
            .command(args, &[("FAKE_STARTED", started)])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let begin = Instant::now();
        while std::fs::read_to_string(started).map_or(true, |s| !s.ends_with('\n')) {
            assert!(
                begin.elapsed() < Duration::from_secs(20),
                "feature extraction never started"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        let kill = Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success());
        // It answers within its poll interval; the stand-in alone would sleep 30 s.
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            assert!(
                begin.elapsed() < Duration::from_secs(25),
                "fogray prepare ignored SIGINT"
            );
            std::thread::sleep(Duration::from_millis(10));
        };
        let mut stderr = String::new();
        child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
        (status.code().unwrap_or(-1), stderr)
    }

    /// The arguments of each step run, in order.
    pub fn calls(&self) -> Vec<String> {
        std::fs::read_to_string(&self.calls)
            .unwrap_or_default()
            .lines()
            .map(String::from)
            .collect()
    }
}

/// Writes a model into `dir`: `images.bin` registering `names` (each with no 2D point) and
/// `cameras.bin` with one OPENCV camera `width` pixels wide, laid out field by field as
/// COLMAP's binary format has them.
pub fn model(dir: &Path, names: &[&str], width: u64) {
    std::fs::create_dir_all(dir).unwrap();
    let mut images = (names.len() as u64).to_le_bytes().to_vec();
    for (i, name) in names.iter().enumerate() {
        images.extend((i as u32 + 1).to_le_bytes());
        for q in [1.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
            images.extend(q.to_le_bytes());
        }
        images.extend(1u32.to_le_bytes());
        images.extend(name.as_bytes());
        images.push(0);
        images.extend(0u64.to_le_bytes());
    }
    std::fs::write(dir.join("images.bin"), images).unwrap();
    let mut cameras = 1u64.to_le_bytes().to_vec();
    cameras.extend(1u32.to_le_bytes());
    cameras.extend(4i32.to_le_bytes());
    cameras.extend(width.to_le_bytes());
    cameras.extend((width * 3 / 4).to_le_bytes());
    for p in [500.0f64, 500.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0] {
        cameras.extend(p.to_le_bytes());
    }
    std::fs::write(dir.join("cameras.bin"), cameras).unwrap();
}
