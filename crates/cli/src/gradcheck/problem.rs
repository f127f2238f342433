//! The finite-difference side of `fogray gradcheck`: the fused op over one ray (full mode) or
//! every ray (fast mode) as a function of its inputs, and the library's check of it.

use fogray_ops::{Background, Composite};
use fogray_tape::gradcheck::{gradcheck, Domain, GradcheckOptions, GradcheckReport};
use fogray_tape::Float;
use ndarray::{Array1, Array2, ArrayD};

use super::super::input::{Packed, Precision};
use super::{subject, Loss, NAMES};
use crate::error::CliError;

pub(super) fn options(inputs: usize) -> GradcheckOptions {
    GradcheckOptions {
        names: NAMES[..inputs].iter().map(|s| s.to_string()).collect(),
        domains: vec![Domain::at_least(0.0), Domain::at_least(0.0)],
        ..Default::default()
    }
}

/// The op over `offsets` with a per-ray background, and its inputs from the packed slices.
pub(super) struct Problem {
    op: Composite,
    pub(super) inputs: Vec<ArrayD<f64>>,
    color: ArrayD<f64>,
    depth: Option<ArrayD<f64>>,
}

/// Ray `r` alone (full mode) as a problem.
pub(super) fn ray_problem(p: &Packed, l: &Loss, r: usize) -> Result<Problem, CliError> {
    let (s, ch) = (p.offsets[r]..p.offsets[r + 1], p.ch);
    let mut op = per_ray_op(&[0, s.len()], p.min_transmittance)?;
    let mut inputs = vec![
        Array1::from(p.sigma[s.clone()].to_vec()).into_dyn(),
        Array1::from(p.delta[s.clone()].to_vec()).into_dyn(),
        Array2::from_shape_vec((s.len(), ch), p.color[s.start * ch..s.end * ch].to_vec())?.into_dyn(),
        Array2::from_shape_vec((1, ch), p.background[r * ch..(r + 1) * ch].to_vec())?.into_dyn(),
    ];
    let mut depth = None;
    if let (Some(t), Some(gd), true) = (&p.t, &l.depth, p.has_t[r]) {
        op = op.with_depth();
        inputs.push(Array1::from(t[s.clone()].to_vec()).into_dyn());
        depth = Some(Array1::from(vec![gd[r]]).into_dyn());
    }
    let color = Array2::from_shape_vec((1, ch), l.color[r * ch..(r + 1) * ch].to_vec())?.into_dyn();
    Ok(Problem {
        op,
        inputs,
        color,
        depth,
    })
}

/// The composite over `offsets` with a background per ray, as the input gives it.
fn per_ray_op(offsets: &[usize], min_transmittance: f64) -> Result<Composite, CliError> {
    Ok(Composite::new(offsets)?
        .background(Background::PerRay)
        .min_transmittance(min_transmittance)?)
}

/// Every ray at once (fast mode), moving the values out of `p`.
pub(super) fn batch_problem(p: &mut Packed, l: &Loss) -> Result<Problem, CliError> {
    let (rays, n, ch) = (p.offsets.len() - 1, p.sigma.len(), p.ch);
    let mut op = per_ray_op(&p.offsets, p.min_transmittance)?;
    let take = std::mem::take;
    let mut inputs = vec![
        Array1::from(take(&mut p.sigma)).into_dyn(),
        Array1::from(take(&mut p.delta)).into_dyn(),
        Array2::from_shape_vec((n, ch), take(&mut p.color))?.into_dyn(),
        Array2::from_shape_vec((rays, ch), take(&mut p.background))?.into_dyn(),
    ];
    let mut depth = None;
    if let (Some(t), Some(gd)) = (p.t.take(), &l.depth) {
        op = op.with_depth();
        inputs.push(Array1::from(t).into_dyn());
        depth = Some(Array1::from(gd.clone()).into_dyn());
    }
    let color = Array2::from_shape_vec((rays, ch), l.color.clone())?.into_dyn();
    Ok(Problem {
        op,
        inputs,
        color,
        depth,
    })
}

fn check<S: Float>(problem: &Problem, opts: &GradcheckOptions) -> Result<GradcheckReport, CliError> {
    let Problem {
        op,
        inputs,
        color,
        depth,
    } = problem;
    Ok(gradcheck(
        |t, v| subject::loss::<S>(t, v, op, color, depth.as_ref()),
        inputs,
        opts,
    )?)
}

pub(super) fn check_in(
    precision: Precision,
    problem: &Problem,
    opts: &GradcheckOptions,
) -> Result<GradcheckReport, CliError> {
    match precision {
        Precision::F32 => check::<f32>(problem, opts),
        Precision::F64 => check::<f64>(problem, opts),
    }
}
