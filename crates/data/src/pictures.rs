//! A dataset's pictures decoded for its frames: checked against the machine's memory before
//! any is decoded, each distinct file decoded once (frames may name the same picture), in
//! parallel, with progress reported to the hook of [`load_with_progress`](crate::load_with_progress).
//!
//! The sizes come from the transforms file's `w` / `h` where it gives them (so that a file
//! claiming a picture too large for the machine is refused before any file is opened), else
//! from each picture's header; the check counts what the frames keep and what the pictures in
//! flight hold while they decode ([`fogray_ops::limits`]).

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use fogray_ops::limits::{self, Bytes};
use rayon::prelude::*;

use crate::downscale::downscale_picture;
use crate::error::DataError;
use crate::picture::{decode, dimensions, Picture};
use crate::spec::FrameSpec;

/// How far a load has come: pictures decoded of those to decode (distinct files of one
/// transforms file, or of one Blender split).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadProgress {
    /// Pictures decoded so far.
    pub decoded: usize,
    /// Pictures to decode.
    pub pictures: usize,
}

/// A hook told of each picture decoded (from the decoding threads).
pub(crate) type ProgressHook = Arc<dyn Fn(LoadProgress) + Send + Sync>;

thread_local! {
    /// The hook of the load running on this thread, if it asked for one.
    static HOOK: RefCell<Option<ProgressHook>> = const { RefCell::new(None) };
}

/// Runs `work` with `hook` as the progress hook of the loads it makes on this thread.
pub(crate) fn with_progress<T>(hook: ProgressHook, work: impl FnOnce() -> T) -> T {
    struct Restore(Option<ProgressHook>);
    impl Drop for Restore {
        fn drop(&mut self) {
            HOOK.with(|h| *h.borrow_mut() = self.0.take());
        }
    }
    let _restore = Restore(HOOK.with(|h| h.borrow_mut().replace(hook)));
    work()
}

/// A decoded image's full size, and the image downscaled.
pub(crate) type Decoded = ((usize, usize), Picture);

/// Every frame's picture of `specs` (each decoded at full size, then downscaled by
/// `downscale`, composited over `background`), in the order of `specs`; frames naming one
/// file share its decoding. `copy_float_bytes` is the size of the floats in which the caller
/// will copy every frame's colour and alpha ([`LoadOptions::copy_float_bytes`](crate::LoadOptions::copy_float_bytes)).
///
/// Errors: pictures that would need more memory than is available
/// ([`DataError::TooLarge`], naming the transforms file and the frame), then the first
/// frame's (in file order) whose picture cannot be read or decoded or is smaller than the
/// downscale factor; then, once the distinct pictures are decoded (and whether they have alpha
/// is known), frames whose copies would not fit, before any is copied.
pub(crate) fn decode_pictures(
    specs: &[FrameSpec],
    downscale: usize,
    background: [f64; 3],
    copy_float_bytes: usize,
) -> Result<Vec<Decoded>, DataError> {
    let mut distinct: Vec<&Path> = Vec::new();
    let mut slot_of: HashMap<&Path, usize> = HashMap::new();
    let slots: Vec<usize> = specs
        .iter()
        .map(|s| {
            *slot_of.entry(s.file.as_path()).or_insert_with(|| {
                distinct.push(&s.file);
                distinct.len() - 1
            })
        })
        .collect();
    let copies = Copies {
        float_bytes: copy_float_bytes as u64,
        downscale,
    };
    check_memory(specs, &slots, &distinct, copies, limits::available())?;
    let hook = HOOK.with(|h| h.borrow().clone());
    let done = AtomicUsize::new(0);
    let decoded: Vec<Result<Decoded, DataError>> = distinct
        .par_iter()
        .map(|file| {
            let result = decode_one(file, downscale, background);
            let decoded = done.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(hook) = &hook {
                hook(LoadProgress {
                    decoded,
                    pictures: distinct.len(),
                });
            }
            result
        })
        .collect();
    let mut decoded = decoded;
    if let Some(&s) = slots.iter().find(|&&s| decoded[s].is_err()) {
        decoded.swap_remove(s)?;
    }
    let mut decoded: Vec<Option<Decoded>> = decoded.into_iter().map(Result::ok).collect();
    let shapes: Vec<PictureShape> = decoded
        .iter()
        .map(|d| d.as_ref().map_or(PictureShape::NONE, |(_, p)| PictureShape::of(p)))
        .collect();
    check_frames(specs, &slots, &shapes, copies, limits::available())?;
    let mut uses = vec![0usize; distinct.len()];
    for &s in &slots {
        uses[s] += 1;
    }
    let mut out = Vec::with_capacity(specs.len());
    for &s in &slots {
        uses[s] -= 1;
        // The last frame naming a picture takes it; the others take a copy.
        let picture = if uses[s] == 0 {
            decoded[s].take()
        } else {
            decoded[s].clone()
        };
        out.push(picture.map_or_else(|| unreachable_slot(distinct[s]), Ok)?);
    }
    Ok(out)
}

/// A slot read after its last use: not reached (each slot is taken once, by its last user).
fn unreachable_slot(file: &Path) -> Result<Decoded, DataError> {
    Err(DataError::io(
        file,
        "picture decoded once but read again after its last use",
    ))
}

fn decode_one(file: &Path, downscale: usize, background: [f64; 3]) -> Result<Decoded, DataError> {
    let full = decode(file, background)?;
    let size = (full.width(), full.height());
    if size.0 / downscale == 0 || size.1 / downscale == 0 {
        return Err(DataError::BadDownscale {
            path: file.to_path_buf(),
            downscale,
            problem: "is larger than the image",
        });
    }
    Ok((size, downscale_picture(&full, downscale)))
}

/// The copies a caller makes of each loaded frame: in floats of `float_bytes` (0: none), of
/// pictures downscaled by `downscale`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Copies {
    pub(crate) float_bytes: u64,
    pub(crate) downscale: usize,
}

/// A decoded (and downscaled) picture's width, height and channels (3, or 4 with alpha).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PictureShape {
    pub(crate) width: usize,
    pub(crate) height: usize,
    pub(crate) channels: u64,
}

impl PictureShape {
    /// No picture (a slot whose decoding failed: not reached, the load stops at it).
    const NONE: PictureShape = PictureShape {
        width: 0,
        height: 0,
        channels: 3,
    };

    fn of(picture: &Picture) -> Self {
        PictureShape {
            width: picture.width(),
            height: picture.height(),
            channels: 3 + u64::from(picture.alpha.is_some()),
        }
    }
}

/// Refuses frames whose pictures cannot be copied in `available` bytes once the distinct
/// pictures (`shapes`, by slot) are decoded (and are counted in what the process holds), before
/// any frame is copied: each further frame naming a decoded picture takes a copy of it (`f32`,
/// [`limits::FRAME_PIXEL_BYTES`] a pixel), and the caller copies every frame
/// (`copies.float_bytes` a channel). The caller's copies are counted beside the frames: it
/// drops each frame as it copies it, but a frame small enough to come from the heap leaves its
/// memory with the process.
pub(crate) fn check_frames(
    specs: &[FrameSpec],
    slots: &[usize],
    shapes: &[PictureShape],
    copies: Copies,
    available: Bytes,
) -> Result<(), DataError> {
    let Some(first) = specs.first() else {
        return Ok(());
    };
    let mut need = Bytes(0);
    let mut copied = vec![false; shapes.len()];
    for &s in slots {
        let Some(shape) = shapes.get(s) else {
            continue;
        };
        // The first frame naming a picture takes the decoded one; the others, a copy.
        if std::mem::replace(&mut copied[s], true) {
            need = need.plus(limits::frame_bytes(shape.width, shape.height));
        }
        let pixels = [shape.width as u64, shape.height as u64];
        need = need.plus(Bytes::product(&[
            pixels[0],
            pixels[1],
            shape.channels,
            copies.float_bytes,
        ]));
    }
    let largest = shapes.iter().max_by_key(|s| s.width.saturating_mul(s.height));
    let what = match largest {
        Some(s) => format!("{} frames, the largest {}x{},", specs.len(), s.width, s.height),
        None => format!("{} frames", specs.len()),
    };
    let needed_for = if copies.float_bytes > 0 {
        format!("their pictures and a copy in {}-bit floats", copies.float_bytes * 8)
    } else {
        "their pictures".to_string()
    };
    Bytes::check(need, available, &what, &needed_for).map_err(|source| DataError::TooLarge {
        path: first.transforms.clone(),
        source,
    })
}

/// Refuses pictures that cannot fit in `available` bytes: one frame's decoding on its own,
/// then all frames' kept pictures and the caller's copies of their colour with one decoding in
/// flight per thread.
fn check_memory(
    specs: &[FrameSpec],
    slots: &[usize],
    distinct: &[&Path],
    copies: Copies,
    available: Bytes,
) -> Result<(), DataError> {
    let downscale = copies.downscale;
    let too_large = |spec: &FrameSpec, source| DataError::TooLarge {
        path: spec.transforms.clone(),
        source,
    };
    let frame_check = |spec: &FrameSpec, (w, h): (usize, usize)| {
        let need = limits::decode_bytes(w, h).plus(limits::frame_bytes(w / downscale, h / downscale));
        let what = format!("{} ({w}x{h} pixels)", spec.key);
        Bytes::check(need, available, &what, "decoding its picture").map_err(|e| too_large(spec, e))
    };
    // Sizes the file states are checked before any picture is opened.
    for spec in specs {
        if let Some(size) = spec.size {
            frame_check(spec, size)?;
        }
    }
    let stated: HashMap<usize, (usize, usize)> = slots
        .iter()
        .zip(specs)
        .filter_map(|(&s, spec)| Some((s, spec.size?)))
        .collect();
    let headers: Vec<Result<(usize, usize), DataError>> = distinct
        .par_iter()
        .enumerate()
        .map(|(s, file)| match stated.get(&s) {
            Some(&size) => Ok(size),
            None => dimensions(file),
        })
        .collect();
    let mut sizes = Vec::with_capacity(distinct.len());
    for size in headers {
        sizes.push(size?);
    }
    let mut kept = Bytes(0);
    for (spec, &s) in specs.iter().zip(slots) {
        frame_check(spec, sizes[s])?;
        let (w, h) = sizes[s];
        let (w, h) = (w / downscale, h / downscale);
        // The copies' colour only: whether a picture has alpha is known once it is decoded.
        let copy = Bytes::product(&[w as u64, h as u64, 3, copies.float_bytes]);
        kept = kept.plus(limits::frame_bytes(w, h)).plus(copy);
    }
    let in_flight = rayon::current_num_threads().min(distinct.len()) as u64;
    let largest = sizes
        .iter()
        .map(|&(w, h)| limits::decode_bytes(w, h))
        .max()
        .unwrap_or_default();
    let need = kept.plus(largest.times(in_flight));
    match specs.first() {
        Some(first) => {
            let what = format!("{} frames", specs.len());
            Bytes::check(need, available, &what, "their decoded pictures").map_err(|e| too_large(first, e))
        }
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use fogray_ops::LensDistortion;

    use super::*;
    use crate::spec::Lens;

    fn spec(i: usize) -> FrameSpec {
        FrameSpec {
            transforms: PathBuf::from("scene/transforms.json"),
            key: format!("frames[{i}]"),
            name: format!("f_{i}"),
            file: PathBuf::from("scene/images/big.png"),
            pose: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
            lens: Lens::default(),
            distortion: LensDistortion::NONE,
            size: Some((800, 800)),
        }
    }

    /// 10 000 frames naming one 800x800 picture with alpha, downscaled by 8: 100x100 pixels,
    /// 4 channels each. The picture decoded once is held already; the 9 999 other frames take
    /// a copy in f32 (16 bytes a pixel) and all 10 000 are copied in f64 (32 bytes a pixel):
    /// 9 999 x 10 000 x 16 + 10 000 x 10 000 x 32 = 4 799 840 000 bytes.
    #[test]
    fn frames_whose_copies_cannot_fit_are_refused_naming_the_transforms_file() {
        let specs: Vec<FrameSpec> = (0..10_000).map(spec).collect();
        let slots = vec![0; specs.len()];
        let shapes = [PictureShape {
            width: 100,
            height: 100,
            channels: 4,
        }];
        let copies = Copies {
            float_bytes: 8,
            downscale: 8,
        };
        let need = 9_999 * 10_000 * 16 + 10_000 * 10_000 * 4 * 8;
        assert_eq!(need, 4_799_840_000u64);
        assert!(check_frames(&specs, &slots, &shapes, copies, Bytes(need)).is_ok());
        let e = check_frames(&specs, &slots, &shapes, copies, Bytes(need - 1)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "scene/transforms.json: 10000 frames, the largest 100x100, would need 4.80 GB for their \
             pictures and a copy in 64-bit floats; 4.80 GB available"
        );
        // Without alpha the copy has 3 channels: 1 599 840 000 + 10 000 x 10 000 x 24.
        let opaque = [PictureShape {
            channels: 3,
            ..shapes[0]
        }];
        assert!(check_frames(&specs, &slots, &opaque, copies, Bytes(3_999_840_000)).is_ok());
        assert!(check_frames(&specs, &slots, &opaque, copies, Bytes(3_999_839_999)).is_err());
        // A caller that keeps the frames as loaded: the 9 999 copies in f32 alone.
        let kept = Copies {
            float_bytes: 0,
            ..copies
        };
        assert!(check_frames(&specs, &slots, &opaque, kept, Bytes(1_599_840_000)).is_ok());
        assert!(check_frames(&specs, &slots, &opaque, kept, Bytes(1_599_839_999)).is_err());
        // Frames each naming their own picture: all decoded already, only the f64 copies to
        // come: 4 x 10 000 x 4 x 8.
        let own: Vec<usize> = (0..4).collect();
        let four = [shapes[0]; 4];
        assert!(check_frames(&specs[..4], &own, &four, copies, Bytes(1_280_000)).is_ok());
        assert!(check_frames(&specs[..4], &own, &four, copies, Bytes(1_279_999)).is_err());
    }

    /// Before decoding, the sizes the file states (800x800 downscaled by 8) count the kept
    /// frames (16 bytes a pixel), the copies' colour (3 channels of 8 bytes) and one picture
    /// decoding at full size (40 bytes a pixel): 10 000 x 10 000 x 40 + 640 000 x 40.
    #[test]
    fn the_stated_sizes_are_checked_with_the_copies_before_any_picture_is_opened() {
        let specs: Vec<FrameSpec> = (0..10_000).map(spec).collect();
        let slots = vec![0; specs.len()];
        let file = Path::new("scene/images/big.png");
        let copies = Copies {
            float_bytes: 8,
            downscale: 8,
        };
        let need = 10_000 * 10_000 * 40 + 640_000 * 40;
        assert!(check_memory(&specs, &slots, &[file], copies, Bytes(need)).is_ok());
        let e = check_memory(&specs, &slots, &[file], copies, Bytes(need - 1)).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("scene/transforms.json: 10000 frames would need"),
            "{e}"
        );
    }
}
