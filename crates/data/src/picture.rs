//! Images: decoded with the `image` crate (8- and 16-bit PNG, JPEG; grey, grey + alpha, RGB,
//! RGBA), composited over a background, as `f32` in `[0, 1]`.
//!
//! Colour values are kept as stored (sRGB-encoded), as NeRF-style training uses them, and an
//! image with alpha is composited with straight (non-premultiplied) alpha,
//! `c * a + background * (1 - a)`, because that is how Blender writes its RGBA PNGs.

use std::path::Path;

use image::DynamicImage;
use ndarray::{Array2, Array3};

use crate::error::{one_line, DataError};

/// One view's image: colour composited over the background and, where the file had one, its
/// alpha channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Colour, `[height][width][3]`, in `[0, 1]`, composited over the load's background.
    pub color: Array3<f32>,
    /// Opacity, `[height][width]`, in `[0, 1]`; `Some` when the file had an alpha channel.
    pub alpha: Option<Array2<f32>>,
}

impl Picture {
    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.color.dim().1
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.color.dim().0
    }
}

/// The width and height of the image file at `path`, from its header only.
pub(crate) fn dimensions(path: &Path) -> Result<(usize, usize), DataError> {
    image::image_dimensions(path)
        .map(|(w, h)| (w as usize, h as usize))
        .map_err(|e| image_error(path, e))
}

/// Decodes the image file at `path` and composites it over `background` (RGB in `[0, 1]`).
pub(crate) fn decode(path: &Path, background: [f64; 3]) -> Result<Picture, DataError> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    if crate::jpeg::is_jpeg(&bytes) && !crate::jpeg::is_complete(&bytes) {
        return Err(DataError::Decode {
            path: path.to_path_buf(),
            message: "truncated JPEG: the file ends before its end-of-image marker".into(),
        });
    }
    let image = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| DataError::io(path, e))?
        .decode()
        .map_err(|e| image_error(path, e))?;
    Ok(composite(&image, background))
}

fn image_error(path: &Path, e: image::ImageError) -> DataError {
    match e {
        image::ImageError::IoError(io) => DataError::io(path, io),
        other => DataError::Decode {
            path: path.to_path_buf(),
            message: one_line(other),
        },
    }
}

/// Straight-alpha compositing of a decoded image over `background`.
pub(crate) fn composite(image: &DynamicImage, background: [f64; 3]) -> Picture {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let has_alpha = image.color().has_alpha();
    let bg = background.map(|b| b as f32);
    let mut color = Array3::<f32>::zeros((h, w, 3));
    let mut alpha_values = Vec::with_capacity(if has_alpha { w * h } else { 0 });
    // 8-bit images (the common case) are read without the f32 copy of the whole image.
    let eight_bit = matches!(
        image,
        DynamicImage::ImageLuma8(_)
            | DynamicImage::ImageLumaA8(_)
            | DynamicImage::ImageRgb8(_)
            | DynamicImage::ImageRgba8(_)
    );
    let rgba: Vec<f32> = if eight_bit {
        image
            .to_rgba8()
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 255.0)
            .collect()
    } else {
        image.to_rgba32f().into_raw()
    };
    let pixels = color.as_slice_mut().expect("a fresh array is contiguous");
    for (px, out) in rgba.chunks_exact(4).zip(pixels.chunks_exact_mut(3)) {
        let a = if has_alpha { px[3] } else { 1.0 };
        for c in 0..3 {
            out[c] = px[c] * a + bg[c] * (1.0 - a);
        }
        if has_alpha {
            alpha_values.push(a);
        }
    }
    let alpha = has_alpha.then(|| Array2::from_shape_vec((h, w), alpha_values).expect("one alpha per pixel"));
    Picture { color, alpha }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Rgba, RgbaImage};

    #[test]
    fn half_alpha_blends_halfway_to_the_background() {
        let img = RgbaImage::from_pixel(1, 1, Rgba([255, 0, 51, 128]));
        let p = composite(&DynamicImage::ImageRgba8(img), [0.0, 1.0, 0.5]);
        let a = 128.0 / 255.0;
        let want = [a, 1.0 - a, 0.2 * a + 0.5 * (1.0 - a)];
        for (c, w) in want.iter().enumerate() {
            assert!((p.color[[0, 0, c]] - w).abs() < 1e-6, "channel {c}");
        }
        assert!((p.alpha.unwrap()[[0, 0]] - a).abs() < 1e-7);
    }
}
