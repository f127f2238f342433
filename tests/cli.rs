//! The `fogray` binary on good and bad inputs: the JSON contract of design.md §4.

use std::io::Write;
use std::process::{Command, Stdio};

fn fogray(args: &[&str], stdin: &str) -> (i32, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_fogray"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(stdin.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

const LESSON: &str = r#"{"rays":[{"sigma":[0,0.5,2,8],"delta":[0.5,0.5,0.5,0.5],"color":[[0.9],[0.2],[0.9],[0.4]],"background":[1],"grad_color":[1]}]}"#;

fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

#[test]
fn composite_reproduces_the_lesson_with_every_method_and_precision() {
    for method in ["fused", "taped", "taped-naive"] {
        for precision in ["f64", "f32"] {
            let input = LESSON.replacen('{', &format!(r#"{{"precision":"{precision}","#), 1);
            let (code, out, err) = fogray(&["composite", "--method", method], &input);
            assert_eq!(code, 0, "{method} {precision}: {err}");
            assert!(err.is_empty());
            let json: serde_json::Value = serde_json::from_str(&out).unwrap();
            let ray = &json["rays"][0];
            assert!((numbers(&ray["color"])[0] - 0.605).abs() < 5e-4);
            assert!(ray["depth"].is_null());
            let want = [0.147, -0.203, 0.070, -0.002];
            for (g, w) in numbers(&ray["grad_sigma"]).iter().zip(want) {
                assert!((g - w).abs() < 5e-4, "{method} {precision}: {g} vs {w}");
            }
            assert_eq!(numbers(&ray["weights"]).len(), 4);
            assert_eq!(numbers(&ray["transmittance"])[0], 1.0);
            assert_eq!(ray["grad_color"].as_array().unwrap().len(), 4);
            // dC/dc_bg = T_end = e^-(0 + 0.25 + 1 + 4)
            assert!((numbers(&ray["grad_background"])[0] - (-5.25f64).exp()).abs() < 1e-6);
        }
    }
}

#[test]
fn depth_empty_rays_and_no_gradient_request() {
    let input = r#"{"rays":[{"sigma":[1,1],"delta":[0.5,0.5],"color":[[1,0],[0,1]],"t":[1,2]},{"sigma":[],"delta":[],"color":[],"background":[0.3,0.7]}]}"#;
    let (code, out, err) = fogray(&["composite"], input);
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let (a, b) = (&json["rays"][0], &json["rays"][1]);
    // depth = w0 * 1 + w1 * 2 with w0 = 1 - e^-0.5, w1 = e^-0.5 (1 - e^-0.5)
    let (w0, w1) = (1.0 - (-0.5f64).exp(), (-0.5f64).exp() * (1.0 - (-0.5f64).exp()));
    assert!((a["depth"].as_f64().unwrap() - (w0 + 2.0 * w1)).abs() < 1e-15);
    assert!(a.get("grad_sigma").is_none(), "grad_* only with grad_color");
    assert_eq!(numbers(&b["color"]), vec![0.3, 0.7]);
    assert!(b["depth"].is_null());
    assert_eq!(b["opacity"].as_f64().unwrap(), 0.0);
}

#[test]
fn bad_input_exits_2_with_one_line_and_no_output() {
    let cases = [
        ("{", "invalid input JSON"),
        (
            r#"{"rays":[{"sigma":["x"],"delta":[1],"color":[[1]]}]}"#,
            "invalid input JSON",
        ),
        (
            r#"{"rays":[{"sigma":[1e999],"delta":[1],"color":[[1]]}]}"#,
            "invalid input JSON",
        ),
        (
            r#"{"rays":[{"sigma":[1],"delta":[1,1],"color":[[1]]}]}"#,
            "ray 0: delta has 2 entries",
        ),
        (
            r#"{"rays":[{"sigma":[1],"delta":[1],"color":[[1]]},{"sigma":[1],"delta":[1],"color":[[1,2]]}]}"#,
            "ray 1, sample 0: color has 2 channels",
        ),
        (
            r#"{"rays":[{"sigma":[1,-2],"delta":[1,1],"color":[[1],[1]]}]}"#,
            "ray 0, sample 1: sigma",
        ),
        (
            r#"{"rays":[{"sigma":[1],"delta":[-1],"color":[[1]]}]}"#,
            "ray 0, sample 0: delta",
        ),
        (
            r#"{"precision":"f16","rays":[{"sigma":[1],"delta":[1],"color":[[1]]}]}"#,
            "unknown precision",
        ),
        (
            r#"{"precision":"f32","rays":[{"sigma":[1e300],"delta":[1],"color":[[1]]}]}"#,
            "overflows f32",
        ),
        (r#"{"rays":[{"delta":[1],"color":[[1]]}]}"#, "missing field"),
        (
            r#"{"rays":[{"sigma":[1],"delta":[1],"color":[[1]],"colour":[1]}]}"#,
            "unknown field",
        ),
        (
            r#"{"min_transmittance":2,"rays":[{"sigma":[1],"delta":[1],"color":[[1]]}]}"#,
            "min_transmittance",
        ),
        (
            r#"{"rays":[{"sigma":[1],"delta":[1],"color":[[1]],"grad_color":[1,2]}]}"#,
            "grad_color has 2 channels",
        ),
    ];
    for (input, needle) in cases {
        for method in ["fused", "taped"] {
            let (code, out, err) = fogray(&["composite", "--method", method], input);
            assert_eq!(code, 2, "{input}: {err}");
            assert!(out.is_empty(), "{input}: stdout {out}");
            assert_eq!(err.trim_end().lines().count(), 1, "{input}: {err}");
            assert!(err.contains(needle), "{input}: {err}");
            assert!(!err.contains("panicked"), "{input}: {err}");
        }
    }
    let (code, _, err) = fogray(
        &["composite", "--method", "taped", "--input", "-"],
        r#"{"min_transmittance":0.1,"rays":[{"sigma":[1],"delta":[1],"color":[[1]]}]}"#,
    );
    assert_eq!(code, 2);
    assert!(err.contains("fused method only"), "{err}");
    let (code, _, err) = fogray(&["composite", "--input", "/nonexistent/x.json"], "");
    assert_eq!(code, 2);
    assert!(err.contains("cannot read"), "{err}");
}

#[test]
fn help_explains_the_format() {
    let (code, out, _) = fogray(&["composite", "--help"], "");
    assert_eq!(code, 0);
    for needle in [
        "\"sigma\"",
        "grad_color",
        "min_transmittance",
        "exit status 2",
        "--method",
    ] {
        assert!(out.contains(needle), "{needle} missing from --help");
    }
}

#[test]
fn gradcheck_prints_small_disagreements() {
    let input = r#"{"rays":[{"sigma":[1,3,5],"delta":[0.4,0.4,0.4],"color":[[0.2],[0.6],[1.0]],"background":[0.5]}]}"#;
    let (code, out, err) = fogray(&["gradcheck"], input);
    assert_eq!(code, 0, "{err}");
    for line in out.lines().filter(|l| l.starts_with("sigma") || l.starts_with("color")) {
        let cols: Vec<f64> = line
            .split_whitespace()
            .skip(1)
            .step_by(2)
            .map(|x| x.parse().unwrap())
            .collect();
        assert!(cols.iter().all(|&e| e < 1e-8), "{line}");
    }
    let (code, _, err) = fogray(&["gradcheck"], LESSON);
    assert_eq!(code, 2, "sigma = 0 cannot be differenced both ways: {err}");
}

#[test]
fn bench_reports_speed_beside_error_and_memory() {
    let (code, out, err) = fogray(&["bench", "--quick", "--json", "--workload", "64x32"], "");
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let results = json["results"].as_array().unwrap();
    // fused on 1 and all threads (one entry if the machine has one core), taped, taped-naive;
    // in f32 and f64.
    assert!(results.len() == 8 || results.len() == 6, "{}", results.len());
    for r in results {
        for field in [
            "samples_per_sec",
            "samples_per_sec_forward",
            "samples_per_sec_spread",
            "samples_per_sec_reused",
            "err_color",
            "err_grad_sigma",
            "peak_extra_bytes",
            "threads",
        ] {
            assert!(r[field].is_number(), "{field} in {r}");
        }
        assert_eq!((r["rays"].as_u64(), r["samples"].as_u64()), (Some(64), Some(32)));
        // Only the fused op has a one-pass path.
        assert_eq!(r["samples_per_sec_one_pass"].is_number(), r["method"] == "fused", "{r}");
        // Accuracy is asserted, never speed: the fused op in f32 stays within 1e-5 element-wise.
        if r["method"] == "fused" {
            let tol = if r["precision"] == "f32" { 1e-5 } else { 1e-12 };
            assert!(
                r["err_color"].as_f64().unwrap() < tol && r["err_grad_sigma"].as_f64().unwrap() < tol,
                "{r}"
            );
        }
    }
    // The tape's own costs, one object per precision (sizes only: speed is never asserted).
    let tape = json["tape_overhead"].as_array().unwrap();
    let precisions: Vec<&str> = tape.iter().map(|t| t["precision"].as_str().unwrap()).collect();
    assert_eq!(precisions, ["f32", "f64"]);
    for t in tape {
        assert!(
            t["ns_per_op"].as_f64().unwrap() > 0.0 && t["ns_per_byte"].as_f64().unwrap() > 0.0,
            "{t}"
        );
    }
    // With glibc keeping freed memory: the same measurements, the same accuracy.
    let (code, out, err) = fogray(
        &[
            "bench",
            "--quick",
            "--json",
            "--workload",
            "64x32",
            "--keep-freed-memory",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(json["results"].as_array().unwrap().len(), results.len());
    let (code, _, err) = fogray(&["bench", "--workload", "64by32"], "");
    assert_eq!(code, 2);
    assert!(err.contains("RxS"), "{err}");
}

#[test]
fn grid_bench_rejects_a_bad_grid_size() {
    for bad in ["1", "64x32", "many"] {
        let (code, out, err) = fogray(&["bench", "--op", "grid", "--workload", bad], "");
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(out.is_empty() && err.contains("node count"), "{bad}: {err}");
    }
}
