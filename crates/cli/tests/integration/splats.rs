//! `fogray fit --model splats` from the command line: the ball's exact photographs as RGBA
//! (so that the splats start in the visual hull and train over random backgrounds), fitted,
//! scored on the held-out views and saved as a 3DGS PLY file; the grid commands refuse that
//! file in one line.

use fogray_data::write_instant_ngp;
use fogray_ops::LensDistortion;
use ndarray::Array3;
use serde_json::Value;

use crate::common::{arg, cameras, fogray, frame_name, intrinsics, photograph};

const VIEWS: usize = 24;
const SIZE: usize = 32;

#[test]
fn splats_fit_the_ball_and_are_saved_as_a_3dgs_ply() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("rgba");
    // The op draws through a pinhole: no lens distortion.
    let cams = cameras(VIEWS, intrinsics(SIZE), LensDistortion::NONE);
    let rgba: Vec<Array3<f64>> = cams
        .iter()
        .map(|c| {
            let photo = photograph(c);
            Array3::from_shape_fn((SIZE, SIZE, 4), |(r, col, ch)| {
                let ball = (0..3).any(|a| photo[[r, col, a]] != 1.0);
                match (ch, ball) {
                    (3, ball) => f64::from(u8::from(ball)),
                    (_, true) => photo[[r, col, ch]],
                    (_, false) => 0.0,
                }
            })
        })
        .collect();
    let names: Vec<String> = (0..VIEWS).map(frame_name).collect();
    let frames: Vec<_> = names
        .iter()
        .zip(&cams)
        .zip(&rgba)
        .map(|((n, c), p)| (n.as_str(), c, p))
        .collect();
    write_instant_ngp(&data, &frames).unwrap();
    let ply = dir.path().join("ball.ply");
    let run = fogray(&[
        "fit",
        "--data",
        arg(&data),
        "--model",
        "splats",
        "--steps",
        "200",
        "--evaluations",
        "1",
        "--json",
        "--save-model",
        arg(&ply),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let json: Value = serde_json::from_str(&run.stdout).unwrap();
    let db = json["final_test_psnr"].as_f64().unwrap();
    // The untrained start (the hull's splats, faint) scores about 11.6 dB on these views;
    // the fit must have learnt the ball's colour and outline from the training views.
    let start = json["log"][0]["test_psnr"].as_f64().unwrap();
    assert!(start < 13.0 && db > start + 5.0, "held-out PSNR {start} -> {db}");
    assert!(json["train_views_psnr"].as_f64().unwrap() > 22.0, "{json}");
    assert_eq!(json["steps"].as_u64(), Some(200));
    let bytes = std::fs::read(&ply).unwrap();
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).expect("a PLY header") + end.len();
    let header = std::str::from_utf8(&bytes[..at]).unwrap();
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .expect("a vertex element")
        .parse()
        .unwrap();
    let properties = header.lines().filter(|l| l.starts_with("property float ")).count();
    // Degree 1 (the default): 3 + 3 + 3 + 9 + 1 + 3 + 4 floats a splat.
    assert_eq!(properties, 26);
    assert!(count > 100, "{count} splats");
    assert_eq!(bytes.len() - at, count * properties * 4);
    // The grid commands read safetensors: the PLY is refused in one line, not misread.
    let out = dir.path().join("renders");
    let run = fogray(&["render", "--model", arg(&ply), "--orbit", "2", "--out", arg(&out)]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert_eq!(run.stderr.trim().lines().count(), 1, "{}", run.stderr);
    assert!(run.stderr.contains("ball.ply"), "{}", run.stderr);
}
