//! 8-bit PNG files written whole (through [`write_atomic`](crate::write_atomic)): the pictures
//! of [`write_blender`](crate::write_blender) and fogray's renders, panels and plots.

use std::io;
use std::path::Path;

use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};

use crate::error::DataError;
use crate::output::write_atomic;

/// The channels of each pixel of a PNG to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PngChannels {
    /// Red, green, blue: 3 bytes a pixel.
    Rgb,
    /// Red, green, blue, straight alpha: 4 bytes a pixel.
    Rgba,
}

impl PngChannels {
    /// Bytes a pixel.
    pub fn count(self) -> usize {
        match self {
            PngChannels::Rgb => 3,
            PngChannels::Rgba => 4,
        }
    }
}

/// Writes `pixels` (row by row from the top, `width * height * channels.count()` bytes) as an
/// 8-bit PNG at `path`, whole or not at all.
///
/// Errors: [`DataError::BadInput`] for a buffer of another length or a zero size,
/// [`DataError::Io`] naming `path` for a file that cannot be written.
pub fn write_png8(path: &Path, pixels: &[u8], width: u32, height: u32, channels: PngChannels) -> Result<(), DataError> {
    let expected = (width as usize)
        .checked_mul(height as usize)
        .and_then(|n| n.checked_mul(channels.count()));
    if width == 0 || height == 0 || expected != Some(pixels.len()) {
        return Err(DataError::BadInput {
            path: path.to_path_buf(),
            message: format!(
                "{} bytes for a {width}x{height} picture of {} channels",
                pixels.len(),
                channels.count()
            ),
        });
    }
    let color = match channels {
        PngChannels::Rgb => ExtendedColorType::Rgb8,
        PngChannels::Rgba => ExtendedColorType::Rgba8,
    };
    write_atomic(path, |out| {
        PngEncoder::new(out)
            .write_image(pixels, width, height, color)
            .map_err(|e| match e {
                image::ImageError::IoError(e) => e,
                other => io::Error::other(other.to_string()),
            })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_png_reads_back_byte_for_byte() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        // 2x1 RGBA: an opaque red pixel and a half-transparent blue one.
        let pixels = [255, 0, 0, 255, 0, 0, 255, 128];
        write_png8(&path, &pixels, 2, 1, PngChannels::Rgba).unwrap();
        let back = image::open(&path).unwrap().into_rgba8();
        assert_eq!(back.dimensions(), (2, 1));
        assert_eq!(back.into_raw(), pixels);
    }

    #[test]
    fn a_buffer_of_the_wrong_length_is_refused_and_nothing_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let err = write_png8(&path, &[0; 5], 2, 1, PngChannels::Rgb).unwrap_err();
        assert!(
            err.to_string().contains("5 bytes for a 2x1 picture of 3 channels"),
            "{err}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
