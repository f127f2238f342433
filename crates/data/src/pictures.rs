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
/// file share its decoding.
///
/// Errors: pictures that would need more memory than is available
/// ([`DataError::TooLarge`], naming the transforms file and the frame), then the first
/// frame's (in file order) whose picture cannot be read or decoded or is smaller than the
/// downscale factor.
pub(crate) fn decode_pictures(
    specs: &[FrameSpec],
    downscale: usize,
    background: [f64; 3],
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
    check_memory(specs, &slots, &distinct, downscale, limits::available())?;
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

/// Refuses pictures that cannot fit in `available` bytes: one frame's decoding on its own,
/// then all frames' kept pictures with one decoding in flight per thread.
fn check_memory(
    specs: &[FrameSpec],
    slots: &[usize],
    distinct: &[&Path],
    downscale: usize,
    available: Bytes,
) -> Result<(), DataError> {
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
        kept = kept.plus(limits::frame_bytes(w / downscale, h / downscale));
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
