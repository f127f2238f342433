//! `fogray gradcheck`: the fused op's gradient, computed in the input's precision, against the
//! stable taped twin's (f64, every element) and against finite differences of the fused op
//! (f64: every element, or random directions with `--fast`), each comparison judged by
//! `|fused - reference| <= atol + rtol |reference|`.
//!
//! Finite differences are taken per ray in full mode (a ray's samples only move its own
//! outputs: the cost is the sum of the squared ray lengths, not the square of their total,
//! and the rounding of the differences scales with one ray's loss, not the batch's).
//! Densities and steps live on `[0, inf)`: within a step of 0 the differences are one-sided.

mod problem;
mod subject;
mod tally;

use fogray_tape::gradcheck::{GradcheckOptions, GradcheckReport};
use fogray_tape::Float;
use rayon::prelude::*;
use serde_json::json;

use super::evaluate::{evaluate, CompositeMethod, InputGrads, Upstream, Wanted};
use super::input::{Packed, Precision};
use crate::error::CliError;
use problem::{batch_problem, check_in, options, ray_problem};
use tally::{Against, Comparison, Place, Tally};

/// Default `(atol, rtol)` for f64 inputs: the finite differences' own error (step 1e-6,
/// rounding about 1e-10 of a ray's loss, truncation about 1e-12) with margin.
pub const F64_TOLERANCE: (f64, f64) = (1e-6, 1e-5);
/// Default `(atol, rtol)` for f32 inputs: f32 rounding (6e-8) of the terms of each gradient,
/// with margin for their cancellation.
pub const F32_TOLERANCE: (f64, f64) = (1e-4, 1e-3);

/// The step of `--fast` along its unit-norm directions.
const FAST_STEP: f64 = 1e-5;

/// The inputs of the op, in its order, as the report names them.
const NAMES: [&str; 5] = ["sigma", "delta", "color", "background", "t"];

/// What the command line asks for.
#[derive(Debug, Clone)]
pub struct Settings {
    /// `None`: the precision's default.
    pub atol: Option<f64>,
    pub rtol: Option<f64>,
    pub fast: bool,
    pub projections: usize,
    pub seed: u64,
    pub json: bool,
    /// How many of the worst comparisons to print.
    pub worst: usize,
}

/// The report, and whether every comparison was within the tolerance.
#[derive(Debug)]
pub struct Outcome {
    pub text: String,
    pub passed: bool,
}

/// The upstream gradients of the loss, with a note for each one defaulted to ones.
struct Loss {
    color: Vec<f64>,
    /// `[R]` when any ray gives t: ones where t is given without grad_depth, 0 without t.
    depth: Option<Vec<f64>>,
    notes: Vec<String>,
}

fn rays_list(rays: &[usize]) -> String {
    let shown: Vec<String> = rays.iter().take(5).map(usize::to_string).collect();
    let more = if rays.len() > 5 { ", ..." } else { "" };
    format!("{} of the rays ({}{more})", rays.len(), shown.join(", "))
}

fn loss(p: &Packed) -> Loss {
    let (rays, ch) = (p.offsets.len() - 1, p.ch);
    let mut notes = Vec::new();
    let mut color = p.grad_color.clone().unwrap_or_else(|| vec![0.0; rays * ch]);
    let missing: Vec<usize> = (0..rays)
        .filter(|&r| p.grad_color.is_none() || !p.has_grad[r])
        .collect();
    for &r in &missing {
        color[r * ch..(r + 1) * ch].fill(1.0);
    }
    if !missing.is_empty() {
        notes.push(format!("grad_color not given: ones for {}", rays_list(&missing)));
    }
    let depth = p.t.as_ref().map(|_| {
        let missing: Vec<usize> = (0..rays)
            .filter(|&r| p.has_t[r] && !p.has_grad_depth.get(r).copied().unwrap_or(false))
            .collect();
        if !missing.is_empty() {
            notes.push(format!("grad_depth not given: ones for {}", rays_list(&missing)));
        }
        (0..rays)
            .map(|r| match (&p.grad_depth, p.has_t[r]) {
                (_, false) => 0.0,
                (Some(g), true) if p.has_grad_depth[r] => g[r],
                _ => 1.0,
            })
            .collect()
    });
    if p.t.is_none() {
        notes.push("no ray gives t: the depth and t are not checked".into());
    }
    Loss { color, depth, notes }
}

/// The input's values as the precision sees them, so that f32 and f64 work at one point.
fn round_to(p: &mut Packed) {
    if p.precision == Precision::F32 {
        let round = |v: &mut Vec<f64>| v.iter_mut().for_each(|x| *x = f64::from(*x as f32));
        for v in [&mut p.sigma, &mut p.delta, &mut p.color, &mut p.background] {
            round(v);
        }
        if let Some(t) = p.t.as_mut() {
            round(t);
        }
    }
}

fn widen<F: Float>(g: InputGrads<F>) -> InputGrads<f64> {
    let w = |v: Vec<F>| v.into_iter().map(Float::as_f64).collect();
    InputGrads {
        sigma: w(g.sigma),
        delta: w(g.delta),
        color: w(g.color),
        background: w(g.background),
        t: g.t.map(w),
    }
}

fn gradients<F: Float>(p: &Packed, method: CompositeMethod, l: &Loss) -> Result<InputGrads<f64>, CliError> {
    let want = Wanted {
        per_sample: false,
        grads: Some(Upstream {
            color: &l.color,
            depth: l.depth.as_deref(),
        }),
    };
    evaluate::<F>(p, method, want)?
        .grads
        .map(widen)
        .ok_or(CliError::Missing("no gradient"))
}

/// Every element of `fused` against `reference`.
fn elementwise(p: &Packed, fused: &InputGrads<f64>, reference: &InputGrads<f64>, tally: &mut Tally) {
    let ch = p.ch;
    let mut add = |input, place, a: f64, b: f64| {
        tally.add(Comparison {
            against: Against::Twin,
            input,
            place,
            fused: a,
            reference: b,
            one_sided: false,
        })
    };
    for (r, w) in p.offsets.windows(2).enumerate() {
        for k in w[0]..w[1] {
            let at = |channel| Place::Element {
                ray: r,
                sample: Some(k - w[0]),
                channel,
            };
            add("sigma", at(None), fused.sigma[k], reference.sigma[k]);
            add("delta", at(None), fused.delta[k], reference.delta[k]);
            for c in 0..ch {
                add(
                    "color",
                    at(Some(c)),
                    fused.color[k * ch + c],
                    reference.color[k * ch + c],
                );
            }
            if let (true, Some(a), Some(b)) = (p.has_t[r], &fused.t, &reference.t) {
                add("t", at(None), a[k], b[k]);
            }
        }
        for c in 0..ch {
            let at = Place::Element {
                ray: r,
                sample: None,
                channel: Some(c),
            };
            add(
                "background",
                at,
                fused.background[r * ch + c],
                reference.background[r * ch + c],
            );
        }
    }
}

/// Full mode: every element of every ray, ray by ray.
fn per_ray(p: &Packed, l: &Loss, tally: &mut Tally) -> Result<(), CliError> {
    let reports: Vec<GradcheckReport> = (0..p.offsets.len() - 1)
        .into_par_iter()
        .map(|r| {
            let problem = ray_problem(p, l, r)?;
            check_in(p.precision, &problem, &options(problem.inputs.len()))
        })
        .collect::<Result<_, _>>()?;
    for (ray, report) in reports.into_iter().enumerate() {
        for e in report.entries {
            let i = e.input.unwrap_or(0);
            let place = Place::Element {
                ray,
                sample: (i != 3).then(|| e.index[0]),
                channel: matches!(i, 2 | 3).then(|| e.index[1]),
            };
            tally.add(Comparison {
                against: Against::FiniteDifferences,
                input: NAMES[i],
                place,
                fused: e.analytic,
                reference: e.numeric,
                one_sided: e.difference.one_sided(),
            });
        }
    }
    Ok(())
}

/// Fast mode: random directions through every input at once.
fn directions(p: &mut Packed, l: &Loss, s: &Settings, tally: &mut Tally) -> Result<(), CliError> {
    let precision = p.precision;
    let problem = batch_problem(p, l)?;
    let opts = GradcheckOptions {
        fast: true,
        // A unit direction spreads the step over every element: the curvature along it does
        // not grow with the sample count, but the rounding of a long ray's sums does, and a
        // step of 1e-6 turns that rounding into differences near the f64 tolerance.
        eps: FAST_STEP,
        projections: s.projections,
        seed: s.seed,
        ..options(problem.inputs.len())
    };
    let report = check_in(precision, &problem, &opts)?;
    for e in report.entries {
        tally.add(Comparison {
            against: Against::FiniteDifferences,
            input: "all inputs",
            place: Place::Direction(e.index[0]),
            fused: e.analytic,
            reference: e.numeric,
            one_sided: e.difference.one_sided(),
        });
    }
    Ok(())
}

/// Warns (on stderr) when full mode will take long: it costs the squared ray lengths.
fn warn_if_slow(p: &Packed) {
    let work: f64 = p
        .offsets
        .windows(2)
        .map(|w| ((w[1] - w[0]) as f64).powi(2) * (p.ch + 3) as f64)
        .sum();
    if work > 1e10 {
        eprintln!(
            "fogray gradcheck: warning: full mode evaluates each ray once per element (about {work:.1e} sample evaluations here); --fast checks random directions in time linear in the samples"
        );
    }
}

/// Checks `p` as `s` asks; `Err` (exit status 2) for input or settings it cannot check.
pub fn run(p: Packed, s: &Settings) -> Result<Outcome, CliError> {
    check_with(p, s, &|_| {})
}

/// [`run`], with the fused gradient passed through `tamper` before it is compared (the tests'
/// deliberately wrong backward).
fn check_with(mut p: Packed, s: &Settings, tamper: &dyn Fn(&mut InputGrads<f64>)) -> Result<Outcome, CliError> {
    let (default_atol, default_rtol) = match p.precision {
        Precision::F32 => F32_TOLERANCE,
        Precision::F64 => F64_TOLERANCE,
    };
    let (atol, rtol) = (s.atol.unwrap_or(default_atol), s.rtol.unwrap_or(default_rtol));
    for (flag, v) in [("--atol", atol), ("--rtol", rtol)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(CliError::Flag {
                flag,
                value: None,
                rule: format!("must be finite and >= 0, got {v}"),
            });
        }
    }
    if s.fast && s.projections == 0 {
        return Err(CliError::Flag {
            flag: "--projections",
            value: None,
            rule: "must be at least 1".into(),
        });
    }
    round_to(&mut p);
    let l = loss(&p);
    let mut fused = match p.precision {
        Precision::F32 => gradients::<f32>(&p, CompositeMethod::Fused, &l)?,
        Precision::F64 => gradients::<f64>(&p, CompositeMethod::Fused, &l)?,
    };
    tamper(&mut fused);
    let mut tally = Tally::new(atol, rtol, s.worst);
    let mut notes = l.notes.clone();
    if p.min_transmittance == 0.0 {
        let twin = gradients::<f64>(&p, CompositeMethod::Taped, &l)?;
        elementwise(&p, &fused, &twin, &mut tally);
    } else {
        notes.push("min_transmittance > 0: no taped twin to compare with (the twins are exact)".into());
    }
    drop(fused);
    if s.fast {
        directions(&mut p, &l, s, &mut tally)?;
    } else {
        warn_if_slow(&p);
        per_ray(&p, &l, &mut tally)?;
    }
    let precision = match p.precision {
        Precision::F32 => "f32",
        Precision::F64 => "f64",
    };
    let tolerance_source = match (s.atol, s.rtol) {
        (None, None) => format!("the {precision} defaults"),
        (Some(_), Some(_)) => "as given".into(),
        _ => format!("given, else the {precision} default"),
    };
    let mode = if s.fast {
        format!(
            "{} random directions through every input (seed {}): central through the elements a step leaves at or above 0, one-sided and inward through the rest",
            s.projections, s.seed
        )
    } else {
        "every element, ray by ray, one-sided where sigma or delta is within a step of 0".into()
    };
    let text = if s.json {
        let mut v = tally.json();
        v["precision"] = json!(precision);
        v["mode"] = json!(if s.fast { "fast" } else { "full" });
        v["notes"] = json!(notes);
        serde_json::to_string_pretty(&v)?
    } else {
        let mut out = format!(
            "fogray gradcheck: the fused op's gradient in {precision} against the stable taped twin (f64, every element) and finite differences of the fused op (f64, {mode})\n"
        );
        out += "loss: L = sum(grad_color . color) + sum(grad_depth depth)\n";
        for note in &notes {
            out += &format!("note: {note}\n");
        }
        out += &format!(
            "tolerance: |fused - reference| <= atol + rtol |reference|, atol {atol:e}, rtol {rtol:e} ({tolerance_source})\n\n"
        );
        out + &tally.text()
    };
    Ok(Outcome {
        text,
        passed: tally.passed(),
    })
}

#[cfg(test)]
mod tests;
