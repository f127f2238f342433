//! The tape: an arena of values in creation order and the records of the ops that made them.

use std::cell::RefCell;
use std::ops::Range;
use std::time::Instant;

use ndarray::{ArrayD, ArrayViewD, Dimension};

use crate::custom::{Backward, CustomOp, Recorded};
use crate::error::{Result, TapeError};
use crate::float::Float;
use crate::gradients::Gradients;
use crate::params::Lent;
use crate::pool::{self, Home};
use crate::profile::Profile;
use crate::storage::Storage;
use crate::var::{fresh_epoch, Var};

/// One value on the tape.
#[derive(Debug)]
pub(crate) struct Value<F: Float> {
    pub(crate) data: Storage<F>,
    /// A param, or the output of a record with an input that needs a gradient.
    pub(crate) needs_grad: bool,
    /// Whether `backward` keeps this intermediate's gradient (params' are always kept).
    pub(crate) retain: bool,
    /// `true` for values made by `param`, `param_from`, `constant`, `constant_shared` or `detach`.
    pub(crate) is_leaf: bool,
}

/// One op application that needs a backward: its inputs, its consecutive outputs, its rule.
#[derive(Debug)]
pub(crate) struct Record<F: Float> {
    pub(crate) inputs: Vec<u32>,
    pub(crate) outputs: Range<u32>,
    pub(crate) op: Box<dyn Backward<F>>,
}

/// Sizes of what a tape holds, from [`Tape::stats`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TapeStats {
    /// Values on the tape (params, constants and op outputs).
    pub values: usize,
    /// Op applications recorded for backward (those with an input that needs a gradient).
    pub records: usize,
    /// Bytes of value data (shared arrays included).
    pub value_bytes: usize,
    /// Bytes of the values that are shared arrays, lent by a [`Params`](crate::params::Params)
    /// store or through [`Tape::constant_shared`] (part of `value_bytes`; never copied).
    pub shared_bytes: usize,
    /// Bytes of residuals saved by ops for their backward, as the ops report them.
    pub saved_bytes: usize,
    /// Bytes of buffers kept from earlier steps for reuse (see [`Tape::clear`]).
    pub pooled_bytes: usize,
}

/// A Wengert list: values in creation order (a topological order) and the records of the ops
/// that need a backward.
///
/// Every op is a method returning `Result<Var>`; a failed op leaves the tape as it was.
/// The tape is `Send` (not `Sync`): parallelism belongs inside ops, never across the tape.
#[derive(Debug)]
pub struct Tape<F: Float> {
    pub(crate) values: Vec<Value<F>>,
    pub(crate) records: Vec<Record<F>>,
    pub(crate) epoch: u64,
    /// The parameters lent to this tape since the last `clear`, one entry each.
    pub(crate) lent: Vec<Lent>,
    grad_enabled: bool,
    /// Large buffers of earlier steps, for the ops of the next ones (see [`crate::pool`]).
    pub(crate) pool: Home<F>,
    /// Op times while profiling is on (a cell: the backward sweep takes `&self`).
    pub(crate) profile: Option<RefCell<Profile>>,
}

impl<F: Float> Default for Tape<F> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Float> Tape<F> {
    /// An empty tape with recording on.
    pub fn new() -> Self {
        Tape {
            values: Vec::new(),
            records: Vec::new(),
            epoch: fresh_epoch(),
            lent: Vec::new(),
            grad_enabled: true,
            pool: Home::new(None),
            profile: None,
        }
    }

    /// A leaf that gradients are computed for.
    ///
    /// The tape takes `value` and, after [`Tape::clear`], recycles its buffer: a parameter that
    /// lives across steps belongs in a [`Params`](crate::params::Params) store and enters each
    /// step through [`Tape::param_from`] without a copy.
    pub fn param<D: Dimension>(&mut self, value: ndarray::Array<F, D>) -> Var {
        self.push_leaf(Storage::Owned(value.into_dyn()), true)
    }

    /// A leaf that never receives a gradient (see [`Tape::constant_shared`] for one that lives
    /// across steps).
    pub fn constant<D: Dimension>(&mut self, value: ndarray::Array<F, D>) -> Var {
        self.push_leaf(Storage::Owned(value.into_dyn()), false)
    }

    /// A zero-dimensional constant holding `x`.
    pub fn scalar(&mut self, x: F) -> Var {
        self.push_leaf(Storage::Owned(ArrayD::from_elem(ndarray::IxDyn(&[]), x)), false)
    }

    /// A constant copy of `v`'s value: no gradient flows through it.
    pub fn detach(&mut self, v: Var) -> Result<Var> {
        let data = self.value(v)?.to_owned();
        Ok(self.push_leaf(Storage::Owned(data), false))
    }

    /// The value behind `v`.
    pub fn value(&self, v: Var) -> Result<ArrayViewD<'_, F>> {
        Ok(self.values[self.check(v)?].data.view())
    }

    /// The shape of `v`'s value.
    pub fn shape(&self, v: Var) -> Result<&[usize]> {
        Ok(self.values[self.check(v)?].data.shape())
    }

    /// Whether `v` needs a gradient (it is a param, or depends on one through recorded ops).
    pub fn needs_grad(&self, v: Var) -> Result<bool> {
        Ok(self.values[self.check(v)?].needs_grad)
    }

    /// Keeps `v`'s gradient in the result of the next `backward`, even if it is an intermediate.
    pub fn retain(&mut self, v: Var) -> Result<()> {
        let i = self.check(v)?;
        self.values[i].retain = true;
        Ok(())
    }

    /// Whether op applications are being recorded (see [`Tape::no_grad`]).
    pub fn grad_enabled(&self) -> bool {
        self.grad_enabled
    }

    /// Turns recording on or off; off, op outputs need no gradient and nothing is recorded.
    pub fn set_grad_enabled(&mut self, on: bool) {
        self.grad_enabled = on;
    }

    /// Runs `f` with recording off (for evaluation loops), then restores the previous mode.
    pub fn no_grad<R>(&mut self, f: impl FnOnce(&mut Self) -> R) -> R {
        let before = std::mem::replace(&mut self.grad_enabled, false);
        let out = f(self);
        self.grad_enabled = before;
        out
    }

    /// Drops every value and record but keeps the allocations, for reuse in a training loop:
    /// the values' buffers of 256 KiB and more go to the tape's pool, from which the ops of the
    /// next step take their outputs and gradients (and the backward its spent gradients) instead
    /// of fresh pages from the system, which would cost a page fault and the kernel's clearing
    /// of each page (a fifth of a taped composite's time). Kept buffers that no op of the step
    /// before took are freed, so the pool holds about one step's worth; see [`Tape::stats`] and
    /// [`Tape::release_buffers`]. A tape that is never cleared keeps no buffer: one-shot use
    /// has the smallest peak memory.
    ///
    /// Every handle made before is invalidated: using one is [`TapeError::StaleVar`]. Arrays
    /// lent by a [`Params`](crate::params::Params) store are given back, so an optimiser can
    /// update them in place.
    ///
    /// A training loop that keeps one tape (gradient descent on `sum((w x - y)^2)`; the data
    /// `x` and `y` live across steps, so they are lent with [`Tape::constant_shared`] instead
    /// of copied onto the tape each step):
    ///
    /// ```
    /// use std::sync::Arc;
    ///
    /// use fogray_tape::Tape;
    /// use ndarray::Array1;
    ///
    /// let n = 100_000; // 400 KB per value: large enough to be pooled
    /// let x = Arc::new(Array1::from_shape_fn(n, |i| (i % 7) as f32 / 7.0).into_dyn());
    /// let y = Arc::new(x.mapv(|v| 3.0 * v));
    /// let mut w = 0.0f32;
    /// let mut tape = Tape::<f32>::new();
    /// for _ in 0..20 {
    ///     tape.clear(); // last step's buffers go to the pool, its handles go stale
    ///     let wv = tape.param(ndarray::arr0(w));
    ///     let xv = tape.constant_shared(&x);
    ///     let yv = tape.constant_shared(&y);
    ///     let wx = tape.mul(xv, wv)?; // broadcast: the output comes from the pool
    ///     let r = tape.sub(wx, yv)?;
    ///     let sq = tape.square(r)?;
    ///     let loss = tape.mean(sq)?;
    ///     let grads = tape.backward(loss)?;
    ///     w -= 1.5 * grads.get(wv).unwrap()[[]];
    ///     tape.recycle(grads); // and the gradients' buffers too
    /// }
    /// assert!((w - 3.0).abs() < 1e-3);
    /// assert!(tape.stats().pooled_bytes > 0);
    /// # Ok::<(), fogray_tape::TapeError>(())
    /// ```
    ///
    /// For parameters that live across steps, see [`crate::params`] and [`crate::optim`].
    pub fn clear(&mut self) {
        let pool = self.pool.get_mut().get_or_insert_with(Box::default);
        pool.next_step();
        for v in self.values.drain(..) {
            // Shared arrays go back to their owner (the `Arc` is dropped), never to the pool.
            if let Storage::Owned(data) = v.data {
                pool.put(data.into_raw_vec_and_offset().0);
            }
        }
        self.records.clear();
        self.lent.clear();
        self.epoch = fresh_epoch();
    }

    /// Hands the buffers of a backward's gradients to the pool, once the step has used them
    /// (and starts the pool, as [`Tape::clear`] does). Gradients of another tape are taken as
    /// well: their buffers are just memory.
    pub fn recycle(&mut self, grads: Gradients<F>) {
        let pool = self.pool.get_mut().get_or_insert_with(Box::default);
        for g in grads.grads.into_iter().flatten() {
            pool.put(g.into_raw_vec_and_offset().0);
        }
    }

    /// Frees the buffers the pool keeps (after a large step that will not come again, say);
    /// the next steps fill it again.
    pub fn release_buffers(&mut self) {
        *self.pool.get_mut() = Some(Box::default());
    }

    /// Number of values on the tape.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether the tape holds no value.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// What the tape holds: values, records and bytes.
    pub fn stats(&self) -> TapeStats {
        TapeStats {
            values: self.values.len(),
            records: self.records.len(),
            value_bytes: self
                .values
                .iter()
                .map(|v| v.data.len() * std::mem::size_of::<F>())
                .sum(),
            shared_bytes: self
                .values
                .iter()
                .filter(|v| v.data.is_shared())
                .map(|v| v.data.len() * std::mem::size_of::<F>())
                .sum(),
            saved_bytes: self.records.iter().map(|r| r.op.saved_bytes()).sum(),
            pooled_bytes: self.pool.borrow().as_ref().map_or(0, |p| p.bytes()),
        }
    }

    /// Turns op profiling on or off (off by default). On, every successful forward and every
    /// backward rule is timed and summed by op name (see [`Profile`]) across steps:
    /// [`Tape::clear`] keeps the profile, [`Tape::take_profile`] hands it over and starts a new
    /// one. Turning it off drops what was gathered. Profiling changes no value.
    pub fn set_profiling(&mut self, on: bool) {
        match (on, &self.profile) {
            (true, None) => self.profile = Some(RefCell::default()),
            (false, _) => self.profile = None,
            (true, Some(_)) => {}
        }
    }

    /// A copy of the op times gathered so far, or `None` with profiling off.
    pub fn profile(&self) -> Option<Profile> {
        self.profile.as_ref().map(|p| p.borrow().clone())
    }

    /// The op times gathered so far, with the count started again from nothing (profiling
    /// stays on); `None` with profiling off.
    pub fn take_profile(&mut self) -> Option<Profile> {
        self.profile.as_mut().map(|p| std::mem::take(p.get_mut()))
    }

    /// Applies an op with any number of inputs and outputs and returns the outputs' handles.
    ///
    /// The forward runs on the input values; if it fails, or returns no output, nothing is
    /// pushed. A record for backward is kept only if recording is on and some input needs a
    /// gradient; otherwise the op computes its outputs alone ([`CustomOp::forward_only`]).
    pub fn apply<O: CustomOp<F>>(&mut self, op: O, inputs: &[Var]) -> Result<Vec<Var>> {
        self.apply_checked(op, inputs, false)
    }

    /// [`Tape::apply`] for an op with exactly one output.
    pub fn apply1<O: CustomOp<F>>(&mut self, op: O, inputs: &[Var]) -> Result<Var> {
        Ok(self.apply_checked(op, inputs, true)?[0])
    }

    /// [`Tape::apply`], refusing (before anything is pushed or profiled) a forward that
    /// returns other than one output when `one` is set.
    fn apply_checked<O: CustomOp<F>>(&mut self, op: O, inputs: &[Var], one: bool) -> Result<Vec<Var>> {
        let ids = inputs.iter().map(|&v| self.check(v)).collect::<Result<Vec<_>>>()?;
        let needs_grad = self.grad_enabled && ids.iter().any(|&i| self.values[i].needs_grad);
        let started = self.profile.is_some().then(Instant::now);
        let (outputs, saved) = {
            let views: Vec<ArrayViewD<'_, F>> = ids.iter().map(|&i| self.values[i].data.view()).collect();
            let _pooled = pool::install(&self.pool);
            let computed = if needs_grad {
                op.forward(&views).map(|(outputs, saved)| (outputs, Some(saved)))
            } else {
                // No record will be kept: the op need not make residuals.
                op.forward_only(&views).map(|outputs| (outputs, None))
            };
            computed.map_err(|e| TapeError::from_op(op.name(), e))?
        };
        let forward_time = started.map(|s| s.elapsed());
        if outputs.is_empty() {
            return Err(TapeError::InvalidArgument {
                op: op.name(),
                reason: "forward returned no output".into(),
            });
        }
        if one && outputs.len() != 1 {
            return Err(TapeError::InvalidArgument {
                op: op.name(),
                reason: format!("apply1 needs one output, the op returned {}", outputs.len()),
            });
        }
        let first = self.values.len();
        let count = outputs.len();
        if first + count > u32::MAX as usize {
            return Err(TapeError::InvalidArgument {
                op: op.name(),
                reason: "the tape is full (2^32 values)".into(),
            });
        }
        for data in outputs {
            self.values.push(Value {
                data: Storage::Owned(data),
                needs_grad,
                retain: false,
                is_leaf: false,
            });
        }
        if let (Some(profile), Some(time)) = (&mut self.profile, forward_time) {
            profile.get_mut().add_forward(op.name(), time);
        }
        if let Some(saved) = saved {
            self.records.push(Record {
                inputs: ids.iter().map(|&i| i as u32).collect(),
                outputs: first as u32..(first + count) as u32,
                op: Box::new(Recorded { op, saved }),
            });
        }
        Ok((first..first + count).map(|i| self.handle(i)).collect())
    }

    /// The arena index of `v`, or `StaleVar` if the handle is not from this tape's epoch.
    pub(crate) fn check(&self, v: Var) -> Result<usize> {
        if v.epoch != self.epoch || v.index() >= self.values.len() {
            return Err(TapeError::StaleVar {
                index: v.index,
                epoch: v.epoch,
                tape_epoch: self.epoch,
            });
        }
        Ok(v.index())
    }

    pub(crate) fn handle(&self, index: usize) -> Var {
        Var {
            index: index as u32,
            epoch: self.epoch,
        }
    }

    pub(crate) fn push_leaf(&mut self, data: Storage<F>, needs_grad: bool) -> Var {
        self.values.push(Value {
            data,
            needs_grad,
            retain: false,
            is_leaf: true,
        });
        self.handle(self.values.len() - 1)
    }
}
