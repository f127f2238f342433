//! COLMAP models written by hand from known cameras read back: every camera's rays are the
//! originals' carried by the exposed world transform, which itself does what the format's
//! docs say (mean centre to the origin, mean up to +Z, largest coordinate 1).

use std::path::Path;

use fogray_data::{
    downscale_intrinsics, load, load_cameras, Format, FullSizeReason, ImageSource, Intrinsics, LensDistortion,
    LoadOptions, PinholeCamera, SceneData, WorldTransform,
};

use crate::capture_files::{colmap_camera, colmap_image, write_model, ColmapCamera, ColmapImage, ColmapPoint};
use crate::common::{solid_png, tempdir};

/// How many views: two are held out (0 and 8).
const VIEWS: usize = 9;

/// A view: its image name, camera and the COLMAP model written for it.
struct View {
    name: String,
    camera: PinholeCamera,
    model: &'static str,
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / n)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// A colour per view, so that a picture shows which file it was read from.
fn color(i: usize) -> [u8; 3] {
    [20 * i as u8, 250 - 20 * i as u8, 7]
}

/// Nine cameras on a tilted ring around (1, 2, -3), at varying heights along a world "up"
/// that is no axis (COLMAP's world is arbitrary), looking at the ring's centre. With
/// `per_image`, each has its own size, intrinsics and lens model; otherwise all share one
/// OPENCV camera.
fn views(per_image: bool) -> Vec<View> {
    let up = unit([0.3, -1.0, 0.2]);
    let e1 = unit(cross(up, [1.0, 0.0, 0.0]));
    let e2 = cross(up, e1);
    let centre = [1.0, 2.0, -3.0];
    let models = ["SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV"];
    (0..VIEWS)
        .map(|i| {
            let a = i as f64 * 0.7;
            let (radius, height) = (4.0 + 0.3 * i as f64, 0.5 * (i % 3) as f64 - 0.2);
            let eye: [f64; 3] =
                std::array::from_fn(|k| centre[k] + radius * (a.cos() * e1[k] + a.sin() * e2[k]) + height * up[k]);
            let (model, k, d) = if per_image {
                let model = models[i % models.len()];
                let f = 7.0 + i as f64;
                let square = model != "PINHOLE" && model != "OPENCV";
                let k = Intrinsics {
                    fx: f,
                    fy: if square { f } else { f * 1.1 },
                    cx: 4.0 + 0.1 * i as f64,
                    cy: 3.0 - 0.05 * i as f64,
                    width: 8 + 2 * (i % 3),
                    height: 6 + 2 * (i % 2),
                };
                let d = LensDistortion {
                    k1: if model.contains("RADIAL") || model == "OPENCV" {
                        0.05
                    } else {
                        0.0
                    },
                    k2: if model == "RADIAL" || model == "OPENCV" {
                        -0.01
                    } else {
                        0.0
                    },
                    p1: if model == "OPENCV" { 0.002 } else { 0.0 },
                    p2: if model == "OPENCV" { -0.001 } else { 0.0 },
                    ..LensDistortion::NONE
                };
                (model, k, d)
            } else {
                let k = Intrinsics {
                    fx: 9.0,
                    fy: 9.5,
                    cx: 4.2,
                    cy: 2.9,
                    width: 8,
                    height: 6,
                };
                let d = LensDistortion {
                    k1: 0.03,
                    k2: 0.01,
                    p1: -0.002,
                    p2: 0.001,
                    ..LensDistortion::NONE
                };
                ("OPENCV", k, d)
            };
            let camera = PinholeCamera::look_at(k, eye, centre, up)
                .unwrap()
                .with_distortion(d)
                .unwrap();
            View {
                name: format!("shot_{i:02}.png"),
                camera,
                model,
            }
        })
        .collect()
}

/// Three points of the scene, with colours.
fn points() -> Vec<ColmapPoint> {
    [
        ([1.0, 2.0, -3.0], [255, 0, 0]),
        ([1.5, 2.2, -2.5], [0, 255, 0]),
        ([0.0, 1.0, -4.0], [0, 0, 255]),
    ]
    .iter()
    .enumerate()
    .map(|(i, &(xyz, rgb))| ColmapPoint {
        id: 10 + i as u64,
        xyz,
        rgb,
    })
    .collect()
}

/// The model of `views` (images listed in reverse order, ids not in name order) and each
/// view's picture in `dir/images`; the model in `dir/model_folder`.
fn write_capture(dir: &Path, model_folder: &str, binary: bool, views: &[View], shared: bool) {
    let cameras: Vec<ColmapCamera> = if shared {
        vec![colmap_camera(3, views[0].model, &views[0].camera)]
    } else {
        views
            .iter()
            .enumerate()
            .map(|(i, v)| colmap_camera(100 + i as i32, v.model, &v.camera))
            .collect()
    };
    let images: Vec<ColmapImage> = views
        .iter()
        .enumerate()
        .rev()
        .map(|(i, v)| {
            let camera = if shared { 3 } else { 100 + i as i32 };
            colmap_image(50 - i as i32, camera, &v.name, &v.camera)
        })
        .collect();
    write_model(&dir.join(model_folder), binary, &cameras, &images, &points());
    for (i, v) in views.iter().enumerate() {
        let k = v.camera.intrinsics();
        solid_png(
            &dir.join("images").join(&v.name),
            k.width as u32,
            k.height as u32,
            color(i),
        );
    }
}

fn close(got: [f64; 3], want: [f64; 3], tol: f64, what: &str) {
    assert!(
        (0..3).all(|i| (got[i] - want[i]).abs() <= tol),
        "{what}: got {got:?}, want {want:?}"
    );
}

/// The world transform does what the docs say, checked on the original cameras: a rotation,
/// the mean centre to the origin, the largest centre coordinate 1, the mean up to +Z.
fn check_world(world: &WorldTransform, views: &[View]) {
    let r = world.rotation;
    for (i, j) in (0..3).flat_map(|i| (0..3).map(move |j| (i, j))) {
        let dot: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
        assert!((dot - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
    }
    let n = views.len() as f64;
    let mean = |f: &dyn Fn(&PinholeCamera) -> [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|k| views.iter().map(|v| f(&v.camera)[k]).sum::<f64>() / n)
    };
    close(world.apply_point(mean(&|c| c.centre())), [0.0; 3], 1e-12, "mean centre");
    let largest = views
        .iter()
        .flat_map(|v| world.apply_point(v.camera.centre()))
        .fold(0.0f64, |m, x| m.max(x.abs()));
    assert!((largest - 1.0).abs() < 1e-12, "largest coordinate {largest}");
    // Image up is -y in OpenCV axes: minus the second column of camera-to-world.
    let up = mean(&|c| {
        let m = c.camera_to_world();
        [-m[0][1], -m[1][1], -m[2][1]]
    });
    close(unit(world.apply_direction(up)), [0.0, 0.0, 1.0], 1e-12, "mean up");
}

/// Every frame of `scene` is its view's camera carried into the scene's world: intrinsics and
/// lens as written, and the ray of each corner and centre pixel (origin and direction) the
/// original's through `scene.world`, to 1e-9.
fn check_frames(scene: &SceneData, views: &[View]) {
    let names: Vec<&str> = scene.test.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["shot_00", "shot_08"]);
    assert_eq!(scene.train.len(), VIEWS - 2);
    for frame in scene.train.iter().chain(&scene.test) {
        let i = views
            .iter()
            .position(|v| v.name == format!("{}.png", frame.name))
            .unwrap();
        let (want, got) = (&views[i].camera, &frame.camera);
        assert_eq!(got.intrinsics(), want.intrinsics(), "{}", frame.name);
        assert_eq!(got.distortion(), want.distortion(), "{}", frame.name);
        close(got.centre(), scene.world.apply_point(want.centre()), 1e-9, "origin");
        let k = want.intrinsics();
        for (row, col) in [(0, 0), (0, k.width - 1), (k.height - 1, 0), (k.height / 2, k.width / 2)] {
            let d = scene.world.apply_direction(want.direction(row, col));
            close(
                got.direction(row, col),
                d,
                1e-9,
                &format!("{} pixel ({row}, {col})", frame.name),
            );
        }
        let rgb = color(i).map(|c| c as f32 / 255.0);
        assert_eq!(frame.picture.color.dim(), (k.height, k.width, 3));
        assert!((0..3).all(|c| (frame.picture.color[[0, 0, c]] - rgb[c]).abs() < 1e-6));
    }
}

fn check_points(scene: &SceneData) {
    let cloud = scene.points.as_ref().expect("points3D was written");
    assert_eq!(cloud.len(), 3);
    for (got, want) in cloud.positions.iter().zip(points()) {
        close(*got, scene.world.apply_point(want.xyz), 1e-12, "point");
        close(scene.world.invert_point(*got), want.xyz, 1e-12, "point back");
    }
    assert_eq!(cloud.colors, [[255, 0, 0], [0, 255, 0], [0, 0, 255]]);
}

#[test]
fn binary_and_text_models_give_the_cameras_they_were_written_from() {
    for binary in [true, false] {
        for shared in [true, false] {
            let dir = tempdir();
            let views = views(!shared);
            write_capture(dir.path(), "sparse/0", binary, &views, shared);
            let scene = load(dir.path(), &LoadOptions::default()).unwrap();
            assert_eq!(scene.format, Format::Colmap);
            check_world(&scene.world, &views);
            check_frames(&scene, &views);
            check_points(&scene);
            assert_eq!(scene.scene_box, ([-1.0; 3], [1.0; 3]));
            assert_eq!((scene.skipped, scene.unregistered), (0, 0));
            assert!(matches!(
                &scene.images,
                ImageSource::FullSize { downscale: 1, why: FullSizeReason::NotAsked, folder } if folder == &dir.path().join("images")
            ));
        }
    }
}

#[test]
fn the_other_model_folders_are_found() {
    for folder in ["sparse", "colmap/sparse/0"] {
        let dir = tempdir();
        let views = views(false);
        write_capture(dir.path(), folder, false, &views, true);
        let scene = load(dir.path(), &LoadOptions::default()).unwrap();
        check_frames(&scene, &views);
    }
}

#[test]
fn cameras_alone_are_the_loaded_ones_and_need_no_picture() {
    let dir = tempdir();
    let views = views(true);
    write_capture(dir.path(), "sparse/0", true, &views, false);
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    std::fs::remove_dir_all(dir.path().join("images")).unwrap();
    let cameras = load_cameras(dir.path(), 1).unwrap();
    let names: Vec<String> = (0..VIEWS).map(|i| format!("shot_{i:02}")).collect();
    assert_eq!(cameras.iter().map(|c| c.name.clone()).collect::<Vec<_>>(), names);
    for frame in scene.train.iter().chain(&scene.test) {
        let named = cameras.iter().find(|c| c.name == frame.name).unwrap();
        assert_eq!(named.camera, frame.camera);
    }
    // Downscaled by 2: the same camera with the intrinsics halved.
    let halved = load_cameras(dir.path(), 2).unwrap();
    assert_eq!(
        halved[3].camera.intrinsics(),
        &downscale_intrinsics(cameras[3].camera.intrinsics(), 2)
    );
}

#[test]
fn images_k_is_read_as_stored_when_it_holds_every_image() {
    let dir = tempdir();
    let views = views(false);
    write_capture(dir.path(), "sparse/0", true, &views, true);
    // Half-size copies (8 x 6 -> 4 x 3) in another colour, so the pictures show their folder.
    for v in &views {
        solid_png(&dir.path().join("images_2").join(&v.name), 4, 3, [1, 2, 3]);
    }
    let options = LoadOptions {
        downscale: 2,
        ..LoadOptions::default()
    };
    let scene = load(dir.path(), &options).unwrap();
    assert_eq!(
        scene.images,
        ImageSource::Prescaled {
            folder: dir.path().join("images_2"),
            factor: 2
        }
    );
    for frame in scene.train.iter().chain(&scene.test) {
        assert_eq!(frame.picture.color.dim(), (3, 4, 3));
        assert!((frame.picture.color[[2, 3, 2]] - 3.0 / 255.0).abs() < 1e-7);
        assert_eq!(
            frame.file,
            dir.path().join("images_2").join(format!("{}.png", frame.name))
        );
        // Pixel (r, c) of the half-size picture covers the full-size square of corner
        // (2r, 2c): its ray is the original's through the full-size point (2r + 1, 2c + 1).
        let want = &views
            .iter()
            .find(|v| v.name == format!("{}.png", frame.name))
            .unwrap()
            .camera;
        let k = want.intrinsics();
        assert_eq!(frame.camera.intrinsics(), &downscale_intrinsics(k, 2));
        for (r, c) in [(0, 0), (2, 3), (1, 2)] {
            let d = scene
                .world
                .apply_direction(want.direction_at(2.0 * r as f64 + 1.0, 2.0 * c as f64 + 1.0));
            close(frame.camera.direction(r, c), d, 1e-9, "half-size ray");
        }
    }
    // The same cameras without reading a picture.
    let cameras = load_cameras(dir.path(), 2).unwrap();
    assert_eq!(cameras[1].camera, scene.train[0].camera);

    // One copy missing: the full-size pictures, block-averaged, with the reason.
    std::fs::remove_file(dir.path().join("images_2/shot_04.png")).unwrap();
    let scene = load(dir.path(), &options).unwrap();
    match &scene.images {
        ImageSource::FullSize {
            downscale: 2,
            why: FullSizeReason::Incomplete { missing: 1, first, .. },
            ..
        } => assert_eq!(first, &dir.path().join("images_2/shot_04.png")),
        other => panic!("{other:?}"),
    }
    assert!((scene.test[0].picture.color[[0, 0, 1]] - 250.0 / 255.0).abs() < 1e-6);
    assert_eq!(
        scene.test[0].camera.intrinsics(),
        &downscale_intrinsics(views[0].camera.intrinsics(), 2)
    );

    // A copy of another size: full size again.
    solid_png(&dir.path().join("images_2/shot_04.png"), 5, 3, [1, 2, 3]);
    let scene = load(dir.path(), &options).unwrap();
    assert!(
        matches!(
            &scene.images,
            ImageSource::FullSize {
                why: FullSizeReason::OtherSize {
                    size: (5, 3),
                    full: (8, 6),
                    ..
                },
                ..
            }
        ),
        "{}",
        scene.images
    );
    // No folder for 4.
    let scene = load(
        dir.path(),
        &LoadOptions {
            downscale: 4,
            ..options
        },
    )
    .unwrap();
    assert!(matches!(
        &scene.images,
        ImageSource::FullSize {
            why: FullSizeReason::NoFolder { .. },
            ..
        }
    ));
}

#[test]
fn an_llff_style_png_copy_stands_for_a_jpeg_name() {
    // LLFF's minify writes images_K/NAME.png for images/NAME.JPG.
    let dir = tempdir();
    let mut views = views(false);
    for v in &mut views {
        v.name = v.name.replace(".png", ".JPG");
    }
    write_capture(dir.path(), "sparse/0", true, &views, true);
    for v in &views {
        solid_png(
            &dir.path().join("images_2").join(v.name.replace(".JPG", ".png")),
            4,
            3,
            [1, 2, 3],
        );
    }
    let scene = load(
        dir.path(),
        &LoadOptions {
            downscale: 2,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert!(matches!(scene.images, ImageSource::Prescaled { factor: 2, .. }));
    assert_eq!(scene.test[0].file, dir.path().join("images_2/shot_00.png"));
}

#[test]
fn missing_and_unregistered_pictures_are_counted() {
    let dir = tempdir();
    let views = views(false);
    write_capture(dir.path(), "sparse/0", true, &views, true);
    solid_png(&dir.path().join("images/extra.png"), 8, 6, [0, 0, 0]);
    solid_png(&dir.path().join("images/more/extra.jpg"), 8, 6, [0, 0, 0]);
    std::fs::write(dir.path().join("images/notes.txt"), "not a picture").unwrap();
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!((scene.unregistered, scene.skipped), (2, 0));

    std::fs::remove_file(dir.path().join("images/shot_03.png")).unwrap();
    let err = load(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(
        matches!(&err, fogray_data::DataError::MissingImages { count: 1, .. }),
        "{err}"
    );
    crate::common::names(&err, &dir.path().join("sparse/0/images.bin"));
    let options = LoadOptions {
        skip_missing: true,
        ..LoadOptions::default()
    };
    let scene = load(dir.path(), &options).unwrap();
    assert_eq!((scene.skipped, scene.train.len() + scene.test.len()), (1, VIEWS - 1));
    // The world is the model's, whichever pictures are on disk.
    check_world(&scene.world, &views);
}

#[test]
fn transforms_files_are_found_before_a_model() {
    let dir = tempdir();
    let views = views(false);
    write_capture(dir.path(), "sparse/0", true, &views, true);
    let frames: Vec<_> = views
        .iter()
        .map(|v| {
            (
                v.name.trim_end_matches(".png"),
                &v.camera,
                ndarray::Array3::from_elem((6, 8, 3), 0.5),
            )
        })
        .collect();
    let refs: Vec<_> = frames.iter().map(|(n, c, a)| (*n, *c, a)).collect();
    fogray_data::write_instant_ngp(dir.path(), &refs).unwrap();
    assert_eq!(
        load(dir.path(), &LoadOptions::default()).unwrap().format,
        Format::InstantNgp
    );
}
