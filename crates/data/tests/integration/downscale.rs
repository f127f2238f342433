//! Downscaling: block means, intrinsics divided, partial blocks dropped.

use fogray_data::LoadOptions;
use image::{Rgba, RgbaImage};

use crate::common::{save, tempdir};
use crate::decode::load_single;

/// A `n x n` RGBA image whose red is `10 (row * n + col)`, green 7, blue 0 and alpha 255
/// except pixel (0, 0), alpha 0.
fn ramp(n: u32) -> RgbaImage {
    RgbaImage::from_fn(n, n, |col, row| {
        let a = if (row, col) == (0, 0) { 0 } else { 255 };
        Rgba([(10 * (row * n + col)) as u8, 7, 0, a])
    })
}

#[test]
fn a_4x4_image_halved_gives_its_block_means() {
    let dir = tempdir();
    save(&dir.path().join("a.png"), &ramp(4));
    let full = load_single(dir.path(), "a.png", &LoadOptions::default());
    let half = load_single(
        dir.path(),
        "a.png",
        &LoadOptions {
            downscale: 2,
            ..LoadOptions::default()
        },
    );
    assert_eq!(half.picture.color.dim(), (2, 2, 3));
    // Red of the block (1, 0): pixels (2, 0), (2, 1), (3, 0), (3, 1) = 80, 90, 120, 130.
    let want = (80.0 + 90.0 + 120.0 + 130.0) / 4.0 / 255.0;
    assert!((half.picture.color[[1, 0, 0]] as f64 - want).abs() < 1e-6);
    // Block (0, 0) holds the transparent pixel, white (255) over the default background, and
    // reds 10, 40, 50.
    let want = (255.0 + 10.0 + 40.0 + 50.0) / 4.0 / 255.0;
    assert!((half.picture.color[[0, 0, 0]] as f64 - want).abs() < 1e-6);
    let alpha = half.picture.alpha.unwrap();
    assert!((alpha[[0, 0]] - 0.75).abs() < 1e-7 && alpha[[1, 1]] == 1.0);
    let (k, k2) = (full.camera.intrinsics(), half.camera.intrinsics());
    assert_eq!((k.fx, k.cx, k.cy), (4.0, 2.0, 2.0));
    assert_eq!(
        (k2.fx, k2.fy, k2.cx, k2.cy, k2.width, k2.height),
        (2.0, 2.0, 1.0, 1.0, 2, 2)
    );
}

#[test]
fn a_5x5_image_halved_drops_the_partial_row_and_column() {
    let dir = tempdir();
    save(&dir.path().join("a.png"), &ramp(5));
    let half = load_single(
        dir.path(),
        "a.png",
        &LoadOptions {
            downscale: 2,
            ..LoadOptions::default()
        },
    );
    assert_eq!(half.picture.color.dim(), (2, 2, 3));
    // Block (1, 1): pixels (2, 2), (2, 3), (3, 2), (3, 3) = 120, 130, 170, 180.
    let want = (120.0 + 130.0 + 170.0 + 180.0) / 4.0 / 255.0;
    assert!((half.picture.color[[1, 1, 0]] as f64 - want).abs() < 1e-6);
    let k = half.camera.intrinsics();
    assert_eq!((k.fx, k.cx, k.cy, k.width, k.height), (2.0, 1.25, 1.25, 2, 2));
}
