//! Device buffers and launches shared by the crate's ops: host copies, length checks, and the
//! launch shape of the one-thread-per-row kernels.

use std::sync::Arc;

use cudarc::driver::{CudaSlice, CudaStream, DeviceRepr, LaunchConfig};

use crate::error::CudaError;

/// Threads per block of the one-thread-per-row kernels (the grid field, the activation, the
/// training step's own).
const THREADS: u32 = 256;

/// One thread per row of `n` (at least one block).
pub(crate) fn launch_config(n: usize) -> LaunchConfig {
    let blocks = u32::try_from(n.div_ceil(THREADS as usize).max(1)).unwrap_or(u32::MAX);
    LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (THREADS, 1, 1),
        shared_mem_bytes: 0,
    }
}

/// A length that must be `expected` (the error names the array).
pub(crate) fn check_len(what: &'static str, expected: usize, got: usize) -> Result<(), CudaError> {
    if expected == got {
        Ok(())
    } else {
        Err(CudaError::Shape { what, expected, got })
    }
}

/// Refuses `n` rows that one launch of [`launch_config`] cannot cover.
pub(crate) fn too_many(n: usize) -> Result<(), CudaError> {
    if n.div_ceil(THREADS as usize) > i32::MAX as usize {
        return Err(CudaError::TooLarge(format!("{n} rows is more than one launch covers")));
    }
    Ok(())
}

/// A copy of `v` on the device; an empty `v` gets one zero element, as the driver refuses
/// zero-length allocations (the kernels never read it).
pub(crate) fn put<T: DeviceRepr + Default + Clone>(s: &Arc<CudaStream>, v: &[T]) -> Result<CudaSlice<T>, CudaError> {
    if v.is_empty() {
        Ok(s.clone_htod(&[T::default()])?)
    } else {
        Ok(s.clone_htod(v)?)
    }
}
