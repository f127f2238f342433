//! Buffers a tape keeps for reuse: the large arrays of one training step become the arrays of
//! the next, instead of going back to the system and coming back as fresh pages.
//!
//! A fresh page costs a fault and the kernel's clearing of it, every step, and glibc hands every
//! buffer above 32 MiB back to the system when it is freed (`fogray-lab bench` measures the
//! difference: its `reused` column runs the taped composite on one tape reused with its pool).
//! The pool is what a caching allocator would give, held by the
//! tape that filled it (released with it, or by [`Tape::release_buffers`](crate::Tape)), and
//! started by the tape's first `clear()`: a tape used once holds no buffer beyond its values.
//!
//! Ops reach the pool without a parameter: the tape installs its pool on the calling thread
//! while an op's forward or the backward sweep runs, and [`buffer`](crate::buffer)'s helpers
//! draw from whatever pool is installed (none outside a tape: then they allocate). Rayon workers
//! never see it, so only the thread that drives the tape takes or returns buffers.

use std::any::Any;
use std::cell::RefCell;
use std::collections::BTreeMap;

use crate::float::Float;

/// Buffers smaller than this go back to the allocator, whose small-size bins are fast and
/// whose pages stay mapped; a pool of them would only make each lookup longer.
pub(crate) const WORTH_POOLING: usize = 256 << 10;

/// Free buffers by capacity (elements), for best-fit lookup, each with the step it came back in.
#[derive(Debug, Default)]
pub(crate) struct Pool<F> {
    free: BTreeMap<usize, Vec<(u64, Vec<F>)>>,
    bytes: usize,
    step: u64,
}

impl<F: Float> Pool<F> {
    /// Keeps `v` for reuse if it is worth it; drops it otherwise.
    pub(crate) fn put(&mut self, v: Vec<F>) {
        let bytes = v.capacity() * std::mem::size_of::<F>();
        if bytes >= WORTH_POOLING {
            self.bytes += bytes;
            self.free.entry(v.capacity()).or_default().push((self.step, v));
        }
    }

    /// The smallest kept buffer that holds `len` elements without wasting more than half of
    /// itself (a larger one is kept for a larger request), with whatever it held; `None` if
    /// there is none.
    pub(crate) fn take(&mut self, len: usize) -> Option<Vec<F>> {
        if len * std::mem::size_of::<F>() < WORTH_POOLING / 2 {
            return None;
        }
        let (&cap, list) = self.free.range_mut(len..=len.saturating_mul(2)).next()?;
        let (_, v) = list.pop()?;
        if list.is_empty() {
            self.free.remove(&cap);
        }
        self.bytes -= cap * std::mem::size_of::<F>();
        Some(v)
    }

    /// Ends a step: drops the buffers that were already kept when the step began and that no
    /// request took during it. Without this, every buffer a step allocates outside the pool
    /// (its inputs, say) would add to the pool for good.
    pub(crate) fn next_step(&mut self) {
        let step = self.step;
        self.free.retain(|_, list| {
            list.retain(|(since, _)| *since >= step);
            !list.is_empty()
        });
        self.bytes = self
            .free
            .iter()
            .map(|(cap, list)| cap * list.len() * std::mem::size_of::<F>())
            .sum();
        self.step += 1;
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        self.bytes
    }
}

thread_local! {
    /// The pool of the tape that is running an op on this thread, as `Box<Pool<F>>`.
    static INSTALLED: RefCell<Option<Box<dyn Any>>> = const { RefCell::new(None) };
}

/// Where a tape keeps its pool: empty until the tape is first cleared (a one-shot tape keeps
/// nothing), and while the pool is installed.
pub(crate) type Home<F> = RefCell<Option<Box<Pool<F>>>>;

/// Puts the pool of `home` on this thread until dropped, then back home (also if an op panics),
/// and reinstates whatever was installed before (a tape used inside an op of another tape).
pub(crate) struct Installed<'a, F: Float> {
    home: &'a Home<F>,
    previous: Option<Box<dyn Any>>,
}

/// `None` when the tape has no pool yet: nothing to lend, and nothing spent per op (a tape of
/// a million one-element ops pays for this on each).
pub(crate) fn install<F: Float>(home: &Home<F>) -> Option<Installed<'_, F>> {
    let mine = home.borrow_mut().take()? as Box<dyn Any>;
    let previous = INSTALLED.with(|slot| slot.replace(Some(mine)));
    Some(Installed { home, previous })
}

impl<F: Float> Drop for Installed<'_, F> {
    fn drop(&mut self) {
        let mine = INSTALLED.with(|slot| slot.replace(self.previous.take()));
        *self.home.borrow_mut() = mine.and_then(|p| p.downcast::<Pool<F>>().ok());
    }
}

/// A buffer with capacity for `len` elements from the installed pool, holding what it held.
pub(crate) fn take<F: Float>(len: usize) -> Option<Vec<F>> {
    if len * std::mem::size_of::<F>() < WORTH_POOLING / 2 {
        return None; // before the thread-local: small buffers are most of a small graph's
    }
    INSTALLED.with(|slot| slot.borrow_mut().as_mut()?.downcast_mut::<Pool<F>>()?.take(len))
}

/// Gives `v` to the installed pool; drops it if there is none.
pub(crate) fn give<F: Float>(v: Vec<F>) {
    if v.capacity() * std::mem::size_of::<F>() < WORTH_POOLING {
        return;
    }
    INSTALLED.with(|slot| {
        if let Some(pool) = slot.borrow_mut().as_mut().and_then(|p| p.downcast_mut::<Pool<F>>()) {
            pool.put(v);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    const BIG: usize = WORTH_POOLING; // elements: 4 or 8 times the threshold in bytes

    #[test]
    fn takes_the_smallest_buffer_that_fits_and_never_one_twice_too_large() {
        let mut pool = Pool::<f32>::default();
        for cap in [BIG, 3 * BIG, 5 * BIG] {
            pool.put(Vec::with_capacity(cap));
        }
        assert_eq!(pool.bytes(), 9 * BIG * 4);
        assert_eq!(pool.take(2 * BIG).map(|v| v.capacity()), Some(3 * BIG));
        assert_eq!(pool.take(BIG / 2).map(|v| v.capacity()), Some(BIG));
        // 5 BIG would waste more than half of itself on 2 BIG.
        assert!(pool.take(2 * BIG).is_none());
        assert_eq!(pool.bytes(), 5 * BIG * 4);
        assert!(pool.take(6 * BIG).is_none());
    }

    #[test]
    fn a_step_drops_what_the_step_before_kept_and_no_one_took() {
        let mut pool = Pool::<f32>::default();
        pool.put(Vec::with_capacity(BIG));
        pool.next_step();
        // Kept since the step began, not taken during it: dropped at the end of the next.
        pool.put(Vec::with_capacity(2 * BIG));
        assert_eq!(pool.bytes(), 3 * BIG * 4);
        pool.next_step();
        assert_eq!(pool.bytes(), 2 * BIG * 4);
        assert!(pool.take(BIG / 2).is_none(), "the first buffer is gone");
        // Taken and given back within a step counts as used.
        let v = pool.take(2 * BIG).unwrap();
        pool.put(v);
        pool.next_step();
        assert_eq!(pool.bytes(), 2 * BIG * 4);
        pool.next_step();
        assert_eq!(pool.bytes(), 0);
    }

    #[test]
    fn small_buffers_are_not_kept() {
        let mut pool = Pool::<f64>::default();
        pool.put(vec![1.0; 10]);
        assert_eq!(pool.bytes(), 0);
        assert!(pool.take(10).is_none());
    }

    #[test]
    fn installing_lends_the_pool_to_this_thread_only_and_brings_it_back() {
        let home: Home<f32> = RefCell::new(Some(Box::default()));
        {
            let _on = install(&home);
            assert!(home.borrow().is_none());
            give(Vec::<f32>::with_capacity(BIG));
            // Another precision or another thread sees no pool.
            assert!(take::<f64>(BIG).is_none());
            assert!(std::thread::spawn(|| take::<f32>(BIG).is_none()).join().unwrap());
            give(Vec::<f32>::with_capacity(BIG));
            assert!(take::<f32>(BIG).is_some());
        }
        assert_eq!(home.borrow().as_ref().map(|p| p.bytes()), Some(BIG * 4));
        assert!(take::<f32>(BIG).is_none(), "uninstalled on drop");
    }

    #[test]
    fn a_nested_install_restores_the_outer_pool() {
        let outer: Home<f32> = RefCell::new(Some(Box::default()));
        let inner: Home<f32> = RefCell::new(Some(Box::default()));
        let _a = install(&outer);
        give(Vec::<f32>::with_capacity(BIG));
        {
            let _b = install(&inner);
            assert!(take::<f32>(BIG).is_none(), "the inner pool is empty");
        }
        assert!(take::<f32>(BIG).is_some(), "the outer pool is back");
    }
}
