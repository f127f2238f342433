//! The bar `fogray fit` shows on stderr while its dataset's pictures decode: a dataset of
//! thousands of frames takes minutes to read, and a silent terminal for that long looks hung.

use std::path::Path;

use fogray_data::{load_with_progress, LoadOptions, LoadProgress, SceneData};
use indicatif::{ProgressBar, ProgressStyle};

use crate::error::CliError;

/// A bar counting pictures decoded, drawn on stderr (so stdout keeps only the command's
/// output), or a hidden one where `shown` is false. indicatif draws only on a terminal, so a
/// redirected stderr gets no bar either.
pub fn load_bar(shown: bool) -> ProgressBar {
    if !shown {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(0);
    if let Ok(style) = ProgressStyle::with_template("load [{bar:40}] {pos}/{len} pictures ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Moves `bar` to what `progress` says. The loader counts each split (or transforms file)
/// from zero, so a first picture, or another total, starts the bar again; within a split the
/// decoding threads may report out of order, and the bar does not go back.
pub fn show(bar: &ProgressBar, progress: LoadProgress) {
    let total = progress.pictures as u64;
    let decoded = progress.decoded as u64;
    if decoded == 1 || bar.length() != Some(total) {
        bar.set_length(total);
        bar.set_position(decoded);
    } else if decoded > bar.position() {
        bar.set_position(decoded);
    }
}

/// [`fogray_data::load`] of `path` with `options`, showing how many pictures are decoded on
/// a [`load_bar`] (hidden unless `shown`), cleared once the load is done or failed.
///
/// Errors: as [`fogray_data::load`], naming the file.
pub fn load_showing_progress(path: &Path, options: &LoadOptions, shown: bool) -> Result<SceneData, CliError> {
    let bar = load_bar(shown);
    // The hook is called from the decoding threads; a ProgressBar is a shared handle.
    let hook_bar = bar.clone();
    let scene = load_with_progress(path, options, move |p| show(&hook_bar, p));
    bar.finish_and_clear();
    Ok(scene?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn progress(decoded: usize, pictures: usize) -> LoadProgress {
        LoadProgress { decoded, pictures }
    }

    #[test]
    fn the_bar_follows_each_split_and_never_goes_back_within_one() {
        let bar = load_bar(false);
        show(&bar, progress(1, 3));
        assert_eq!((bar.position(), bar.length()), (1, Some(3)));
        // Threads finishing out of order: the third picture reported before the second.
        show(&bar, progress(3, 3));
        show(&bar, progress(2, 3));
        assert_eq!((bar.position(), bar.length()), (3, Some(3)));
        // The next split counts its own pictures from the start, whether or not it has as
        // many.
        show(&bar, progress(1, 3));
        assert_eq!((bar.position(), bar.length()), (1, Some(3)));
        show(&bar, progress(2, 5));
        assert_eq!((bar.position(), bar.length()), (2, Some(5)));
    }
}
