//! One test per way a COLMAP model can be wrong: the error variant, and a one-line message
//! naming the file.

use std::path::{Path, PathBuf};

use fogray_data::{load, load_cameras, DataError, LoadOptions};

use crate::capture_files::{cameras_bin, cameras_txt, images_bin, images_txt, write_model, ColmapCamera, ColmapImage};
use crate::common::{names, solid_png, tempdir};

fn camera(id: i32, model: &'static str, width: u64, height: u64, params: &[f64]) -> ColmapCamera {
    ColmapCamera {
        id,
        model,
        width,
        height,
        params: params.to_vec(),
    }
}

fn image(id: i32, camera: i32, name: &str) -> ColmapImage {
    ColmapImage {
        id,
        q: [1.0, 0.0, 0.0, 0.0],
        t: [0.0, 0.0, id as f64],
        camera,
        name: name.to_string(),
    }
}

/// A good two-image model (binary or text) with its pictures; returns the model folder.
fn good(dir: &Path, binary: bool) -> PathBuf {
    let folder = dir.join("sparse/0");
    let cameras = [camera(1, "PINHOLE", 4, 3, &[5.0, 5.0, 2.0, 1.5])];
    let images = [image(1, 1, "a.png"), image(2, 1, "b.png")];
    write_model(&folder, binary, &cameras, &images, &[]);
    for name in ["a.png", "b.png"] {
        solid_png(&dir.join("images").join(name), 4, 3, [9, 9, 9]);
    }
    folder
}

/// Loads `dir` and checks that the error names `file` on one line.
fn refused(dir: &Path, file: &Path) -> DataError {
    let err = load(dir, &LoadOptions::default()).unwrap_err();
    names(&err, file);
    err
}

#[test]
fn the_good_models_load() {
    for binary in [true, false] {
        let dir = tempdir();
        good(dir.path(), binary);
        let scene = load(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(scene.train.len() + scene.test.len(), 2);
        assert!(scene.points.is_some_and(|p| p.is_empty()));
        // No points file: no point cloud.
        std::fs::remove_file(dir.path().join(if binary {
            "sparse/0/points3D.bin"
        } else {
            "sparse/0/points3D.txt"
        }))
        .unwrap();
        assert!(load(dir.path(), &LoadOptions::default()).unwrap().points.is_none());
    }
}

#[test]
fn a_truncated_bin_is_refused_at_its_offset() {
    let dir = tempdir();
    let folder = good(dir.path(), true);
    let file = folder.join("cameras.bin");
    let bytes = std::fs::read(&file).unwrap();
    // Cut in the middle of the last parameter: 8 + 24 header bytes, 4 parameters.
    std::fs::write(&file, &bytes[..bytes.len() - 3]).unwrap();
    let err = refused(dir.path(), &file);
    assert!(
        matches!(
            &err,
            DataError::Truncated {
                offset: 56,
                needed: 8,
                available: 5,
                ..
            }
        ),
        "{err}"
    );
    // An image name without its NUL.
    let file = folder.join("images.bin");
    let bytes = images_bin(&[image(1, 1, "a.png")]);
    // Count, id, pose, camera id: 8 + 4 + 56 + 4 bytes, then a name running to the end (long
    // enough that the count of one image fits).
    let cut = [&bytes[..8 + 4 + 56 + 4], b"a-name-with-no-end.png"].concat();
    std::fs::write(&file, cut).unwrap();
    std::fs::write(
        folder.join("cameras.bin"),
        cameras_bin(&[camera(1, "PINHOLE", 4, 3, &[5.0, 5.0, 2.0, 1.5])]),
    )
    .unwrap();
    let err = refused(dir.path(), &file);
    assert!(err.to_string().contains("no terminating NUL"), "{err}");
    // Bytes after the last record.
    std::fs::write(&file, [images_bin(&[image(1, 1, "a.png")]), vec![0; 3]].concat()).unwrap();
    let err = refused(dir.path(), &file);
    assert!(
        matches!(&err, DataError::Malformed { .. }) && err.to_string().contains("3 byte(s) after"),
        "{err}"
    );
}

#[test]
fn lying_counts_are_refused_without_allocating() {
    let dir = tempdir();
    let folder = good(dir.path(), true);
    // Each count patched to 2^62: no allocation of that many records can be made.
    let huge = (1u64 << 62).to_le_bytes();
    let images = folder.join("images.bin");
    let mut bytes = images_bin(&[image(1, 1, "a.png"), image(2, 1, "b.png")]);
    bytes[..8].copy_from_slice(&huge);
    std::fs::write(&images, &bytes).unwrap();
    let err = refused(dir.path(), &images);
    assert!(
        matches!(&err, DataError::Truncated { offset: 0, what, .. } if what.starts_with("4611686018427387904 images")),
        "{err}"
    );
    // The 2-D points count of the first image: after 8 + 4 + 56 + 4 bytes and "a.png\0".
    let mut bytes = images_bin(&[image(1, 1, "a.png"), image(2, 1, "b.png")]);
    let at = 8 + 4 + 56 + 4 + 6;
    bytes[at..at + 8].copy_from_slice(&huge);
    std::fs::write(&images, &bytes).unwrap();
    let err = refused(dir.path(), &images);
    assert!(
        matches!(&err, DataError::Truncated { offset, .. } if *offset == at as u64),
        "{err}"
    );

    let cameras = folder.join("cameras.bin");
    let mut bytes = cameras_bin(&[camera(1, "PINHOLE", 4, 3, &[5.0, 5.0, 2.0, 1.5])]);
    bytes[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&cameras, &bytes).unwrap();
    let err = refused(dir.path(), &cameras);
    assert!(matches!(&err, DataError::Truncated { .. }), "{err}");
    good(dir.path(), true);

    // The track length of a point.
    let points = folder.join("points3D.bin");
    let mut bytes = crate::capture_files::points_bin(&[crate::capture_files::ColmapPoint {
        id: 1,
        xyz: [0.0; 3],
        rgb: [1, 2, 3],
    }]);
    let at = 8 + 8 + 24 + 3 + 8;
    bytes[at..at + 8].copy_from_slice(&huge);
    std::fs::write(&points, &bytes).unwrap();
    let err = refused(dir.path(), &points);
    assert!(
        matches!(&err, DataError::Truncated { offset, .. } if *offset == at as u64),
        "{err}"
    );
}

#[test]
fn other_camera_models_are_refused_by_name() {
    let dir = tempdir();
    let folder = good(dir.path(), true);
    let file = folder.join("cameras.bin");
    let fisheye = camera(7, "OPENCV_FISHEYE", 4, 3, &[5.0, 5.0, 2.0, 1.5, 0.0, 0.0, 0.0, 0.0]);
    std::fs::write(&file, cameras_bin(&[fisheye])).unwrap();
    let err = refused(dir.path(), &file);
    assert!(
        matches!(&err, DataError::CameraModel { camera: 7, model, .. } if model == "OPENCV_FISHEYE"),
        "{err}"
    );
    // An id no model has.
    let mut bytes = cameras_bin(&[camera(1, "PINHOLE", 4, 3, &[5.0, 5.0, 2.0, 1.5])]);
    bytes[12..16].copy_from_slice(&99i32.to_le_bytes());
    std::fs::write(&file, bytes).unwrap();
    let err = refused(dir.path(), &file);
    assert!(err.to_string().contains("id 99"), "{err}");

    let dir = tempdir();
    let folder = good(dir.path(), false);
    let file = folder.join("cameras.txt");
    std::fs::write(&file, "1 FULL_OPENCV 4 3 5 5 2 1.5 0 0 0 0 0 0 0 0\n").unwrap();
    let err = refused(dir.path(), &file);
    assert!(
        matches!(&err, DataError::CameraModel { model, .. } if model == "FULL_OPENCV"),
        "{err}"
    );
    std::fs::write(&file, "1 MY_LENS 4 3 5\n").unwrap();
    let err = refused(dir.path(), &file);
    assert!(err.to_string().contains("MY_LENS"), "{err}");
}

#[test]
fn an_image_of_no_camera_is_refused() {
    for binary in [true, false] {
        let dir = tempdir();
        let folder = good(dir.path(), binary);
        let images = [image(1, 1, "a.png"), image(2, 42, "b.png")];
        let (file, cameras_file) = if binary {
            std::fs::write(folder.join("images.bin"), images_bin(&images)).unwrap();
            (folder.join("images.bin"), folder.join("cameras.bin"))
        } else {
            std::fs::write(folder.join("images.txt"), images_txt(&images)).unwrap();
            (folder.join("images.txt"), folder.join("cameras.txt"))
        };
        let err = refused(dir.path(), &file);
        assert!(
            matches!(&err, DataError::UnknownCamera { camera: 42, image, .. } if image == "b.png"),
            "{err}"
        );
        names(&err, &cameras_file);
        // load_cameras reads the same model.
        assert!(matches!(
            load_cameras(dir.path(), 1),
            Err(DataError::UnknownCamera { .. })
        ));
    }
}

#[test]
fn absurd_values_are_refused_naming_the_camera_or_image() {
    let cases: [(ColmapCamera, &str); 5] = [
        (camera(1, "PINHOLE", 4, 3, &[0.0, 5.0, 2.0, 1.5]), "camera 1 fx"),
        (camera(1, "SIMPLE_PINHOLE", 4, 3, &[-2.0, 2.0, 1.5]), "camera 1 fx"),
        (camera(1, "PINHOLE", 4, 3, &[5.0, f64::NAN, 2.0, 1.5]), "camera 1 fy"),
        (camera(1, "PINHOLE", 0, 3, &[5.0, 5.0, 2.0, 1.5]), "camera 1 width"),
        (
            camera(1, "PINHOLE", 4, 1 << 40, &[5.0, 5.0, 2.0, 1.5]),
            "camera 1 height",
        ),
    ];
    for binary in [true, false] {
        for (bad, key) in &cases {
            let dir = tempdir();
            let folder = good(dir.path(), binary);
            let file = if binary {
                std::fs::write(folder.join("cameras.bin"), cameras_bin(std::slice::from_ref(bad))).unwrap();
                folder.join("cameras.bin")
            } else {
                std::fs::write(folder.join("cameras.txt"), cameras_txt(std::slice::from_ref(bad))).unwrap();
                folder.join("cameras.txt")
            };
            let err = refused(dir.path(), &file);
            assert!(matches!(&err, DataError::BadValue { key: k, .. } if k == key), "{err}");
        }
    }
    let dir = tempdir();
    let folder = good(dir.path(), true);
    let mut nan = image(2, 1, "b.png");
    nan.q[2] = f64::NAN;
    std::fs::write(folder.join("images.bin"), images_bin(&[image(1, 1, "a.png"), nan])).unwrap();
    let err = refused(dir.path(), &folder.join("images.bin"));
    assert!(
        matches!(&err, DataError::BadValue { key, .. } if key == "image 2 (`b.png`) qy"),
        "{err}"
    );
    let mut zero = image(2, 1, "b.png");
    zero.q = [0.0; 4];
    std::fs::write(folder.join("images.bin"), images_bin(&[image(1, 1, "a.png"), zero])).unwrap();
    let err = refused(dir.path(), &folder.join("images.bin"));
    assert!(err.to_string().contains("quaternion"), "{err}");
    // A picture of another size than its camera's.
    std::fs::write(
        folder.join("images.bin"),
        images_bin(&[image(1, 1, "a.png"), image(2, 1, "b.png")]),
    )
    .unwrap();
    solid_png(&dir.path().join("images/b.png"), 5, 3, [0, 0, 0]);
    let err = refused(dir.path(), &dir.path().join("images/b.png"));
    assert!(
        matches!(
            &err,
            DataError::SizeMismatch {
                size: (5, 3),
                expected: (4, 3),
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn text_that_does_not_read_is_refused_at_its_line() {
    let dir = tempdir();
    let folder = good(dir.path(), false);
    let file = folder.join("cameras.txt");
    std::fs::write(&file, "# comment\n\n1 PINHOLE 4 three 5 5 2 1.5\n").unwrap();
    let err = refused(dir.path(), &file);
    assert!(
        matches!(&err, DataError::Malformed { at, .. } if at == "line 3") && err.to_string().contains("HEIGHT `three`"),
        "{err}"
    );
    std::fs::write(&file, "1 PINHOLE 4 3 5 5 2\n").unwrap();
    assert!(refused(dir.path(), &file).to_string().contains("missing a parameter"));
    std::fs::write(&file, "1 PINHOLE 4 3 5 5 2 1.5 0.1\n").unwrap();
    assert!(refused(dir.path(), &file).to_string().contains("unexpected `0.1`"));
    std::fs::write(&file, "1 PINHOLE 4 3 5 5 2 1.5\n1 PINHOLE 4 3 5 5 2 1.5\n").unwrap();
    assert!(refused(dir.path(), &file)
        .to_string()
        .contains("camera id 1 appears twice"));
    good(dir.path(), false);
    let file = folder.join("images.txt");
    std::fs::write(&file, "1 1 0 0 0 0 0 1 1\n\n").unwrap();
    assert!(refused(dir.path(), &file).to_string().contains("missing NAME"));
    std::fs::write(&file, "1 1 0 0 0 0 0 1 1 a.png\n\n1 1 0 0 0 0 0 2 1 b.png\n\n").unwrap();
    assert!(refused(dir.path(), &file)
        .to_string()
        .contains("image id 1 appears twice"));
    std::fs::write(&file, "# no images\n").unwrap();
    assert!(matches!(refused(dir.path(), &file), DataError::NoFrames { .. }));
}

#[test]
fn a_capture_without_its_images_folder_is_refused() {
    let dir = tempdir();
    good(dir.path(), true);
    std::fs::remove_dir_all(dir.path().join("images")).unwrap();
    let err = refused(dir.path(), &dir.path().join("images"));
    assert!(matches!(&err, DataError::MissingFolder { .. }), "{err}");
    // Its cameras need no picture.
    assert_eq!(load_cameras(dir.path(), 1).unwrap().len(), 2);
}

#[test]
fn a_folder_with_no_dataset_names_what_it_looked_for() {
    let dir = tempdir();
    std::fs::create_dir_all(dir.path().join("sparse/0")).unwrap();
    let err = refused(dir.path(), dir.path());
    assert!(matches!(&err, DataError::NoTransforms { .. }), "{err}");
    assert!(err.to_string().contains("poses_bounds.npy"), "{err}");
}
