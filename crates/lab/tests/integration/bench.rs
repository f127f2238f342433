//! The `fogray-lab` binary's `bench`: speed beside error and memory as JSON, its refusals in
//! one line (exit status 2), and the stamped report and README block of `--markdown` and
//! `--readme`.

use std::process::Command;

/// Runs `fogray-lab` with `args`: its exit status, stdout and stderr.
fn lab(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fogray-lab"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

#[test]
fn bench_reports_speed_beside_error_and_memory() {
    let (code, out, err) = lab(&["bench", "--quick", "--json", "--workload", "64x32"]);
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
        // Only the fused op has a one-pass path, and a fraction of the memory bound.
        assert_eq!(r["samples_per_sec_one_pass"].is_number(), r["method"] == "fused", "{r}");
        assert_eq!(r["memory_bound"].is_object(), r["method"] == "fused", "{r}");
        if r["method"] == "fused" {
            let b = &r["memory_bound"];
            // Bytes per sample by hand: sigma, delta and RGB read (twice through two calls),
            // dL/dsigma and dL/dcolour written.
            let value = if r["precision"] == "f32" { 4 } else { 8 };
            assert_eq!(b["bytes_per_sample_two_calls"].as_u64(), Some(14 * value), "{r}");
            assert_eq!(b["bytes_per_sample_one_pass"].as_u64(), Some(9 * value), "{r}");
            let triad = json["bandwidth"]
                .as_array()
                .unwrap()
                .iter()
                .find(|t| t["threads"] == r["threads"])
                .unwrap()["bytes_per_sec"]
                .as_f64()
                .unwrap();
            assert_eq!(b["triad_bytes_per_sec"].as_f64(), Some(triad));
            let rate = r["samples_per_sec_one_pass"].as_f64().unwrap();
            let want = rate * (9 * value) as f64 / triad;
            assert!(
                (b["fraction_one_pass"].as_f64().unwrap() / want - 1.0).abs() < 1e-12,
                "{r}"
            );
        }
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
    let (code, out, err) = lab(&[
        "bench",
        "--quick",
        "--json",
        "--workload",
        "64x32",
        "--keep-freed-memory",
    ]);
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(json["results"].as_array().unwrap().len(), results.len());
    let (code, _, err) = lab(&["bench", "--workload", "64by32"]);
    assert_eq!(code, 2);
    assert!(err.contains("RxS"), "{err}");
}

#[test]
fn grid_bench_rejects_a_bad_grid_size() {
    for bad in ["1", "64x32", "many"] {
        let (code, out, err) = lab(&["bench", "--op", "grid", "--workload", bad]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(out.is_empty() && err.contains("node count"), "{bad}: {err}");
    }
}

#[test]
fn a_bad_workload_is_one_line_naming_the_command() {
    let (code, out, err) = lab(&["bench", "--workload", "64by32"]);
    assert_eq!(code, 2);
    assert!(out.is_empty(), "{out}");
    assert_eq!(err.lines().count(), 1, "{err:?}");
    assert!(err.starts_with("fogray-lab bench: error: "), "{err:?}");
    // --readme needs --markdown: refused by the flags, exit status 2.
    let (code, out, err) = lab(&["bench", "--readme", "README.md"]);
    assert_eq!(code, 2, "{err}");
    assert!(out.is_empty() && err.contains("--markdown"), "{err}");
}

#[test]
fn markdown_writes_a_stamped_report_and_the_readme_block_only() {
    let dir = tempfile::tempdir().unwrap();
    let readme = dir.path().join("README.md");
    let before = "intro\n<!-- headline:composite:start -->\nold\n<!-- headline:composite:end -->\nafter\n";
    std::fs::write(&readme, before).unwrap();
    let reports = dir.path().join("reports");
    let (r, m) = (readme.to_str().unwrap(), reports.to_str().unwrap());
    let args = [
        "bench",
        "--quick",
        "--workload",
        "64x32",
        "--markdown",
        m,
        "--readme",
        r,
    ];
    let (code, _, err) = lab(&args);
    assert_eq!(code, 0, "{err}");
    // The stamp names the command that wrote the report: this binary, with its arguments.
    let stamped = format!("by `fogray-lab {}`", args.join(" "));
    let report = std::fs::read_to_string(reports.join("bench-composite.md")).unwrap();
    assert!(report.contains(&stamped), "{report}");
    let after = std::fs::read_to_string(&readme).unwrap();
    assert!(
        after.starts_with("intro\n<!-- headline:composite:start -->\n"),
        "{after}"
    );
    assert!(after.ends_with("<!-- headline:composite:end -->\nafter\n"), "{after}");
    assert!(!after.contains("old") && after.contains(&stamped), "{after}");
    // A README without the block: refused, and left as it was.
    std::fs::write(&readme, "no markers\n").unwrap();
    let (code, _, err) = lab(&args);
    assert_eq!(code, 2);
    assert!(err.contains("headline:composite:start"), "{err}");
    assert_eq!(std::fs::read_to_string(&readme).unwrap(), "no markers\n");
}
