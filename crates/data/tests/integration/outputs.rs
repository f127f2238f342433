//! Safe output as a library user meets it: outputs checked against a dataset before any work,
//! a file written whole or not at all, and a frame's name with control characters shown
//! escaped in an error.

use fogray_data::{check_outputs, load, write_atomic, DataError, Inputs, LoadOptions, Output, OutputProblem};
use serde_json::json;

use crate::common::{at, tempdir, write_json};

#[test]
fn outputs_on_a_datasets_files_are_refused_and_beside_it_allowed() {
    let dir = tempdir();
    let data = dir.path().join("data");
    std::fs::create_dir_all(data.join("images")).unwrap();
    let doc = json!({"fl_x": 10.0, "cx": 4.0, "cy": 4.0, "w": 8, "h": 8,
        "frames": [{"file_path": "images/a.png", "transform_matrix": at([0.0, 0.0, 3.0])}]});
    write_json(&data.join("transforms.json"), &doc);
    // Given as its transforms file: the file and the picture it names are the inputs.
    let inputs = Inputs::new().dataset(&data.join("transforms.json")).unwrap();
    let picture = data.join("images/a.png");
    let err = check_outputs(&inputs, &[Output::File(&picture)]).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::Output {
                problem: OutputProblem::IsInput { .. },
                ..
            }
        ),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        format!(
            "{}: refused as an output: it is the input {}",
            picture.display(),
            picture.display()
        )
    );
    check_outputs(&inputs, &[Output::File(&data.join("images/b.png"))]).unwrap();
    // Given as a folder: nothing inside it may be written.
    let inputs = Inputs::new().dataset(&data).unwrap();
    let err = check_outputs(&inputs, &[Output::File(&data.join("images/b.png"))]).unwrap_err();
    let inside = format!("it lies inside the input dataset folder {}", data.display());
    assert!(err.to_string().ends_with(&inside), "{err}");
    check_outputs(&inputs, &[Output::Folder(&dir.path().join("renders"))]).unwrap();
}

#[test]
fn a_failed_write_keeps_the_old_file_and_leaves_nothing_beside_it() {
    let dir = tempdir();
    let target = dir.path().join("transforms.json");
    std::fs::write(&target, "{}").unwrap();
    let err = write_atomic(&target, |out| {
        out.write_all(b"{\"frames\": [")?;
        Err(std::io::Error::from(std::io::ErrorKind::StorageFull))
    })
    .unwrap_err();
    assert!(err.to_string().starts_with(&target.display().to_string()), "{err}");
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "{}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn a_frame_name_with_an_escape_is_shown_escaped() {
    let dir = tempdir();
    let doc = json!({"fl_x": 10.0, "cx": 4.0, "cy": 4.0, "w": 8, "h": 8,
        "frames": [{"file_path": "images/\u{1b}[2Jred.png", "transform_matrix": at([0.0, 0.0, 3.0])}]});
    write_json(&dir.path().join("transforms.json"), &doc);
    let err = load(dir.path(), &LoadOptions::default()).unwrap_err();
    let shown = err.to_string();
    assert!(shown.contains("images/\\u{1b}[2Jred.png"), "{shown}");
    assert!(!shown.contains('\u{1b}'), "{shown}");
}
