//! `fogray composite`: JSON in, JSON out (the format `fogray composite --help` documents;
//! scripts depend on it), every field or only those asked for.

use fogray_tape::Float;
use serde::Serialize;

use super::error::CliError;
use super::evaluate::{evaluate, CompositeMethod, Upstream, Wanted};
use super::input::{Packed, Precision};

/// A field of a ray's output, named as in the JSON.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Field {
    /// Pixel colour.
    #[value(name = "color")]
    Color,
    /// `1 - T_end`.
    #[value(name = "opacity")]
    Opacity,
    /// Unnormalised expected depth (null without t).
    #[value(name = "depth")]
    Depth,
    /// Per-sample weights.
    #[value(name = "weights")]
    Weights,
    /// Per-sample transmittance.
    #[value(name = "transmittance")]
    Transmittance,
    /// dL/dsigma per sample.
    #[value(name = "grad_sigma")]
    GradSigma,
    /// dL/ddelta per sample.
    #[value(name = "grad_delta")]
    GradDelta,
    /// dL/dcolor per sample.
    #[value(name = "grad_color")]
    GradColor,
    /// dL/dbackground of the ray.
    #[value(name = "grad_background")]
    GradBackground,
    /// dL/dt per sample (rays that give grad_depth).
    #[value(name = "grad_t")]
    GradT,
}

impl Field {
    /// Every field, in output order: the default.
    pub const ALL: [Field; 10] = [
        Field::Color,
        Field::Opacity,
        Field::Depth,
        Field::Weights,
        Field::Transmittance,
        Field::GradSigma,
        Field::GradDelta,
        Field::GradColor,
        Field::GradBackground,
        Field::GradT,
    ];
    /// The fields with one value (or one colour) per ray, whatever the ray's length.
    pub const PER_RAY: [Field; 4] = [Field::Color, Field::Opacity, Field::Depth, Field::GradBackground];
}

/// One ray of the output. Numbers are written in the computing precision's shortest form;
/// a field that was not asked for is left out.
#[derive(Debug, Serialize)]
struct RayOut<F> {
    #[serde(skip_serializing_if = "Option::is_none")]
    color: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    opacity: Option<F>,
    /// `Some(None)` prints `null` (a ray without t).
    #[serde(skip_serializing_if = "Option::is_none")]
    depth: Option<Option<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    weights: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    transmittance: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_sigma: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_delta: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_color: Option<Vec<Vec<F>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_background: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_t: Option<Vec<F>>,
}

#[derive(Debug, Serialize)]
struct Output<F> {
    rays: Vec<RayOut<F>>,
}

fn split<F: Float + Serialize>(p: &Packed, method: CompositeMethod, fields: &[Field]) -> Result<String, CliError> {
    let on = |f: Field| fields.contains(&f);
    let per_sample = on(Field::Weights) || on(Field::Transmittance);
    let any_grad = [
        Field::GradSigma,
        Field::GradDelta,
        Field::GradColor,
        Field::GradBackground,
        Field::GradT,
    ]
    .into_iter()
    .any(on);
    let zeros;
    let upstream = if any_grad && (p.grad_color.is_some() || p.grad_depth.is_some()) {
        let color = match &p.grad_color {
            Some(g) => &g[..],
            None => {
                zeros = vec![0.0; (p.offsets.len() - 1) * p.ch];
                &zeros[..]
            }
        };
        Some(Upstream {
            color,
            depth: p.grad_depth.as_deref(),
        })
    } else {
        None
    };
    let e = evaluate::<F>(
        p,
        method,
        Wanted {
            per_sample,
            grads: upstream,
        },
    )?;
    let ch = p.ch;
    let pick = |f: Field, v: Option<&Vec<F>>, s: std::ops::Range<usize>| v.filter(|_| on(f)).map(|v| v[s].to_vec());
    let rays = (0..p.offsets.len() - 1)
        .map(|r| {
            let s = p.offsets[r]..p.offsets[r + 1];
            let grads = e.grads.as_ref().filter(|_| p.has_grad[r] || p.has_grad_depth[r]);
            let grad = |f: Field, v: fn(&super::evaluate::InputGrads<F>) -> &Vec<F>, s| {
                grads.and_then(|g| pick(f, Some(v(g)), s))
            };
            RayOut {
                color: pick(Field::Color, Some(&e.color), r * ch..(r + 1) * ch),
                opacity: on(Field::Opacity).then(|| e.opacity[r]),
                depth: on(Field::Depth).then(|| e.depth.as_ref().filter(|_| p.has_t[r]).map(|d| d[r])),
                weights: pick(Field::Weights, e.weights.as_ref(), s.clone()),
                transmittance: pick(Field::Transmittance, e.transmittance.as_ref(), s.clone()),
                grad_sigma: grad(Field::GradSigma, |g| &g.sigma, s.clone()),
                grad_delta: grad(Field::GradDelta, |g| &g.delta, s.clone()),
                grad_color: grad(Field::GradColor, |g| &g.color, s.start * ch..s.end * ch)
                    .map(|c| c.chunks(ch).map(<[F]>::to_vec).collect()),
                grad_background: grad(Field::GradBackground, |g| &g.background, r * ch..(r + 1) * ch),
                grad_t: grads
                    .filter(|_| p.has_grad_depth[r])
                    .and_then(|g| pick(Field::GradT, g.t.as_ref(), s.clone())),
            }
        })
        .collect();
    Ok(serde_json::to_string(&Output { rays })?)
}

/// The output JSON for the input with the fields asked for (in output order, whatever the
/// order given), or the one-line reason it cannot be computed.
pub fn run(p: &Packed, method: CompositeMethod, fields: &[Field]) -> Result<String, CliError> {
    match p.precision {
        Precision::F32 => split::<f32>(p, method, fields),
        Precision::F64 => split::<f64>(p, method, fields),
    }
}
