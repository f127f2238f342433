//! What reaches the terminal: a flag error is one line on stderr (exit status 2, nothing on
//! stdout) for every subcommand, and a name read from a transforms file is printed with its
//! control characters escaped, in the paths a command prints and in its errors; `--json`
//! keeps stdout to its JSON, the load's and the fit's bars off.

use crate::common::{arg, fogray, render_cameras, tiny_fit};
use crate::outputs::write_model;

#[test]
fn every_flag_error_is_one_line() {
    let cases: [(&[&str], &str); 9] = [
        (&["fit", "--data", "d", "--background", "2,2,2"], "fit"),
        (&["fit", "--data", "d", "--box", "0"], "fit"),
        (
            &["fit", "--data", "d", "--steps", "10", "--seconds", "3", "--bogus"],
            "fit",
        ),
        (
            &["render", "--model", "m", "--orbit", "3", "--size", "32x", "--out", "o"],
            "render",
        ),
        (
            &["render", "--model", "m", "--orbit", "3", "--cameras", "c", "--out", "o"],
            "render",
        ),
        (&["export", "--model", "m"], "export"),
        (&["composite", "--method", "nope"], "composite"),
        // A negative number is a value, refused by the flag's own check.
        (&["fit", "--data", "d", "--lr", "-1"], "fit"),
        (&["view", "--model", "m", "--port", "-1"], "view"),
    ];
    for (args, subcommand) in cases {
        let run = fogray(args);
        assert_eq!(run.code, 2, "{args:?}: {}", run.stderr);
        assert!(run.stdout.is_empty(), "{args:?}: {}", run.stdout);
        assert_eq!(run.stderr.lines().count(), 1, "{args:?}: {:?}", run.stderr);
        let prefix = format!("fogray {subcommand}: error: ");
        assert!(run.stderr.starts_with(&prefix), "{args:?}: {:?}", run.stderr);
        assert!(!run.stderr.contains("Usage"), "{args:?}: {:?}", run.stderr);
    }
    // What the error names survives the folding: the missing flag, the possible values, the
    // flag a negative number was given to.
    assert!(fogray(&["fit", "--data", "d", "--lr", "-1"]).stderr.contains("--lr"));
    assert!(fogray(&["view", "--model", "m", "--port", "-1"])
        .stderr
        .contains("--port"));
    assert!(fogray(&["export", "--model", "m"]).stderr.contains("--mesh"));
    assert!(fogray(&["composite", "--method", "nope"])
        .stderr
        .contains("taped-naive"));
    // Help is still help: on stdout, exit status 0.
    let help = fogray(&["render", "--help"]);
    assert_eq!(help.code, 0);
    assert!(help.stdout.contains("--orbit"));
}

/// An instant-ngp transforms file of one 8x8 frame whose `file_path` is `images/<name>.png`.
fn transforms_naming(dir: &std::path::Path, name: &str) -> std::path::PathBuf {
    let doc = serde_json::json!({
        "fl_x": 10.0, "fl_y": 10.0, "cx": 4.0, "cy": 4.0, "w": 8, "h": 8,
        "frames": [{
            "file_path": format!("images/{name}.png"),
            "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]],
        }],
    });
    let path = dir.join("transforms.json");
    std::fs::write(&path, serde_json::to_string(&doc).unwrap()).unwrap();
    path
}

#[test]
fn a_frame_name_with_control_characters_is_printed_escaped() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.safetensors");
    write_model(&model);
    // ESC [ 2 J clears the screen of whoever reads it raw.
    let transforms = transforms_naming(dir.path(), "\u{1b}[2Jred");
    let out = dir.path().join("out");
    let run = render_cameras(&model, &transforms, &out, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stdout.ends_with("\\u{1b}[2Jred.png\n"), "{:?}", run.stdout);
    assert!(!run.stdout.contains('\u{1b}'), "{:?}", run.stdout);
    // The file keeps the name the transforms file gives it.
    assert!(out.join("\u{1b}[2Jred.png").is_file());
    // In an error: the picture is missing, and the fit names it.
    let run = fogray(&["fit", "--data", arg(&transforms), "--steps", "1"]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert_eq!(run.stderr.lines().count(), 1, "{:?}", run.stderr);
    assert!(run.stderr.contains("images/\\u{1b}[2Jred.png"), "{:?}", run.stderr);
    assert!(!run.stderr.contains('\u{1b}'), "{:?}", run.stderr);
    // A carriage return and a NUL (which no file name can hold: the write fails, named).
    let transforms = transforms_naming(dir.path(), "a\rb\0c");
    let run = render_cameras(&model, &transforms, &out, &[]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stderr.contains("a\\rb\\0c.png"), "{:?}", run.stderr);
    assert!(!run.stderr.contains(['\r', '\0']), "{:?}", run.stderr);
}

#[test]
fn a_fit_with_json_prints_only_its_json_on_stdout_while_the_pictures_load() {
    let dir = tempfile::tempdir().unwrap();
    let (_, run) = tiny_fit(dir.path(), &[]);
    let summary: serde_json::Value = serde_json::from_str(&run.stdout).expect("stdout is one JSON value");
    assert_eq!(summary["steps"], 1, "{}", run.stdout);
    assert!(
        !run.stderr.contains("pictures"),
        "a load bar with --json: {:?}",
        run.stderr
    );
}
