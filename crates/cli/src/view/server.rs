//! `fogray view`'s routes: the page, the model's description, and frames.
//!
//! - `GET /`: the page (`page.html`, compiled in).
//! - `GET /info`: JSON: the model, its bounds or framing, a first camera, the dataset's views.
//! - `GET /frame?...`: a frame from the camera the query names ([`super::camera`]), as PNG.
//!
//! Nothing else is served: no route reads a file, so no path (`/../x`, `/%2e%2e/x`) can reach
//! one; every other path is 404.

use std::sync::Mutex;

use fogray_ops::PinholeCamera;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};

use super::camera::{frame_request, parse_query, FrameRequest, RequestError};
use super::http::{Handler, Request, Response};
use crate::error::CliError;

/// The page, served at `/`.
const PAGE: &str = include_str!("page.html");

/// A frame as 8-bit RGB.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbFrame {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `height * width * 3` bytes, row-major, as `fogray render`'s PNGs hold them.
    pub pixels: Vec<u8>,
}

/// Something that renders a camera's view: a model loaded from a file now; a fit under way
/// later, whose implementation would render the latest model it published behind a lock
/// (the server only ever asks through `&self`, from several threads).
pub trait Scene: Sync {
    /// The view from `camera`, with its intrinsics' size.
    ///
    /// Errors: a frame the machine has no memory for ([`CliError::TooLarge`]), the renderer's.
    fn render(&self, camera: &PinholeCamera) -> Result<RgbFrame, CliError>;
}

/// What the server answers from.
pub struct Site<'a> {
    /// The renderer.
    pub scene: &'a dyn Scene,
    /// The JSON of `/info`.
    pub info: String,
    /// The dataset's cameras, by index (`/frame?view=N`).
    pub views: Vec<PinholeCamera>,
    /// Held while a frame renders: one at a time, so that the memory the frames take is that of
    /// one, and each gets every core (the renderer is parallel inside).
    pub rendering: Mutex<()>,
}

impl Handler for Site<'_> {
    fn handle(&self, request: &Request) -> Response {
        match request.path.as_str() {
            "/" | "/index.html" => Response::ok("text/html; charset=utf-8", PAGE.as_bytes().to_vec()),
            "/info" => Response::ok("application/json", self.info.as_bytes().to_vec()),
            "/frame" => self.frame(&request.query),
            other => {
                let shown: String = other.chars().take(80).collect();
                Response::refuse(404, &format!("no such page: {}", fogray_data::escape_controls(&shown)))
            }
        }
    }
}

impl Site<'_> {
    /// `/frame`: the PNG of the camera the query names.
    fn frame(&self, query: &str) -> Response {
        let camera = match parse_query(query).and_then(|pairs| frame_request(&pairs)) {
            Ok(FrameRequest::Camera(c)) => c,
            Ok(FrameRequest::View(index)) => match self.view(&index) {
                Ok(c) => c,
                Err(e) => return Response::refuse(400, &e.to_string()),
            },
            Err(e) => return Response::refuse(400, &e.to_string()),
        };
        // A poisoned lock only means another frame's render panicked; the model is untouched.
        let guard = self.rendering.lock().unwrap_or_else(|e| e.into_inner());
        let rendered = self.scene.render(&camera);
        drop(guard);
        let frame = match rendered {
            Ok(f) => f,
            Err(e @ CliError::TooLarge(_)) => return Response::refuse(503, &e.to_string()),
            Err(e) => return Response::refuse(500, &e.to_string()),
        };
        match png(&frame) {
            Ok(bytes) => Response::ok("image/png", bytes),
            Err(e) => Response::refuse(500, &format!("cannot encode the frame: {e}")),
        }
    }

    /// The dataset's camera `index` (decimal), no larger than a frame may be.
    fn view(&self, index: &str) -> Result<PinholeCamera, RequestError> {
        let no_view = || RequestError::NoView {
            index: index.chars().take(32).collect(),
            count: self.views.len(),
        };
        let i: usize = index.parse().map_err(|_| no_view())?;
        let camera = self.views.get(i).ok_or_else(no_view)?;
        let k = camera.intrinsics();
        if k.width > super::camera::MAX_SIDE || k.height > super::camera::MAX_SIDE {
            return Err(RequestError::ViewTooLarge {
                index: i,
                width: k.width,
                height: k.height,
            });
        }
        Ok(camera.clone())
    }
}

/// The frame as PNG: lossless, so that the page shows exactly the bytes `fogray render` would
/// write, at a cost beside the render's that fast compression keeps small.
fn png(frame: &RgbFrame) -> Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::new();
    let encoder = PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub);
    // Sides of at most MAX_SIDE fit u32.
    encoder.write_image(
        &frame.pixels,
        frame.width as u32,
        frame.height as u32,
        ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}
