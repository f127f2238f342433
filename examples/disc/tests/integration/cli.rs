//! The `fogray-disc` binary: the JSON contract of `docs/cli.md` and its errors.

use std::process::Command;

fn disc(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fogray-disc"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

fn json(args: &[&str]) -> serde_json::Value {
    let (code, out, err) = disc(args);
    assert_eq!(code, 0, "{args:?}: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{args:?}: {e}: {out}"))
}

#[test]
fn subcommands_print_the_contracted_json() {
    let s = json(&["staircase", "--json"]);
    assert_eq!(s["distinct_values"], 58);
    assert!((s["unchanged_fraction"].as_f64().unwrap() - 0.9644).abs() < 5e-5);
    let dir = std::env::temp_dir().join(format!("fogray-disc-cli-{}", std::process::id()));
    let out = dir.to_str().unwrap();
    let l = json(&[
        "landscape",
        "--tau",
        "0.45",
        "--from",
        "-1.5",
        "--to",
        "1.5",
        "--step",
        "0.05",
        "--json",
        "--out",
        out,
    ]);
    let valleys: Vec<f64> = l["false_valleys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(valleys, vec![-1.3, 1.3]);
    assert!(l["minima"].is_array() && l["truth_is_local_max"] == false);
    assert!(dir.join("landscape-tau0.45.png").exists());
    let f = json(&[
        "fit",
        "--renderer",
        "soft",
        "--start",
        "-1.5",
        "--steps",
        "80",
        "--lr",
        "0.05",
        "--json",
    ]);
    assert!((f["end"].as_f64().unwrap().abs() - 0.0619).abs() < 5e-4);
    assert_eq!(f["path"].as_array().unwrap().len(), 81);
    let h = json(&["fit", "--renderer", "hard", "--start", "-2.8", "--json"]);
    assert_eq!(h["end"].as_f64().unwrap(), -2.8);
    let r = json(&[
        "ray", "--camera", "0", "--pixel", "36", "--x", "-1.5", "--tau", "0.15", "--json", "--out", out,
    ]);
    assert!((r["t_after_first_crossing"].as_f64().unwrap() - 0.0024503).abs() < 5e-7);
    assert_eq!(r["sigma"].as_array().unwrap().len(), 64);
    let rep = json(&["reproduce", "--json", "--out", out]);
    let ids: Vec<&str> = rep["figures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        vec![
            "staircase_distinct",
            "staircase_unchanged_fraction",
            "soft_loss_at_-1.5",
            "soft_slope_at_-1.5",
            "hard_loss_at_-1.5",
            "hard_slope_at_-1.5",
            "pixel36_T_after_first_crossing",
            "pixel36_back_half_weight",
            "adam_soft_end_from_-1.5",
            "hard_loss_at_-2.8",
            "soft_slope_at_-2.8",
            "adam_soft_end_from_-2.8",
            "adam_hard_end_from_-2.8",
            "tau0.45_false_valleys",
            "tau0.45_end_from_-2.8",
            "tau0.6_truth_is_local_max",
            "tau0.6_end_from_-2.8",
        ]
    );
    assert!(rep["figures"][0]["ours"].is_u64(), "counts are integers");
    assert!(rep["figures"][15]["ours"].is_boolean(), "booleans are true/false");
    for plot in ["landscape", "ray", "strips", "fits"] {
        for ext in ["svg", "png"] {
            assert!(dir.join(format!("{plot}.{ext}")).exists(), "{plot}.{ext}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_arguments_exit_2_with_a_message() {
    for args in [
        &["staircase", "--tau", "-1"][..],
        &["fit", "--start", "0", "--renderer", "hard", "--anneal"][..],
        &["ray", "--camera", "9"][..],
        &["landscape", "--from", "1", "--to", "0"][..],
        &["staircase", "--disc-color", "1,0"][..],
    ] {
        let (code, out, err) = disc(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(out.is_empty() && err.contains("error"), "{args:?}: {out} {err}");
    }
}
