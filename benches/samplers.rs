//! Criterion benches of the samplers on the grid example's workload: 32 cameras on a sphere
//! of radius 3 looking at the origin, 64x64 pixels, 40 degrees vertically; batches of 8192
//! random (camera, pixel) rays clipped to [-1, 1]^3; a scene that is one ball of radius 0.45
//! (density 50), the rest empty. Samples per ray of each sampler are printed first.
//!
//! `cargo bench -p fogray-benches --bench samplers -- --warm-up-time 1 --measurement-time 3`

mod common;
use common::{cameras, picks, RAYS};

use std::convert::Infallible;
use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fogray_ops::rays::{rays_for_camera_pixels, Aabb, RayBatch, RayIntervals};
use fogray_ops::sample::{
    CellPoints, Importance, Jitter, OccupancyConfig, OccupancyGrid, Spacing, Stratified, Uniform,
};
use fogray_ops::{Background, Composite, CompositeArrays};
use ndarray::{Array1, Array2, ArrayView2};

const STEP: f64 = 1.0 / 64.0; // half a voxel of a 64^3 grid over [-1, 1]^3
const RADIUS: f64 = 0.45;

fn ball(p: ArrayView2<'_, f32>) -> Result<Array1<f32>, Infallible> {
    let r2 = (RADIUS * RADIUS) as f32;
    Ok(Array1::from_iter(p.rows().into_iter().map(|q| {
        if q.dot(&q) < r2 {
            50.0
        } else {
            0.0
        }
    })))
}

fn occupancy(resolution: usize) -> OccupancyGrid {
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    let mut grid = OccupancyGrid::new(bounds, resolution, OccupancyConfig::opacity(STEP, 0.01).unwrap()).unwrap();
    grid.update(ball, CellPoints::Centre).unwrap();
    grid
}

/// The composite's weights for `samples` in the ball scene (for the importance sampler).
fn weights(s: &fogray_ops::sample::PackedSamples<f32>) -> Array1<f32> {
    let op = Composite::new(&s.offsets)
        .unwrap()
        .background(Background::None)
        .with_weights();
    let sigma = ball(s.positions.view()).unwrap().into_dyn();
    let color = Array2::<f32>::ones((s.len(), 1)).into_dyn();
    let delta = s.delta.clone().into_dyn();
    let (outs, _) = op
        .evaluate(&CompositeArrays::new(sigma.view(), delta.view(), color.view()))
        .unwrap();
    let weights = outs.weights.expect("the op was built with weights");
    weights.into_dimensionality().unwrap()
}

/// CPU seconds of this process so far (user + system, all threads; Linux only, else 0):
/// on a machine shared with other jobs, wall time measures the load more than the code.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // After the command name (which ends with ')') come the state, then numbers; utime and
    // stime are the 12th and 13th fields after it, in clock ticks of 1/100 s.
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok());
    tick(11).zip(tick(12)).map_or(0.0, |(u, s)| (u + s) / 100.0)
}

/// Mean CPU milliseconds per call of `f` over enough calls for the 10 ms tick to matter little.
fn cpu_ms<T>(mut f: impl FnMut() -> T) -> f64 {
    let (start, mut calls) = (cpu_seconds(), 0);
    // At most 200 calls, in case the CPU time cannot be read.
    while cpu_seconds() - start < 1.0 && calls < 200 {
        black_box(f());
        calls += 1;
    }
    1000.0 * (cpu_seconds() - start) / calls as f64
}

fn report(rays: &RayBatch<f32>, clip: &RayIntervals) {
    let hits = clip.hit().iter().filter(|&&h| h).count();
    let uniform = Uniform::new(Spacing::Step(STEP)).unwrap().sample(rays, clip).unwrap();
    println!("{RAYS} rays, {hits} hit the box; step {STEP}; ball of radius {RADIUS}");
    let u = Uniform::new(Spacing::Step(STEP)).unwrap();
    println!(
        "uniform: {:.1} samples per ray, {:.1} ms CPU per batch",
        uniform.samples_per_ray(),
        cpu_ms(|| u.sample(rays, clip).unwrap())
    );
    let strat = Stratified::new(Spacing::Step(STEP), Jitter::PerSample { seed: 3 }).unwrap();
    let s = strat.sample(rays, clip).unwrap();
    println!(
        "stratified per sample: {:.1} samples per ray, {:.1} ms CPU per batch",
        s.samples_per_ray(),
        cpu_ms(|| strat.sample(rays, clip).unwrap())
    );
    let coarse = Uniform::new(Spacing::Count(32)).unwrap().sample(rays, clip).unwrap();
    let w = weights(&coarse);
    let imp = Importance::new(64, 0.01, Jitter::PerRay { seed: 5 }).unwrap();
    let fine = imp.sample(rays, &coarse, w.view()).unwrap();
    println!(
        "importance 64 from 32 uniform: {:.1} samples per ray, {:.1} ms CPU per batch",
        fine.samples_per_ray(),
        cpu_ms(|| imp.sample(rays, &coarse, w.view()).unwrap())
    );
    for r in [32, 64, 128] {
        let g = occupancy(r);
        let m = g.march(rays, clip, STEP, Jitter::None).unwrap();
        println!(
            "occupancy {r}^3 ({:.2} % occupied): {:.1} samples per ray ({:.1}x fewer), {:.1} ms CPU per batch, update {:.1} ms CPU",
            100.0 * g.occupied_fraction(),
            m.samples_per_ray(),
            uniform.samples_per_ray() / m.samples_per_ray(),
            cpu_ms(|| g.march(rays, clip, STEP, Jitter::None).unwrap()),
            cpu_ms(|| occupancy(r)),
        );
        let p = g.march_midpoints(rays, clip, STEP, Jitter::None).unwrap();
        println!(
            "  midpoints {r}^3: {:.1} samples per ray, {:.1} ms CPU per batch",
            p.samples_per_ray(),
            cpu_ms(|| g.march_midpoints(rays, clip, STEP, Jitter::None).unwrap()),
        );
    }
    report_random_updates(rays, clip, uniform.samples_per_ray());
}

/// The 64^3 grid after eight updates at the centre and a random point of each cell: it also
/// marks the cells the ball reaches without covering their centres.
fn report_random_updates(rays: &RayBatch<f32>, clip: &RayIntervals, uniform_per_ray: f64) {
    let mut g = occupancy(64);
    for seed in 0..8 {
        g.update(ball, CellPoints::CentreAndRandom { seed }).unwrap();
    }
    let m = g.march(rays, clip, STEP, Jitter::None).unwrap();
    println!(
        "occupancy 64^3 after 8 centre+random updates ({:.2} % occupied): {:.1} samples per ray ({:.1}x fewer)",
        100.0 * g.occupied_fraction(),
        m.samples_per_ray(),
        uniform_per_ray / m.samples_per_ray()
    );
}

fn samplers(c: &mut Criterion) {
    let cams = cameras();
    let rays = rays_for_camera_pixels::<f32>(&cams, &picks(&cams, 1)).unwrap();
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    let clip = bounds.clip(&rays);
    report(&rays, &clip);
    let coarse = Uniform::new(Spacing::Count(32)).unwrap().sample(&rays, &clip).unwrap();
    let w = weights(&coarse);
    let grid64 = occupancy(64);
    let mut g = c.benchmark_group("samplers");
    g.throughput(Throughput::Elements(RAYS as u64));
    g.bench_function("rays-8192", |b| {
        b.iter(|| rays_for_camera_pixels::<f32>(&cams, black_box(&picks(&cams, 2))).unwrap())
    });
    g.bench_function("clip", |b| b.iter(|| bounds.clip(black_box(&rays))));
    let uniform = Uniform::new(Spacing::Step(STEP)).unwrap();
    g.bench_function("uniform", |b| {
        b.iter(|| uniform.sample(black_box(&rays), &clip).unwrap())
    });
    let strat = Stratified::new(Spacing::Step(STEP), Jitter::PerSample { seed: 3 }).unwrap();
    g.bench_function("stratified-per-sample", |b| {
        b.iter(|| strat.sample(black_box(&rays), &clip).unwrap())
    });
    let imp = Importance::new(64, 0.01, Jitter::PerRay { seed: 5 }).unwrap();
    g.bench_function("importance-64-from-32", |b| {
        b.iter(|| imp.sample(black_box(&rays), &coarse, w.view()).unwrap())
    });
    g.bench_function("occupancy-64-march", |b| {
        b.iter(|| grid64.march(black_box(&rays), &clip, STEP, Jitter::None).unwrap())
    });
    g.bench_function("occupancy-64-midpoints", |b| {
        b.iter(|| {
            grid64
                .march_midpoints(black_box(&rays), &clip, STEP, Jitter::None)
                .unwrap()
        })
    });
    g.finish();
    let mut u = c.benchmark_group("occupancy-update");
    u.sample_size(10);
    let mut grid = occupancy(64);
    u.bench_function("64^3-centre", |b| {
        b.iter(|| grid.update(ball, CellPoints::Centre).unwrap())
    });
    u.finish();
}

criterion_group!(benches, samplers);
criterion_main!(benches);
