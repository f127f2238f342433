//! Criterion benches: the fused grid field against its taped twin, forward + backward into
//! the grid values (and the fused forward alone), 4,194,304 lookups (the twin: a quarter of
//! them, its memory being about a hundred times the op's) at uniform random positions in
//! 128^3 x 4 and 64^3 x 4 grids, as `fogray-lab bench --op grid` measures them; and the grid
//! example's case (`grid/<prec>/fused-rays/64^3x4`): 8192 rays through random points of the
//! box in random directions, a sample every half cell, in ray order, so that consecutive
//! lookups fall in neighbouring cells; `fused-rays-into` runs them through `evaluate_into` and
//! `vjp_into` into buffers kept across runs.
//!
//! `cargo bench -p fogray-benches --bench grid` runs them all; `cargo bench -p fogray-benches --bench grid
//! -- fused/f32` selects.
//! `fogray-lab bench --op grid` gives the same speeds beside each method's error and memory.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fogray_ops::grid::twin;
use fogray_ops::{GridBox, GridField, GridGradientBuffers, GridWanted};
use fogray_tape::{Float, Tape};
use ndarray::{Array2, ArrayD, IxDyn};
use rand::{Rng, SeedableRng};

const LOOKUPS: usize = 1 << 22;
const CHANNELS: usize = 4;

struct Inputs<F: Float> {
    field: GridField,
    grid: ArrayD<F>,
    positions: Array2<F>,
    upstream: ArrayD<F>,
}

/// Grid values and dL/doutput ~ U[-1, 1], positions uniform in the unit cube.
fn inputs<F: Float>(nodes: usize, lookups: usize) -> Inputs<F> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let mut u = |lo: f64, hi: f64, len: usize| -> Vec<F> { (0..len).map(|_| F::lit(rng.gen_range(lo..hi))).collect() };
    let shape = [nodes, nodes, nodes, CHANNELS];
    let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
    Inputs {
        field: GridField::new(bbox, &shape).unwrap(),
        grid: ArrayD::from_shape_vec(IxDyn(&shape), u(-1.0, 1.0, nodes.pow(3) * CHANNELS)).unwrap(),
        positions: Array2::from_shape_vec((lookups, 3), u(0.0, 1.0, 3 * lookups)).unwrap(),
        upstream: ArrayD::from_shape_vec(vec![lookups, CHANNELS], u(-1.0, 1.0, lookups * CHANNELS)).unwrap(),
    }
}

/// Samples along `rays` random rays across the unit cube, every half cell of a grid of
/// `nodes` nodes per axis, in ray order (the order of a renderer's packed samples).
fn ray_ordered(nodes: usize, rays: usize) -> Vec<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let step = 0.5 / (nodes - 1) as f64;
    let mut pts = Vec::new();
    for _ in 0..rays {
        let o: [f64; 3] = std::array::from_fn(|_| rng.gen_range(0.0..1.0));
        let d: [f64; 3] = loop {
            let d: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
            let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            if (1e-3..=1.0).contains(&norm) {
                break d.map(|x| x / norm);
            }
        };
        // The line through o crosses the cube for t in [near, far].
        let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
        for a in 0..3 {
            let (t0, t1) = (-o[a] / d[a], (1.0 - o[a]) / d[a]);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        let mut t = near + step / 2.0;
        while t < far {
            pts.extend((0..3).map(|a| (o[a] + t * d[a]).clamp(0.0, 1.0)));
            t += step;
        }
    }
    pts
}

fn fused<F: Float>(x: &Inputs<F>, backward: bool) {
    let p = x.positions.view().into_dyn();
    let out = x.field.evaluate(&x.grid.view(), &p).unwrap();
    if backward {
        let wanted = GridWanted {
            grid: true,
            positions: false,
        };
        black_box(x.field.vjp(&x.grid.view(), &p, &x.upstream.view(), wanted).unwrap());
    }
    black_box(out);
}

/// Forward + backward into the grid through `evaluate_into` / `vjp_into`, into buffers kept
/// across runs (a training loop's steady state).
fn fused_into<F: Float>(x: &Inputs<F>, out: &mut ArrayD<F>, dgrid: &mut ArrayD<F>) {
    let p = x.positions.view().into_dyn();
    x.field.evaluate_into(&x.grid.view(), &p, &mut out.view_mut()).unwrap();
    let mut buffers = GridGradientBuffers {
        grid: Some(dgrid.view_mut()),
        positions: None,
    };
    x.field
        .vjp_into(&x.grid.view(), &p, &x.upstream.view(), &mut buffers)
        .unwrap();
    black_box((out, dgrid));
}

fn taped<F: Float>(x: &Inputs<F>) {
    let mut tape = Tape::new();
    let grid = tape.param(x.grid.clone());
    let positions = tape.constant(x.positions.clone());
    let out = twin::lookup(&mut tape, &x.field, grid, positions).unwrap();
    let g = tape.backward_with(out, x.upstream.clone()).unwrap();
    black_box(g.get(grid));
}

fn bench_precision<F: Float>(c: &mut Criterion) {
    for nodes in [128, 64] {
        let id = format!("{nodes}^3x{CHANNELS}");
        let mut group = c.benchmark_group(format!("grid/{}", F::NAME));
        group.sample_size(10);
        let x = inputs::<F>(nodes, LOOKUPS);
        group.throughput(Throughput::Elements(LOOKUPS as u64));
        group.bench_with_input(BenchmarkId::new("fused", &id), &x, |b, x| b.iter(|| fused(x, true)));
        group.bench_with_input(BenchmarkId::new("fused-forward", &id), &x, |b, x| {
            b.iter(|| fused(x, false))
        });
        drop(x);
        let x = inputs::<F>(nodes, LOOKUPS / 4);
        group.throughput(Throughput::Elements((LOOKUPS / 4) as u64));
        group.bench_with_input(BenchmarkId::new("taped", &id), &x, |b, x| b.iter(|| taped(x)));
        group.finish();
    }
}

/// The grid example's lookups: 64^3 x 4, 8192 rays, ray-ordered samples.
fn bench_rays<F: Float>(c: &mut Criterion) {
    let nodes = 64;
    let positions = ray_ordered(nodes, 8192);
    let n = positions.len() / 3;
    let mut x = inputs::<F>(nodes, n);
    x.positions = Array2::from_shape_vec((n, 3), positions.iter().map(|&v| F::lit(v)).collect()).unwrap();
    let mut group = c.benchmark_group(format!("grid/{}", F::NAME));
    group.sample_size(10);
    group.throughput(Throughput::Elements(n as u64));
    let id = format!("{nodes}^3x{CHANNELS}");
    group.bench_with_input(BenchmarkId::new("fused-rays", &id), &x, |b, x| {
        b.iter(|| fused(x, true))
    });
    group.bench_with_input(BenchmarkId::new("fused-rays-forward", &id), &x, |b, x| {
        b.iter(|| fused(x, false))
    });
    let mut out = ArrayD::zeros(vec![n, CHANNELS]);
    let mut dgrid = ArrayD::zeros(x.grid.shape());
    group.bench_with_input(BenchmarkId::new("fused-rays-into", &id), &x, |b, x| {
        b.iter(|| fused_into(x, &mut out, &mut dgrid))
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    bench_rays::<f32>(c);
    bench_precision::<f32>(c);
    bench_precision::<f64>(c);
}

criterion_group!(grid, benches);
criterion_main!(grid);
