//! The temporaries this process has created and not yet renamed or removed, so that an
//! interruption (Ctrl-C) can remove them before the process exits.
//!
//! Creating a temporary, renaming it and removing it all happen under one lock, which
//! [`remove_temporaries_and_exit`] takes and never gives back: once it has removed what it
//! found, no other thread can create a new temporary or finish a rename before the process
//! ends.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The live temporaries.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The registry, even if a thread panicked while holding it (the list is still valid: every
/// change to it is a single push or remove).
fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Creates `temporary` with `create` and records it, both under the lock.
pub(super) fn create(temporary: &Path, create: impl FnOnce(&Path) -> std::io::Result<File>) -> std::io::Result<File> {
    let mut live = live();
    let file = create(temporary)?;
    live.push(temporary.to_path_buf());
    Ok(file)
}

/// Runs `finish` (a rename or a removal of `temporary`) and forgets `temporary`, under the
/// lock.
pub(super) fn finish<T>(temporary: &Path, finish: impl FnOnce() -> T) -> T {
    let mut live = live();
    let result = finish();
    if let Some(i) = live.iter().position(|p| p == temporary) {
        live.swap_remove(i);
    }
    result
}

/// The temporaries now live, in no particular order (for diagnostics and tests).
pub fn live_temporaries() -> Vec<PathBuf> {
    live().clone()
}

/// Removes every live temporary and ends the process with exit status `code`, holding the
/// registry's lock to the end so that no thread creates or renames one meanwhile. Meant for
/// a Ctrl-C handler (`fogray` exits 130, as a shell reports a command stopped by SIGINT).
pub fn remove_temporaries_and_exit(code: i32) -> ! {
    let live = live();
    for temporary in live.iter() {
        // Nothing to report to: the process is ending, and a temporary already gone is fine.
        let _ = std::fs::remove_file(temporary);
    }
    std::process::exit(code)
}
