//! The reverse sweep: one loop over the records in reverse creation order, no recursion.

use std::time::Instant;

use ndarray::{ArrayD, ArrayViewD};

use crate::error::{Result, TapeError};
use crate::float::Float;
use crate::gradients::Gradients;
use crate::pool;
use crate::tape::Tape;
use crate::var::Var;

impl<F: Float> Tape<F> {
    /// Gradients of a one-element output `y` with respect to every param it depends on.
    ///
    /// Errors: [`TapeError::NotScalar`] if `y` has more than one element (use
    /// [`Tape::backward_with`]), `StaleVar`, or whatever an op's backward reports.
    pub fn backward(&self, y: Var) -> Result<Gradients<F>> {
        let i = self.check(y)?;
        let shape = self.values[i].data.shape();
        if self.values[i].data.len() != 1 {
            return Err(TapeError::NotScalar { shape: shape.to_vec() });
        }
        self.backward_with(y, ArrayD::ones(shape))
    }

    /// A vector-Jacobian product: gradients of `sum(seed * y)` for any `y`.
    ///
    /// `seed` must have `y`'s shape. The tape is not changed, so the sweep can be run again.
    pub fn backward_with(&self, y: Var, seed: ArrayD<F>) -> Result<Gradients<F>> {
        let top = self.check(y)?;
        let expected = self.values[top].data.shape();
        if seed.shape() != expected {
            return Err(TapeError::ShapeMismatch {
                op: "backward_with",
                lhs: expected.to_vec(),
                rhs: seed.shape().to_vec(),
            });
        }
        let mut grads = Gradients {
            grads: (0..=top).map(|_| None).collect(),
            epoch: self.epoch,
            lent: self.lent.clone(),
        };
        if !self.values[top].needs_grad {
            return Ok(grads);
        }
        grads.grads[top] = Some(seed);
        // Ops take their gradients' buffers from the pool; spent gradients go back to it.
        let _pooled = pool::install(&self.pool);
        for record in self.records.iter().rev() {
            if record.outputs.start as usize > top {
                continue;
            }
            let outs = record.outputs.start as usize..(record.outputs.end as usize).min(top + 1);
            // Intermediates' gradients are released once pushed back, unless retained.
            let upstream: Vec<Option<ArrayD<F>>> = outs
                .clone()
                .map(|j| {
                    if self.values[j].retain {
                        grads.grads[j].clone()
                    } else {
                        grads.grads[j].take()
                    }
                })
                .collect();
            if upstream.iter().all(Option::is_none) {
                continue;
            }
            let mut grad_views: Vec<Option<ArrayViewD<'_, F>>> =
                upstream.iter().map(|g| g.as_ref().map(|g| g.view())).collect();
            // Outputs beyond `y` cannot have a gradient.
            grad_views.resize(record.outputs.len(), None);
            let inputs: Vec<ArrayViewD<'_, F>> = record
                .inputs
                .iter()
                .map(|&i| self.values[i as usize].data.view())
                .collect();
            let outputs: Vec<ArrayViewD<'_, F>> = record
                .outputs
                .clone()
                .map(|j| self.values[j as usize].data.view())
                .collect();
            let needs: Vec<bool> = record
                .inputs
                .iter()
                .map(|&i| self.values[i as usize].needs_grad)
                .collect();
            let name = record.op.name();
            let started = self.profile.is_some().then(Instant::now);
            let returned = record
                .op
                .backward(&inputs, &outputs, &needs, &grad_views)
                .map_err(|e| TapeError::from_op(name, e))?;
            if returned.len() != inputs.len() {
                return Err(TapeError::BadGradientCount {
                    op: name,
                    expected: inputs.len(),
                    got: returned.len(),
                });
            }
            for (k, g) in returned.iter().enumerate() {
                if let Some(g) = g {
                    if g.shape() != inputs[k].shape() {
                        return Err(TapeError::BadGradient {
                            op: name,
                            input: k,
                            expected: inputs[k].shape().to_vec(),
                            got: g.shape().to_vec(),
                        });
                    }
                }
            }
            for (k, g) in returned.into_iter().enumerate() {
                if let (Some(g), true) = (g, needs[k]) {
                    grads.accumulate(record.inputs[k] as usize, g);
                }
            }
            if let (Some(profile), Some(started)) = (&self.profile, started) {
                profile.borrow_mut().add_backward(name, started.elapsed());
            }
            drop(grad_views);
            for g in upstream.into_iter().flatten() {
                pool::give(g.into_raw_vec_and_offset().0);
            }
        }
        // Keep only what the caller may read: params and retained values.
        for (j, slot) in grads.grads.iter_mut().enumerate() {
            let v = &self.values[j];
            let readable = v.retain || (v.is_leaf && v.needs_grad);
            if !readable {
                if let Some(g) = slot.take() {
                    pool::give(g.into_raw_vec_and_offset().0);
                }
            }
        }
        Ok(grads)
    }
}
