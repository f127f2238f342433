//! The `fogray-grid` binary: its JSON, its PNGs, and one line on stderr with status 2 for
//! every kind of bad input.

use fogray_grid::photographs::photographs;
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;

use crate::common;
use common::{grid, ok, temp_dir};

#[test]
fn scene_writes_the_built_in_scene_which_reads_back() {
    let printed = ok(&["scene"]);
    assert_eq!(Scene::from_json(&printed).unwrap(), Scene::default());
    let dir = temp_dir("scene");
    let file = dir.join("scene.json");
    ok(&["scene", "--out", file.to_str().unwrap()]);
    assert_eq!(std::fs::read_to_string(&file).unwrap(), printed);
    // The written scene gives the built-in scene's photographs.
    let args = [
        "photographs",
        "--views",
        "2",
        "--test-views",
        "1",
        "--size",
        "6",
        "--json",
    ];
    let from_file = ok(&[&args[..], &["--scene", file.to_str().unwrap()]].concat());
    assert_eq!(from_file, ok(&args));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn photographs_json_is_view_row_column_channel() {
    let out = ok(&[
        "photographs",
        "--views",
        "3",
        "--test-views",
        "1",
        "--size",
        "5",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let images = v["images"].as_array().unwrap();
    let want = photographs(&Scene::default(), &Ring::new(3, 1, 5).unwrap()).unwrap();
    assert_eq!(images.len(), 4);
    for (view, image) in want.iter().enumerate() {
        for ((a, b, c), value) in image.indexed_iter() {
            assert_eq!(
                images[view][a][b][c].as_f64().unwrap(),
                *value,
                "view {view} ({a}, {b}, {c})"
            );
        }
        assert_eq!(images[view].as_array().unwrap().len(), 5);
        assert_eq!(images[view][0].as_array().unwrap().len(), 5);
    }
    // No test views is allowed.
    let out = ok(&[
        "photographs",
        "--views",
        "2",
        "--test-views",
        "0",
        "--size",
        "3",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["images"].as_array().unwrap().len(), 2);
}

#[test]
fn photographs_out_writes_one_png_per_view() {
    let dir = temp_dir("pngs");
    let out = ok(&[
        "photographs",
        "--views",
        "4",
        "--test-views",
        "2",
        "--size",
        "7",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.contains("6 views of 7 x 7 pixels; test views: 1, 4"), "{out}");
    for i in 0..6 {
        let bytes = std::fs::read(dir.join(format!("view-{i:03}.png"))).unwrap();
        // PNG signature, then the IHDR chunk: width and height as big-endian u32 at 16 and 20.
        assert_eq!(&bytes[1..4], b"PNG");
        assert_eq!(
            (&bytes[16..20], &bytes[20..24]),
            (&7u32.to_be_bytes()[..], &7u32.to_be_bytes()[..])
        );
    }
    assert!(!dir.join("view-006.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fit_prints_its_log_and_writes_renders_and_pictures() {
    let dir = temp_dir("fit");
    let renders = dir.join("renders.json");
    let out = ok(&[
        "fit",
        "--views",
        "8",
        "--test-views",
        "2",
        "--size",
        "10",
        "--grid",
        "10",
        "--steps",
        "6",
        "--batch",
        "256",
        "--json",
        "--out",
        dir.to_str().unwrap(),
        "--save-renders",
        renders.to_str().unwrap(),
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let log = v["log"].as_array().unwrap();
    assert_eq!(log[0]["step"], 0);
    assert_eq!(log.last().unwrap()["step"], 6);
    for e in log {
        for key in ["step", "seconds", "train_loss", "test_psnr"] {
            assert!(e.get(key).is_some(), "{key} in {e}");
        }
    }
    assert!(v["final_test_psnr"].as_f64().unwrap() > 5.0);
    // The mean of the two held-out views' PSNRs, checked below against the saved renders.
    let view_mean = v["final_test_psnr_view_mean"].as_f64().unwrap();
    assert!(v["seconds"].as_f64().unwrap() > 0.0);
    assert!(v["samples_per_ray_mean"].as_f64().unwrap() > 1.0);
    assert_eq!(v["occupied_fraction"], 1.0);
    assert!(v.get("profile").is_none(), "only with --profile");
    // 10 views in all, e = 5, test views 2 and 7: [view][row][column][channel].
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&renders).unwrap()).unwrap();
    let images = r["images"].as_array().unwrap();
    assert_eq!(images.len(), 2);
    assert_eq!(images[1].as_array().unwrap().len(), 10);
    assert_eq!(images[1][9].as_array().unwrap().len(), 10);
    assert_eq!(images[1][9][9].as_array().unwrap().len(), 3);
    // Each held-out view's PSNR from its saved render and its photograph, then their mean.
    let exact = photographs(&Scene::default(), &Ring::new(8, 2, 10).unwrap()).unwrap();
    let view_psnr = |k: usize, view: usize| {
        let mut sum = 0.0;
        for ((a, b, c), value) in exact[view].indexed_iter() {
            sum += (images[k][a][b][c].as_f64().unwrap() - value).powi(2);
        }
        -10.0 * (sum / exact[view].len() as f64).log10()
    };
    let mean = (view_psnr(0, 2) + view_psnr(1, 7)) / 2.0;
    assert!((view_mean - mean).abs() < 1e-9, "{view_mean} against {mean}");
    for name in ["test-view-002.png", "test-view-007.png", "psnr.png", "psnr.svg"] {
        assert!(dir.join(name).exists(), "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_exits_2_with_one_line() {
    let dir = temp_dir("bad");
    let sphere = r#"{"kind": "sphere", "center": [0, 0, 0], "radius": 0.5, "density": 2, "color": [1, 0, 0]}"#;
    let scenes = [
        ("kind", sphere.replace("sphere", "cone")),
        ("density", sphere.replace(r#""density": 2"#, r#""density": -2"#)),
        ("huge", sphere.replace(r#""density": 2"#, r#""density": 1e999"#)),
        ("radius", sphere.replace(r#""radius": 0.5"#, r#""radius": -0.5"#)),
        ("color", sphere.replace("[1, 0, 0]", "[1, 0, 1.01]")),
        (
            "minmax",
            r#"{"kind": "box", "min": [0, 0, 0], "max": [1, 1, -1], "density": 1, "color": [0, 0, 0]}"#.into(),
        ),
        ("syntax", "{".into()),
    ];
    let mut cases: Vec<Vec<String>> = Vec::new();
    for (name, primitive) in &scenes {
        let file = dir.join(format!("{name}.json"));
        std::fs::write(
            &file,
            format!(r#"{{"background": [1, 1, 1], "primitives": [{primitive}]}}"#),
        )
        .unwrap();
        cases.push(vec![
            "photographs".into(),
            "--scene".into(),
            file.to_str().unwrap().into(),
        ]);
    }
    for args in [
        &["photographs", "--scene", "/nonexistent/scene.json"][..],
        &["photographs", "--views", "0"][..],
        &["photographs", "--size", "0"][..],
        &["photographs", "--views", "many"][..],
        &["photographs", "--colour"][..],
        &["scene", "--out", "/nonexistent/dir/scene.json"][..],
        &["photographs", "--size", "2", "--out", "/proc/fogray-grid"][..],
        &["fit", "--size", "4", "--grid", "1"][..],
        &["fit", "--size", "4", "--grid", "0"][..],
        &["fit", "--size", "4", "--steps", "0"][..],
        &["fit", "--size", "4", "--batch", "0"][..],
        &["fit", "--size", "4", "--seconds", "-1"][..],
        &["fit", "--size", "4", "--seconds", "nan"][..],
        &["fit", "--size", "4", "--steps", "3", "--seconds", "3"][..],
        &["fit", "--size", "4", "--test-views", "0"][..],
        &["fit", "--size", "4", "--method", "magic"][..],
        &["fit", "--size", "0"][..],
        &["paint"][..],
        &[][..],
    ] {
        cases.push(args.iter().map(|s| s.to_string()).collect());
    }
    for args in &cases {
        let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let (code, out, err) = grid(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(out.is_empty(), "{args:?}: {out}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("fogray-grid: error: "), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fit_profile_prints_the_phases_and_the_ops_a_step() {
    let args = [
        "fit",
        "--views",
        "6",
        "--test-views",
        "1",
        "--size",
        "6",
        "--grid",
        "6",
        "--steps",
        "3",
        "--batch",
        "32",
    ];
    let out = ok(&[&args[..], &["--json", "--profile"]].concat());
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let p = &v["profile"];
    assert_eq!(p["steps"], 3);
    let phases: Vec<&str> = p["phases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        phases,
        ["batch", "sample", "forward", "backward", "optimiser", "occupancy"]
    );
    let composite = p["ops"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["name"] == "composite_mse")
        .expect("the fused composite and loss");
    assert_eq!(composite["calls_per_step"], 1.0);
    // As text: the tables follow the final line.
    let text = ok(&[&args[..], &["--profile"]].concat());
    assert!(
        text.contains("where a step went (ms a step, mean over 3 steps):"),
        "{text}"
    );
    assert!(
        text.lines().any(|l| l.trim_start().starts_with("grid_field ")),
        "{text}"
    );
}
