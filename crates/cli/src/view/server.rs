//! `fogray view`'s routes: the page, the model's description, and frames.
//!
//! - `GET /`: the page (`page.html`, compiled in).
//! - `GET /info`: JSON: the model, its bounds or framing, a first camera, the dataset's views.
//! - `GET /frame?...`: a frame from the camera the query names ([`super::camera`]), as PNG.
//! - `GET /photo?view=N`: the dataset's photograph of view N.
//! - `GET /progress`: JSON: a fit's step and evaluations so far (`fogray fit --view` only).
//!
//! Nothing else is served. The only files read are the photographs of the dataset the
//! checkpoint names, by index into its list: no path (`/../x`, `/%2e%2e/x`) reaches a file;
//! every other path is 404.

use std::path::PathBuf;
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

/// Something that renders a camera's view: a model loaded from a file, or a fit under way
/// ([`super::live`]), which renders the latest copy of the model the fit handed it (the server
/// only ever asks through `&self`, from several threads).
pub trait Scene: Sync {
    /// The view from `camera`, with its intrinsics' size.
    ///
    /// Errors: a frame the machine has no memory for ([`CliError::TooLarge`]), the renderer's.
    fn render(&self, camera: &PinholeCamera) -> Result<RgbFrame, CliError>;

    /// The JSON of `/progress` (a fit under way: [`super::live`]); none for a saved model.
    fn progress(&self) -> Option<String> {
        None
    }
}

/// What the server answers from.
pub struct Site<'a> {
    /// The renderer.
    pub scene: &'a dyn Scene,
    /// The JSON of `/info`.
    pub info: String,
    /// The dataset's cameras, by index (`/frame?view=N`).
    pub views: Vec<PinholeCamera>,
    /// Their photographs, by index (`/photo?view=N`), or none: the only files a request can
    /// make the server read.
    pub photos: Vec<PathBuf>,
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
            "/photo" => self.photo(&request.query),
            "/progress" => match self.scene.progress() {
                Some(json) => Response::ok("application/json", json.into_bytes()),
                None => Response::refuse(404, "no fit under way: /progress is fogray fit --view's"),
            },
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
            Err(e @ (CliError::TooLarge(_) | CliError::NotYet(_))) => return Response::refuse(503, &e.to_string()),
            Err(e) => return Response::refuse(500, &e.to_string()),
        };
        match png(&frame) {
            Ok(bytes) => Response::ok("image/png", bytes),
            Err(e) => Response::refuse(500, &format!("cannot encode the frame: {e}")),
        }
    }

    /// `/photo?view=N`: the dataset's photograph of view N, its file's bytes as they are.
    fn photo(&self, query: &str) -> Response {
        let pairs = match parse_query(query) {
            Ok(p) => p,
            Err(e) => return Response::refuse(400, &e.to_string()),
        };
        let index = match (pairs.get("view"), pairs.len()) {
            (Some(index), 1) => index,
            _ => return Response::refuse(400, "/photo takes view=N alone"),
        };
        let file = index.parse::<usize>().ok().and_then(|i| self.photos.get(i));
        let Some(file) = file else {
            let shown: String = index.chars().take(32).collect();
            let count = self.photos.len();
            return Response::refuse(404, &format!("view {shown}: {count} photographs are offered"));
        };
        let extension = file.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        let content_type = match extension.as_deref() {
            Some("png") => "image/png",
            Some("jpg" | "jpeg") => "image/jpeg",
            _ => return Response::refuse(404, "the photograph is neither PNG nor JPEG"),
        };
        let size = std::fs::metadata(file).map(|m| m.len()).unwrap_or(u64::MAX);
        if size > MAX_PHOTO_BYTES {
            return Response::refuse(413, "the photograph is missing or larger than 64 MiB");
        }
        match std::fs::read(file) {
            Ok(bytes) => Response::ok(content_type, bytes),
            Err(e) => Response::refuse(404, &format!("the photograph cannot be read: {e}")),
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

/// The largest photograph file served: a dataset's full-size pictures are a few MiB.
const MAX_PHOTO_BYTES: u64 = 64 << 20;

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
