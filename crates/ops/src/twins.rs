//! The composite written with tape primitives only: the references the fused op is checked
//! against, and the baselines it is measured against.
//!
//! - [`stable`]: `T = exp(-segment_exclusive_cumsum(sigma delta))`, `alpha = -expm1(-sigma delta)`,
//!   `opacity = -expm1(-total)`: the fused op's numerics, one tape node per step.
//! - [`naive`]: `alpha = 1 - exp(-sigma delta)`, `T = segment_exclusive_cumprod(1 - alpha)`,
//!   background weight `1 - sum w`: how most NeRF code writes it. Kept to measure what it loses.
//!
//! Both take the same [`Composite`] configuration and inputs as the fused op and return the
//! same outputs; early termination is not offered (a threshold other than 0 is an error).

use fogray_tape::{Float, Tape, TapeError, Var};

use crate::composite::{validate, Background, Composite, CompositeArrays, CompositeInputs, CompositeVars};

fn invalid(reason: &str) -> TapeError {
    TapeError::InvalidArgument {
        op: "composite_twin",
        reason: reason.into(),
    }
}

/// The same checks as the fused op (shapes, packing, finite non-negative densities and
/// steps...), so that both paths reject exactly the same inputs.
fn check<F: Float>(tape: &Tape<F>, op: &Composite, inputs: &CompositeInputs) -> Result<(), TapeError> {
    if op.min_transmittance != 0.0 {
        return Err(invalid("the taped twins are exact: min_transmittance must be 0"));
    }
    if (op.background == Background::None) != inputs.background.is_none() {
        return Err(invalid("background input does not match the configuration"));
    }
    if op.depth != inputs.t.is_some() {
        return Err(invalid("t input does not match the depth option"));
    }
    let optional = |v: Option<Var>| v.map(|v| tape.value(v)).transpose();
    let arrays = CompositeArrays {
        sigma: tape.value(inputs.sigma)?,
        delta: tape.value(inputs.delta)?,
        color: tape.value(inputs.color)?,
        background: optional(inputs.background)?,
        t: optional(inputs.t)?,
    };
    validate(op, &arrays).map(|_| ()).map_err(|e| invalid(&e.to_string()))
}

/// The colour and the optional depth, weights and transmittance shared by both forms, given
/// the per-sample weights `w`, the transmittance `T`, the ray's end transmittance `T_end` and
/// the opacity.
fn finish<F: Float>(
    tape: &mut Tape<F>,
    op: &Composite,
    inputs: &CompositeInputs,
    per_sample: (Var, Var),
    per_ray: (Var, Var),
) -> Result<CompositeVars, TapeError> {
    let ((w, transmittance), (t_end, opacity)) = (per_sample, per_ray);
    let offsets = op.offsets();
    let (n, rays) = (op.samples(), op.rays());
    let w_col = tape.reshape(w, &[n, 1])?;
    let wc = tape.mul(w_col, inputs.color)?;
    let mut color = tape.segment_sum(wc, offsets)?;
    if let Some(bg) = inputs.background {
        let t_end_col = tape.reshape(t_end, &[rays, 1])?;
        let seen = tape.mul(t_end_col, bg)?;
        color = tape.add(color, seen)?;
    }
    let depth = match inputs.t {
        Some(t) => {
            let wt = tape.mul(w, t)?;
            Some(tape.segment_sum(wt, offsets)?)
        }
        None => None,
    };
    Ok(CompositeVars {
        color,
        opacity,
        depth,
        weights: op.weights.then_some(w),
        transmittance: op.transmittance.then_some(transmittance),
    })
}

/// The stable taped composite: transmittance from the running optical depth, `-expm1` for
/// alpha and opacity. Same configuration, inputs and outputs as [`Composite::apply`].
pub fn stable<F: Float>(
    tape: &mut Tape<F>,
    op: &Composite,
    inputs: &CompositeInputs,
) -> Result<CompositeVars, TapeError> {
    check(tape, op, inputs)?;
    let offsets = op.offsets();
    let tau = tape.mul(inputs.sigma, inputs.delta)?;
    let before = tape.segment_exclusive_cumsum(tau, offsets)?;
    let minus_before = tape.neg(before)?;
    let transmittance = tape.exp(minus_before)?;
    let minus_tau = tape.neg(tau)?;
    let minus_alpha = tape.expm1(minus_tau)?;
    let alpha = tape.neg(minus_alpha)?;
    let w = tape.mul(transmittance, alpha)?;
    let total = tape.segment_sum(tau, offsets)?;
    let minus_total = tape.neg(total)?;
    let t_end = tape.exp(minus_total)?;
    let minus_opacity = tape.expm1(minus_total)?;
    let opacity = tape.neg(minus_opacity)?;
    finish(tape, op, inputs, (w, transmittance), (t_end, opacity))
}

/// The naive taped composite: `alpha = 1 - exp(-sigma delta)`, transmittance as the
/// cumulative product of `1 - alpha`, background weight `1 - sum w`.
pub fn naive<F: Float>(
    tape: &mut Tape<F>,
    op: &Composite,
    inputs: &CompositeInputs,
) -> Result<CompositeVars, TapeError> {
    check(tape, op, inputs)?;
    let offsets = op.offsets();
    let tau = tape.mul(inputs.sigma, inputs.delta)?;
    let minus_tau = tape.neg(tau)?;
    let survive = tape.exp(minus_tau)?;
    let alpha = tape.rsub_scalar(survive, F::one())?;
    let one_minus_alpha = tape.rsub_scalar(alpha, F::one())?;
    let transmittance = tape.segment_exclusive_cumprod(one_minus_alpha, offsets)?;
    let w = tape.mul(transmittance, alpha)?;
    let opacity = tape.segment_sum(w, offsets)?;
    let t_end = tape.rsub_scalar(opacity, F::one())?;
    finish(tape, op, inputs, (w, transmittance), (t_end, opacity))
}
