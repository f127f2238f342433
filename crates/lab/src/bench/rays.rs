//! The bench's rays: a workload's packed samples in f64 and in the measured float type.

use super::*;

/// Random packed rays as the anchors measure them: sigma ~ U[0, 5], delta = 2 / samples
/// (total optical depth about 5), RGB colours and background ~ U[0, 1], dL/dC ~ U[-1, 1].
pub struct Data {
    pub(crate) sigma: Vec<f64>,
    pub(crate) delta: Vec<f64>,
    pub(crate) color: Vec<f64>,
    pub(crate) background: Vec<f64>,
    pub(crate) grad_color: Vec<f64>,
    pub(crate) offsets: Vec<usize>,
}

impl Data {
    /// The composite of these rays, over their shared background.
    pub fn op(&self) -> Result<Composite, LabError> {
        Ok(Composite::new(&self.offsets)?.background(Background::Shared))
    }

    /// Samples in all.
    pub fn samples(&self) -> usize {
        self.sigma.len()
    }
}

/// `rays` rays of `samples` samples each (the workload `RxS`).
pub fn data(rays: usize, samples: usize) -> Data {
    let offsets: Vec<usize> = (0..=rays).map(|r| r * samples).collect();
    data_on(&offsets, samples)
}

/// Rays of the lengths that `offsets` give, `samples` being their mean length (for delta).
pub fn data_on(offsets: &[usize], samples: usize) -> Data {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2026);
    let (rays, n) = (offsets.len() - 1, offsets[offsets.len() - 1]);
    // Rounded to f32 so that both precisions see the same inputs.
    let mut u = |lo: f64, hi: f64| f64::from(rng.gen_range(lo..hi) as f32);
    Data {
        sigma: (0..n).map(|_| u(0.0, 5.0)).collect(),
        delta: vec![f64::from((2.0 / samples as f64) as f32); n],
        color: (0..n * CHANNELS).map(|_| u(0.0, 1.0)).collect(),
        background: (0..CHANNELS).map(|_| u(0.0, 1.0)).collect(),
        grad_color: (0..rays * CHANNELS).map(|_| u(-1.0, 1.0)).collect(),
        offsets: offsets.to_vec(),
    }
}

pub(crate) fn cast<F: Float>(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F::lit(x)).collect()
}

/// The inputs in precision F.
pub struct Typed<F: Float> {
    pub(crate) sigma: Array1<F>,
    pub(crate) delta: Array1<F>,
    pub(crate) color: Array2<F>,
    pub(crate) background: Array1<F>,
    /// dL/dC, `[R, 3]` (also a target colour of the same shape).
    pub grad_color: ArrayD<F>,
}

impl<F: Float> Typed<F> {
    /// The op's inputs: sigma, delta, colour, the shared background.
    pub(crate) fn views(&self) -> CompositeArrays<'_, F> {
        CompositeArrays::new(
            self.sigma.view().into_dyn(),
            self.delta.view().into_dyn(),
            self.color.view().into_dyn(),
        )
        .with_background(self.background.view().into_dyn())
    }

    /// The upstream gradient of every run: dL/dC only.
    pub(crate) fn upstream(&self) -> CompositeUpstream<'_, F> {
        CompositeUpstream::color(self.grad_color.view())
    }
}

/// The rays of `d` in precision F.
pub fn typed<F: Float>(d: &Data) -> Result<Typed<F>, LabError> {
    let n = d.sigma.len();
    let rays = d.offsets.len() - 1;
    Ok(Typed {
        sigma: Array1::from(cast::<F>(&d.sigma)),
        delta: Array1::from(cast::<F>(&d.delta)),
        color: Array2::from_shape_vec((n, CHANNELS), cast::<F>(&d.color))?,
        background: Array1::from(cast::<F>(&d.background)),
        grad_color: ArrayD::from_shape_vec(vec![rays, CHANNELS], cast::<F>(&d.grad_color))?,
    })
}
