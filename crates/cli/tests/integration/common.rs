//! Helpers of the dataset tests: running `fogray` on paths, and a scene photographed exactly
//! (an opaque ball in front of a white background), written as an instant-ngp dataset.

use std::path::{Path, PathBuf};
use std::process::Command;

use fogray_data::write_instant_ngp;
use fogray_ops::{Intrinsics, LensDistortion, PinholeCamera};
use ndarray::Array3;

/// What a run of the binary left: its exit status, stdout and stderr.
pub struct Run {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

/// Runs `fogray` with `args` (no standard input).
pub fn fogray(args: &[&str]) -> Run {
    run_output(Command::new(env!("CARGO_BIN_EXE_fogray")).args(args).output().unwrap())
}

/// [`fogray`] run in the folder `cwd` (relative paths in `args` are relative to it).
pub fn fogray_in(cwd: &Path, args: &[&str]) -> Run {
    run_output(
        Command::new(env!("CARGO_BIN_EXE_fogray"))
            .current_dir(cwd)
            .args(args)
            .output()
            .unwrap(),
    )
}

/// `fogray render` of the model file `model` from the cameras of the dataset or transforms
/// file `cameras` into the folder `out`, with the flags `extra` after.
pub fn render_cameras(model: &Path, cameras: &Path, out: &Path, extra: &[&str]) -> Run {
    let mut args = vec![
        "render",
        "--model",
        arg(model),
        "--cameras",
        arg(cameras),
        "--out",
        arg(out),
    ];
    args.extend(extra);
    fogray(&args)
}

/// What a finished child process left, as a [`Run`].
pub fn run_output(out: std::process::Output) -> Run {
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8(out.stdout).unwrap(),
        stderr: String::from_utf8(out.stderr).unwrap(),
    }
}

/// The flags of the smallest fit the tests save a model from: one step of 64 rays on an 8^3
/// grid, JSON on stdout.
pub const TINY_FIT: [&str; 7] = ["--steps", "1", "--grid", "8", "--batch", "64", "--json"];

/// A [`TINY_FIT`] of the ball's dataset (8 views of 8x8 pixels), written in `dir/data`, with
/// the flags `extra`: the dataset and the run, which succeeded.
pub fn tiny_fit(dir: &Path, extra: &[&str]) -> (PathBuf, Run) {
    let data = dir.join("data");
    write_ball(&data, &cameras(8, intrinsics(8), LENS));
    let mut args = vec!["fit", "--data", arg(&data)];
    args.extend(TINY_FIT);
    args.extend(extra);
    let run = fogray(&args);
    assert_eq!(run.code, 0, "{}", run.stderr);
    (data, run)
}

/// A [`tiny_fit`] in `dir` saved to `dir/tiny.safetensors`: the dataset and the model file.
pub fn tiny_model(dir: &Path) -> (PathBuf, PathBuf) {
    let model = dir.join("tiny.safetensors");
    let (data, _) = tiny_fit(dir, &["--save-model", arg(&model)]);
    (data, model)
}

/// A path as a command-line argument (temporary paths are UTF-8 here).
pub fn arg(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// The ball's radius; it sits at the origin.
pub const RADIUS: f64 = 0.5;
/// The ball's colour (opaque), far from the white background in every channel but red.
pub const BALL: [f64; 3] = [0.9, 0.35, 0.1];
/// How far every camera is from the origin.
pub const EYE_DISTANCE: f64 = 3.0;

/// A lens as instant-ngp / COLMAP calibrate them: barrel distortion and a little tangential.
pub const LENS: LensDistortion = LensDistortion {
    k1: -0.1,
    k2: 0.02,
    p1: 0.001,
    p2: -0.001,
    k3: 0.0,
    k4: 0.0,
};

/// `size x size` pixels, focal lengths a little apart and the principal point off the centre
/// (by about a pixel in x and y), so that a reader that assumed a centred principal point or
/// square pixels would shift or stretch every ray. At `size = 24` the ball's silhouette
/// (angular radius asin(0.5 / 3) = 9.6 degrees) is about 16 pixels across.
pub fn intrinsics(size: usize) -> Intrinsics {
    let s = size as f64;
    Intrinsics {
        fx: 1.85 * s,
        fy: 1.9 * s,
        cx: 0.5 * s + 0.7,
        cy: 0.5 * s - 1.2,
        width: size,
        height: size,
    }
}

/// `n` cameras with intrinsics `k` and lens `lens` spread evenly over the sphere of radius 3
/// (a Fibonacci lattice), each looking at the origin, up `+z` (`+y` for a steep view).
pub fn cameras(n: usize, k: Intrinsics, lens: LensDistortion) -> Vec<PinholeCamera> {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = std::f64::consts::PI * (1.0 + 5f64.sqrt()) * (i as f64 + 0.5);
            let eye = [r * phi.cos(), r * phi.sin(), z].map(|x| EYE_DISTANCE * x);
            let up = if z.abs() > 0.99 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            PinholeCamera::look_at(k, eye, [0.0; 3], up)
                .unwrap()
                .with_distortion(lens)
                .unwrap()
        })
        .collect()
}

/// The exact photograph from `camera`: a pixel is the ball's colour where its ray (through
/// the lens) passes within the radius of the origin, else white. No anti-aliasing: each pixel
/// is its centre's ray, as fogray renders it.
pub fn photograph(camera: &PinholeCamera) -> Array3<f64> {
    let k = camera.intrinsics();
    let o = camera.centre();
    let mut image = Array3::from_elem((k.height, k.width, 3), 1.0);
    for row in 0..k.height {
        for col in 0..k.width {
            let d = camera.direction(row, col);
            let t = -(o[0] * d[0] + o[1] * d[1] + o[2] * d[2]);
            let miss: f64 = (0..3).map(|a| (o[a] + t * d[a]).powi(2)).sum();
            if t > 0.0 && miss < RADIUS * RADIUS {
                for (c, v) in BALL.iter().enumerate() {
                    image[[row, col, c]] = *v;
                }
            }
        }
    }
    image
}

/// The file stem of frame `i`.
pub fn frame_name(i: usize) -> String {
    format!("view_{i:02}")
}

/// Writes the exact photographs from `cameras` as an instant-ngp dataset in `dir`
/// (`dir/transforms.json`, `dir/images/view_NN.png`); returns the photographs.
pub fn write_ball(dir: &Path, cameras: &[PinholeCamera]) -> Vec<Array3<f64>> {
    let photos: Vec<Array3<f64>> = cameras.iter().map(photograph).collect();
    let names: Vec<String> = (0..cameras.len()).map(frame_name).collect();
    let frames: Vec<_> = names
        .iter()
        .zip(cameras)
        .zip(&photos)
        .map(|((n, c), p)| (n.as_str(), c, p))
        .collect();
    write_instant_ngp(dir, &frames).unwrap();
    photos
}

/// PSNR (dB, peak 1) of `renders` against `photos`, over all their values together.
pub fn psnr(renders: &[&Array3<f64>], photos: &[&Array3<f64>]) -> f64 {
    assert_eq!(renders.len(), photos.len());
    let (mut sum, mut count) = (0.0, 0usize);
    for (r, p) in renders.iter().zip(photos) {
        assert_eq!(r.dim(), p.dim());
        sum += r.iter().zip(p.iter()).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        count += r.len();
    }
    -10.0 * (sum / count as f64).log10()
}

/// Asserts a refusal of bad input: exit status 2, nothing on stdout, and one line on stderr
/// that contains `names` (the offending file's name).
pub fn assert_refused(run: &Run, names: &str, what: &str) {
    assert_eq!(run.code, 2, "{what}: status {}, stderr {:?}", run.code, run.stderr);
    assert!(run.stdout.is_empty(), "{what}: stdout {:?}", run.stdout);
    assert_eq!(run.stderr.lines().count(), 1, "{what}: stderr {:?}", run.stderr);
    assert!(run.stderr.ends_with('\n'), "{what}: stderr {:?}", run.stderr);
    assert!(
        run.stderr.contains(names),
        "{what}: stderr {:?} does not name {names:?}",
        run.stderr
    );
    assert!(!run.stderr.contains("panicked"), "{what}: {:?}", run.stderr);
}
