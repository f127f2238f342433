//! Criterion benches: the fused composite against its taped twins, forward and backward
//! (gradients for sigma and colour), on the workloads of `fogray bench`.
//!
//! `fused-into` is the fused op through `evaluate_into` / `vjp_into` with buffers kept across
//! iterations, `fused-one-pass` through `evaluate_vjp_into` (one pass per ray) into them, each
//! also `-packed` (rays eight at a time across the vector lanes, `Composite::pack_rays`); `taped-reused` and `taped-naive-reused` keep one tape across iterations (cleared
//! each time, its buffer pool reused). `fused-tape-mse` and `fused-tape-chain` are a training
//! step's composite and mean squared error on a kept tape, forward and backward: one op
//! (`Composite::apply_mse`) against `apply`, `sub`, `square` and `mean`. `cargo bench --bench composite` runs them all; `cargo bench --bench composite -- fused/f32`
//! selects. `ragged` runs the two fused steady states on a training batch's shape, rays of random
//! lengths. `fogray bench` gives the same speeds beside each method's error and memory.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fogray::ops::{
    twins, Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeInputs, CompositeOutputBuffers,
    CompositeUpstream, CompositeWanted,
};
use fogray::tape::{Float, Tape};
use ndarray::{Array1, Array2, ArrayD};
use rand::{Rng, SeedableRng};

struct Inputs<F: Float> {
    op: Composite,
    sigma: Array1<F>,
    delta: Array1<F>,
    color: Array2<F>,
    background: Array1<F>,
    grad: ArrayD<F>,
}

impl<F: Float> Inputs<F> {
    /// The op's inputs: sigma, delta, colour, the shared background.
    fn views(&self) -> CompositeArrays<'_, F> {
        CompositeArrays::new(
            self.sigma.view().into_dyn(),
            self.delta.view().into_dyn(),
            self.color.view().into_dyn(),
        )
        .with_background(self.background.view().into_dyn())
    }

    /// The op's inputs on `tape`: sigma and colour as parameters (gradients wanted), delta and
    /// the background as constants.
    fn on_tape(&self, tape: &mut Tape<F>) -> CompositeInputs {
        CompositeInputs {
            sigma: tape.param(self.sigma.clone()),
            delta: tape.constant(self.delta.clone()),
            color: tape.param(self.color.clone()),
            background: Some(tape.constant(self.background.clone())),
            t: None,
        }
    }
}

/// sigma ~ U[0, 5], delta = 2 / samples (total optical depth ~5), RGB in [0, 1].
fn inputs<F: Float>(rays: usize, samples: usize) -> Inputs<F> {
    let offsets: Vec<usize> = (0..=rays).map(|r| r * samples).collect();
    inputs_on(&offsets, samples)
}

/// [`inputs`] on rays of the given `offsets`, with delta = 2 / `samples` (`samples` the mean
/// length).
fn inputs_on<F: Float>(offsets: &[usize], samples: usize) -> Inputs<F> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let rays = offsets.len() - 1;
    let n = offsets[rays];
    let mut u = |lo: f64, hi: f64, len: usize| -> Vec<F> { (0..len).map(|_| F::lit(rng.gen_range(lo..hi))).collect() };
    Inputs {
        op: Composite::new(offsets).unwrap().background(Background::Shared),
        sigma: Array1::from(u(0.0, 5.0, n)),
        delta: Array1::from(vec![F::lit(2.0 / samples as f64); n]),
        color: Array2::from_shape_vec((n, 3), u(0.0, 1.0, 3 * n)).unwrap(),
        background: Array1::from(u(0.0, 1.0, 3)),
        grad: ArrayD::from_shape_vec(vec![rays, 3], u(-1.0, 1.0, 3 * rays)).unwrap(),
    }
}

/// Kept buffers for the outputs and gradients of `x`.
fn buffers_for<F: Float>(x: &Inputs<F>) -> Buffers<F> {
    let (rays, n) = (x.grad.shape()[0], x.sigma.len());
    Buffers {
        color: ArrayD::zeros(vec![rays, 3]),
        opacity: ArrayD::zeros(vec![rays]),
        grad_sigma: ArrayD::zeros(vec![n]),
        grad_color: ArrayD::zeros(vec![n, 3]),
    }
}

fn fused<F: Float>(x: &Inputs<F>) {
    let views = x.views();
    let (outs, res) = x.op.evaluate(&views).unwrap();
    let g =
        x.op.vjp(&views, &res, &CompositeUpstream::color(x.grad.view()), SIGMA_AND_COLOR)
            .unwrap();
    black_box((outs, g));
}

/// Output and gradient buffers kept across iterations (a training loop's steady state).
struct Buffers<F: Float> {
    color: ArrayD<F>,
    opacity: ArrayD<F>,
    grad_sigma: ArrayD<F>,
    grad_color: ArrayD<F>,
}

impl<F: Float> Buffers<F> {
    fn outputs(&mut self) -> CompositeOutputBuffers<'_, F> {
        CompositeOutputBuffers::new(self.color.view_mut(), self.opacity.view_mut())
    }

    fn gradients(&mut self) -> CompositeGradientBuffers<'_, F> {
        CompositeGradientBuffers {
            sigma: Some(self.grad_sigma.view_mut()),
            color: Some(self.grad_color.view_mut()),
            ..Default::default()
        }
    }

    fn outputs_and_gradients(&mut self) -> (CompositeOutputBuffers<'_, F>, CompositeGradientBuffers<'_, F>) {
        let outputs = CompositeOutputBuffers::new(self.color.view_mut(), self.opacity.view_mut());
        let gradients = CompositeGradientBuffers {
            sigma: Some(self.grad_sigma.view_mut()),
            color: Some(self.grad_color.view_mut()),
            ..Default::default()
        };
        (outputs, gradients)
    }
}

/// The gradients every run asks for.
const SIGMA_AND_COLOR: CompositeWanted = CompositeWanted {
    sigma: true,
    delta: false,
    color: true,
    background: false,
    t: false,
};

fn fused_into<F: Float>(op: &Composite, x: &Inputs<F>, b: &mut Buffers<F>) {
    let views = x.views();
    let res = op.evaluate_into(&views, &mut b.outputs()).unwrap();
    op.vjp_into(
        &views,
        &res,
        &CompositeUpstream::color(x.grad.view()),
        &mut b.gradients(),
    )
    .unwrap();
}

/// [`fused_into`] in one pass per ray, each ray's upstream gradient handed over by the callback.
fn fused_one_pass<F: Float>(op: &Composite, x: &Inputs<F>, b: &mut Buffers<F>) {
    let views = x.views();
    let upstream = x.grad.as_slice().unwrap();
    let (mut outputs, mut grads) = b.outputs_and_gradients();
    op.evaluate_vjp_into(
        &views,
        |r, _, d: &mut [F]| d.copy_from_slice(&upstream[r * d.len()..(r + 1) * d.len()]),
        &mut outputs,
        &mut grads,
    )
    .unwrap();
}

/// A training step's composite and loss, `mean((C - target)^2)` with the fused op, forward and
/// backward on `tape` (cleared first, its pool reused): as one op (`apply_mse`, one pass per
/// ray) or as the chain `apply`, `sub`, `square`, `mean` (the same bits).
fn fused_loss<F: Float>(x: &Inputs<F>, one_op: bool, tape: &mut Tape<F>) {
    tape.clear();
    let inputs = x.on_tape(tape);
    let target = tape.constant(x.grad.clone());
    let loss = if one_op {
        x.op.apply_mse(tape, &inputs, target).unwrap()
    } else {
        let color = x.op.apply(tape, &inputs).unwrap().color;
        let error = tape.sub(color, target).unwrap();
        let squared = tape.square(error).unwrap();
        tape.mean(squared).unwrap()
    };
    let g = tape.backward(loss).unwrap();
    black_box(g.get(inputs.sigma));
    tape.recycle(g);
}

/// One forward and backward of a taped twin on `tape`, which is cleared first; its gradients
/// go back to it. With a new tape each time that is a one-shot use; with one tape kept, a
/// training loop's (its pool lends the ops the buffers of the iteration before).
fn taped<F: Float>(x: &Inputs<F>, naive: bool, tape: &mut Tape<F>) {
    tape.clear();
    let inputs = x.on_tape(tape);
    let out = if naive {
        twins::naive(tape, &x.op, &inputs)
    } else {
        twins::stable(tape, &x.op, &inputs)
    }
    .unwrap();
    let g = tape.backward_with(out.color, x.grad.clone()).unwrap();
    black_box(g.get(inputs.sigma));
    tape.recycle(g);
}

fn bench_precision<F: Float>(c: &mut Criterion) {
    for (rays, samples) in [(4096, 64), (65536, 64), (16384, 256), (1024, 4096)] {
        let x = inputs::<F>(rays, samples);
        let id = format!("{rays}x{samples}");
        let mut group = c.benchmark_group(format!("composite/{}", F::NAME));
        group.throughput(Throughput::Elements((rays * samples) as u64));
        group.sample_size(10);
        group.bench_with_input(BenchmarkId::new("fused", &id), &x, |b, x| b.iter(|| fused(x)));
        let mut buffers = buffers_for(&x);
        // `-packed`: rays eight at a time across the vector lanes (`Composite::pack_rays`).
        let packed = x.op.clone().pack_rays(true);
        for (suffix, op) in [("", &x.op), ("-packed", &packed)] {
            group.bench_with_input(BenchmarkId::new(format!("fused-into{suffix}"), &id), &x, |b, x| {
                b.iter(|| fused_into(op, x, &mut buffers))
            });
            group.bench_with_input(BenchmarkId::new(format!("fused-one-pass{suffix}"), &id), &x, |b, x| {
                b.iter(|| fused_one_pass(op, x, &mut buffers))
            });
        }
        for (name, one_op) in [("fused-tape-mse", true), ("fused-tape-chain", false)] {
            let mut kept = Tape::new();
            group.bench_with_input(BenchmarkId::new(name, &id), &x, |b, x| {
                b.iter(|| fused_loss(x, one_op, &mut kept))
            });
        }
        for (name, naive) in [("taped", false), ("taped-naive", true)] {
            group.bench_with_input(BenchmarkId::new(name, &id), &x, |b, x| {
                b.iter(|| taped(x, naive, &mut Tape::new()))
            });
            let mut kept = Tape::new();
            group.bench_with_input(BenchmarkId::new(format!("{name}-reused"), &id), &x, |b, x| {
                b.iter(|| taped(x, naive, &mut kept))
            });
        }
        group.finish();
    }
}

/// `ragged/16384x0-54`: a training batch's shape, 16384 rays of random lengths 0 to 54 (27 on
/// average, as an occupancy grid's samples), into kept buffers. Each loop of a ray then ends
/// at a count that changes from ray to ray.
fn bench_ragged<F: Float>(c: &mut Criterion) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2);
    let mut offsets = vec![0];
    for _ in 0..16384 {
        offsets.push(offsets[offsets.len() - 1] + rng.gen_range(0..=54usize));
    }
    let x = inputs_on::<F>(&offsets, 27);
    let mut buffers = buffers_for(&x);
    let mut group = c.benchmark_group(format!("composite/{}", F::NAME));
    group.throughput(Throughput::Elements(x.sigma.len() as u64));
    group.sample_size(10);
    let id = "ragged-16384x0-54";
    group.bench_with_input(BenchmarkId::new("fused-into", id), &x, |b, x| {
        b.iter(|| fused_into(&x.op, x, &mut buffers))
    });
    group.bench_with_input(BenchmarkId::new("fused-one-pass", id), &x, |b, x| {
        b.iter(|| fused_one_pass(&x.op, x, &mut buffers))
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    bench_precision::<f32>(c);
    bench_precision::<f64>(c);
    bench_ragged::<f32>(c);
    bench_ragged::<f64>(c);
}

criterion_group!(composite, benches);
criterion_main!(composite);
