use super::*;

/// A Blender dataset `dir/data` with one train frame `train/a` (the picture need not exist
/// for its path to count) and a model file beside it.
fn scene(dir: &Path) -> (PathBuf, PathBuf) {
    let data = dir.join("data");
    std::fs::create_dir_all(data.join("train")).unwrap();
    let doc = r#"{"camera_angle_x": 0.8, "frames": [{"file_path": "./train/a",
        "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,3],[0,0,0,1]]}]}"#;
    std::fs::write(data.join("transforms_train.json"), doc).unwrap();
    let model = dir.join("model.safetensors");
    std::fs::write(&model, b"weights").unwrap();
    (data, model)
}

fn refused(inputs: &Inputs, outputs: &[Output<'_>]) -> OutputProblem {
    match check_outputs(inputs, outputs) {
        Err(DataError::Output { problem, .. }) => problem,
        other => panic!("{outputs:?}: {other:?}"),
    }
}

#[test]
fn an_output_on_an_input_or_inside_a_dataset_folder_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (data, model) = scene(dir.path());
    let inputs = Inputs::new().file(&model).dataset(&data).unwrap();
    let into_data = |rest: &str| data.join(rest);
    assert!(matches!(
        refused(&inputs, &[Output::File(&model)]),
        OutputProblem::IsInput { .. }
    ));
    // The picture a frame names, reached through `..`: not yet on disk, still the dataset's.
    let picture = dir.path().join("data/train/../train/a.png");
    let problem = refused(&inputs, &[Output::File(&picture)]);
    assert_eq!(
        problem,
        OutputProblem::IsInput {
            input: into_data("./train/a.png")
        }
    );
    for inside in [into_data(""), into_data("train"), into_data("renders/new")] {
        let problem = refused(&inputs, &[Output::Folder(&inside)]);
        assert_eq!(
            problem,
            OutputProblem::InsideInput { folder: data.clone() },
            "{inside:?}"
        );
    }
    let transforms = into_data("transforms_train.json");
    assert!(matches!(
        refused(&inputs, &[Output::File(&transforms)]),
        OutputProblem::IsInput { .. }
    ));
    // Beside the dataset, all is well.
    let beside = dir.path().join("renders");
    check_outputs(&inputs, &[Output::Folder(&beside), Output::File(&beside.join("a.png"))]).unwrap();
    assert!(!beside.exists(), "the check writes nothing");
}

#[cfg(unix)]
#[test]
fn a_link_to_the_dataset_is_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = scene(dir.path());
    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&data, &link).unwrap();
    let inputs = Inputs::new().dataset(&data).unwrap();
    let problem = refused(&inputs, &[Output::Folder(&link.join("train"))]);
    assert_eq!(problem, OutputProblem::InsideInput { folder: data });
}

#[test]
fn a_report_folder_may_not_hold_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = scene(dir.path());
    let inputs = Inputs::new().dataset(&data).unwrap();
    let problem = plan_fit_outputs(&inputs, None, Some(dir.path()), &["test"]).unwrap_err();
    assert!(
        matches!(
            &problem,
            DataError::Output {
                problem: OutputProblem::HoldsInput { .. },
                ..
            }
        ),
        "{problem:?}"
    );
    // A plain folder output may: only what it writes is checked.
    check_outputs(&inputs, &[Output::Folder(dir.path())]).unwrap();
}

#[test]
fn a_model_file_is_checked_against_its_folder() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = scene(dir.path());
    let inputs = Inputs::new().dataset(&data).unwrap();
    let transforms = data.join("transforms_train.json");
    let err = plan_fit_outputs(&inputs, Some(&transforms), None, &["test"]).unwrap_err();
    assert!(
        err.to_string().starts_with(&format!(
            "{}: refused as an output: it is the input",
            transforms.display()
        )),
        "{err}"
    );
    assert_eq!(refused(&inputs, &[Output::File(dir.path())]), OutputProblem::IsFolder);
    let missing = dir.path().join("no/such/model.safetensors");
    assert_eq!(
        refused(&inputs, &[Output::File(&missing)]),
        OutputProblem::FolderMissing {
            folder: dir.path().join("no/such")
        }
    );
    // Into the report's folder, which the fit creates.
    let out = dir.path().join("report");
    plan_fit_outputs(&inputs, Some(&out.join("model.safetensors")), Some(&out), &["test"]).unwrap();
    let file = dir.path().join("model.safetensors");
    let under_a_file = file.join("x.png");
    assert_eq!(
        refused(&inputs, &[Output::File(&under_a_file)]),
        OutputProblem::NotAFolder { path: file.clone() }
    );
}

#[test]
fn resolution_follows_dot_dot_through_missing_names() {
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().canonicalize().unwrap();
    assert_eq!(resolved(&dir.path().join("a/b/../c")), real.join("a/c"));
    assert_eq!(
        resolved(&dir.path().join("a/../../x")),
        real.parent().unwrap().join("x")
    );
    assert_eq!(resolved(&dir.path().join("./.")), real);
}

#[cfg(unix)]
#[test]
fn a_report_subfolder_linked_into_the_dataset_or_a_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = scene(dir.path());
    let inputs = Inputs::new().dataset(&data).unwrap();
    let out = dir.path().join("report");
    std::fs::create_dir(&out).unwrap();
    // The report's folder itself is fine; its test/ is a link to a folder of the dataset.
    std::os::unix::fs::symlink(data.join("train"), out.join("test")).unwrap();
    let err = plan_fit_outputs(&inputs, None, Some(&out), &["test"]).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::Output {
                problem: OutputProblem::InsideInput { .. },
                ..
            }
        ),
        "{err:?}"
    );
    // Without the subfolder named, the link goes unseen: the check is what names it.
    plan_fit_outputs(&inputs, None, Some(&out), &[]).unwrap();
    // A file where the report puts a folder.
    std::fs::remove_file(out.join("test")).unwrap();
    std::fs::write(out.join("test"), b"x").unwrap();
    let err = plan_fit_outputs(&inputs, None, Some(&out), &["test"]).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::Output {
                problem: OutputProblem::NotAFolder { .. },
                ..
            }
        ),
        "{err:?}"
    );
}
