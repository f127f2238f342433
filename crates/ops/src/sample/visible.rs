//! Early termination before the render: the samples a ray still sees.
//!
//! Behind an opaque surface a ray's transmittance is nearly 0 and its samples add nearly
//! nothing to the pixel or to any gradient, yet a training step would look each of them up
//! and scatter its (nearly zero) gradient into the field. Given the densities of a cheap
//! first pass (a forward lookup, no tape), [`PackedSamples::visible`] drops them, so the
//! expensive differentiable pass runs only where the ray still sees something.

use fogray_tape::{Float, Offsets};
use ndarray::{Array1, Array2, ArrayView1};

use super::packed::PackedSamples;
use crate::error::{At, Op, OpsError};

impl<F: Float> PackedSamples<F> {
    /// The samples of each ray up to the last one whose transmittance on arrival,
    /// `T_k = exp(-sum_{j<k} sigma_j delta_j)`, is at least `min_transmittance`; the rest of
    /// the ray is dropped. Every ray keeps its range (possibly shorter), in order.
    ///
    /// The kept samples composite to the full render up to `min_transmittance` times the
    /// largest colour (the light the dropped part could add), and their gradients are those
    /// of that truncated render. The optical depth is accumulated in f64 and compared with
    /// `ln(1 / min_transmittance)`, so no exponential is evaluated and f32 densities lose
    /// nothing to rounding over long rays.
    ///
    /// Expects `sigma` `[n]`, one finite non-negative density per sample (for example the
    /// field's density at [`PackedSamples::positions`]), and `min_transmittance` in `[0, 1)`
    /// (0 keeps every sample).
    ///
    /// Errors: `sigma` of the wrong length, a negative or non-finite density (naming its
    /// ray), `min_transmittance` outside `[0, 1)`. `self` is never changed.
    pub fn visible(&self, sigma: ArrayView1<'_, F>, min_transmittance: f64) -> Result<Self, OpsError> {
        if !(0.0..1.0).contains(&min_transmittance) {
            return Err(OpsError::Config {
                op: Op::Sample,
                what: "min_transmittance",
                value: min_transmittance,
                rule: "must be in [0, 1)",
            });
        }
        if sigma.len() != self.len() {
            return Err(OpsError::Shape {
                op: Op::Sample,
                what: "sigma",
                expected: format!("one density per sample ({})", self.len()),
                got: format!("{}", sigma.len()),
            });
        }
        let max_depth = if min_transmittance == 0.0 {
            f64::INFINITY
        } else {
            -min_transmittance.ln()
        };
        let mut kept = Vec::with_capacity(self.len());
        let mut lengths = Vec::with_capacity(self.rays());
        for (r, range) in self.offsets.ranges().enumerate() {
            let before = kept.len();
            let mut depth = 0.0f64;
            let start = range.start;
            for k in range {
                let s = sigma[k].as_f64();
                if !(s.is_finite() && s >= 0.0) {
                    return Err(OpsError::domain(
                        Op::Sample,
                        At::Sample {
                            ray: r,
                            sample: k - start,
                        },
                        "sigma",
                        s,
                        "must be finite and non-negative",
                    ));
                }
                if depth > max_depth {
                    continue; // keep scanning: every density is still checked
                }
                kept.push(k);
                depth += s * self.delta[k].as_f64();
            }
            lengths.push(kept.len() - before);
        }
        Ok(PackedSamples {
            // A direct copy: ndarray's `select` concatenates one view per kept row.
            positions: Array2::from_shape_fn((kept.len(), 3), |(i, c)| self.positions[[kept[i], c]]),
            t: Array1::from_iter(kept.iter().map(|&k| self.t[k])),
            delta: Array1::from_iter(kept.iter().map(|&k| self.delta[k])),
            offsets: Offsets::from_lengths(lengths),
            ray: kept.iter().map(|&k| self.ray[k]).collect(),
        })
    }
}
