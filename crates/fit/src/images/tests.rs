//! PSNR against hand-computed values; PNGs decoded back and compared pixel by pixel.

use super::*;
use crate::metrics::psnr;
use ndarray::Array3;

fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogray-fit-images-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A 3 x 5 test card whose every value differs.
fn card() -> Array3<f64> {
    Array3::from_shape_fn((3, 5, 3), |(a, b, c)| (a * 15 + b * 3 + c) as f64 / 44.0)
}

#[test]
fn channels_round_to_the_nearest_byte_and_clamp() {
    assert_eq!(
        [to_u8(0.0), to_u8(0.5), to_u8(1.0), to_u8(-1.0), to_u8(2.0)],
        [0, 128, 255, 0, 255]
    );
    assert_eq!(to_u8(f64::NAN), 0);
}

#[test]
fn psnr_clamps_the_render_and_averages_over_all_images() {
    // Half the values: render 1.5 against 1.0 (clamped: no error); the other half: render
    // -0.2 against 0.1 (clamped: 0.1 off). MSE 0.005, PSNR -10 log10(0.005) = 23.0103 dB.
    let render = Array3::from_shape_fn((2, 2, 3), |(a, _, _)| if a == 0 { 1.5 } else { -0.2 });
    let exact = Array3::from_shape_fn((2, 2, 3), |(a, _, _)| if a == 0 { 1.0 } else { 0.1 });
    let db = psnr(&[render.view()], &[exact.view()]).unwrap();
    assert!((db - 23.010299956639813).abs() < 1e-9, "{db}");
    // Two images, 0.1 off everywhere and exact: the mean is again 0.005.
    let (a, b) = (Array3::from_elem((2, 2, 3), 0.3), Array3::from_elem((2, 2, 3), 0.4));
    let db = psnr(&[a.view(), b.view()], &[b.view(), b.view()]).unwrap();
    assert!((db - 23.010299956639813).abs() < 1e-9, "{db}");
    assert_eq!(psnr(&[b.view()], &[b.view()]), Ok(f64::INFINITY));
    assert_eq!(psnr(&[], &[]), Err(ImageError::Empty));
    assert!(matches!(
        psnr(&[a.view()], &[a.view(), b.view()]),
        Err(ImageError::Shape { .. })
    ));
    let small = Array3::zeros((1, 2, 3));
    assert!(matches!(
        psnr(&[small.view()], &[a.view()]),
        Err(ImageError::Shape { .. })
    ));
}

#[test]
fn abs_error_is_per_value() {
    let (a, b) = (card(), Array3::from_elem((3, 5, 3), 0.5));
    let e = abs_error(a.view(), b.view()).unwrap();
    assert_eq!(e[[2, 4, 2]], (44.0f64 / 44.0 - 0.5).abs());
    assert_eq!(e[[0, 0, 0]], 0.5);
    assert!(abs_error(a.view(), Array3::zeros((3, 5, 1)).view()).is_err());
}

#[test]
fn a_png_holds_the_image_pixel_for_pixel() {
    let image = card();
    let path = temp("card.png");
    write_png(&path, image.view()).unwrap();
    let (w, h, bytes) = decode(&path);
    assert_eq!((w, h), (5, 3));
    for ((a, b, c), v) in image.indexed_iter() {
        assert_eq!(bytes[(a * 5 + b) * 3 + c], to_u8(*v), "({a}, {b}, {c})");
    }
    let grey = Array3::zeros((3, 5, 1));
    assert!(matches!(write_png(&path, grey.view()), Err(ImageError::Shape { .. })));
    let nowhere = Path::new("/nonexistent-dir/card.png");
    assert!(matches!(
        write_png(nowhere, image.view()),
        Err(ImageError::Write { .. })
    ));
}

#[test]
fn a_row_of_panels_places_each_magnified_pixel_under_its_title() {
    let exact = card();
    let render = exact.mapv(|v| v * 0.5);
    let path = temp("row.png");
    let scale = 4;
    write_comparison_png(&path, exact.view(), render.view(), 2.0, scale).unwrap();
    let (w, h, bytes) = decode(&path);
    // Three panels of 20 x 12 with gaps of 8 around them and a title strip of 26 above.
    assert_eq!((w, h), (3 * 20 + 4 * 8, 12 + 26 + 8));
    let error = (&exact - &render).mapv(|v| v.abs() * 2.0);
    for (k, image) in [&exact, &render, &error].into_iter().enumerate() {
        for ((a, b, c), v) in image.indexed_iter() {
            let x0 = 8 + k as u32 * (20 + 8) + b as u32 * scale;
            let y0 = 26 + a as u32 * scale;
            // Both corners of the magnified pixel carry its value.
            for (x, y) in [(x0, y0), (x0 + scale - 1, y0 + scale - 1)] {
                assert_eq!(
                    bytes[((y * w + x) * 3) as usize + c],
                    to_u8(*v),
                    "panel {k} ({a}, {b}, {c})"
                );
            }
        }
    }
    // The frame just left of the second panel is grey; the middle of the gap stays white.
    let (x, y) = (8 + 20 + 8 - 1, 30);
    assert_eq!(&bytes[((y * w + x) * 3) as usize..][..3], &[160, 160, 160]);
    let (x, y) = (8 + 20 + 3, 30);
    assert_eq!(&bytes[((y * w + x) * 3) as usize..][..3], &[255, 255, 255]);
    assert!(write_row_png(&path, &[], 2).is_err());
    let other = Array3::zeros((2, 5, 3));
    let panels = [
        Panel {
            title: "a".into(),
            image: exact.view(),
        },
        Panel {
            title: "b".into(),
            image: other.view(),
        },
    ];
    assert!(matches!(
        write_row_png(&path, &panels, 2),
        Err(ImageError::Shape { .. })
    ));
}
