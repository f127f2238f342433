//! An animated GIF of rendered frames, looping forever, written whole: the frames go to a
//! fresh temporary beside the final name ([`AtomicFile`]), renamed only once the last frame is
//! in; an error, a drop and Ctrl-C remove it, so an interrupted render leaves no GIF, whole or
//! truncated, and no temporary.
//!
//! Each frame gets its own 256-colour palette, quantised by the `gif` crate (NeuQuant).

use std::io::BufWriter;
use std::path::{Path, PathBuf};

use fogray_data::AtomicFile;
use fogray_fit::images::to_u8;
use ndarray::ArrayView3;

use crate::error::CliError;

/// Each frame's time on screen, in hundredths of a second: 20 frames a second (viewers
/// slow down delays under 2).
pub const FRAME_DELAY: u16 = 5;

/// NeuQuant's sampling factor (1 best and slowest, 30 fastest; 10 is the crate's default).
const QUANTISE_SPEED: i32 = 10;

/// A GIF being written.
pub struct GifWriter {
    encoder: gif::Encoder<BufWriter<AtomicFile>>,
    path: PathBuf,
    size: [u16; 2],
}

impl GifWriter {
    /// Starts a GIF of `width x height` frames at `path` (at most 65535 pixels each way, the
    /// format's limit).
    ///
    /// Errors: a size beyond the format, a file that cannot be created.
    pub fn create(path: &Path, width: usize, height: usize) -> Result<Self, CliError> {
        let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
            return Err(CliError::GifTooLarge { width, height });
        };
        let file = AtomicFile::create(path)?;
        let gif_error = |source| CliError::Gif {
            path: path.to_path_buf(),
            source,
        };
        let mut encoder = gif::Encoder::new(BufWriter::new(file), w, h, &[]).map_err(gif_error)?;
        encoder.set_repeat(gif::Repeat::Infinite).map_err(gif_error)?;
        Ok(GifWriter {
            encoder,
            path: path.to_path_buf(),
            size: [w, h],
        })
    }

    /// Appends `image` (`[height][width][3]` in `[0, 1]`, clamped, as the PNGs are).
    ///
    /// Errors: an image of another size, a failed write.
    pub fn push(&mut self, image: ArrayView3<'_, f64>) -> Result<(), CliError> {
        let [w, h] = self.size;
        if image.dim() != (usize::from(h), usize::from(w), 3) {
            return Err(CliError::GifFrame {
                path: self.path.clone(),
                got: image.dim(),
                size: self.size,
            });
        }
        let rgb: Vec<u8> = image.iter().map(|&v| to_u8(v)).collect();
        let mut frame = gif::Frame::from_rgb_speed(w, h, &rgb, QUANTISE_SPEED);
        frame.delay = FRAME_DELAY;
        self.encoder.write_frame(&frame).map_err(|source| CliError::Gif {
            path: self.path.clone(),
            source,
        })
    }

    /// Ends the GIF and gives it its name; returns it.
    ///
    /// Errors: a failed write, sync or rename (no file is then left).
    pub fn finish(self) -> Result<PathBuf, CliError> {
        let path = self.path;
        let writer = self.encoder.into_inner().map_err(CliError::file("write", &path))?;
        writer
            .into_inner()
            .map_err(|e| CliError::file("write", &path)(e.into_error()))?
            .commit()?;
        Ok(path)
    }
}
