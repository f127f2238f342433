//! `load_split_cameras`: the train and test frames are the ones `load` trains on and holds out.

use fogray_data::{load, load_cameras, load_split_cameras, LoadOptions, Split};
use serde_json::json;

use crate::common::{at, blender_folder, ngp_file, solid_png, tempdir, write_json};

fn names(path: &std::path::Path, split: Split) -> Vec<String> {
    load_split_cameras(path, 1, split)
        .unwrap()
        .into_iter()
        .map(|c| c.name)
        .collect()
}

#[test]
fn an_ngp_capture_holds_out_every_eighth_frame_as_load_does() {
    let dir = tempdir();
    let frames: Vec<_> = (0..17)
        .map(|i| {
            let file = format!("images/f{i:02}.png");
            solid_png(&dir.path().join(&file), 4, 3, [10, 20, 30]);
            json!({ "file_path": file, "transform_matrix": at([i as f64, 0.0, 4.0]) })
        })
        .collect();
    ngp_file(dir.path(), json!({ "fl_x": 4.0, "fl_y": 4.0, "w": 4, "h": 3 }), frames);
    assert_eq!(names(dir.path(), Split::Test), ["f00", "f08", "f16"]);
    let train = names(dir.path(), Split::Train);
    assert_eq!(train.len(), 14);
    assert!(!train.iter().any(|n| ["f00", "f08", "f16"].contains(&n.as_str())));
    assert_eq!(names(dir.path(), Split::All).len(), 17);
    assert_eq!(load_cameras(dir.path(), 1).unwrap().len(), 17);
    // The frames `load` holds out, by name.
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    let held: Vec<String> = scene.test.iter().map(|f| f.name.clone()).collect();
    assert_eq!(held, names(dir.path(), Split::Test));
}

#[test]
fn a_blender_folder_holds_out_its_test_split_and_a_split_file_stands_for_its_folder() {
    let dir = tempdir();
    let train_file = blender_folder(
        dir.path(),
        0.7,
        &[("r_0", [0.0, 0.0, 4.0]), ("r_1", [1.0, 0.0, 4.0])],
        4,
        4,
    );
    solid_png(&dir.path().join("t_0.png"), 4, 4, [0, 0, 0]);
    write_json(
        &dir.path().join("transforms_test.json"),
        &json!({ "camera_angle_x": 0.7, "frames": [{ "file_path": "t_0", "transform_matrix": at([0.0, 1.0, 4.0]) }] }),
    );
    assert_eq!(names(dir.path(), Split::Test), ["t_0"]);
    assert_eq!(names(dir.path(), Split::Train), ["r_0", "r_1"]);
    assert_eq!(names(dir.path(), Split::All), ["r_0", "r_1", "t_0"]);
    assert_eq!(names(&train_file, Split::Test), ["t_0"]);
}
