//! The JSON input of `fogray composite` and `fogray gradcheck` (the format `fogray composite
//! --help` documents), parsed and checked into packed arrays. Every problem is one line naming the ray and sample.

use serde::Deserialize;

use super::error::InputError;

/// One ray as the JSON gives it.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RayJson {
    sigma: Vec<f64>,
    delta: Vec<f64>,
    color: Vec<Vec<f64>>,
    background: Option<Vec<f64>>,
    t: Option<Vec<f64>>,
    grad_color: Option<Vec<f64>>,
    grad_depth: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct InputJson {
    precision: Option<String>,
    min_transmittance: Option<f64>,
    rays: Vec<RayJson>,
}

/// Which float type to compute in: the fit's own choice of float.
pub use fogray_fit::settings::Precision;

/// The input, packed: ray `r` owns samples `offsets[r]..offsets[r+1]`.
#[derive(Debug, Clone)]
pub struct Packed {
    pub precision: Precision,
    pub min_transmittance: f64,
    pub offsets: Vec<usize>,
    pub sigma: Vec<f64>,
    pub delta: Vec<f64>,
    /// `[n * ch]`.
    pub color: Vec<f64>,
    pub ch: usize,
    /// `[R * ch]`, zeros where a ray gives none.
    pub background: Vec<f64>,
    /// `[n]` when any ray gives `t` (zeros for the others), and which rays gave it.
    pub t: Option<Vec<f64>>,
    pub has_t: Vec<bool>,
    /// `[R * ch]` when any ray gives `grad_color` (zeros for the others), and which rays did.
    pub grad_color: Option<Vec<f64>>,
    pub has_grad: Vec<bool>,
    /// `[R]` when any ray gives `grad_depth` (zeros for the others), and which rays did.
    pub grad_depth: Option<Vec<f64>>,
    pub has_grad_depth: Vec<bool>,
}

fn check_finite(values: &[f64], precision: Precision, what: impl Fn(usize) -> String) -> Result<(), InputError> {
    for (i, &v) in values.iter().enumerate() {
        if !v.is_finite() {
            return Err(InputError::NotFinite { what: what(i) });
        }
        if precision == Precision::F32 && v.abs() > f64::from(f32::MAX) {
            return Err(InputError::OverflowsF32 {
                what: what(i),
                value: v,
            });
        }
    }
    Ok(())
}

/// Parses and checks the JSON text. Domain rules of the op itself (non-negative density and
/// step) are checked by the op, which names the ray and sample too.
pub fn parse(text: &str) -> Result<Packed, InputError> {
    let input: InputJson = serde_json::from_str(text).map_err(InputError::Json)?;
    let precision = match input.precision.as_deref() {
        None | Some("f64") => Precision::F64,
        Some("f32") => Precision::F32,
        Some(other) => return Err(InputError::UnknownPrecision(other.into())),
    };
    let min_transmittance = input.min_transmittance.unwrap_or(0.0);
    if !(0.0..=1.0).contains(&min_transmittance) {
        return Err(InputError::MinTransmittance(min_transmittance));
    }
    if input.rays.is_empty() {
        return Err(InputError::NoRays);
    }
    let ch = input
        .rays
        .iter()
        .find_map(|r| r.color.first().map(Vec::len).or(r.background.as_ref().map(Vec::len)))
        .unwrap_or(1);
    if ch == 0 {
        return Err(InputError::NoChannels);
    }
    let any_t = input.rays.iter().any(|r| r.t.is_some());
    let any_grad = input.rays.iter().any(|r| r.grad_color.is_some());
    let any_grad_depth = input.rays.iter().any(|r| r.grad_depth.is_some());
    let mut p = Packed {
        precision,
        min_transmittance,
        offsets: vec![0],
        sigma: Vec::new(),
        delta: Vec::new(),
        color: Vec::new(),
        ch,
        background: Vec::new(),
        t: any_t.then(Vec::new),
        has_t: Vec::new(),
        grad_color: any_grad.then(Vec::new),
        has_grad: Vec::new(),
        grad_depth: any_grad_depth.then(Vec::new),
        has_grad_depth: Vec::new(),
    };
    for (r, ray) in input.rays.iter().enumerate() {
        let n = ray.sigma.len();
        let mismatch = |what: &'static str, got: usize| InputError::SampleCount {
            ray: r,
            what,
            got,
            samples: n,
        };
        if ray.delta.len() != n {
            return Err(mismatch("delta", ray.delta.len()));
        }
        if ray.color.len() != n {
            return Err(mismatch("color", ray.color.len()));
        }
        if let Some(t) = &ray.t {
            if t.len() != n {
                return Err(mismatch("t", t.len()));
            }
        }
        for (what, values) in [("sigma", &ray.sigma), ("delta", &ray.delta)] {
            check_finite(values, precision, |i| format!("ray {r}, sample {i}: {what}"))?;
        }
        for (i, c) in ray.color.iter().enumerate() {
            if c.len() != ch {
                return Err(InputError::SampleChannels {
                    ray: r,
                    sample: i,
                    got: c.len(),
                    channels: ch,
                });
            }
            check_finite(c, precision, |k| format!("ray {r}, sample {i}: color[{k}]"))?;
            p.color.extend_from_slice(c);
        }
        let per_ray = |what: &'static str, v: &Option<Vec<f64>>| -> Result<Vec<f64>, InputError> {
            match v {
                None => Ok(vec![0.0; ch]),
                Some(v) if v.len() != ch => Err(InputError::RayChannels {
                    ray: r,
                    what,
                    got: v.len(),
                    channels: ch,
                }),
                Some(v) => {
                    check_finite(v, precision, |k| format!("ray {r}: {what}[{k}]"))?;
                    Ok(v.clone())
                }
            }
        };
        p.background.extend(per_ray("background", &ray.background)?);
        if let Some(g) = p.grad_color.as_mut() {
            g.extend(per_ray("grad_color", &ray.grad_color)?);
        }
        if let Some(t) = p.t.as_mut() {
            match &ray.t {
                Some(tv) => {
                    check_finite(tv, precision, |i| format!("ray {r}, sample {i}: t"))?;
                    t.extend_from_slice(tv);
                }
                None => t.extend(std::iter::repeat_n(0.0, n)),
            }
        }
        if let Some(g) = p.grad_depth.as_mut() {
            match (ray.grad_depth, &ray.t) {
                (Some(_), None) => return Err(InputError::GradDepthWithoutT(r)),
                (Some(gd), Some(_)) => {
                    check_finite(&[gd], precision, |_| format!("ray {r}: grad_depth"))?;
                    g.push(gd);
                }
                (None, _) => g.push(0.0),
            }
        }
        p.has_t.push(ray.t.is_some());
        p.has_grad_depth.push(ray.grad_depth.is_some());
        p.has_grad.push(ray.grad_color.is_some());
        p.sigma.extend_from_slice(&ray.sigma);
        p.delta.extend_from_slice(&ray.delta);
        p.offsets.push(p.sigma.len());
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packs_rays_and_defaults() {
        let p = parse(r#"{"rays":[{"sigma":[1,2],"delta":[0.5,0.5],"color":[[1,0],[0,1]]},{"sigma":[],"delta":[],"color":[],"background":[0.5,0.5]}]}"#).unwrap();
        assert_eq!(p.offsets, vec![0, 2, 2]);
        assert_eq!(p.ch, 2);
        assert_eq!(p.background, vec![0.0, 0.0, 0.5, 0.5]);
        assert_eq!(p.precision, Precision::F64);
        assert!(p.t.is_none() && p.grad_color.is_none());
    }

    #[test]
    fn rejects_what_it_cannot_compute() {
        for (bad, needle) in [
            ("{", "invalid input JSON"),
            (
                r#"{"rays":[{"sigma":["a"],"delta":[1],"color":[[1]]}]}"#,
                "invalid input JSON",
            ),
            (
                r#"{"rays":[{"sigma":[1e400],"delta":[1],"color":[[1]]}]}"#,
                "invalid input JSON",
            ),
            (r#"{"precision":"f16","rays":[]}"#, "unknown precision"),
            (
                r#"{"rays":[{"sigma":[1],"delta":[1,2],"color":[[1]]}]}"#,
                "ray 0: delta has 2 entries",
            ),
            (
                r#"{"rays":[{"sigma":[1,1],"delta":[1,1],"color":[[1],[1,2]]}]}"#,
                "ray 0, sample 1: color has 2 channels",
            ),
            (
                r#"{"precision":"f32","rays":[{"sigma":[1e39],"delta":[1],"color":[[1]]}]}"#,
                "overflows f32",
            ),
            (r#"{"rays":[{"delta":[1],"color":[[1]]}]}"#, "missing field `sigma`"),
            (r#"{"rays":[]}"#, "at least one ray"),
            (
                r#"{"rays":[{"sigma":[1],"delta":[1],"color":[[1]],"grad_depth":1}]}"#,
                "ray 0: grad_depth needs t",
            ),
        ] {
            let e = parse(bad).unwrap_err();
            assert!(e.to_string().contains(needle), "{bad}: {e}");
        }
    }
}
