//! The gradient store returned by `backward`, read by handle.

use ndarray::{ArrayD, ArrayViewD, Zip};

use crate::error::Result;
use crate::float::Float;
use crate::optim::chunks::zip2;
use crate::params::Lent;
use crate::tape::Tape;
use crate::var::Var;

/// Gradients of one backward sweep, indexed by the handles of the tape that made them.
///
/// Params always keep their gradient; intermediates only if [`Tape::retain`] was called before
/// the sweep. A value the sweep never reached has no entry: [`Gradients::get`] returns `None`,
/// which is not the same as a gradient of zeros.
#[derive(Debug, Clone)]
pub struct Gradients<F: Float> {
    pub(crate) grads: Vec<Option<ArrayD<F>>>,
    pub(crate) epoch: u64,
    /// The parameters the tape had lent, pairing each with its gradient's index.
    pub(crate) lent: Vec<Lent>,
}

impl<F: Float> Gradients<F> {
    /// The gradient of `v`, or `None` if the sweep never reached it (or `v` is stale, or an
    /// intermediate that was not retained).
    pub fn get(&self, v: Var) -> Option<ArrayViewD<'_, F>> {
        if v.epoch != self.epoch {
            return None;
        }
        self.grads.get(v.index()).and_then(|g| g.as_ref()).map(|g| g.view())
    }

    /// The gradient of `v`, or zeros of `v`'s shape if the sweep never reached it.
    pub fn get_or_zeros(&self, tape: &Tape<F>, v: Var) -> Result<ArrayD<F>> {
        let shape = tape.shape(v)?.to_vec();
        Ok(self
            .get(v)
            .map(|g| g.to_owned())
            .unwrap_or_else(|| ArrayD::zeros(shape)))
    }

    /// Moves the gradient of `v` out of the store.
    pub fn take(&mut self, v: Var) -> Option<ArrayD<F>> {
        if v.epoch != self.epoch {
            return None;
        }
        self.grads.get_mut(v.index()).and_then(Option::take)
    }

    /// Adds `g` into the entry at `index`: the first contribution is moved in, later ones are
    /// added in place (no zero-filled buffer is ever allocated).
    pub(crate) fn accumulate(&mut self, index: usize, g: ArrayD<F>) {
        match &mut self.grads[index] {
            slot @ None => *slot = Some(g),
            Some(acc) => {
                // Contiguous sums of one shape (a parameter's, from several ops) are added in
                // parallel chunks: they can be a whole grid, on the thread that runs the
                // backward while the others wait.
                let added_in_chunks = acc.shape() == g.shape()
                    && match (acc.as_slice_mut(), g.as_slice()) {
                        (Some(a), Some(b)) => {
                            zip2(a, b, |a, b| *a += b);
                            true
                        }
                        _ => false,
                    };
                if !added_in_chunks {
                    Zip::from(&mut *acc).and(&g).for_each(|a, &b| *a += b);
                }
                crate::pool::give(g.into_raw_vec_and_offset().0);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::Tape;
    use ndarray::Array1;

    #[test]
    fn contributions_to_a_large_value_add_up_exactly() {
        // Larger than one parallel chunk, reached by three paths: d/dx (sum x + sum x^2 +
        // sum x) = 2 + 2x, exact in f64 for these x.
        let n = 3 * (1 << 14) + 5;
        let mut t = Tape::<f64>::new();
        let x = t.param(Array1::from_shape_fn(n, |i| i as f64 * 0.25 - 100.0));
        let s1 = t.sum(x).unwrap();
        let sq = t.square(x).unwrap();
        let s2 = t.sum(sq).unwrap();
        let s3 = t.sum(x).unwrap();
        let s12 = t.add(s1, s2).unwrap();
        let total = t.add(s12, s3).unwrap();
        let g = t.backward(total).unwrap();
        let gx = g.get(x).unwrap();
        assert_eq!(gx.len(), n);
        for (i, &v) in gx.iter().enumerate() {
            assert_eq!(v, 2.0 + 2.0 * (i as f64 * 0.25 - 100.0), "element {i}");
        }
    }
}
