//! Batches of packed rays, the CPU op's results on them, and element-wise comparisons scaled
//! by the size of the terms each value is made of (`docs/volume-rendering.md`: norm-wise
//! errors hide failures in the tails of rays).

#![allow(dead_code)]

use fogray_cuda::{CudaComposite, DeviceFloat, HostGradients, HostOutputs, HostRays};
use fogray_ops::{Background, Composite, CompositeArrays, CompositeUpstream, CompositeWanted};
use fogray_tape::Float;
use ndarray::ArrayViewD;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A batch with its upstream gradients, in f64 (converted to the tested type).
#[derive(Debug, Clone, Default)]
pub struct Case {
    pub name: &'static str,
    pub offsets: Vec<usize>,
    pub sigma: Vec<f64>,
    pub delta: Vec<f64>,
    pub color: Vec<f64>,
    pub background: [f64; 3],
    pub d_color: Vec<f64>,
    pub d_opacity: Option<Vec<f64>>,
}

impl Case {
    pub fn new(name: &'static str, rays: &[Vec<(f64, f64)>], rng: &mut StdRng) -> Case {
        let mut c = Case {
            name,
            offsets: vec![0],
            background: [0.3, 0.7, 1.0],
            ..Case::default()
        };
        for ray in rays {
            for &(s, d) in ray {
                c.sigma.push(s);
                c.delta.push(d);
                for _ in 0..3 {
                    c.color.push(rng.gen_range(-0.5..1.5));
                }
            }
            c.offsets.push(c.sigma.len());
        }
        let r = rays.len();
        c.d_color = (0..3 * r).map(|_| rng.gen_range(-1.0..1.0)).collect();
        c.d_opacity = Some((0..r).map(|_| rng.gen_range(-1.0..1.0)).collect());
        c
    }

    pub fn rays(&self) -> usize {
        self.offsets.len() - 1
    }
}

pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// Random rays: lengths 0..max_len, densities 0 or log-uniform in 1e-3..1e3, steps
/// log-uniform in 1e-4..1e-1 or 0.
pub fn random_case(rng: &mut StdRng, rays: usize, max_len: usize) -> Case {
    let rays: Vec<Vec<(f64, f64)>> = (0..rays)
        .map(|_| {
            let len = rng.gen_range(0..max_len);
            (0..len)
                .map(|_| {
                    let s = if rng.gen_bool(0.2) {
                        0.0
                    } else {
                        10f64.powf(rng.gen_range(-3.0..3.0))
                    };
                    let d = if rng.gen_bool(0.05) {
                        0.0
                    } else {
                        10f64.powf(rng.gen_range(-4.0..-1.0))
                    };
                    (s, d)
                })
                .collect()
        })
        .collect();
    Case::new("random", &rays, rng)
}

fn cast<F: Float>(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F::lit(x)).collect()
}

/// The case's arrays in type F.
pub struct Typed<F> {
    pub sigma: Vec<F>,
    pub delta: Vec<F>,
    pub color: Vec<F>,
    pub background: Vec<F>,
    pub d_color: Vec<F>,
    pub d_opacity: Option<Vec<F>>,
}

impl<F: Float> Typed<F> {
    pub fn of(c: &Case) -> Self {
        Typed {
            sigma: cast(&c.sigma),
            delta: cast(&c.delta),
            color: cast(&c.color),
            background: cast(&c.background),
            d_color: cast(&c.d_color),
            d_opacity: c.d_opacity.as_deref().map(cast),
        }
    }

    pub fn host<'a>(&'a self, c: &'a Case) -> HostRays<'a, F> {
        HostRays {
            offsets: &c.offsets,
            sigma: &self.sigma,
            delta: &self.delta,
            color: &self.color,
            background: &self.background,
        }
    }
}

fn view<'a, F>(v: &'a [F], shape: &[usize]) -> ArrayViewD<'a, F> {
    ArrayViewD::from_shape(shape, v).expect("shape of a test array")
}

/// The CPU op's forward and backward (shared background, colour and opacity upstream).
pub fn cpu<F: Float>(c: &Case, t: &Typed<F>) -> (HostOutputs<F>, HostGradients<F>) {
    let (n, r) = (t.sigma.len(), c.rays());
    let op = Composite::new(&c.offsets)
        .expect("offsets")
        .background(Background::Shared);
    let inputs = CompositeArrays::new(view(&t.sigma, &[n]), view(&t.delta, &[n]), view(&t.color, &[n, 3]))
        .with_background(view(&t.background, &[3]));
    let (outs, res) = op.evaluate(&inputs).expect("CPU forward");
    let upstream = CompositeUpstream {
        color: Some(view(&t.d_color, &[r, 3])),
        opacity: t.d_opacity.as_deref().map(|g| view(g, &[r])),
        ..CompositeUpstream::default()
    };
    let wanted = CompositeWanted {
        sigma: true,
        delta: true,
        color: true,
        background: true,
        t: false,
    };
    let g = op.vjp(&inputs, &res, &upstream, wanted).expect("CPU backward");
    let flat = |a: Option<ndarray::ArrayD<F>>| a.map(|a| a.iter().copied().collect()).unwrap_or_default();
    (
        HostOutputs {
            color: outs.color.iter().copied().collect(),
            opacity: outs.opacity.iter().copied().collect(),
        },
        HostGradients {
            sigma: flat(g.sigma),
            delta: flat(g.delta),
            color: flat(g.color),
            background: flat(g.background),
        },
    )
}

/// The size of the terms each output and gradient is made of, in f64 from the typed inputs:
/// the error of each value is judged against it.
pub struct Scales {
    pub color: Vec<f64>,
    pub opacity: Vec<f64>,
    pub sigma: Vec<f64>,
    pub delta: Vec<f64>,
    pub g_color: Vec<f64>,
    pub background: Vec<f64>,
}

pub fn scales<F: Float>(c: &Case, t: &Typed<F>) -> Scales {
    let n = t.sigma.len();
    let f = |v: &[F]| v.iter().map(|x| x.as_f64()).collect::<Vec<f64>>();
    let (sigma, delta, color, bg, gc) = (f(&t.sigma), f(&t.delta), f(&t.color), f(&t.background), f(&t.d_color));
    let go = t.d_opacity.as_deref().map(f);
    let mut s = Scales {
        color: vec![0.0; 3 * c.rays()],
        opacity: vec![0.0; c.rays()],
        sigma: vec![0.0; n],
        delta: vec![0.0; n],
        g_color: vec![0.0; 3 * n],
        background: vec![0.0; 3],
    };
    for r in 0..c.rays() {
        let (a, b) = (c.offsets[r], c.offsets[r + 1]);
        let mut depth = vec![0.0; b - a + 1];
        for k in a..b {
            depth[k - a + 1] = depth[k - a] + sigma[k] * delta[k];
        }
        let t_end = (-depth[b - a]).exp();
        s.opacity[r] = -(-depth[b - a]).exp_m1();
        let g = &gc[3 * r..3 * r + 3];
        // |v|-weighted recurrence: bounds |R| and |S| (alpha in [0, 1]).
        let mut behind: f64 = (0..3).map(|j| (g[j] * bg[j]).abs()).sum();
        for k in (a..b).rev() {
            let alpha = -(-sigma[k] * delta[k]).exp_m1();
            let t_k = (-depth[k - a]).exp();
            let t_next = (-depth[k - a + 1]).exp();
            let v: f64 =
                (0..3).map(|j| (g[j] * color[3 * k + j]).abs()).sum::<f64>() + go.as_ref().map_or(0.0, |o| o[r].abs());
            let term = t_next * (v + behind);
            s.sigma[k] = delta[k] * term;
            s.delta[k] = sigma[k] * term;
            for j in 0..3 {
                s.g_color[3 * k + j] = t_k * alpha * g[j].abs();
                s.color[3 * r + j] += t_k * alpha * color[3 * k + j].abs();
            }
            behind += alpha * (v - behind);
        }
        for j in 0..3 {
            s.color[3 * r + j] += t_end * bg[j].abs();
            s.background[j] += t_end * g[j].abs();
        }
    }
    s
}

/// The largest scaled error of `got` against `want`, and where.
pub fn worst<F: Float>(got: &[F], want: &[F], scale: &[f64], floor: f64) -> (f64, usize) {
    assert_eq!(got.len(), want.len());
    let mut w = (0.0, 0);
    for (i, ((a, b), s)) in got.iter().zip(want).zip(scale).enumerate() {
        let (a, b) = (a.as_f64(), b.as_f64());
        let e = if a == b { 0.0 } else { (a - b).abs() / s.max(floor) };
        // NaN anywhere is the worst error.
        let e = if e.is_nan() { f64::INFINITY } else { e };
        if e > w.0 {
            w = (e, i);
        }
    }
    w
}

/// Runs the case on the GPU and the CPU in type F and returns the worst scaled error of each
/// output and gradient (colour, opacity, dsigma, ddelta, dcolor, dbackground), printing them.
pub fn compare<F: Float + DeviceFloat>(gpu: &CudaComposite, c: &Case, floor: f64) -> [f64; 6] {
    let t = Typed::<F>::of(c);
    let (g_out, g_grad) = gpu
        .evaluate_vjp(&t.host(c), &t.d_color, t.d_opacity.as_deref())
        .unwrap_or_else(|e| panic!("{}: GPU: {e}", c.name));
    let (c_out, c_grad) = cpu(c, &t);
    let s = scales(c, &t);
    let results = [
        ("colour", worst(&g_out.color, &c_out.color, &s.color, floor)),
        ("opacity", worst(&g_out.opacity, &c_out.opacity, &s.opacity, floor)),
        ("dsigma", worst(&g_grad.sigma, &c_grad.sigma, &s.sigma, floor)),
        ("ddelta", worst(&g_grad.delta, &c_grad.delta, &s.delta, floor)),
        ("dcolor", worst(&g_grad.color, &c_grad.color, &s.g_color, floor)),
        (
            "dbackground",
            worst(&g_grad.background, &c_grad.background, &s.background, floor),
        ),
    ];
    let line: Vec<String> = results.iter().map(|(n, (e, i))| format!("{n} {e:.2e}@{i}")).collect();
    println!(
        "{} {} ({} rays, {} samples): max scaled error {}",
        std::any::type_name::<F>(),
        c.name,
        c.rays(),
        c.sigma.len(),
        line.join(", ")
    );
    results.map(|(_, (e, _))| e)
}
