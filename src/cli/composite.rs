//! `fogray composite`: JSON in, JSON out (design.md §4; scripts depend on the format).

use fogray_tape::Float;
use serde::Serialize;

use super::evaluate::{evaluate, Method};
use super::input::{Packed, Precision};

/// One ray of the output. Numbers are written in the computing precision's shortest form.
#[derive(Debug, Serialize)]
struct RayOut<F> {
    color: Vec<F>,
    opacity: F,
    depth: Option<F>,
    weights: Vec<F>,
    transmittance: Vec<F>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_sigma: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_delta: Option<Vec<F>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_color: Option<Vec<Vec<F>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    grad_background: Option<Vec<F>>,
}

#[derive(Debug, Serialize)]
struct Output<F> {
    rays: Vec<RayOut<F>>,
}

fn split<F: Float + Serialize>(p: &Packed, method: Method) -> Result<String, String> {
    let e = evaluate::<F>(p, method, None)?;
    let ch = p.ch;
    let rays = (0..p.offsets.len() - 1)
        .map(|r| {
            let s = p.offsets[r]..p.offsets[r + 1];
            let grads = e.grads.as_ref().filter(|_| p.has_grad[r]);
            RayOut {
                color: e.color[r * ch..(r + 1) * ch].to_vec(),
                opacity: e.opacity[r],
                depth: e.depth.as_ref().filter(|_| p.has_t[r]).map(|d| d[r]),
                weights: e.weights[s.clone()].to_vec(),
                transmittance: e.transmittance[s.clone()].to_vec(),
                grad_sigma: grads.map(|g| g.sigma[s.clone()].to_vec()),
                grad_delta: grads.map(|g| g.delta[s.clone()].to_vec()),
                grad_color: grads.map(|g| {
                    g.color[s.start * ch..s.end * ch]
                        .chunks(ch)
                        .map(<[F]>::to_vec)
                        .collect()
                }),
                grad_background: grads.map(|g| g.background[r * ch..(r + 1) * ch].to_vec()),
            }
        })
        .collect();
    serde_json::to_string(&Output { rays }).map_err(|e| e.to_string())
}

/// The output JSON for the input, or the one-line reason it cannot be computed.
pub fn run(p: &Packed, method: Method) -> Result<String, String> {
    match p.precision {
        Precision::F32 => split::<f32>(p, method),
        Precision::F64 => split::<f64>(p, method),
    }
}
