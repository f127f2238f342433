//! Criterion benches: rows of a table gathered by index and the gradient scattered back, on a
//! 2-D grid renderer's bilinear lookups (110,592 corner indices into a [1024, 3] colour table,
//! f32: the 4 corners of each of 27,648 samples in a 32x32 grid, from 8 cameras of 64 pixels
//! at up to 64 samples a ray).
//!
//! `taped` is `Tape::gather` and a backward seeded with an upstream gradient on a new tape each
//! time; `taped-reused` keeps one tape (cleared each time, its buffer pool reused); `plain-loop`
//! does the same work in two loops over slices with fresh output buffers, the floor a taped op
//! is measured against. `cargo bench -p fogray-benches --bench gather` runs them.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fogray_tape::Tape;
use ndarray::{Array2, ArrayD};
use rand::{Rng, SeedableRng};

const ROWS: usize = 1024;
const COLUMNS: usize = 3;
const INDICES: usize = 110_592;

struct Case {
    table: Array2<f32>,
    indices: Vec<usize>,
    upstream: ArrayD<f32>,
}

fn case() -> Case {
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    Case {
        table: Array2::from_shape_fn((ROWS, COLUMNS), |_| rng.gen_range(0.0..1.0)),
        indices: (0..INDICES).map(|_| rng.gen_range(0..ROWS)).collect(),
        upstream: ArrayD::from_shape_fn(vec![INDICES, COLUMNS], |_| rng.gen_range(-1.0..1.0)),
    }
}

/// One gather forward and backward on `tape`, which is cleared first; the gradients go back
/// to it.
fn taped(x: &Case, tape: &mut Tape<f32>) {
    tape.clear();
    let table = tape.param(x.table.clone());
    let rows = tape.gather(table, &x.indices).unwrap();
    let g = tape.backward_with(rows, x.upstream.clone()).unwrap();
    black_box(g.get(table));
    tape.recycle(g);
}

/// The same work without a tape: copy each picked row out, add each upstream row back in.
fn plain_loop(x: &Case) {
    let table = x.table.as_slice().unwrap();
    let upstream = x.upstream.as_slice().unwrap();
    let mut rows = vec![0.0f32; INDICES * COLUMNS];
    for (out, &i) in rows.chunks_exact_mut(COLUMNS).zip(&x.indices) {
        out.copy_from_slice(&table[i * COLUMNS..(i + 1) * COLUMNS]);
    }
    let mut grad = vec![0.0f32; ROWS * COLUMNS];
    for (g, &i) in upstream.chunks_exact(COLUMNS).zip(&x.indices) {
        for (acc, &v) in grad[i * COLUMNS..(i + 1) * COLUMNS].iter_mut().zip(g) {
            *acc += v;
        }
    }
    black_box((rows, grad));
}

fn benches(c: &mut Criterion) {
    let x = case();
    let mut group = c.benchmark_group("gather/f32/110592x[1024,3]");
    group.throughput(Throughput::Elements(INDICES as u64));
    group.bench_function("taped", |b| b.iter(|| taped(&x, &mut Tape::new())));
    let mut kept = Tape::new();
    group.bench_function("taped-reused", |b| b.iter(|| taped(&x, &mut kept)));
    group.bench_function("plain-loop", |b| b.iter(|| plain_loop(&x)));
    group.finish();
}

criterion_group!(gather, benches);
criterion_main!(gather);
