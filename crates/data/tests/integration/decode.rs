//! Decoding: compositing over the background, 16-bit and grey PNG, JPEG.

use std::path::Path;

use fogray_data::{load, Frame, LoadOptions};
use image::{GrayImage, ImageBuffer, Luma, LumaA, Rgb, Rgba, RgbaImage};
use serde_json::json;

use crate::common::{at, ngp_file, save, tempdir};

/// Loads an instant-ngp file of two frames naming `file` (relative to `dir`; a fit needs a
/// frame to train on and one held out): the held-out one.
pub fn load_single(dir: &Path, file: &str, options: &LoadOptions) -> Frame {
    let frames = [3.0, 4.0].map(|z| json!({ "file_path": file, "transform_matrix": at([0.0, 0.0, z]) }));
    let path = ngp_file(dir, json!({ "fl_x": 4.0 }), frames.to_vec());
    let scene = load(&path, options).unwrap();
    assert_eq!((scene.train.len(), scene.test.len()), (1, 1));
    // Both frames name one file: decoded once, the same picture.
    assert_eq!(scene.train[0].picture, scene.test[0].picture);
    scene.test.into_iter().next().unwrap()
}

#[test]
fn half_alpha_over_a_background_is_the_straight_alpha_blend() {
    let dir = tempdir();
    let mut img = RgbaImage::from_pixel(2, 1, Rgba([200, 100, 0, 128]));
    img.put_pixel(1, 0, Rgba([10, 20, 30, 255]));
    save(&dir.path().join("a.png"), &img);
    let bg = [0.2, 0.4, 0.6];
    let f = load_single(
        dir.path(),
        "a.png",
        &LoadOptions {
            background: bg,
            ..LoadOptions::default()
        },
    );
    let a = 128.0 / 255.0;
    for (c, v) in [200.0, 100.0, 0.0].into_iter().enumerate() {
        let want = v / 255.0 * a + bg[c] * (1.0 - a);
        assert!((f.picture.color[[0, 0, c]] as f64 - want).abs() < 1e-6, "channel {c}");
    }
    // An opaque pixel ignores the background.
    assert!((f.picture.color[[0, 1, 2]] as f64 - 30.0 / 255.0).abs() < 1e-6);
    let alpha = f.picture.alpha.expect("an RGBA file keeps its alpha");
    assert!((alpha[[0, 0]] as f64 - a).abs() < 1e-6);
    assert_eq!(alpha[[0, 1]], 1.0);

    // The default background is white: a transparent pixel is white.
    let dir = tempdir();
    save(
        &dir.path().join("t.png"),
        &RgbaImage::from_pixel(1, 1, Rgba([0, 0, 0, 0])),
    );
    let f = load_single(dir.path(), "t.png", &LoadOptions::default());
    assert_eq!(f.picture.color.as_slice().unwrap(), &[1.0, 1.0, 1.0]);
}

#[test]
fn sixteen_bit_png_keeps_its_precision() {
    let dir = tempdir();
    let img: ImageBuffer<Rgb<u16>, Vec<u16>> = ImageBuffer::from_pixel(2, 2, Rgb([30000, 1, 65535]));
    save(&dir.path().join("a.png"), &img);
    let f = load_single(dir.path(), "a.png", &LoadOptions::default());
    assert!((f.picture.color[[1, 1, 0]] as f64 - 30000.0 / 65535.0).abs() < 1e-6);
    assert!((f.picture.color[[1, 1, 1]] as f64 - 1.0 / 65535.0).abs() < 1e-7);
    assert_eq!(f.picture.color[[1, 1, 2]], 1.0);
    assert!(f.picture.alpha.is_none());

    // 16-bit grey with alpha: composited over black, grey on all three channels.
    let dir = tempdir();
    let img: ImageBuffer<LumaA<u16>, Vec<u16>> = ImageBuffer::from_pixel(1, 1, LumaA([40000, 32768]));
    save(&dir.path().join("g.png"), &img);
    let f = load_single(
        dir.path(),
        "g.png",
        &LoadOptions {
            background: [0.0; 3],
            ..LoadOptions::default()
        },
    );
    let want = 40000.0 / 65535.0 * (32768.0 / 65535.0);
    for c in 0..3 {
        assert!((f.picture.color[[0, 0, c]] as f64 - want).abs() < 1e-6);
    }
    assert!((f.picture.alpha.unwrap()[[0, 0]] as f64 - 32768.0 / 65535.0).abs() < 1e-6);
}

#[test]
fn grey_png_fills_all_three_channels() {
    let dir = tempdir();
    let mut img = GrayImage::from_pixel(3, 2, Luma([77]));
    img.put_pixel(2, 1, Luma([255]));
    save(&dir.path().join("a.png"), &img);
    let f = load_single(dir.path(), "a.png", &LoadOptions::default());
    assert_eq!(f.picture.color.dim(), (2, 3, 3));
    for c in 0..3 {
        assert!((f.picture.color[[0, 0, c]] as f64 - 77.0 / 255.0).abs() < 1e-6);
        assert_eq!(f.picture.color[[1, 2, c]], 1.0);
    }
    assert!(f.picture.alpha.is_none());
}

#[test]
fn jpeg_decodes_near_its_colour() {
    let dir = tempdir();
    let rgb = [200u8, 50, 100];
    let img = image::RgbImage::from_pixel(16, 16, Rgb(rgb));
    let path = dir.path().join("a.jpg");
    let mut out = std::fs::File::create(&path).unwrap();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
        .encode_image(&img)
        .unwrap();
    drop(out);
    let f = load_single(dir.path(), "a.jpg", &LoadOptions::default());
    assert_eq!(f.picture.color.dim(), (16, 16, 3));
    for (c, &v) in rgb.iter().enumerate() {
        let got = f.picture.color[[7, 9, c]] as f64;
        assert!((got - v as f64 / 255.0).abs() < 4.0 / 255.0, "channel {c}: {got}");
    }
    assert!(f.picture.alpha.is_none());
}
