//! The instant-ngp scene box, against instant-ngp's definition worked by hand.

use fogray_data::{load, ngp_scene_box, LoadOptions, BLENDER_SCENE_BOX};
use serde_json::json;

use crate::common::{at, blender_folder, ngp_file, solid_png, tempdir};

fn ngp_box(top: serde_json::Value) -> ([f64; 3], [f64; 3]) {
    let dir = tempdir();
    solid_png(&dir.path().join("a.png"), 2, 2, [0, 0, 0]);
    let frames = [3.0, 4.0].map(|z| json!({ "file_path": "a.png", "transform_matrix": at([0.0, 0.0, z]) }));
    let path = ngp_file(dir.path(), top, frames.to_vec());
    load(&path, &LoadOptions::default()).unwrap().scene_box
}

fn close(got: ([f64; 3], [f64; 3]), want: ([f64; 3], [f64; 3])) {
    for i in 0..3 {
        assert!((got.0[i] - want.0[i]).abs() < 1e-12, "min {got:?} vs {want:?}");
        assert!((got.1[i] - want.1[i]).abs() < 1e-12, "max {got:?} vs {want:?}");
    }
}

#[test]
fn aabb_scale_scale_and_offset_give_the_box_worked_by_hand() {
    // aabb_scale 4: instant-ngp's cube is [0.5 - 2, 0.5 + 2] = [-1.5, 2.5] in its coordinates
    // q = cycle(0.5 p + offset). Undoing the map, axis by axis: p_i = (q - offset_i) / 0.5.
    // x: offset 0.5  -> [(-1.5 - 0.5) / 0.5, (2.5 - 0.5) / 0.5]   = [-4, 4]
    // y: offset 0.25 -> [(-1.5 - 0.25) / 0.5, (2.5 - 0.25) / 0.5] = [-3.5, 4.5]
    // z: offset 1    -> [(-1.5 - 1) / 0.5, (2.5 - 1) / 0.5]       = [-5, 3]
    let got = ngp_box(json!({ "fl_x": 2.0, "aabb_scale": 4, "scale": 0.5, "offset": [0.5, 0.25, 1.0] }));
    close(got, ([-4.0, -3.5, -5.0], [4.0, 4.5, 3.0]));
    // Its corners map onto the corners of instant-ngp's cube (cycle: (x, y, z) -> (y, z, x)).
    let (min, max) = got;
    let offset = [0.5, 0.25, 1.0];
    let to_ngp = |p: [f64; 3]| {
        let s = [0, 1, 2].map(|i| p[i] * 0.5 + offset[i]);
        [s[1], s[2], s[0]]
    };
    assert_eq!(to_ngp(min), [-1.5; 3]);
    assert_eq!(to_ngp(max), [2.5; 3]);
}

#[test]
fn defaults_and_a_scalar_offset() {
    // No keys: aabb_scale 1, scale 0.33, offset 0.5: the cube [0, 1]^3 is [-0.5/0.33, 0.5/0.33].
    let h = 0.5 / 0.33;
    close(ngp_box(json!({ "fl_x": 2.0 })), ([-h; 3], [h; 3]));
    // aabb_scale 16 with a scalar offset 0.
    let got = ngp_box(json!({ "fl_x": 2.0, "aabb_scale": 16, "offset": 0.0 }));
    close(got, ([-7.5 / 0.33; 3], [8.5 / 0.33; 3]));
    close(ngp_scene_box(16.0, 0.33, [0.0; 3]), got);
}

#[test]
fn an_aabb_key_sets_scale_and_offset_as_instant_ngp_does() {
    // aabb [[-1, 0, 2], [3, 1, 4]]: longest side 4, scale 1/4, centre (1, 0.5, 3) sent to 0.5;
    // with aabb_scale 1 the box is the aabb's centre +- 2 (half the longest side) per axis.
    let got = ngp_box(json!({ "fl_x": 2.0, "aabb": [[-1.0, 0.0, 2.0], [3.0, 1.0, 4.0]] }));
    close(got, ([-1.0, -1.5, 1.0], [3.0, 2.5, 5.0]));
}

#[test]
fn blender_has_the_fixed_box() {
    let dir = tempdir();
    blender_folder(
        dir.path(),
        0.7,
        &[("r_0", [0.0, 0.0, 4.0]), ("r_1", [0.0, 0.0, 5.0])],
        2,
        2,
    );
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.scene_box, ([-1.5; 3], [1.5; 3]));
    assert_eq!(scene.scene_box, BLENDER_SCENE_BOX);
}
