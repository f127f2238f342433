//! The `fogray` binary on good and bad inputs: the JSON contract `fogray composite --help`
//! documents, and `fogray gradcheck`'s verdicts and exit statuses.

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
    // A command refused on its arguments exits before reading its input, so the pipe may close
    // under us: that is the command's right, not a test failure.
    match child.stdin.take().unwrap().write_all(stdin.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        written => written.unwrap(),
    }
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

/// `fogray gradcheck --json` on `input` with `args`: exit status and the parsed report.
fn gradcheck(args: &[&str], input: &str) -> (i32, serde_json::Value) {
    let mut all = vec!["gradcheck", "--json"];
    all.extend_from_slice(args);
    let (code, out, err) = fogray(&all, input);
    assert!(code == 0 || code == 1, "{input}: exit {code}: {err}");
    (code, serde_json::from_str(&out).unwrap())
}

/// The row of the report for `input` against `against`.
fn row<'a>(report: &'a serde_json::Value, against: &str, input: &str) -> &'a serde_json::Value {
    report["inputs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["against"] == against && r["input"] == input)
        .unwrap_or_else(|| panic!("no {against} row for {input} in {report}"))
}

#[test]
fn gradcheck_passes_the_lesson_ray_with_its_zero_density() {
    // sigma_0 = 0: a central difference would step to -1e-6, which the op rejects.
    let (code, out, err) = fogray(&["gradcheck"], LESSON);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.trim_end()
            .ends_with("PASS: all 26 comparisons within the tolerance"),
        "{out}"
    );
    assert!(out.contains("(one-sided)"), "{out}");
    assert!(!out.contains("grad_color not given"), "{out}");
    let (code, report) = gradcheck(&[], LESSON);
    assert_eq!(code, 0);
    // The one-sided difference at sigma = 0 against the closed form (lesson value 0.147).
    let sigma = row(&report, "finite_differences", "sigma");
    assert_eq!(sigma["checked"], 4);
    let zero = report["worst"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["input"] == "sigma" && w["sample"] == 0 && w["against"] == "finite_differences")
        .expect("sample 0 of sigma among the worst");
    assert_eq!(zero["one_sided"], true);
    assert!((zero["reference"].as_f64().unwrap() - 0.147).abs() < 5e-4, "{zero}");
    // A zero step too.
    let input =
        r#"{"rays":[{"sigma":[1,2],"delta":[0,0.5],"color":[[0.3],[0.6]],"background":[0.2],"grad_color":[1]}]}"#;
    assert_eq!(gradcheck(&[], input).0, 0);
}

#[test]
fn gradcheck_fails_with_exit_1_when_differences_cannot_agree() {
    // Finite differences of exp(-sigma delta) carry rounding (about 1e-11 here): at a zero
    // tolerance they cannot agree with the exact gradient.
    let input = r#"{"rays":[{"sigma":[1,3],"delta":[0.3,1],"color":[[1],[0.5]],"background":[0],"grad_color":[1]}]}"#;
    let (code, out, _) = fogray(&["gradcheck", "--atol", "0", "--rtol", "0"], input);
    assert_eq!(code, 1, "{out}");
    assert!(out.contains("FAIL: "), "{out}");
    assert!(out.contains("finite diff  delta at ray 0, sample"), "{out}");
    let (code, report) = gradcheck(&["--atol", "0", "--rtol", "0"], input);
    assert_eq!(code, 1);
    assert_eq!(report["passed"], false);
    let worst = &report["worst"][0];
    assert_eq!(worst["against"], "finite_differences");
    assert_eq!(worst["ray"], 0);
    assert!(worst["abs_diff"].as_f64().unwrap() > 0.0, "{worst}");
    // The same input passes the defaults, and a tolerance just above the worst difference.
    assert_eq!(gradcheck(&[], input).0, 0);
    let above = format!("{:e}", 2.0 * worst["abs_diff"].as_f64().unwrap());
    let (code, _) = gradcheck(&["--atol", &above, "--rtol", "0"], input);
    assert_eq!(code, 0);
    // Fast mode fails at a zero tolerance too, naming directions.
    let (code, report) = gradcheck(&["--fast", "--atol", "0", "--rtol", "0"], input);
    assert_eq!(code, 1);
    let fd = row(&report, "finite_differences", "all inputs");
    assert_eq!((fd["checked"].as_u64(), fd["failing"].as_u64()), (Some(8), Some(8)));
    assert!(fd["worst"]["direction"].is_u64(), "{fd}");
}

#[test]
fn gradcheck_checks_t_and_f32_and_says_what_it_defaulted() {
    // Two channels, t with grad_depth on ray 0; ray 1 gives grad_color only.
    let input = r#"{"rays":[{"sigma":[0,0.5,2],"delta":[0.5,0.5,0.5],"color":[[0.9,0.1],[0.2,0.3],[0.9,1]],"t":[1,2,3],"grad_depth":0.5,"background":[1,0]},{"sigma":[1,3],"delta":[0.2,0.2],"color":[[0.9,0.1],[0.2,0.3]],"grad_color":[1,-2]}]}"#;
    let (code, report) = gradcheck(&[], input);
    assert_eq!(code, 0, "{report}");
    // t only for the ray that gives it; dL/dt_k = w_k grad_depth.
    assert_eq!(row(&report, "finite_differences", "t")["checked"], 3);
    assert_eq!(row(&report, "taped_twin", "t")["checked"], 3);
    assert_eq!(row(&report, "finite_differences", "color")["checked"], 10);
    let notes = report["notes"].to_string();
    assert!(
        notes.contains("grad_color not given: ones for 1 of the rays (0)"),
        "{notes}"
    );
    assert!(!notes.contains("grad_depth"), "{notes}");
    let without = input.replace(r#""grad_depth":0.5,"#, "");
    let (_, report) = gradcheck(&[], &without);
    assert!(report["notes"].to_string().contains("grad_depth not given"), "{report}");
    // f32: the fused gradient is computed in f32 (differences well above f64 rounding) and
    // judged with the f32 defaults.
    let f32_input = input.replacen('{', r#"{"precision":"f32","#, 1);
    let (code, report) = gradcheck(&[], &f32_input);
    assert_eq!(code, 0, "{report}");
    assert_eq!(report["precision"], "f32");
    assert_eq!(
        (report["atol"].as_f64(), report["rtol"].as_f64()),
        (Some(1e-4), Some(1e-3))
    );
    let twin = row(&report, "taped_twin", "sigma")["worst"]["abs_diff"]
        .as_f64()
        .unwrap();
    assert!(twin > 1e-12 && twin < 1e-6, "f32 against the f64 twin: {twin}");
    let (_, report) = gradcheck(&[], input);
    let twin = row(&report, "taped_twin", "sigma")["worst"]["abs_diff"]
        .as_f64()
        .unwrap();
    assert!(twin < 1e-14, "f64 against the f64 twin: {twin}");
    // Under the f64 tolerance, f32 cannot pass.
    assert_eq!(gradcheck(&["--atol", "1e-12", "--rtol", "0"], &f32_input).0, 1);
}

#[test]
fn gradcheck_rejects_bad_input_with_the_composites_own_message() {
    for (input, args, needle) in [
        (
            r#"{"rays":[{"sigma":[1,-2],"delta":[1,1],"color":[[1],[1]]}]}"#,
            &[][..],
            "ray 0, sample 1: sigma is -2",
        ),
        (
            r#"{"rays":[{"sigma":[1],"delta":[-1],"color":[[1]]}]}"#,
            &["--fast"][..],
            "ray 0, sample 0: delta is -1",
        ),
        (LESSON, &["--atol=-1"][..], "--atol must be finite and >= 0"),
        (LESSON, &["--fast", "--projections", "0"][..], "--projections"),
    ] {
        let mut all = vec!["gradcheck"];
        all.extend_from_slice(args);
        let (code, out, err) = fogray(&all, input);
        assert_eq!(code, 2, "{input}: {out}{err}");
        assert!(out.is_empty(), "{out}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(needle), "{needle}: {err}");
    }
    let (code, out, _) = fogray(&["gradcheck", "--help"], "");
    assert_eq!(code, 0);
    for needle in [
        "--atol",
        "--rtol",
        "atol 1e-6",
        "atol 1e-4",
        "--fast",
        "Exit status",
        "grad_depth",
    ] {
        assert!(out.contains(needle), "{needle} missing from gradcheck --help");
    }
}

#[test]
fn composite_prints_only_the_fields_asked_for() {
    let input = LESSON.replace(r#""background""#, r#""t":[1,2,3,4],"grad_depth":2,"background""#);
    let (code, all, err) = fogray(&["composite"], &input);
    assert_eq!(code, 0, "{err}");
    let all: serde_json::Value = serde_json::from_str(&all).unwrap();
    // dL/dt_k = w_k grad_depth.
    let w = numbers(&all["rays"][0]["weights"]);
    for (g, w) in numbers(&all["rays"][0]["grad_t"]).iter().zip(&w) {
        assert_eq!(*g, 2.0 * w);
    }
    for (args, keys) in [
        (
            &["--per-ray"][..],
            &["color", "opacity", "depth", "grad_background"][..],
        ),
        (&["--fields", "weights,color"][..], &["color", "weights"][..]),
        (&["--fields", "depth"][..], &["depth"][..]),
    ] {
        let mut cmd = vec!["composite"];
        cmd.extend_from_slice(args);
        let (code, out, err) = fogray(&cmd, &input);
        assert_eq!(code, 0, "{err}");
        let json: serde_json::Value = serde_json::from_str(&out).unwrap();
        let ray = json["rays"][0].as_object().unwrap();
        let got: Vec<&str> = ray.keys().map(String::as_str).collect();
        let mut want = keys.to_vec();
        want.sort();
        let mut got_sorted = got.clone();
        got_sorted.sort();
        assert_eq!(got_sorted, want, "{args:?}");
        for k in keys {
            assert_eq!(ray[*k], all["rays"][0][*k], "{args:?} {k}");
        }
    }
    // Without t, depth is still printed as null when asked for.
    let (_, out, _) = fogray(&["composite", "--fields", "depth"], LESSON);
    assert_eq!(out.trim(), r#"{"rays":[{"depth":null}]}"#);
    let (code, _, err) = fogray(&["composite", "--fields", "colour"], LESSON);
    assert_eq!(code, 2, "{err}");
    let (code, out, _) = fogray(&["composite", "--help"], "");
    assert_eq!(code, 0);
    assert!(out.contains("--per-ray") && out.contains("--fields"), "{out}");
}
