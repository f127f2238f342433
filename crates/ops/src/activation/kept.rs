//! The decays `exp(-|x|)` the activation's forward keeps on a tape for its backward, and the
//! one buffer a thread keeps between steps to hold them: a training loop's forward then reuses
//! last step's buffer instead of paging in a fresh one (megabytes a step) every time.

use std::cell::RefCell;

thread_local! {
    /// The largest decay buffer dropped on this thread and not yet reused.
    static SPARE: RefCell<Option<Vec<f64>>> = const { RefCell::new(None) };
}

/// The residuals of [`DensityColor`](super::DensityColor) on a tape: every raw value's decay,
/// in f64, 8 bytes a raw value. When the tape lets them go (at `clear`, or when it is
/// dropped), the buffer is kept on that thread, one buffer at most (the largest), for the next
/// forward of the activation there, until
/// [`DensityColor::release_buffers`](super::DensityColor::release_buffers) drops it.
#[derive(Debug)]
pub struct KeptDecays(Vec<f64>);

impl KeptDecays {
    /// Room for `len` decays, to be written whole: the thread's spare buffer if it is large
    /// enough (holding whatever it held), else zeros.
    pub(crate) fn with_len(len: usize) -> Self {
        let spare = SPARE.with(|s| s.borrow_mut().take()).filter(|v| v.capacity() >= len);
        KeptDecays(match spare {
            Some(mut v) => {
                // Shrinks without writing when it held at least `len` values.
                v.resize(len, 0.0);
                v
            }
            None => vec![0.0; len],
        })
    }

    pub(crate) fn values(&self) -> &[f64] {
        &self.0
    }

    pub(crate) fn values_mut(&mut self) -> &mut [f64] {
        &mut self.0
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        std::mem::size_of_val(self.0.as_slice())
    }
}

/// Drops this thread's spare buffer, if it has one.
pub(crate) fn release_spare() {
    let _ = SPARE.try_with(|s| s.borrow_mut().take());
}

/// The capacity of this thread's spare buffer (0 without one).
#[cfg(test)]
pub(crate) fn spare_capacity() -> usize {
    SPARE.with(|s| s.borrow().as_ref().map_or(0, Vec::capacity))
}

impl Drop for KeptDecays {
    fn drop(&mut self) {
        let v = std::mem::take(&mut self.0);
        // `try_with`: a tape dropped while its thread is exiting has no spare to give to.
        let _ = SPARE.try_with(|s| {
            let mut s = s.borrow_mut();
            if s.as_ref().is_none_or(|kept| kept.capacity() < v.capacity()) {
                *s = Some(v);
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::activation::DensityColor;
    use fogray_tape::Tape;
    use ndarray::Array2;

    #[test]
    fn decays_are_kept_only_for_a_recorded_application_and_released_on_request() {
        // A thread of its own: its spare buffer starts empty.
        std::thread::spawn(|| {
            let op = DensityColor::new(-1.0).unwrap();
            let raw = Array2::from_shape_fn((1000, 4), |(i, c)| (i as f64 - 500.0) / 50.0 + c as f64);
            let mut tape = Tape::<f64>::new();
            let x = tape.param(raw.clone());
            let c = tape.constant(raw);
            tape.no_grad(|t| op.apply(t, x)).unwrap();
            op.apply(&mut tape, c).unwrap();
            assert_eq!(tape.stats().saved_bytes, 0);
            tape.clear();
            assert_eq!(spare_capacity(), 0, "no record, no decays");
            let x = tape.param(Array2::zeros((1000, 4)));
            op.apply(&mut tape, x).unwrap();
            assert_eq!(tape.stats().saved_bytes, 1000 * 4 * 8);
            tape.clear();
            assert!(spare_capacity() >= 4000, "the recorded decays' buffer is kept");
            op.release_buffers();
            assert_eq!(spare_capacity(), 0);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn a_dropped_buffer_is_reused_by_the_next_request_that_fits() {
        let first = KeptDecays::with_len(1000);
        let at = first.values().as_ptr();
        drop(first);
        // Smaller: the same memory, shortened.
        let second = KeptDecays::with_len(600);
        assert_eq!((second.values().as_ptr(), second.values().len()), (at, 600));
        drop(second);
        // Larger than the spare: a fresh buffer of zeros, and the spare is gone.
        let third = KeptDecays::with_len(5000);
        assert!(third.values().iter().all(|&v| v == 0.0) && third.values().len() == 5000);
        drop(third);
        // The larger buffer is kept over a smaller one.
        let (big, small) = (KeptDecays::with_len(5000), KeptDecays::with_len(10));
        let big_at = big.values().as_ptr();
        drop(big);
        drop(small);
        assert_eq!(KeptDecays::with_len(4000).values().as_ptr(), big_at);
    }
}
