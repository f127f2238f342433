//! Packed rays in f64 and one function that runs the fused composite or a taped twin on them
//! through the facade (`fogray::ops`, `fogray::tape`), in either precision, returning every
//! output and gradient as f64. The same helper as crates/ops/tests/integration/composite_common,
//! cut to what this binary's composite modules use: that one imports `fogray_ops` (the ops
//! crate's tests cannot reach the facade above it), this one only what a user of `fogray` sees.

use fogray::ops::{twins, Background, Composite, CompositeInputs};
use fogray::tape::{Float, Tape};
use ndarray::{Array1, Array2};

/// Packed rays, stored in f64 (tests build them from f32-representable values when they
/// compare precisions).
#[derive(Debug, Clone)]
pub struct Rays {
    pub sigma: Vec<f64>,
    pub delta: Vec<f64>,
    /// `[n * ch]`
    pub color: Vec<f64>,
    pub ch: usize,
    pub offsets: Vec<usize>,
    /// Shared background `[ch]`.
    pub background: Vec<f64>,
}

impl Rays {
    /// One ray.
    pub fn one(sigma: &[f64], delta: &[f64], color: &[f64], ch: usize, background: &[f64]) -> Rays {
        Rays {
            sigma: sigma.to_vec(),
            delta: delta.to_vec(),
            color: color.to_vec(),
            ch,
            offsets: vec![0, sigma.len()],
            background: background.to_vec(),
        }
    }

    pub fn n(&self) -> usize {
        self.sigma.len()
    }

    pub fn rays(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The same rays rounded to f32 and back, so that both precisions see identical inputs.
    pub fn f32_representable(&self) -> Rays {
        let r = |v: &Vec<f64>| v.iter().map(|&x| f64::from(x as f32)).collect();
        Rays {
            sigma: r(&self.sigma),
            delta: r(&self.delta),
            color: r(&self.color),
            background: r(&self.background),
            ..self.clone()
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Fused,
    Stable,
    Naive,
}

/// Every output and gradient of one run, as f64. Gradients are of `L = sum(gC * C)` with the
/// given upstream colour gradient (all ones by default).
#[derive(Debug, Clone)]
pub struct Run {
    pub color: Vec<f64>,
    pub opacity: Vec<f64>,
    pub weights: Vec<f64>,
    pub transmittance: Vec<f64>,
    pub d_sigma: Vec<f64>,
    pub d_delta: Vec<f64>,
    pub d_color: Vec<f64>,
    pub d_background: Vec<f64>,
}

fn to<F: Float>(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F::lit(x)).collect()
}

fn back<F: Float>(v: ndarray::ArrayViewD<'_, F>) -> Vec<f64> {
    v.iter().map(|x| x.as_f64()).collect()
}

/// Runs `method` in precision `F`, exact (no early termination), with an upstream colour
/// gradient of ones.
pub fn run<F: Float>(rays: &Rays, method: Method) -> Run {
    let mut tape = Tape::<F>::new();
    let (n, ch, r) = (rays.n(), rays.ch, rays.rays());
    let sigma = tape.param(Array1::from(to::<F>(&rays.sigma)));
    let delta = tape.param(Array1::from(to::<F>(&rays.delta)));
    let color = tape.param(Array2::from_shape_vec((n, ch), to::<F>(&rays.color)).unwrap());
    let background = tape.param(Array1::from(to::<F>(&rays.background)));
    let op = Composite::new(&rays.offsets)
        .unwrap()
        .background(Background::Shared)
        .with_weights()
        .with_transmittance();
    let inputs = CompositeInputs {
        sigma,
        delta,
        color,
        background: Some(background),
        t: None,
    };
    let out = match method {
        Method::Fused => op.apply(&mut tape, &inputs),
        Method::Stable => twins::stable(&mut tape, &op, &inputs),
        Method::Naive => twins::naive(&mut tape, &op, &inputs),
    }
    .unwrap();
    let seed = ndarray::ArrayD::from_shape_vec(vec![r, ch], vec![F::lit(1.0); r * ch]).unwrap();
    let g = tape.backward_with(out.color, seed).unwrap();
    let grad = |v| back(g.get_or_zeros(&tape, v).unwrap().view());
    Run {
        color: back(tape.value(out.color).unwrap()),
        opacity: back(tape.value(out.opacity).unwrap()),
        weights: back(tape.value(out.weights.unwrap()).unwrap()),
        transmittance: back(tape.value(out.transmittance.unwrap()).unwrap()),
        d_sigma: grad(sigma),
        d_delta: grad(delta),
        d_color: grad(color),
        d_background: grad(background),
    }
}

/// The size of the terms that make up each dC/dsigma_k (summed over channels, for an
/// upstream gradient of ones): `delta_k (T_{k+1} |c_k| + |S_k|)`, with `|S_k|` bounded by the
/// suffix sum of `w_i |c_i|` plus `T_end |c_bg|`. Computed here in f64 from the definitions.
pub fn grad_scale(rays: &Rays) -> Vec<f64> {
    let ch = rays.ch;
    let mut scale = vec![0.0; rays.n()];
    for w in rays.offsets.windows(2) {
        let (s, e) = (w[0], w[1]);
        let mut depth = vec![0.0; e - s + 1];
        for k in s..e {
            depth[k - s + 1] = depth[k - s] + rays.sigma[k] * rays.delta[k];
        }
        let abs_c = |k: usize| -> f64 { rays.color[k * ch..(k + 1) * ch].iter().map(|c| c.abs()).sum() };
        let t_end = (-depth[e - s]).exp();
        let mut suffix: f64 = t_end * rays.background.iter().map(|c| c.abs()).sum::<f64>();
        for k in (s..e).rev() {
            let t_next = (-depth[k - s + 1]).exp();
            scale[k] = rays.delta[k] * (t_next * abs_c(k) + suffix);
            let w = (-depth[k - s]).exp() * -(-rays.sigma[k] * rays.delta[k]).exp_m1();
            suffix += w * abs_c(k);
        }
    }
    scale
}

/// Worst `|got - want| / scale` over elements (scale floored at `floor`).
pub fn worst_scaled(got: &[f64], want: &[f64], scale: &[f64], floor: f64) -> (f64, usize) {
    assert_eq!(got.len(), want.len());
    let mut worst = (0.0, 0);
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        let e = (g - w).abs() / scale[k].max(floor);
        let e = if e.is_nan() { f64::INFINITY } else { e };
        if e > worst.0 {
            worst = (e, k);
        }
    }
    worst
}

/// Asserts `|got - want| <= tol * max(scale, floor)` element by element, naming the worst.
pub fn assert_close_scaled(what: &str, got: &[f64], want: &[f64], scale: &[f64], floor: f64, tol: f64) {
    let (e, k) = worst_scaled(got, want, scale, floor);
    assert!(
        e <= tol,
        "{what}: element {k}: got {}, want {} (scaled error {e:.3e} > {tol:.1e})",
        got[k],
        want[k]
    );
}
