//! `fogray-grid report` as a user runs it: on a tiny problem budgeted by steps it writes its
//! files and prints one line per configuration; bad input exits 2 with one line on stderr.

use crate::common;
use common::grid;

#[test]
fn report_writes_its_files_and_names_its_command() {
    let dir = std::env::temp_dir().join(format!("fogray-grid-report-cli-{}", std::process::id()));
    let out = dir.join("report");
    let tiny = [
        "--views",
        "4",
        "--test-views",
        "1",
        "--size",
        "8",
        "--grid",
        "8",
        "--batch",
        "64",
        "--steps",
        "6",
    ];
    std::fs::create_dir_all(&dir).unwrap();
    let anchor = dir.join("anchor.json");
    std::fs::write(
        &anchor,
        r#"{"name": "a slow pipeline", "log": [{"seconds": 0, "test_psnr": 0.5}, {"seconds": 1000, "test_psnr": 1}]}"#,
    )
    .unwrap();
    let args = [
        &["report"][..],
        &tiny,
        &[
            "--configs",
            "fused-uniform,fused-occupancy-f64",
            "--anchor",
            anchor.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    ]
    .concat();
    let (code, stdout, err) = grid(&args);
    assert_eq!(code, 0, "{err}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 4, "{stdout}");
    assert!(
        lines[0].starts_with("fused-uniform ") && lines[0].contains("6 steps"),
        "{stdout}"
    );
    assert!(lines[1].starts_with("fused-occupancy-f64 "), "{stdout}");
    assert!(
        lines[2].starts_with("memory bandwidth (STREAM triad, ") && lines[2].ends_with(" GB/s after"),
        "{stdout}"
    );
    assert!(lines[3].ends_with("report.md"), "{stdout}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains(" GB/s just before the first run and "), "{md}");
    let given = args[1..].join(" ");
    assert!(
        md.contains(&format!("`cargo run --release -p fogray-grid -- report {given}`")),
        "{md}"
    );
    // No taped run, no f32 occupancy run: neither comparison has a pair.
    assert!(!md.contains("## Fused against taped"), "{md}");
    assert!(!md.contains("## Occupancy against uniform"), "{md}");
    // Every run starts above the anchor's final 1 dB: reached at 0 s, so no ratio.
    assert!(md.contains("## Against an outside pipeline: a slow pipeline"), "{md}");
    assert!(md.contains("| fused-uniform | 0.00 | - |"), "{md}");
    for file in [
        "psnr-vs-seconds.png",
        "psnr-vs-steps.svg",
        "psnr-vs-seconds-log.png",
        "report.json",
        "density-slices.png",
        "occupancy-slices.png",
    ] {
        assert!(out.join(file).exists(), "{file}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["configurations"][1]["precision"], "f64");
    assert_eq!(json["budget_steps"], 6);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_report_input_exits_2_with_one_line() {
    let dir = std::env::temp_dir().join(format!("fogray-grid-report-bad-{}", std::process::id()));
    let out = dir.to_str().unwrap();
    let tiny = ["--size", "4", "--steps", "2", "--out", out];
    let empty_anchor = std::env::temp_dir().join(format!("fogray-grid-empty-anchor-{}.json", std::process::id()));
    std::fs::write(&empty_anchor, r#"{"name": "nothing", "log": []}"#).unwrap();
    for extra in [
        &["--anchor", empty_anchor.to_str().unwrap()][..],
        &["--anchor", "/nonexistent/anchor.json"][..],
        &["--configs", "fused-dense"][..],
        &["--configs", "fused-uniform,fused-uniform"][..],
        &["--configs", "fused-uniform-f16"][..],
        &["--seconds", "3"][..],
        &["--grid", "1"][..],
        &["--batch", "0"][..],
        &["--test-views", "0"][..],
    ] {
        let args = [&["report"][..], &tiny, extra].concat();
        let (code, stdout, err) = grid(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(stdout.is_empty(), "{args:?}: {stdout}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("fogray-grid: error: "), "{args:?}: {err}");
    }
    assert!(!dir.join("report.md").exists());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&empty_anchor);
}
