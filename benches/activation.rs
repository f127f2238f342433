//! The density/colour activation, forward + backward, on 1,048,576 rows of 4 raw values
//! ~ U[-8, 8] (upstream gradients ~ U[-1, 1]), f32 and f64:
//!
//! - `fused`: [`DensityColor::evaluate_into`] + [`DensityColor::vjp_into`] into buffers kept
//!   across iterations;
//! - `libm`: the same work per element through the C library's f64 `exp` and `ln_1p` (the grid
//!   example's activation before this op: parallel over the same chunks, slope `y (1 - y)`);
//! - `fused-tape` and `twin-tape`: the fused op and its taped twin on a tape, with the loss
//!   `sum(ws sigma) + sum(wc color)` and its backward (the same five extra records for both).
//!
//! Before criterion runs, the pairs (fused, libm) and (fused-tape, twin-tape) are timed
//! interleaved, A B A B ..., and the ratios of their medians printed: on a machine shared with
//! other work these ratios mean more than criterion's absolute figures.
//!
//! `cargo bench -p fogray-benches --bench activation` runs it all; `-- fused/f32` selects.

use std::hint::black_box;
use std::time::Instant;

use criterion::{BenchmarkId, Criterion, Throughput};
use fogray_ops::activation::{twin, DensityColor};
use fogray_ops::{ActivatedGrads, ActivatedMut};
use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

const ROWS: usize = 1 << 20;
const K: usize = 4;
const SHIFT: f64 = -4.0;

struct Inputs<F: Float> {
    raw: Array2<F>,
    g_sigma: Array1<F>,
    g_color: Array2<F>,
}

struct Buffers<F: Float> {
    sigma: Array1<F>,
    color: Array2<F>,
    g_raw: Array2<F>,
}

fn inputs<F: Float>() -> (Inputs<F>, Buffers<F>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let mut u = |scale: f64| F::lit(rng.gen_range(-scale..scale));
    let x = Inputs {
        raw: Array2::from_shape_simple_fn((ROWS, K), || u(8.0)),
        g_sigma: Array1::from_shape_simple_fn(ROWS, || u(1.0)),
        g_color: Array2::from_shape_simple_fn((ROWS, K - 1), || u(1.0)),
    };
    let b = Buffers {
        sigma: Array1::zeros(ROWS),
        color: Array2::zeros((ROWS, K - 1)),
        g_raw: Array2::zeros((ROWS, K)),
    };
    (x, b)
}

fn fused<F: Float>(op: &DensityColor, x: &Inputs<F>, b: &mut Buffers<F>) {
    let out = ActivatedMut {
        sigma: b.sigma.view_mut(),
        color: b.color.view_mut(),
    };
    op.evaluate_into(x.raw.view(), out).unwrap();
    let upstream = ActivatedGrads {
        sigma: Some(x.g_sigma.view()),
        color: Some(x.g_color.view()),
    };
    op.vjp_into(x.raw.view(), &upstream, b.g_raw.view_mut()).unwrap();
    black_box(&b.g_raw);
}

/// The grid example's activation kernel before the fused op, per element through libm in f64.
mod libm_form {
    use super::*;

    const CHUNK: usize = 4096;

    fn softplus(x: f64) -> f64 {
        x.max(0.0) + (-x.abs()).exp().ln_1p()
    }

    fn sigmoid(x: f64) -> f64 {
        x.min(0.0).exp() / (1.0 + (-x.abs()).exp())
    }

    pub(super) fn run<F: Float>(x: &Inputs<F>, b: &mut Buffers<F>) {
        let raw = x.raw.as_slice().unwrap();
        let sigma = b.sigma.as_slice_mut().unwrap();
        let color = b.color.as_slice_mut().unwrap();
        sigma
            .par_chunks_mut(CHUNK)
            .zip(color.par_chunks_mut(3 * CHUNK))
            .zip(raw.par_chunks(K * CHUNK))
            .for_each(|((s, c), r)| {
                for ((s, c), r) in s.iter_mut().zip(c.chunks_exact_mut(3)).zip(r.chunks_exact(K)) {
                    *s = F::lit(softplus(r[0].as_f64() + SHIFT));
                    for k in 0..3 {
                        c[k] = F::lit(sigmoid(r[k + 1].as_f64()));
                    }
                }
            });
        let (gs, gc) = (x.g_sigma.as_slice().unwrap(), x.g_color.as_slice().unwrap());
        let color = b.color.as_slice().unwrap();
        let g = b.g_raw.as_slice_mut().unwrap();
        g.par_chunks_mut(K * CHUNK).enumerate().for_each(|(chunk, g)| {
            for (k, g) in g.chunks_exact_mut(K).enumerate() {
                let i = chunk * CHUNK + k;
                g[0] = gs[i] * F::lit(sigmoid(raw[K * i].as_f64() + SHIFT));
                for c in 0..3 {
                    let s = color[3 * i + c];
                    g[c + 1] = gc[3 * i + c] * s * (F::one() - s);
                }
            }
        });
        black_box(&b.g_raw);
    }
}

/// Forward and backward on a tape, fused or through the twin.
fn on_tape<F: Float>(op: &DensityColor, x: &Inputs<F>, fused: bool) -> Result<(), TapeError> {
    let mut tape = Tape::new();
    let raw = tape.param(x.raw.clone());
    let out = if fused {
        op.apply(&mut tape, raw)?
    } else {
        twin::density_color(&mut tape, op, raw)?
    };
    let weighted = |tape: &mut Tape<F>, v: Var, w: Var| -> Result<Var, TapeError> {
        let p = tape.mul(v, w)?;
        tape.sum(p)
    };
    let ws = tape.constant(x.g_sigma.clone());
    let wc = tape.constant(x.g_color.clone());
    let s = weighted(&mut tape, out.sigma, ws)?;
    let c = weighted(&mut tape, out.color, wc)?;
    let loss = tape.add(s, c)?;
    black_box(tape.backward(loss)?.get(raw));
    Ok(())
}

/// Median seconds of `a` and of `b`, run alternately `rounds` times each after a warm-up.
fn interleaved(rounds: usize, mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64) {
    a();
    b();
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        let t = Instant::now();
        a();
        ta.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        b();
        tb.push(t.elapsed().as_secs_f64());
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(&mut ta), median(&mut tb))
}

fn ratios<F: Float>(op: &DensityColor) {
    let (x, mut b) = inputs::<F>();
    let mut b2 = inputs::<F>().1;
    let (fused_s, libm_s) = interleaved(15, || fused(op, &x, &mut b), || libm_form::run(&x, &mut b2));
    let (tape_s, twin_s) = interleaved(7, || on_tape(op, &x, true).unwrap(), || on_tape(op, &x, false).unwrap());
    println!(
        "interleaved medians, {}: libm / fused = {:.2}, twin-tape / fused-tape = {:.2} \
         (fused {:.2} ms, fused-tape {:.2} ms on this run; absolute figures need a quiet machine)",
        F::NAME,
        libm_s / fused_s,
        twin_s / tape_s,
        fused_s * 1e3,
        tape_s * 1e3
    );
}

fn bench_precision<F: Float>(c: &mut Criterion, op: &DensityColor) {
    let mut group = c.benchmark_group(format!("field/{}", F::NAME));
    group.sample_size(10);
    group.throughput(Throughput::Elements(ROWS as u64));
    let (x, mut b) = inputs::<F>();
    let id = format!("{ROWS}x{K}");
    group.bench_function(BenchmarkId::new("fused", &id), |bench| {
        bench.iter(|| fused(op, &x, &mut b))
    });
    group.bench_function(BenchmarkId::new("libm", &id), |bench| {
        bench.iter(|| libm_form::run(&x, &mut b))
    });
    group.bench_function(BenchmarkId::new("fused-tape", &id), |bench| {
        bench.iter(|| on_tape(op, &x, true).unwrap())
    });
    group.bench_function(BenchmarkId::new("twin-tape", &id), |bench| {
        bench.iter(|| on_tape(op, &x, false).unwrap())
    });
    group.finish();
}

fn main() {
    let op = DensityColor::new(SHIFT).unwrap();
    ratios::<f32>(&op);
    ratios::<f64>(&op);
    let mut c = Criterion::default().configure_from_args();
    bench_precision::<f32>(&mut c, &op);
    bench_precision::<f64>(&mut c, &op);
    c.final_summary();
}
