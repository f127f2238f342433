//! `fogray-lab bench --keep-freed-memory`: tells glibc to keep freed memory for reuse instead of
//! returning it to the kernel, the steady state of a training loop under a caching allocator.
//! By default every large buffer is fresh memory that the kernel must map and clear page by
//! page, which the bench shows is a large share of both the fused op's and the tape's time.
//!
//! It governs glibc's main arena, which serves the main thread: the taped runs and the fused
//! runs on all threads allocate there. The fused 1-thread runs execute inside a one-thread
//! rayon pool, whose thread glibc serves from a per-thread arena that still maps buffers of
//! this size afresh (with the setting, the same loop runs far slower on a pool thread than on
//! the main thread), so their figures are not comparable across the flag.

use crate::error::LabError;

/// Serves large allocations from the heap and never trims it.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn keep_freed_memory() -> Result<(), LabError> {
    // SAFETY: mallopt only changes two of glibc's allocation thresholds; it is called from the
    // main thread before the bench allocates anything large or starts a thread pool, and glibc
    // serialises it with its own lock in any case. It returns 1 on success.
    let done = unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 30) == 1 && libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX) == 1
    };
    if done {
        Ok(())
    } else {
        Err(LabError::Unsupported(
            "glibc refused to change its mmap and trim thresholds",
        ))
    }
}

/// Serves large allocations from the heap and never trims it.
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn keep_freed_memory() -> Result<(), LabError> {
    Err(LabError::Unsupported("--keep-freed-memory needs Linux with glibc"))
}
