//! Criterion benches: the fused composite against its taped twins, forward and backward
//! (gradients for sigma and colour), on the workloads of `fogray-lab bench`, with its rays and its
//! timed steps (`fogray_lab::bench`: the same calls, so the two cannot drift apart).
//!
//! `fused-into` is the fused op through `evaluate_into` / `vjp_into` with buffers kept across
//! iterations, `fused-one-pass` through `evaluate_vjp_into` (one pass per ray) into them; `taped-reused` and `taped-naive-reused` keep one tape across iterations (cleared
//! each time, its buffer pool reused). `fused-tape-mse` and `fused-tape-chain` are a training
//! step's composite and mean squared error on a kept tape, forward and backward: one op
//! (`Composite::apply_mse`) against `apply`, `sub`, `square` and `mean`. `cargo bench -p fogray-benches --bench composite` runs them all; `cargo bench -p fogray-benches --bench composite -- fused/f32`
//! selects. `ragged` runs the two fused steady states on a training batch's shape, rays of random
//! lengths. `fogray-lab bench` gives the same speeds beside each method's error and memory.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fogray_lab::bench::{self, Buffers, Data, Typed};
use fogray_ops::Composite;
use fogray_tape::{Float, Tape};
use rand::{Rng, SeedableRng};

/// The composite of `d` and its rays in precision F.
fn setup<F: Float>(d: &Data) -> (Composite, Typed<F>) {
    (d.op().unwrap(), bench::typed(d).unwrap())
}

/// A training step's composite and loss, `mean((C - target)^2)` with the fused op, forward and
/// backward on `tape` (cleared first, its pool reused): as one op (`apply_mse`, one pass per
/// ray) or as the chain `apply`, `sub`, `square`, `mean` (the same bits).
fn fused_loss<F: Float>(op: &Composite, x: &Typed<F>, one_op: bool, tape: &mut Tape<F>) {
    tape.clear();
    let inputs = bench::put_inputs(tape, x);
    let target = tape.constant(x.grad_color.clone());
    let loss = if one_op {
        op.apply_mse(tape, &inputs, target).unwrap()
    } else {
        let color = op.apply(tape, &inputs).unwrap().color;
        let error = tape.sub(color, target).unwrap();
        let squared = tape.square(error).unwrap();
        tape.mean(squared).unwrap()
    };
    let g = tape.backward(loss).unwrap();
    black_box(g.get(inputs.sigma));
    tape.recycle(g);
}

fn bench_precision<F: Float>(c: &mut Criterion) {
    for (rays, samples) in bench::WORKLOADS {
        let (op, x) = setup::<F>(&bench::data(rays, samples));
        let id = format!("{rays}x{samples}");
        let mut group = c.benchmark_group(format!("composite/{}", F::NAME));
        group.throughput(Throughput::Elements((rays * samples) as u64));
        group.sample_size(10);
        group.bench_with_input(BenchmarkId::new("fused", &id), &x, |b, x| {
            b.iter(|| bench::fused_step(&op, x, true).unwrap())
        });
        let mut buffers = Buffers::new(&x);
        group.bench_with_input(BenchmarkId::new("fused-into", &id), &x, |b, x| {
            b.iter(|| bench::fused_step_into(&op, x, &mut buffers).unwrap())
        });
        group.bench_with_input(BenchmarkId::new("fused-one-pass", &id), &x, |b, x| {
            b.iter(|| bench::fused_step_one_pass(&op, x, &mut buffers).unwrap())
        });
        for (name, one_op) in [("fused-tape-mse", true), ("fused-tape-chain", false)] {
            let mut kept = Tape::new();
            group.bench_with_input(BenchmarkId::new(name, &id), &x, |b, x| {
                b.iter(|| fused_loss(&op, x, one_op, &mut kept))
            });
        }
        for (name, naive) in [("taped", false), ("taped-naive", true)] {
            group.bench_with_input(BenchmarkId::new(name, &id), &x, |b, x| {
                b.iter(|| bench::taped_step(&op, x, naive, true).unwrap())
            });
            let mut kept = Tape::new();
            group.bench_with_input(BenchmarkId::new(format!("{name}-reused"), &id), &x, |b, x| {
                b.iter(|| bench::taped_step_reused(&op, x, naive, &mut kept).unwrap())
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
    let d = bench::data_on(&offsets, 27);
    let (op, x) = setup::<F>(&d);
    let mut buffers = Buffers::new(&x);
    let mut group = c.benchmark_group(format!("composite/{}", F::NAME));
    group.throughput(Throughput::Elements(d.samples() as u64));
    group.sample_size(10);
    let id = "ragged-16384x0-54";
    group.bench_with_input(BenchmarkId::new("fused-into", id), &x, |b, x| {
        b.iter(|| bench::fused_step_into(&op, x, &mut buffers).unwrap())
    });
    group.bench_with_input(BenchmarkId::new("fused-one-pass", id), &x, |b, x| {
        b.iter(|| bench::fused_step_one_pass(&op, x, &mut buffers).unwrap())
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
