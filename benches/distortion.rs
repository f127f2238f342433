//! The distortion loss, forward + backward on a tape, on 4096 rays of 48 samples (a training
//! batch of the uniform sampler's shape: t over [2, 6], densities log-uniform in
//! [1e-2, 1e2]), f32 and f64:
//!
//! - `fused-tape`: [`DistortionLoss::apply`] and the tape's backward;
//! - `twin-tape`: [`twin::distortion_loss`], the pairwise form from tape primitives
//!   (1128 pairs a ray), and the tape's backward.
//!
//! Before criterion runs, the pair is timed interleaved, A B A B ..., and the ratio of their
//! medians printed beside the largest difference between the two gradients: on a machine
//! shared with other work the ratio means more than criterion's absolute figures.
//!
//! `cargo bench -p fogray-benches --bench distortion` runs it all; `-- fused-tape/f32` selects.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput};
use fogray_ops::distortion::twin;
use fogray_ops::DistortionLoss;
use fogray_tape::{Float, Tape, TapeError};
use ndarray::Array1;
use rand::{Rng, SeedableRng};

const RAYS: usize = 4096;
const SAMPLES: usize = 48;

struct Inputs<F: Float> {
    sigma: Array1<F>,
    delta: Array1<F>,
    t: Array1<F>,
}

fn inputs<F: Float>() -> Inputs<F> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let step = 4.0 / SAMPLES as f64;
    let n = RAYS * SAMPLES;
    Inputs {
        sigma: Array1::from_shape_simple_fn(n, || F::lit(10f64.powf(rng.gen_range(-2.0..2.0)))),
        delta: Array1::from_elem(n, F::lit(step)),
        t: Array1::from_shape_fn(n, |k| F::lit(2.0 + step * ((k % SAMPLES) as f64 + 0.5))),
    }
}

/// The loss and its gradient for sigma on a tape, fused or through the twin.
fn on_tape<F: Float>(op: &DistortionLoss, x: &Inputs<F>, fused: bool) -> Result<Array1<F>, TapeError> {
    let mut tape = Tape::new();
    let sigma = tape.param(x.sigma.clone());
    let delta = tape.constant(x.delta.clone());
    let t = tape.constant(x.t.clone());
    let loss = if fused {
        op.apply(&mut tape, sigma, delta, t)?
    } else {
        twin::distortion_loss(&mut tape, op, sigma, delta, t)?
    };
    let grads = tape.backward(loss)?;
    let g = grads.get(sigma).expect("sigma is a param").to_owned();
    Ok(black_box(g.into_dimensionality().expect("sigma is 1-d")))
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

fn ratio<F: Float>(op: &DistortionLoss) {
    let x = inputs::<F>();
    let g_fused = on_tape(op, &x, true).unwrap();
    let g_twin = on_tape(op, &x, false).unwrap();
    let max_diff = g_fused
        .iter()
        .zip(&g_twin)
        .map(|(a, b)| (a.as_f64() - b.as_f64()).abs())
        .fold(0.0, f64::max);
    let max_grad = g_fused.iter().map(|g| g.as_f64().abs()).fold(0.0, f64::max);
    let (fused_s, twin_s) = interleaved(
        7,
        || {
            on_tape(op, &x, true).unwrap();
        },
        || {
            on_tape(op, &x, false).unwrap();
        },
    );
    println!(
        "interleaved medians, {}: twin-tape / fused-tape = {:.1} (fused {:.2} ms, twin {:.2} ms on this \
         run); max |dL/dsigma fused - twin| = {max_diff:.2e} (largest |dL/dsigma| {max_grad:.2e})",
        F::NAME,
        twin_s / fused_s,
        fused_s * 1e3,
        twin_s * 1e3,
    );
}

fn bench_precision<F: Float>(c: &mut Criterion, op: &DistortionLoss) {
    let mut group = c.benchmark_group(format!("distortion/{}", F::NAME));
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(2));
    group.throughput(Throughput::Elements((RAYS * SAMPLES) as u64));
    let x = inputs::<F>();
    let id = format!("{RAYS}x{SAMPLES}");
    group.bench_function(BenchmarkId::new("fused-tape", &id), |bench| {
        bench.iter(|| on_tape(op, &x, true).unwrap())
    });
    group.bench_function(BenchmarkId::new("twin-tape", &id), |bench| {
        bench.iter(|| on_tape(op, &x, false).unwrap())
    });
    group.finish();
}

fn main() {
    let op = DistortionLoss::new(&(0..=RAYS).map(|r| r * SAMPLES).collect::<Vec<_>>()).unwrap();
    ratio::<f32>(&op);
    ratio::<f64>(&op);
    let mut c = Criterion::default().configure_from_args();
    bench_precision::<f32>(&mut c, &op);
    bench_precision::<f64>(&mut c, &op);
    c.final_summary();
}
