//! Sizes the machine cannot hold and budgets that cannot end, refused before any work: exit
//! status 2, one line naming the flag or the file and the bytes, nothing on stdout (the refused
//! size is never allocated, so each refusal returns at once).

use crate::common::{arg, assert_refused, fogray, tiny_model};

#[test]
fn renders_and_fits_the_machine_cannot_hold_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = tiny_model(dir.path());
    let out = dir.path().join("out");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--model", arg(&model), "--out", arg(&out)];
        args.extend(extra);
        fogray(&args)
    };
    // Four billion cameras of one pixel each; then one frame of 1e10 pixels.
    let run = render(&["--orbit", "4294967296", "--size", "1x1"]);
    assert_refused(&run, "--orbit 4294967296 at 1x1 would need ", "a long orbit");
    let run = render(&["--orbit", "2", "--size", "100000x100000"]);
    assert_refused(&run, "--orbit 2 at 100000x100000 would need ", "a huge frame");
    assert!(run.stderr.contains(" available"), "{}", run.stderr);

    // A transforms file whose one frame claims 200000 x 200000 pixels (no picture needed:
    // the cameras are read without their images).
    let transforms = dir.path().join("huge.json");
    let pose = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let doc = serde_json::json!({
        "fl_x": 200000.0, "w": 200000, "h": 200000,
        "frames": [{ "file_path": "a.png", "transform_matrix": pose }],
    });
    std::fs::write(&transforms, doc.to_string()).unwrap();
    let run = render(&["--cameras", arg(&transforms)]);
    assert_refused(
        &run,
        "huge.json: 1 frames, the largest 200000x200000, would need ",
        "w/h 200000",
    );
    assert!(!out.exists(), "a refused render created its folder");

    let data = dir.path().join("data");
    let fit = |extra: &[&str]| {
        let mut args = vec!["fit", "--data", arg(&data)];
        args.extend(extra);
        fogray(&args)
    };
    assert_refused(&fit(&["--grid", "100000"]), "--grid 100000 would need ", "a huge grid");
    assert_refused(
        &fit(&["--batch", "4000000000"]),
        "--batch 4000000000 would need ",
        "a huge batch",
    );
    assert_refused(
        &fit(&["--seconds", "1e308"]),
        "--seconds 1e308: at most",
        "endless seconds",
    );
    assert_refused(
        &fit(&["--steps", "18446744073709551615"]),
        "--steps 18446744073709551615: at most",
        "endless steps",
    );
    // Each evaluation renders every held-out view off the clock: refused before the dataset
    // is read, so a missing one is not what is reported.
    let missing = dir.path().join("no-such-data");
    let run = fogray(&["fit", "--data", arg(&missing), "--evaluations", "18446744073709551615"]);
    assert_refused(
        &run,
        "--evaluations 18446744073709551615: at most",
        "endless evaluations",
    );
}
