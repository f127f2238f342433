//! What it costs a 128³ × 4 `f32` grid (33.5 MB) to enter a training step: copied onto the
//! tape with `param(grid.clone())`, or lent from a `Params` store with `param_from`; and the
//! Adam update that is then the only per-step work on the parameter's data.
//!
//! `cargo bench -p fogray-benches --bench param_entry -- --warm-up-time 1 --measurement-time 3`

use criterion::{black_box, criterion_group, criterion_main, BatchSize, Criterion};
use fogray_tape::optim::{Adam, AdamConfig, ParamGradients};
use fogray_tape::params::Params;
use fogray_tape::Tape;
use ndarray::Array4;

const N: usize = 128;

fn grid() -> Array4<f32> {
    Array4::from_shape_fn((N, N, N, 4), |(i, j, k, c)| ((i + 2 * j + 3 * k + c) % 17) as f32 * 0.1)
}

fn entry(c: &mut Criterion) {
    let mut group = c.benchmark_group("grid 128^3x4 f32 enters a step");
    group.sample_size(20);
    let grid = grid();
    let mut tape = Tape::<f32>::new();
    group.bench_function("copy: clear + param(grid.clone())", |b| {
        b.iter(|| {
            tape.clear();
            black_box(tape.param(grid.clone()))
        })
    });
    let mut params = Params::<f32>::new();
    let id = params.add("grid", grid.clone()).expect("a fresh store");
    let mut tape = Tape::<f32>::new();
    group.bench_function("shared: clear + param_from(&params, id)", |b| {
        b.iter(|| {
            tape.clear();
            black_box(tape.param_from(&params, id).expect("the store's id"))
        })
    });
    group.finish();
}

fn update(c: &mut Criterion) {
    let mut group = c.benchmark_group("grid 128^3x4 f32 optimiser update");
    group.sample_size(20);
    let mut params = Params::<f32>::new();
    let id = params.add("grid", grid()).expect("a fresh store");
    let g = grid().mapv(|v| v - 0.8);
    let mut adam = Adam::new(AdamConfig::default()).expect("default settings");
    group.bench_function("adam step in place", |b| {
        b.iter_batched(
            || g.clone(),
            |g| {
                let mut grads = ParamGradients::new();
                grads.insert(&params, id, g).expect("the store's id");
                adam.step(&mut params, &grads).expect("a valid gradient")
            },
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

criterion_group!(benches, entry, update);
criterion_main!(benches);
