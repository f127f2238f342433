//! The op written with tape primitives only, in the direct pairwise form: the weights as the
//! composite's stable twin builds them (`exp` of the exclusive cumsum of `sigma delta`,
//! `-expm1(-sigma delta)`), every pair `i < j` of a ray gathered (`O(n^2)` per ray), the
//! pairwise term `2 sum_{i<j} w_i w_j (t_j - t_i)` and the own term `(1/3) sum w_i^2 delta_i`
//! summed per ray, and their mean: about twenty records and `n_r (n_r - 1) / 2` pairs a ray
//! instead of one record. It shares nothing with the fused op but the input checks, so the
//! fused op is checked against it.

use fogray_tape::{Float, Tape, TapeError, Var};

use crate::error::{Op, OpsError};
use ndarray::Array1;

use super::check::{check_shapes, check_values};
use super::config::DistortionLoss;

/// `v`'s value as a flat `[n]` vector.
fn values<F: Float>(tape: &Tape<F>, what: &'static str, v: Var, n: usize) -> Result<Vec<F>, TapeError> {
    let x = tape.value(v)?;
    if x.shape() != [n] {
        return Err(TapeError::from(OpsError::shape_of(
            Op::DistortionLoss,
            what,
            format!("[{n}] (the offsets end at {n})"),
            x.shape(),
        )));
    }
    Ok(x.iter().copied().collect())
}

/// Records `op`'s loss of `sigma`, `delta` and `t` (each `[n]`) with the tape's own ops, as
/// [`DistortionLoss::apply`] does in one: a 0-d value whose backward gives `dL/dsigma`.
/// `delta` and `t` are read as constants (detached), so that, as for the fused op, no gradient
/// flows to them.
///
/// Errors (the tape is unchanged): those of [`DistortionLoss::evaluate`] (the
/// [`OpsError`](crate::OpsError) inside [`TapeError::Op`]), a stale handle.
pub fn distortion_loss<F: Float>(
    tape: &mut Tape<F>,
    op: &DistortionLoss,
    sigma: Var,
    delta: Var,
    t: Var,
) -> Result<Var, TapeError> {
    let offsets = op.offsets();
    let (n, rays) = (op.samples(), op.rays());
    let shapes = [
        ("sigma", tape.shape(sigma)?.to_vec()),
        ("delta", tape.shape(delta)?.to_vec()),
        ("t", tape.shape(t)?.to_vec()),
    ];
    check_shapes(op.packing(), shapes.each_ref().map(|(w, s)| (*w, s.as_slice())))?;
    let t_values = values(tape, "t", t, n)?;
    check_values(
        op.packing(),
        &values(tape, "sigma", sigma, n)?,
        &values(tape, "delta", delta, n)?,
        &t_values,
    )?;
    if rays == 0 {
        // The mean over no ray is 0, as for the fused op.
        return Ok(tape.scalar(F::zero()));
    }

    // Every pair i < j of each ray, grouped by ray, and its distance t_j - t_i >= 0.
    let (mut first, mut second, mut distance) = (Vec::new(), Vec::new(), Vec::new());
    let mut pair_offsets = vec![0];
    for r in 0..rays {
        for j in offsets[r]..offsets[r + 1] {
            for i in offsets[r]..j {
                first.push(i);
                second.push(j);
                distance.push(F::lit(t_values[j].as_f64() - t_values[i].as_f64()));
            }
        }
        pair_offsets.push(first.len());
    }

    let delta = tape.detach(delta)?;
    let tau = tape.mul(sigma, delta)?;
    let before = tape.segment_exclusive_cumsum(tau, offsets)?;
    let minus_before = tape.neg(before)?;
    let transmittance = tape.exp(minus_before)?;
    let minus_tau = tape.neg(tau)?;
    let minus_alpha = tape.expm1(minus_tau)?;
    let alpha = tape.neg(minus_alpha)?;
    let w = tape.mul(transmittance, alpha)?;

    let w_first = tape.gather(w, &first)?;
    let w_second = tape.gather(w, &second)?;
    let distance = tape.constant(Array1::from_vec(distance));
    let products = tape.mul(w_first, w_second)?;
    let pair_terms = tape.mul(products, distance)?;
    let pairs = tape.segment_sum(pair_terms, &pair_offsets)?;
    let pairs = tape.mul_scalar(pairs, F::lit(2.0))?;

    let w_squared = tape.square(w)?;
    let own_terms = tape.mul(w_squared, delta)?;
    let own = tape.segment_sum(own_terms, offsets)?;
    let own = tape.div_scalar(own, F::lit(3.0))?;

    let per_ray = tape.add(pairs, own)?;
    tape.mean(per_ray)
}
