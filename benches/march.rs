//! Criterion benches of the occupancy marcher on the grid example's training workload: a 63^3
//! occupancy grid over [-1, 1]^3 whose occupied cells are the grid example's default scene
//! (two spheres, a box and a floor slab) grown by 0.05, about a quarter of the cells, as a fit
//! learns it; batches of 8192 random (camera, pixel) rays from 32 cameras on a sphere of
//! radius 3 looking at the origin (64x64 pixels, 40 degrees); half-voxel steps (1/63).
//! Also the same rays through a grid with every cell occupied (nothing to skip) and one with
//! none. Each case twice: the march (cell by cell, `march`) and the midpoint sampler (each
//! uniform piece tested, `midpoints`). The occupied share and samples per ray are printed
//! first.
//!
//! `cargo bench -p fogray-benches --bench march -- --warm-up-time 1 --measurement-time 3`

mod common;
use common::{cameras, picks, RAYS};

use std::convert::Infallible;
use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fogray_ops::rays::{rays_for_camera_pixels, Aabb, RayBatch};
use fogray_ops::sample::{CellPoints, Jitter, OccupancyConfig, OccupancyGrid};
use ndarray::{Array1, ArrayView2};

const CELLS: usize = 63;
const STEP: f64 = 1.0 / 63.0; // half a cell of 63 over [-1, 1]
const MARGIN: f64 = 0.05;

/// 8192 random (camera, pixel) rays, as one training batch.
fn batch() -> RayBatch<f32> {
    let cams = cameras();
    rays_for_camera_pixels(&cams, &picks(&cams, 1)).unwrap()
}

/// 1 inside the default scene's primitives grown by `MARGIN`, 0 elsewhere.
fn scene(p: ArrayView2<'_, f32>) -> Result<Array1<f32>, Infallible> {
    let spheres = [([0.0, 0.0, 0.1], 0.45), ([0.45, 0.35, -0.2], 0.25)];
    let boxes = [
        ([-0.8, -0.7, -0.5], [-0.35, -0.1, 0.45]),
        ([-0.9, -0.9, -0.75], [0.9, 0.9, -0.6]),
    ];
    Ok(Array1::from_iter(p.rows().into_iter().map(|q| {
        let q = [q[0], q[1], q[2]].map(f64::from);
        let in_sphere = spheres
            .iter()
            .any(|(c, r): &([f64; 3], f64)| (0..3).map(|a| (q[a] - c[a]).powi(2)).sum::<f64>() < (r + MARGIN).powi(2));
        let in_box = boxes
            .iter()
            .any(|(lo, hi)| (0..3).all(|a| lo[a] - MARGIN < q[a] && q[a] < hi[a] + MARGIN));
        if in_sphere || in_box {
            1.0
        } else {
            0.0
        }
    })))
}

fn grid(fill: Option<f32>) -> OccupancyGrid {
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    let mut g = OccupancyGrid::new(bounds, CELLS, OccupancyConfig::density(0.5).unwrap()).unwrap();
    match fill {
        None => g.update(scene, CellPoints::Centre).unwrap(),
        Some(v) => g
            .update(
                |p: ArrayView2<'_, f32>| Ok::<_, Infallible>(Array1::from_elem(p.nrows(), v)),
                CellPoints::Centre,
            )
            .unwrap(),
    }
    g
}

fn march(c: &mut Criterion) {
    let rays = batch();
    let clip = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&rays);
    let cases = [
        ("scene", grid(None)),
        ("full", grid(Some(1.0))),
        ("empty", grid(Some(0.0))),
    ];
    for (name, g) in &cases {
        let s = g.march(&rays, &clip, STEP, Jitter::None).unwrap();
        let m = g.march_midpoints(&rays, &clip, STEP, Jitter::None).unwrap();
        println!(
            "{name}: {CELLS}^3 cells, {:.1} % occupied, {:.1} samples per ray marched, {:.1} by midpoints",
            100.0 * g.occupied_fraction(),
            s.samples_per_ray(),
            m.samples_per_ray()
        );
    }
    let mut group = c.benchmark_group("march");
    group.throughput(Throughput::Elements(RAYS as u64));
    for (name, g) in &cases {
        group.bench_function(format!("{CELLS}^3-{name}-march"), |b| {
            b.iter(|| g.march(black_box(&rays), &clip, STEP, Jitter::None).unwrap())
        });
        group.bench_function(format!("{CELLS}^3-{name}-midpoints"), |b| {
            b.iter(|| g.march_midpoints(black_box(&rays), &clip, STEP, Jitter::None).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, march);
criterion_main!(benches);
