//! Images as arrays `[row][column][channel]` of RGB in `[0, 1]`: PNG files (one image, or a
//! titled row of them such as photograph, render and error side by side).
//!
//! ```
//! use fogray_fit::metrics::psnr;
//! use ndarray::Array3;
//!
//! // Every value off by 0.1: MSE 0.01, PSNR = -10 log10(0.01) = 20 dB.
//! let exact = Array3::from_elem((4, 4, 3), 0.5);
//! let render = Array3::from_elem((4, 4, 3), 0.6);
//! let db = psnr(&[render.view()], &[exact.view()])?;
//! assert!((db - 20.0).abs() < 1e-9);
//! # Ok::<(), fogray_fit::images::ImageError>(())
//! ```

use std::path::{Path, PathBuf};

use fogray_data::{write_png8, DataError, PngChannels};
use ndarray::{Array3, ArrayView3, Zip};
use plotters::prelude::*;
use thiserror::Error;

const FONT: &str = "sans-serif";
/// Height of the title strip above each panel of a row, in PNG pixels.
const TITLE_HEIGHT: u32 = 26;
/// Space between panels, in PNG pixels.
const GAP: u32 = 8;

/// Why an image could not be compared or written.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ImageError {
    /// Images that should match in shape do not, or an image is not `[rows][columns][3]`.
    #[error("{what}: expected shape {expected:?}, got {got:?}")]
    Shape {
        /// Which image.
        what: String,
        /// The shape required.
        expected: Vec<usize>,
        /// The shape given.
        got: Vec<usize>,
    },
    /// Nothing to compare or draw.
    #[error("no images given")]
    Empty,
    /// The PNG could not be drawn or written (nothing is left under its name or beside it).
    #[error("cannot write {path}: {message}", path = fogray_data::shown(.path))]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// One titled image of a row.
#[derive(Debug, Clone)]
pub(crate) struct Panel<'a> {
    /// Drawn above the image.
    pub title: String,
    /// `[rows][columns][3]`, values clamped to `[0, 1]` for display.
    pub image: ArrayView3<'a, f64>,
}

/// A value in `[0, 1]` as an 8-bit channel (clamped, rounded to nearest).
pub fn to_u8(v: f64) -> u8 {
    // NaN clamps to NaN and casts to 0.
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn check_rgb(what: &str, image: &ArrayView3<'_, f64>) -> Result<(), ImageError> {
    let s = image.shape();
    if s[2] != 3 || s[0] == 0 || s[1] == 0 {
        return Err(ImageError::Shape {
            what: what.to_string(),
            expected: vec![s[0].max(1), s[1].max(1), 3],
            got: s.to_vec(),
        });
    }
    Ok(())
}

pub(crate) fn check_same(what: &str, a: &ArrayView3<'_, f64>, b: &ArrayView3<'_, f64>) -> Result<(), ImageError> {
    if a.shape() != b.shape() {
        return Err(ImageError::Shape {
            what: what.to_string(),
            expected: b.shape().to_vec(),
            got: a.shape().to_vec(),
        });
    }
    Ok(())
}

/// `|render - exact|` per pixel and channel. Error: [`ImageError::Shape`] if the shapes differ.
pub(crate) fn abs_error(render: ArrayView3<'_, f64>, exact: ArrayView3<'_, f64>) -> Result<Array3<f64>, ImageError> {
    check_same("render", &render, &exact)?;
    Ok(Zip::from(&render).and(&exact).map_collect(|r, e| (r - e).abs()))
}

fn write_error(path: &Path) -> impl Fn(String) -> ImageError + '_ {
    move |message| ImageError::Write {
        path: path.to_path_buf(),
        message,
    }
}

fn rgb(image: &ArrayView3<'_, f64>, row: usize, column: usize) -> RGBColor {
    let c = |k| to_u8(image[[row, column, k]]);
    RGBColor(c(0), c(1), c(2))
}

/// An RGB canvas of `size` (width, height) for plotters' [`BitMapBackend::with_buffer`], all
/// black; [`save_canvas`] writes it.
pub(crate) fn canvas((w, h): (u32, u32)) -> Vec<u8> {
    vec![0; w as usize * h as usize * 3]
}

/// Writes a canvas of `size` drawn by plotters as an 8-bit RGB PNG, whole or not at all (a
/// fresh temporary renamed into place, see [`fogray_data::write_atomic`]).
///
/// Errors: [`ImageError::Write`].
pub fn save_canvas(path: &Path, pixels: &[u8], (w, h): (u32, u32)) -> Result<(), ImageError> {
    write_png8(path, pixels, w, h, PngChannels::Rgb).map_err(|e| not_written(path, e))
}

/// A failed write of fogray-data's as an [`ImageError::Write`] (naming the file once).
pub(crate) fn not_written(path: &Path, e: DataError) -> ImageError {
    ImageError::Write {
        path: path.to_path_buf(),
        message: match e {
            DataError::Io { message, .. } => message,
            other => other.to_string(),
        },
    }
}

/// Writes one image as a PNG of its own size, one PNG pixel per image pixel, whole or not at
/// all.
///
/// Errors: [`ImageError::Shape`] unless `[rows >= 1][columns >= 1][3]`, [`ImageError::Write`].
pub fn write_png(path: &Path, image: ArrayView3<'_, f64>) -> Result<(), ImageError> {
    check_rgb("image", &image)?;
    let (h, w) = (image.shape()[0], image.shape()[1]);
    let size = (u32::try_from(w), u32::try_from(h));
    let (Ok(w), Ok(h)) = size else {
        return Err(write_error(path)(format!("a {w}x{h} image is larger than PNG holds")));
    };
    // `iter` walks rows, columns, channels: the PNG's order.
    let pixels: Vec<u8> = image.iter().map(|&v| to_u8(v)).collect();
    save_canvas(path, &pixels, (w, h))
}

/// Writes images side by side, each magnified `scale` times (nearest neighbour) under its
/// title, on white. All panels must have one shape.
///
/// Errors: [`ImageError::Empty`], [`ImageError::Shape`], [`ImageError::Write`] (including a
/// `scale` of 0).
pub(crate) fn write_row_png(path: &Path, panels: &[Panel<'_>], scale: u32) -> Result<(), ImageError> {
    let first = panels.first().ok_or(ImageError::Empty)?;
    check_rgb(&first.title, &first.image)?;
    for p in panels {
        check_same(&p.title, &p.image, &first.image)?;
    }
    let wrap = write_error(path);
    if scale == 0 {
        return Err(wrap("scale must be at least 1".into()));
    }
    let (h, w) = (
        first.image.shape()[0] as u32 * scale,
        first.image.shape()[1] as u32 * scale,
    );
    let n = panels.len() as u32;
    let size = (n * w + (n + 1) * GAP, h + TITLE_HEIGHT + GAP);
    let mut pixels = canvas(size);
    let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| wrap(e.to_string()))?;
    for (k, p) in panels.iter().enumerate() {
        let x0 = GAP + k as u32 * (w + GAP);
        root.draw(&Text::new(p.title.clone(), (x0 as i32, 4), (FONT, 18).into_font()))
            .map_err(|e| wrap(e.to_string()))?;
        // A grey frame just outside the panel, so a white image stands out from the page.
        let frame = [
            (x0 as i32 - 1, TITLE_HEIGHT as i32 - 1),
            ((x0 + w) as i32, (TITLE_HEIGHT + h) as i32),
        ];
        root.draw(&Rectangle::new(frame, RGBColor(160, 160, 160)))
            .map_err(|e| wrap(e.to_string()))?;
        let (rows, columns) = (p.image.shape()[0], p.image.shape()[1]);
        for a in 0..rows {
            for b in 0..columns {
                let (x, y) = ((x0 + b as u32 * scale) as i32, (TITLE_HEIGHT + a as u32 * scale) as i32);
                // A filled rectangle covers [x0, x1) x [y0, y1).
                let s = scale as i32;
                root.draw(&Rectangle::new([(x, y), (x + s, y + s)], rgb(&p.image, a, b).filled()))
                    .map_err(|e| wrap(e.to_string()))?;
            }
        }
    }
    root.present().map_err(|e| wrap(e.to_string()))?;
    drop(root);
    save_canvas(path, &pixels, size)
}

/// Writes the exact photograph, the render and `|render - exact|` times `gain` side by side,
/// in one row; a gain above 1 makes small errors visible.
pub fn write_comparison_png(
    path: &Path,
    exact: ArrayView3<'_, f64>,
    render: ArrayView3<'_, f64>,
    gain: f64,
    scale: u32,
) -> Result<(), ImageError> {
    let error = abs_error(render, exact)? * gain;
    let panels = [
        Panel {
            title: "exact photograph".into(),
            image: exact.view(),
        },
        Panel {
            title: "render".into(),
            image: render.view(),
        },
        Panel {
            title: if gain == 1.0 {
                "|render - exact|".into()
            } else {
                format!("|render - exact| x {gain}")
            },
            image: error.view(),
        },
    ];
    write_row_png(path, &panels, scale)
}

#[cfg(test)]
mod tests;
