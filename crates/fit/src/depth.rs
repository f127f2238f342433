//! Depth maps as PNGs: the expected depth of each pixel in the viridis colour map (dark near,
//! yellow far) with a labelled colour bar, background pixels (NaN depth) in light grey, which
//! viridis never shows.
//!
//! ```
//! use fogray_fit::depth::write_depth_png;
//! use ndarray::Array2;
//!
//! let mut depth = Array2::from_shape_fn((8, 8), |(a, b)| 2.0 + 0.1 * (a + b) as f64);
//! depth[[0, 0]] = f64::NAN; // background
//! let file = std::env::temp_dir().join(format!("depth-doc-{}.png", std::process::id()));
//! let range = write_depth_png(&file, depth.view(), "view 3", 4)?.unwrap();
//! assert!((range.near - 2.1).abs() < 1e-12 && (range.far - 3.4).abs() < 1e-12);
//! # std::fs::remove_file(&file).ok();
//! # Ok::<(), fogray_fit::images::ImageError>(())
//! ```

use std::path::Path;

use ndarray::ArrayView2;
use plotters::prelude::*;

use crate::images::{canvas, save_canvas, ImageError};
use crate::render::BACKGROUND_OPACITY;

/// The colour of background pixels (no depth).
pub(crate) const BACKGROUND: RGBColor = RGBColor(215, 215, 215);

const FONT: &str = "sans-serif";
const TITLE_HEIGHT: u32 = 26;
const GAP: u32 = 8;
const BAR_WIDTH: u32 = 16;
const LABEL_WIDTH: u32 = 64;

/// The depths the colour map spans: the nearest and farthest of the foreground pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthRange {
    /// Depth shown darkest.
    pub near: f64,
    /// Depth shown brightest.
    pub far: f64,
}

fn color_of(d: f64, range: Option<DepthRange>) -> RGBColor {
    match range {
        Some(r) if d.is_finite() => {
            let f = if r.far > r.near {
                (d - r.near) / (r.far - r.near)
            } else {
                0.5
            };
            ViridisRGB.get_color(f.clamp(0.0, 1.0) as f32)
        }
        _ => BACKGROUND,
    }
}

/// Writes `depth` (`[rows][columns]`, NaN for background) magnified `scale` times under
/// `title`, with a colour bar labelled from the nearest to the farthest finite depth. Returns
/// that range, `None` if every pixel is background (then all is grey and the bar is empty).
///
/// Errors: [`ImageError::Empty`] for an image without pixels, [`ImageError::Write`]
/// (including a `scale` of 0).
pub fn write_depth_png(
    path: &Path,
    depth: ArrayView2<'_, f64>,
    title: &str,
    scale: u32,
) -> Result<Option<DepthRange>, ImageError> {
    let wrap = |message: String| ImageError::Write {
        path: path.to_path_buf(),
        message,
    };
    if depth.is_empty() {
        return Err(ImageError::Empty);
    }
    if scale == 0 {
        return Err(wrap("scale must be at least 1".into()));
    }
    let finite = depth.iter().copied().filter(|d| d.is_finite());
    let range = finite.clone().fold(None, |r: Option<DepthRange>, d| {
        Some(match r {
            None => DepthRange { near: d, far: d },
            Some(r) => DepthRange {
                near: r.near.min(d),
                far: r.far.max(d),
            },
        })
    });
    let (rows, columns) = (depth.nrows() as u32, depth.ncols() as u32);
    let (h, w) = (rows * scale, columns * scale);
    let heading = format!("{title}: expected depth (grey: opacity < {BACKGROUND_OPACITY})");
    let font = (FONT, 16).into_font();
    // As wide as the heading, so that it is not cut off beside a small image.
    let heading_width = font.box_size(&heading).map_or(0, |(w, _)| w) + 2 * GAP;
    let width = (GAP + w + 2 * GAP + BAR_WIDTH + LABEL_WIDTH).max(heading_width);
    let size = (width.max(300), h + TITLE_HEIGHT + GAP);
    let mut pixels = canvas(size);
    let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
    let draw = |r: Result<(), DrawingAreaErrorKind<_>>| r.map_err(|e| wrap(e.to_string()));
    draw(root.fill(&WHITE))?;
    draw(root.draw(&Text::new(heading, (GAP as i32, 4), font)))?;
    let y0 = TITLE_HEIGHT as i32;
    for ((a, b), d) in depth.indexed_iter() {
        let (x, y) = (GAP as i32 + (b as u32 * scale) as i32, y0 + (a as u32 * scale) as i32);
        let s = scale as i32;
        draw(root.draw(&Rectangle::new([(x, y), (x + s, y + s)], color_of(*d, range).filled())))?;
    }
    // The bar: near at the bottom, far at the top, one band per PNG row.
    let bar_x = (GAP + w + 2 * GAP) as i32;
    if let Some(r) = range {
        for k in 0..h {
            let f = 1.0 - (k as f64 + 0.5) / h as f64;
            let d = r.near + f * (r.far - r.near);
            let y = y0 + k as i32;
            draw(root.draw(&Rectangle::new(
                [(bar_x, y), (bar_x + BAR_WIDTH as i32, y + 1)],
                color_of(d, range).filled(),
            )))?;
        }
        let label_x = bar_x + BAR_WIDTH as i32 + 4;
        let labels = [
            (r.far, y0),
            ((r.near + r.far) / 2.0, y0 + h as i32 / 2 - 6),
            (r.near, y0 + h as i32 - 12),
        ];
        for (d, y) in labels {
            draw(root.draw(&Text::new(format!("{d:.3}"), (label_x, y), (FONT, 13).into_font())))?;
        }
    }
    draw(root.draw(&Rectangle::new(
        [(bar_x - 1, y0 - 1), (bar_x + BAR_WIDTH as i32, y0 + h as i32)],
        RGBColor(160, 160, 160),
    )))?;
    draw(root.present())?;
    drop(root);
    save_canvas(path, &pixels, size)?;
    Ok(range)
}
