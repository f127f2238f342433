//! The soft renderer: the model disc as a Gaussian fog sheet whose density is built on the
//! tape from the offset `x` (a tape param), composited by the fused op through the tape's
//! custom-op interface; the loss is on the tape and `dE/dx` comes from `backward`.

use fogray::ops::{twins, Background, Composite, CompositeInputs, CompositeVars};
use fogray::tape::{Tape, TapeError, Var};
use ndarray::{arr1, Array1, Array2};

use crate::scene::{Ray, Scene};

/// Which composite the soft renderer uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compositor {
    /// The fused op with its hand-written backward.
    Fused,
    /// The same composite written with tape primitives (the stable twin).
    Taped,
}

/// Where each ray is sampled: packed sample positions (x, z), steps and depths.
#[derive(Debug, Clone)]
pub struct Samples {
    pub x: Vec<f64>,
    pub z: Vec<f64>,
    pub delta: Vec<f64>,
    pub t: Vec<f64>,
    pub offsets: Vec<usize>,
}

impl Samples {
    /// The lesson's sampling: `samples` midpoints evenly on `[t0, t1]` for every ray.
    pub fn uniform(scene: &Scene, rays: &[Ray]) -> Samples {
        let s = scene.samples;
        let mut out = Samples::with_capacity(rays.len() * s);
        for ray in rays {
            for i in 0..s {
                out.push(ray, scene.sample_t(i), scene.delta());
            }
            out.offsets.push(out.x.len());
        }
        out
    }

    pub(crate) fn with_capacity(n: usize) -> Samples {
        Samples {
            x: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            delta: Vec::with_capacity(n),
            t: Vec::with_capacity(n),
            offsets: vec![0],
        }
    }

    pub(crate) fn push(&mut self, ray: &Ray, t: f64, delta: f64) {
        self.x.push(ray.origin[0] + t * ray.dir[0]);
        self.z.push(ray.origin[1] + t * ray.dir[1]);
        self.delta.push(delta);
        self.t.push(t);
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    pub fn rays(&self) -> usize {
        self.offsets.len() - 1
    }
}

/// The soft sheet's density at every sample, as a tape value depending on the param `x`:
/// `sigma = kappa / (tau sqrt(2 pi)) exp(-(d - R)^2 / (2 tau^2))`, `d = |p - (x, 0)|`.
pub fn density_on_tape(
    tape: &mut Tape<f64>,
    scene: &Scene,
    samples: &Samples,
    x: Var,
    tau: f64,
) -> Result<Var, TapeError> {
    let px = tape.constant(Array1::from(samples.x.clone()));
    let pz2 = tape.constant(Array1::from(samples.z.iter().map(|z| z * z).collect::<Vec<_>>()));
    let dx = tape.sub(px, x)?;
    let dx2 = tape.square(dx)?;
    let d2 = tape.add(dx2, pz2)?;
    let d = tape.sqrt(d2)?;
    let off = tape.sub_scalar(d, scene.radius)?;
    let off2 = tape.square(off)?;
    let exponent = tape.mul_scalar(off2, -0.5 / (tau * tau))?;
    let g = tape.exp(exponent)?;
    tape.mul_scalar(g, scene.kappa / (tau * (2.0 * std::f64::consts::PI).sqrt()))
}

/// Composites the sheet of softness `tau` at offset `x` on `tape`; returns the param `x`
/// and the composite's outputs (colour `[rays, ch]`, weights and transmittance).
pub fn render_on_tape(
    tape: &mut Tape<f64>,
    scene: &Scene,
    samples: &Samples,
    x: f64,
    tau: f64,
    compositor: Compositor,
) -> Result<(Var, CompositeVars), TapeError> {
    let xv = tape.param(arr1(&[x]));
    let sigma = density_on_tape(tape, scene, samples, xv, tau)?;
    let n = samples.len();
    let ch = scene.channels();
    let delta = tape.constant(Array1::from(samples.delta.clone()));
    let colors: Vec<f64> = (0..n).flat_map(|_| scene.disc_color.iter().copied()).collect();
    let color = tape.constant(
        Array2::from_shape_vec((n, ch), colors).map_err(|e| TapeError::InvalidArgument {
            op: "render",
            reason: e.to_string(),
        })?,
    );
    let background = Some(tape.constant(Array1::from(scene.background.clone())));
    let op = Composite::new(&samples.offsets)
        .map_err(|e| TapeError::InvalidArgument {
            op: "render",
            reason: e.to_string(),
        })?
        .background(Background::Shared)
        .with_weights()
        .with_transmittance();
    let inputs = CompositeInputs {
        sigma,
        delta,
        color,
        background,
        t: None,
    };
    let out = match compositor {
        Compositor::Fused => op.apply(tape, &inputs)?,
        Compositor::Taped => twins::stable(tape, &op, &inputs)?,
    };
    Ok((xv, out))
}

/// The soft loss and its exact slope at `x`, and the rendered image `[rays * ch]`.
#[derive(Debug, Clone)]
pub struct SoftEval {
    pub loss: f64,
    pub slope: f64,
    pub image: Vec<f64>,
}

/// `E(x) = mean over pixels and channels of (C - photo)^2` and `dE/dx` from the tape.
pub fn evaluate(
    scene: &Scene,
    samples: &Samples,
    photo: &[f64],
    x: f64,
    tau: f64,
    compositor: Compositor,
) -> Result<SoftEval, TapeError> {
    let mut tape = Tape::new();
    let (xv, out) = render_on_tape(&mut tape, scene, samples, x, tau, compositor)?;
    let ch = scene.channels();
    let target = tape.constant(
        Array2::from_shape_vec((samples.rays(), ch), photo.to_vec()).map_err(|e| TapeError::InvalidArgument {
            op: "loss",
            reason: e.to_string(),
        })?,
    );
    let diff = tape.sub(out.color, target)?;
    let sq = tape.square(diff)?;
    let loss = tape.mean(sq)?;
    let grads = tape.backward(loss)?;
    let slope = grads.get(xv).map(|g| g[[0]]).unwrap_or(0.0);
    Ok(SoftEval {
        loss: tape.value(loss)?[[]],
        slope,
        image: tape.value(out.color)?.iter().copied().collect(),
    })
}
