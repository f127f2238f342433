//! Hints that ask the CPU to start loading cache lines before they are read: they change no
//! value, never fault, and do nothing on architectures other than x86_64.

/// Asks for the cache line holding `x`.
#[inline(always)]
pub(crate) fn prefetch<T>(x: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults (not even for an address outside the process) and has
    // no visible effect; SSE is part of the x86_64 baseline. (The intrinsic is a safe function from Rust 1.87.)
    #[allow(unused_unsafe)]
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(x.cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// Asks for every cache line of `values[range]` (clipped to the slice), one request a line.
#[inline(always)]
pub(crate) fn prefetch_span<T>(values: &[T], range: std::ops::Range<usize>) {
    const LINE: usize = 64;
    let end = range.end.min(values.len());
    if range.start >= end || std::mem::size_of::<T>() == 0 {
        return;
    }
    let per_line = (LINE / std::mem::size_of::<T>()).max(1);
    let mut at = range.start;
    // One request a line's width after the one before: each lands in the next line, so every
    // line the range touches is asked for once, but perhaps the last.
    while at < end {
        prefetch(values.as_ptr().wrapping_add(at));
        at += per_line;
    }
    // The last line, when the steps above stopped short of it.
    prefetch(values.as_ptr().wrapping_add(end - 1));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_span_is_clipped_to_its_slice_and_may_be_empty() {
        // Hints only, so no value to check: what can fail is the clipping (an index past the
        // slice, or `end - 1` below zero, panics).
        let v = vec![1.0f32; 100];
        for range in [0..0, 0..100, 99..100, 50..10_000, 100..200, 5_000..6_000] {
            prefetch_span(&v, range);
        }
        prefetch_span::<f64>(&[], 0..8);
        prefetch_span(&[(); 4], 0..4);
    }
}
