//! Validation of the op's inputs: shapes against the packing, then values (densities finite
//! and non-negative, steps finite and positive, midpoints finite and non-decreasing along each
//! ray). The rays are checked in parallel over the kernel's fixed chunks, and the first fault
//! in sample order is the one reported, whatever the number of threads.

use fogray_tape::{Float, Offsets};
use rayon::prelude::*;

use super::kernel::RAYS_PER_CHUNK;
use crate::error::{At, Op, OpsError};

/// Checks that `sigma`, `delta` and `t` (given by their shapes) are each `[n]`, `n` the
/// packing's number of samples.
pub(crate) fn check_shapes(offsets: &Offsets, shapes: [(&'static str, &[usize]); 3]) -> Result<(), OpsError> {
    let n = offsets.rows();
    for (what, shape) in shapes {
        if shape != [n] {
            return Err(OpsError::shape_of(
                Op::DistortionLoss,
                what,
                format!("[{n}] (the offsets end at {n})"),
                shape,
            ));
        }
    }
    Ok(())
}

/// The first fault of ray `r` (samples `range`), by sample: its density, then its step, then
/// its midpoint (not finite, or below the previous one).
fn ray_fault<F: Float>(r: usize, start: usize, end: usize, sigma: &[F], delta: &[F], t: &[F]) -> Option<OpsError> {
    let bad = |k: usize, what: &str, value: F, rule: &'static str| {
        OpsError::domain(
            Op::DistortionLoss,
            At::Sample {
                ray: r,
                sample: k - start,
            },
            what,
            value.as_f64(),
            rule,
        )
    };
    for k in start..end {
        let (s, d, tk) = (sigma[k], delta[k], t[k]);
        if !(s.is_finite() && s >= F::zero()) {
            return Some(bad(k, "sigma", s, "density must be finite and >= 0"));
        }
        if !(d.is_finite() && d > F::zero()) {
            return Some(bad(k, "delta", d, "interval length must be finite and > 0"));
        }
        if !tk.is_finite() {
            return Some(bad(k, "t", tk, "must be finite"));
        }
        if k > start && tk < t[k - 1] {
            return Some(bad(
                k,
                "t",
                tk,
                "midpoints must not decrease along a ray (below the previous sample's)",
            ));
        }
    }
    None
}

/// Checks the values of the (shape-checked) flat inputs; the error names the first ray and
/// sample at fault.
pub(crate) fn check_values<F: Float>(offsets: &Offsets, sigma: &[F], delta: &[F], t: &[F]) -> Result<(), OpsError> {
    let rays = offsets.segments();
    let starts: Vec<usize> = (0..rays).step_by(RAYS_PER_CHUNK).collect();
    let fault = starts.par_iter().find_map_first(|&r0| {
        (r0..(r0 + RAYS_PER_CHUNK).min(rays)).find_map(|r| ray_fault(r, offsets[r], offsets[r + 1], sigma, delta, t))
    });
    match fault {
        Some(e) => Err(e),
        None => Ok(()),
    }
}
