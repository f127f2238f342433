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

mod rays;
mod steps;
mod timing;

pub use rays::*;
pub use steps::*;
pub use timing::*;

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
