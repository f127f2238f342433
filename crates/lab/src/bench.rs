//! `fogray-lab bench`: samples per second of the fused op (1 thread and all) and of the stable and
//! naive taped twins, in f32 and f64, each beside its error against an independent f64
//! reference on the same rays and its peak extra memory (`docs/performance.md`).
//!
//! The rays ([`data`], [`typed`]) and the timed steps ([`fused_step`], [`fused_step_into`],
//! [`fused_step_one_pass`], [`taped_step`], [`taped_step_reused`]) are public so that the
//! criterion bench (`benches/composite.rs`) times the same calls on the same rays.

use std::hint::black_box;
use std::time::Instant;

use fogray_ops::{
    twins, Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeInputs, CompositeOutputBuffers,
    CompositeUpstream, CompositeWanted,
};
use fogray_tape::{Float, Tape, Var};
use ndarray::{Array1, Array2, ArrayD, ArrayViewD};
use rand::{Rng, SeedableRng};
use serde::Serialize;

use crate::bandwidth::{fraction_of_bound, fused_bytes_per_sample, Bandwidth, FusedPath};
use crate::error::LabError;
use crate::reference::{errors, reference, Rays};

/// Colour channels of every workload (RGB).
const CHANNELS: usize = 3;

/// The workloads of the issue: rays x samples per ray.
pub const WORKLOADS: [(usize, usize); 4] = [(4096, 64), (65536, 64), (16384, 256), (1024, 4096)];

/// How the bench counts bytes: the binary's global allocator.
pub trait Memory: Sync {
    /// Starts a new measurement.
    fn reset(&self);
    /// The most bytes allocated beyond those held at the last reset, at any moment since.
    fn peak_since_reset(&self) -> usize;
}

/// One measurement (one JSON object of `{"results": [...]}`).
#[derive(Debug, Clone, Serialize)]
pub struct Measurement {
    /// `"fused"`, `"taped"` or `"taped-naive"`.
    pub method: &'static str,
    /// `"f32"` or `"f64"`.
    pub precision: &'static str,
    /// Threads of the rayon pool the row ran on.
    pub threads: usize,
    /// Rays of the workload.
    pub rays: usize,
    /// Samples per ray.
    pub samples: usize,
    /// Forward and backward (gradients for sigma and colour), from the median run.
    pub samples_per_sec: f64,
    /// Interquartile range over the median of the forward+backward run times (0 with one run):
    /// how far to trust `samples_per_sec` on a noisy machine.
    pub samples_per_sec_spread: f64,
    /// Forward and backward in a training loop's steady state (the same bits): fused through
    /// `evaluate_into` / `vjp_into` into output and gradient buffers kept across runs; taped on
    /// one tape cleared before each run, whose pool lends the ops the buffers of the run before.
    pub samples_per_sec_reused: f64,
    /// Fused only: forward, upstream gradient and backward in one pass per ray
    /// (`evaluate_vjp_into`, into kept buffers; the same bits as the two calls).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples_per_sec_one_pass: Option<f64>,
    /// The forward alone, from the median run.
    pub samples_per_sec_forward: f64,
    /// Worst element-wise relative error of the colour.
    pub err_color: f64,
    /// Worst element-wise error of dL/dsigma, relative to the size of its terms.
    pub err_grad_sigma: f64,
    /// `||C - C_ref|| / ||C_ref||`.
    pub err_color_norm: f64,
    /// `||g - g_ref|| / ||g_ref||`.
    pub err_grad_sigma_norm: f64,
    /// Peak bytes allocated during forward and backward, beyond the inputs.
    pub peak_extra_bytes: usize,
    /// Fused only: the speeds against the machine's memory bound on the row's threads (filled
    /// in by [`attach_bounds`] once the triad has run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_bound: Option<MemoryBound>,
    /// Bytes of one value in the row's precision.
    #[serde(skip)]
    pub value_bytes: usize,
}

/// A fused row's speeds as fractions of what the machine can stream (see [`crate::bandwidth`]).
#[derive(Debug, Clone, Serialize)]
pub struct MemoryBound {
    /// The triad's bytes per second on the row's thread count.
    pub triad_bytes_per_sec: f64,
    /// Bytes the two calls must move per sample (inputs read twice, gradients written).
    pub bytes_per_sample_two_calls: usize,
    /// Bytes one pass must move per sample (inputs read once, gradients written).
    pub bytes_per_sample_one_pass: usize,
    /// `samples_per_sec` (the allocating two calls) times their bytes, over the triad's.
    pub fraction: f64,
    /// The same for `samples_per_sec_reused`.
    pub fraction_reused: f64,
    /// The same for `samples_per_sec_one_pass`, at one pass's bytes.
    pub fraction_one_pass: f64,
}

impl MemoryBound {
    fn of(bw: &Bandwidth, value_bytes: usize, both: f64, reused: f64, one_pass: f64) -> Self {
        let two = fused_bytes_per_sample(value_bytes, CHANNELS, FusedPath::TwoCalls);
        let one = fused_bytes_per_sample(value_bytes, CHANNELS, FusedPath::OnePass);
        MemoryBound {
            triad_bytes_per_sec: bw.bytes_per_sec,
            bytes_per_sample_two_calls: two,
            bytes_per_sample_one_pass: one,
            fraction: fraction_of_bound(both, two, bw),
            fraction_reused: fraction_of_bound(reused, two, bw),
            fraction_one_pass: fraction_of_bound(one_pass, one, bw),
        }
    }
}

/// Random packed rays as the anchors measure them: sigma ~ U[0, 5], delta = 2 / samples
/// (total optical depth about 5), RGB colours and background ~ U[0, 1], dL/dC ~ U[-1, 1].
pub struct Data {
    sigma: Vec<f64>,
    delta: Vec<f64>,
    color: Vec<f64>,
    background: Vec<f64>,
    grad_color: Vec<f64>,
    offsets: Vec<usize>,
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

fn cast<F: Float>(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F::lit(x)).collect()
}

/// The inputs in precision F.
pub struct Typed<F: Float> {
    sigma: Array1<F>,
    delta: Array1<F>,
    color: Array2<F>,
    background: Array1<F>,
    /// dL/dC, `[R, 3]` (also a target colour of the same shape).
    pub grad_color: ArrayD<F>,
}

impl<F: Float> Typed<F> {
    /// The op's inputs: sigma, delta, colour, the shared background.
    fn views(&self) -> CompositeArrays<'_, F> {
        CompositeArrays::new(
            self.sigma.view().into_dyn(),
            self.delta.view().into_dyn(),
            self.color.view().into_dyn(),
        )
        .with_background(self.background.view().into_dyn())
    }

    /// The upstream gradient of every run: dL/dC only.
    fn upstream(&self) -> CompositeUpstream<'_, F> {
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

/// Wall times of repeated runs: the median, and the spread, the interquartile range over the
/// median (robust to the odd outlier run; 0 with a single run).
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// The median run's seconds.
    pub median: f64,
    /// The interquartile range of the runs' seconds over their median.
    pub spread: f64,
}

/// Runs of `f` go on past `reps` until they have taken this long (short workloads get more
/// runs, so that their median means as much), up to [`MAX_RUNS`].
const MIN_SECS: f64 = 0.3;
const MAX_RUNS: usize = 200;

/// Times at least `reps` runs of `f` (more for short runs when `reps > 1`, see [`MIN_SECS`]),
/// after one warm-up run when `reps > 1`.
pub fn time_runs(reps: usize, mut f: impl FnMut() -> Result<(), LabError>) -> Result<Timing, LabError> {
    if reps > 1 {
        f()?;
    }
    let mut t = Vec::with_capacity(reps);
    let mut total = 0.0;
    while t.len() < reps.max(1) || (reps > 1 && total < MIN_SECS && t.len() < MAX_RUNS) {
        let start = Instant::now();
        f()?;
        let secs = start.elapsed().as_secs_f64();
        t.push(secs);
        total += secs;
    }
    t.sort_by(f64::total_cmp);
    let median = t[t.len() / 2];
    Ok(Timing {
        median,
        spread: (t[(3 * t.len()) / 4] - t[t.len() / 4]) / median.max(1e-12),
    })
}

/// Median wall time of `reps` runs of `f` (see [`time_runs`]).
pub fn median_secs(reps: usize, f: impl FnMut() -> Result<(), LabError>) -> Result<f64, LabError> {
    Ok(time_runs(reps, f)?.median)
}

fn to_f64<F: Float>(v: ArrayViewD<'_, F>) -> Vec<f64> {
    v.iter().map(|x| x.as_f64()).collect()
}

/// Colour and dL/dsigma of one run, and its peak extra bytes.
struct Outcome {
    color: Vec<f64>,
    grad_sigma: Vec<f64>,
    peak_extra: usize,
}

fn fused_run<F: Float>(op: &Composite, x: &Typed<F>, mem: &dyn Memory) -> Result<Outcome, LabError> {
    let views = x.views();
    mem.reset();
    let (outs, res) = op.evaluate(&views)?;
    let grads = op.vjp(&views, &res, &x.upstream(), SIGMA_AND_COLOR)?;
    let peak_extra = mem.peak_since_reset();
    let g = grads.sigma.as_ref().ok_or(LabError::Missing("no sigma gradient"))?;
    Ok(Outcome {
        color: to_f64(outs.color.view()),
        grad_sigma: to_f64(g.view()),
        peak_extra,
    })
}

/// The fused op's forward, and with `backward` its gradients for sigma and colour, each call
/// allocating what it returns.
pub fn fused_step<F: Float>(op: &Composite, x: &Typed<F>, backward: bool) -> Result<(), LabError> {
    let views = x.views();
    let (outs, res) = op.evaluate(&views)?;
    if backward {
        let g = op.vjp(&views, &res, &x.upstream(), SIGMA_AND_COLOR)?;
        black_box(g);
    }
    black_box(outs);
    Ok(())
}

/// Output and gradient buffers kept across fused runs (colour, opacity; dL/dsigma, dL/dcolour).
pub struct Buffers<F: Float> {
    color: ArrayD<F>,
    opacity: ArrayD<F>,
    grad_sigma: ArrayD<F>,
    grad_color: ArrayD<F>,
}

impl<F: Float> Buffers<F> {
    /// Zeroed buffers for the outputs and gradients of `x`.
    pub fn new(x: &Typed<F>) -> Self {
        let (n, rays) = (x.sigma.len(), x.grad_color.shape()[0]);
        Buffers {
            color: ArrayD::zeros(vec![rays, CHANNELS]),
            opacity: ArrayD::zeros(vec![rays]),
            grad_sigma: ArrayD::zeros(vec![n]),
            grad_color: ArrayD::zeros(vec![n, CHANNELS]),
        }
    }

    /// The output buffers and the gradient buffers (dL/dsigma, dL/dcolour).
    fn split(&mut self) -> (CompositeOutputBuffers<'_, F>, CompositeGradientBuffers<'_, F>) {
        let outputs = CompositeOutputBuffers::new(self.color.view_mut(), self.opacity.view_mut());
        let gradients = CompositeGradientBuffers {
            sigma: Some(self.grad_sigma.view_mut()),
            color: Some(self.grad_color.view_mut()),
            ..Default::default()
        };
        (outputs, gradients)
    }
}

/// The gradients every fused run asks for.
const SIGMA_AND_COLOR: CompositeWanted = CompositeWanted {
    sigma: true,
    delta: false,
    color: true,
    background: false,
    t: false,
};

/// [`fused_step`] through the `_into` API, forward and backward, into `b`.
pub fn fused_step_into<F: Float>(op: &Composite, x: &Typed<F>, b: &mut Buffers<F>) -> Result<(), LabError> {
    let views = x.views();
    let (mut outputs, mut gradients) = b.split();
    let res = op.evaluate_into(&views, &mut outputs)?;
    op.vjp_into(&views, &res, &x.upstream(), &mut gradients)?;
    black_box(&b.grad_sigma);
    Ok(())
}

/// [`fused_step_into`] in one pass per ray (`evaluate_vjp_into`), the upstream gradient of
/// each ray handed over by the callback.
pub fn fused_step_one_pass<F: Float>(op: &Composite, x: &Typed<F>, b: &mut Buffers<F>) -> Result<(), LabError> {
    let views = x.views();
    let upstream = x
        .grad_color
        .as_slice()
        .ok_or(LabError::Missing("upstream gradient not contiguous"))?;
    let (mut outputs, mut gradients) = b.split();
    op.evaluate_vjp_into(
        &views,
        |r, _, d: &mut [F]| d.copy_from_slice(&upstream[r * d.len()..(r + 1) * d.len()]),
        &mut outputs,
        &mut gradients,
    )?;
    black_box(&b.grad_sigma);
    Ok(())
}

/// Puts the inputs on a new tape (sigma and colour as params): the part of a taped run that is
/// the same for every method, timed separately and subtracted.
fn tape_with_inputs<F: Float>(x: &Typed<F>) -> (Tape<F>, CompositeInputs) {
    let mut tape = Tape::new();
    let inputs = put_inputs(&mut tape, x);
    (tape, inputs)
}

/// The inputs on `tape`: sigma and colour as parameters (gradients wanted), delta and the
/// background as constants.
pub fn put_inputs<F: Float>(tape: &mut Tape<F>, x: &Typed<F>) -> CompositeInputs {
    CompositeInputs {
        sigma: tape.param(x.sigma.clone()),
        delta: tape.constant(x.delta.clone()),
        color: tape.param(x.color.clone()),
        background: Some(tape.constant(x.background.clone())),
        t: None,
    }
}

fn twin<F: Float>(tape: &mut Tape<F>, op: &Composite, inputs: &CompositeInputs, naive: bool) -> Result<Var, LabError> {
    let out = if naive {
        twins::naive(tape, op, inputs)
    } else {
        twins::stable(tape, op, inputs)
    };
    Ok(out?.color)
}

/// The stable (or with `naive` the naive) taped twin on a new tape, forward and with `backward`
/// its backward from dL/dC.
pub fn taped_step<F: Float>(op: &Composite, x: &Typed<F>, naive: bool, backward: bool) -> Result<(), LabError> {
    let (mut tape, inputs) = tape_with_inputs(x);
    let color = twin(&mut tape, op, &inputs, naive)?;
    if backward {
        let g = tape.backward_with(color, x.grad_color.clone())?;
        black_box(g);
    }
    black_box(tape);
    Ok(())
}

/// [`taped_step`] on one tape kept across runs: cleared first, its gradients handed back to it
/// after use (a training loop's steady state).
pub fn taped_step_reused<F: Float>(
    op: &Composite,
    x: &Typed<F>,
    naive: bool,
    tape: &mut Tape<F>,
) -> Result<(), LabError> {
    tape.clear();
    let inputs = put_inputs(tape, x);
    let color = twin(tape, op, &inputs, naive)?;
    let g = tape.backward_with(color, x.grad_color.clone())?;
    black_box(g.get(inputs.sigma));
    tape.recycle(g);
    Ok(())
}

fn taped_run<F: Float>(op: &Composite, x: &Typed<F>, naive: bool, mem: &dyn Memory) -> Result<Outcome, LabError> {
    let (mut tape, inputs) = tape_with_inputs(x);
    mem.reset();
    let color = twin(&mut tape, op, &inputs, naive)?;
    let g = tape.backward_with(color, x.grad_color.clone())?;
    let peak_extra = mem.peak_since_reset();
    let gs = g.get(inputs.sigma).ok_or(LabError::Missing("no sigma gradient"))?;
    Ok(Outcome {
        color: to_f64(tape.value(color)?),
        grad_sigma: to_f64(gs),
        peak_extra,
    })
}

/// Runs `f` in `pool`, or in the global pool when `None`.
pub fn within<R: Send>(pool: Option<&rayon::ThreadPool>, f: impl FnOnce() -> R + Send) -> R {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// Runs every measurement of one workload in precision F.
#[allow(clippy::too_many_arguments)]
fn measure<F: Float>(
    d: &Data,
    samples: usize,
    reps: usize,
    mem: &dyn Memory,
    refs: &crate::reference::Reference,
    out: &mut Vec<Measurement>,
    log: &mut dyn FnMut(&Measurement),
) -> Result<(), LabError> {
    let x = typed::<F>(d)?;
    let rays = d.offsets.len() - 1;
    let n = d.sigma.len() as f64;
    let op = d.op()?;
    let all = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut push = |method: &'static str,
                    threads: usize,
                    both: Timing,
                    (reused, one_pass): (f64, Option<f64>),
                    fwd: f64,
                    o: Outcome| {
        let (err_color, err_color_norm) = errors(
            &o.color,
            &refs.color,
            &refs.color.iter().map(|c| c.abs()).collect::<Vec<_>>(),
        );
        let (err_grad_sigma, err_grad_sigma_norm) = errors(&o.grad_sigma, &refs.grad_sigma, &refs.grad_scale);
        let m = Measurement {
            method,
            precision: F::NAME,
            threads,
            rays,
            samples,
            samples_per_sec: n / both.median,
            samples_per_sec_spread: both.spread,
            samples_per_sec_reused: n / reused,
            samples_per_sec_one_pass: one_pass.map(|t| n / t),
            samples_per_sec_forward: n / fwd,
            err_color,
            err_grad_sigma,
            err_color_norm,
            err_grad_sigma_norm,
            peak_extra_bytes: o.peak_extra,
            memory_bound: None,
            value_bytes: std::mem::size_of::<F>(),
        };
        log(&m);
        out.push(m);
    };
    let counts = if all > 1 { vec![1, all] } else { vec![1] };
    for threads in counts {
        let pool = (threads == 1).then_some(&one);
        let both = within(pool, || time_runs(reps, || fused_step(&op, &x, true)))?;
        let fwd = within(pool, || median_secs(reps, || fused_step(&op, &x, false)))?;
        let mut buffers = Buffers::new(&x);
        let reused = within(pool, || {
            // Buffers that were never written are fresh pages: touch them first, also in --quick.
            fused_step_into(&op, &x, &mut buffers)?;
            median_secs(reps, || fused_step_into(&op, &x, &mut buffers))
        })?;
        let one_pass = within(pool, || {
            median_secs(reps, || fused_step_one_pass(&op, &x, &mut buffers))
        })?;
        let outcome = within(pool, || fused_run(&op, &x, mem))?;
        push("fused", threads, both, (reused, Some(one_pass)), fwd, outcome);
    }
    for (method, naive) in [("taped", false), ("taped-naive", true)] {
        let setup = median_secs(reps, || {
            black_box(tape_with_inputs(&x));
            Ok(())
        })?;
        let both = time_runs(reps, || taped_step(&op, &x, naive, true))?;
        let both = Timing {
            median: (both.median - setup).max(1e-9),
            ..both
        };
        let fwd = median_secs(reps, || taped_step(&op, &x, naive, false))? - setup;
        let mut tape = Tape::new();
        // The first run fills the pool (fresh pages): not timed, also in --quick.
        taped_step_reused(&op, &x, naive, &mut tape)?;
        let reused = median_secs(reps, || taped_step_reused(&op, &x, naive, &mut tape))? - setup;
        // The twins run in the global pool: the tape's element-wise ops use all its threads.
        push(
            method,
            all,
            both,
            (reused.max(1e-9), None),
            fwd.max(1e-9),
            taped_run(&op, &x, naive, mem)?,
        );
    }
    Ok(())
}

/// The triad on 1 thread and on all (see [`crate::bandwidth::triad`]), once per bench run.
pub fn bandwidths(quick: bool) -> Result<Vec<Bandwidth>, LabError> {
    // A pass takes milliseconds: even --quick keeps the best of several.
    let runs = if quick { 5 } else { 20 };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut out = vec![crate::bandwidth::triad(Some(&one), runs)?];
    if rayon::current_num_threads() > 1 {
        out.push(crate::bandwidth::triad(None, runs)?);
    }
    Ok(out)
}

/// Gives each fused row its fraction of the memory bound on its thread count, from `bandwidth`
/// (see [`bandwidths`]). The triad runs after the workloads: run before them, it left the
/// fused rows on all threads 5-20 % slower on a 2-core instance, whichever the triad's size
/// (the cause was not found; the slowdown is not the op's).
pub fn attach_bounds(results: &mut [Measurement], bandwidth: &[Bandwidth]) {
    for m in results {
        let bw = bandwidth.iter().find(|b| b.threads == m.threads);
        m.memory_bound = match (m.samples_per_sec_one_pass, bw) {
            (Some(one_pass), Some(bw)) => Some(MemoryBound::of(
                bw,
                m.value_bytes,
                m.samples_per_sec,
                m.samples_per_sec_reused,
                one_pass,
            )),
            _ => None,
        };
    }
}

/// Runs the bench over `workloads`; `log` sees each measurement as it is made. The fused rows'
/// memory bounds are left to [`attach_bounds`].
pub fn run(
    workloads: &[(usize, usize)],
    quick: bool,
    mem: &dyn Memory,
    log: &mut dyn FnMut(&Measurement),
) -> Result<Vec<Measurement>, LabError> {
    let reps = if quick { 1 } else { 5 };
    let mut out = Vec::new();
    for &(rays, samples) in workloads {
        let d = data(rays, samples);
        let refs = reference(&Rays {
            sigma: &d.sigma,
            delta: &d.delta,
            color: &d.color,
            ch: CHANNELS,
            offsets: &d.offsets,
            background: &d.background,
            grad_color: &d.grad_color,
        });
        measure::<f32>(&d, samples, reps, mem, &refs, &mut out, log)?;
        measure::<f64>(&d, samples, reps, mem, &refs, &mut out, log)?;
    }
    Ok(out)
}

/// Parses `RxS`.
pub fn parse_workload(s: &str) -> Result<(usize, usize), LabError> {
    let (r, n) = s
        .split_once('x')
        .ok_or_else(|| LabError::Option(format!("workload {s:?} is not RxS (for example 4096x64)")))?;
    let parse = |v: &str| {
        v.parse::<usize>()
            .ok()
            .filter(|&x| x > 0)
            .ok_or_else(|| LabError::Option(format!("workload {s:?}: {v:?} is not a positive integer")))
    };
    Ok((parse(r)?, parse(n)?))
}

/// A fraction as a whole percentage, or `-` when there is none.
fn percent(fraction: Option<f64>) -> String {
    fraction.map_or("-".into(), |f| format!("{:.0}%", f * 100.0))
}

/// The machine's bandwidth as the bench measured it, one line per thread count, and what the
/// `bound` columns mean.
pub fn bandwidth_table(bandwidth: &[Bandwidth]) -> String {
    let mut s =
        String::from("memory bound (STREAM triad, best run; `bound` = bytes moved per second over the triad's):\n");
    for b in bandwidth {
        s += &format!("  {} thread(s): {:.1} GB/s\n", b.threads, b.bytes_per_sec / 1e9);
    }
    s + &format!(
        "  bytes per sample (RGB): two calls {} (f32) / {} (f64), one pass {} / {}\n\n",
        fused_bytes_per_sample(4, CHANNELS, FusedPath::TwoCalls),
        fused_bytes_per_sample(8, CHANNELS, FusedPath::TwoCalls),
        fused_bytes_per_sample(4, CHANNELS, FusedPath::OnePass),
        fused_bytes_per_sample(8, CHANNELS, FusedPath::OnePass)
    )
}

/// The text report: one line per measurement, then the fused/taped ratios.
pub fn table(results: &[Measurement]) -> String {
    let mut s = format!(
        "{:<12} {:<4} {:>3} {:>12} {:>10} {:>7} {:>10} {:>6} {:>10} {:>6} {:>10} {:>10} {:>10} {:>10} {:>10}\n",
        "method",
        "prec",
        "thr",
        "workload",
        "Ms/s f+b",
        "spread",
        "reused",
        "bound",
        "1-pass",
        "bound",
        "Ms/s fwd",
        "err C",
        "err dC/ds",
        "dC/ds norm",
        "peak MB"
    );
    for m in results {
        s += &format!(
            "{:<12} {:<4} {:>3} {:>12} {:>10.1} {:>6.0}% {:>10.1} {:>6} {:>10} {:>6} {:>10.1} {:>10.1e} {:>10.1e} {:>10.1e} {:>10.1}\n",
            m.method,
            m.precision,
            m.threads,
            format!("{}x{}", m.rays, m.samples),
            m.samples_per_sec / 1e6,
            m.samples_per_sec_spread * 100.0,
            m.samples_per_sec_reused / 1e6,
            percent(m.memory_bound.as_ref().map(|b| b.fraction_reused)),
            m.samples_per_sec_one_pass
                .map_or("-".into(), |r| format!("{:.1}", r / 1e6)),
            percent(m.memory_bound.as_ref().map(|b| b.fraction_one_pass)),
            m.samples_per_sec_forward / 1e6,
            m.err_color,
            m.err_grad_sigma,
            m.err_grad_sigma_norm,
            m.peak_extra_bytes as f64 / 1e6
        );
    }
    s += "\nfused (all threads) against the stable taped twin:\n";
    for m in results
        .iter()
        .filter(|m| m.method == "fused" && m.threads == rayon::current_num_threads())
    {
        let twin = results
            .iter()
            .find(|t| t.method == "taped" && t.precision == m.precision && t.rays == m.rays && t.samples == m.samples);
        if let Some(t) = twin {
            // dL/dsigma and dL/dcolour, which any op must return: the floor of the memory ratio.
            let value_bytes = if m.precision == "f32" { 4 } else { 8 };
            let gradient_bytes = m.rays * m.samples * (1 + CHANNELS) * value_bytes;
            s += &format!(
                "  {} {}x{}: {:.1}x faster ({:.1}x when both reuse their buffers, {:.1}x in one pass), {:.3}x the peak extra memory (the gradients returned alone: {:.3}x)\n",
                m.precision,
                m.rays,
                m.samples,
                m.samples_per_sec / t.samples_per_sec,
                m.samples_per_sec_reused / t.samples_per_sec_reused,
                m.samples_per_sec_one_pass.unwrap_or(m.samples_per_sec_reused) / t.samples_per_sec_reused,
                m.peak_extra_bytes as f64 / t.peak_extra_bytes.max(1) as f64,
                gradient_bytes as f64 / t.peak_extra_bytes.max(1) as f64
            );
        }
    }
    s
}
