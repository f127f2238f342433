//! The GPU grid field and activations against the CPU ops (`fogray_ops::GridField`,
//! `fogray_ops::DensityColor`, `fogray_ops::ShColor`), element by element, in f32 (to 1e-6) and f64 (to 1e-12) of
//! the size of the terms each value is made of, on random positions and the hard ones: on
//! inner cell faces, on the max faces, at corners, outside every face, at infinities. Skipped,
//! with a message, where there is no CUDA driver or device.

use fogray_cuda::{device_for_tests, CudaDensityColor, CudaError, CudaGrid, CudaShDensityColor, DeviceFloat, GridSpec};
use fogray_ops::{ActivatedGrads, DensityColor, GridBox, GridField, GridWanted, ShColor};
use fogray_tape::Float;
use ndarray::{ArrayView2, ArrayViewD};
use rand::Rng;

use crate::common::rng;

const SPEC: GridSpec = GridSpec {
    min: [-1.0, 0.0, -0.5],
    max: [2.0, 1.0, 0.5],
    nodes: [5, 4, 3],
    channels: 4,
};

/// Random positions over a box a little larger than the grid's, and the hard ones.
fn positions(n: usize) -> Vec<f64> {
    let mut r = rng(5);
    let mut p = Vec::new();
    for _ in 0..n {
        for a in 0..3 {
            let (lo, hi) = (SPEC.min[a], SPEC.max[a]);
            let pad = 0.1 * (hi - lo);
            p.push(r.gen_range(lo - pad..hi + pad));
        }
    }
    let face = |a: usize, i: usize| SPEC.min[a] + i as f64 * (SPEC.max[a] - SPEC.min[a]) / (SPEC.nodes[a] - 1) as f64;
    // Every node (inner faces meet there), the box's corners, the max faces.
    for i in 0..SPEC.nodes[0] {
        for j in 0..SPEC.nodes[1] {
            for k in 0..SPEC.nodes[2] {
                p.extend([face(0, i), face(1, j), face(2, k)]);
            }
        }
    }
    p.extend([2.0, 0.3, 0.1, 0.25, 1.0, 0.1, 0.25, 0.3, 0.5, 2.0, 1.0, 0.5]);
    // Just outside each face, and infinities.
    p.extend([
        -1.0 - 1e-12,
        0.5,
        0.0,
        2.0 + 1e-12,
        0.5,
        0.0,
        0.5,
        -1e-300,
        0.0,
        0.5,
        0.5,
        0.5 + 1e-9,
    ]);
    p.extend([f64::INFINITY, 0.5, 0.0, 0.5, f64::NEG_INFINITY, 0.0]);
    p
}

fn cast<F: Float>(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F::lit(x)).collect()
}

/// Worst `|got - want| / max(scale, floor)` and where.
fn worst<F: Float + DeviceFloat>(got: &[F], want: &[F], scale: &[f64], floor: f64) -> (f64, usize) {
    assert_eq!(got.len(), want.len());
    let mut w = (0.0, 0);
    for (i, ((&g, &c), &s)) in got.iter().zip(want).zip(scale).enumerate() {
        let (g, c) = (DeviceFloat::to_f64(g), DeviceFloat::to_f64(c));
        // Equal values (infinities too) agree; anything else, NaN included, is measured.
        let e = if g == c { 0.0 } else { (g - c).abs() / s.max(floor) };
        if e > w.0 || e.is_nan() {
            w = (e, i);
        }
    }
    w
}

fn check_grid<F: Float + DeviceFloat>(grid_gpu: &CudaGrid, tol: f64, floor: f64) {
    let field = GridField::new(
        GridBox::new(&SPEC.min, &SPEC.max).unwrap(),
        &[SPEC.nodes[0], SPEC.nodes[1], SPEC.nodes[2], SPEC.channels],
    )
    .unwrap();
    let mut r = rng(9);
    let values: Vec<f64> = (0..SPEC.values()).map(|_| r.gen_range(-2.0..2.0)).collect();
    let pos = positions(3000);
    let n = pos.len() / 3;
    let up: Vec<f64> = (0..n * SPEC.channels).map(|_| r.gen_range(-1.0..1.0)).collect();
    let (g, p, u) = (cast::<F>(&values), cast::<F>(&pos), cast::<F>(&up));
    let shape = [SPEC.nodes[0], SPEC.nodes[1], SPEC.nodes[2], SPEC.channels];
    let gv = ArrayViewD::from_shape(&shape[..], &g).unwrap();
    let pv = ArrayViewD::from_shape(&[n, 3][..], &p).unwrap();
    let uv = ArrayViewD::from_shape(&[n, SPEC.channels][..], &u).unwrap();

    let cpu_out = field.evaluate(&gv, &pv).unwrap();
    let gpu_out = grid_gpu.evaluate(&g, &p).unwrap();
    // Scale of an output: the sum of |w_k v_k| <= max |v|.
    let vmax = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let (e_out, at_out) = worst(&gpu_out, cpu_out.as_slice().unwrap(), &vec![vmax; gpu_out.len()], floor);
    let same_bits = gpu_out
        .iter()
        .zip(cpu_out.iter())
        .all(|(a, b)| DeviceFloat::to_f64(*a).to_bits() == DeviceFloat::to_f64(*b).to_bits());

    let wanted = GridWanted {
        grid: true,
        positions: true,
    };
    let cpu = field.vjp(&gv, &pv, &uv, wanted).unwrap();
    let (gpu_grid, gpu_pos) = grid_gpu.vjp(&g, &p, &u).unwrap();
    // A node's scale: the sum of its terms' sizes, the CPU op's grid gradient for |upstream|
    // (the weights are non-negative).
    let abs_up: Vec<F> = u.iter().map(|x| x.abs()).collect();
    let auv = ArrayViewD::from_shape(&[n, SPEC.channels][..], &abs_up).unwrap();
    let node_scale: Vec<f64> = field
        .vjp(
            &gv,
            &pv,
            &auv,
            GridWanted {
                grid: true,
                positions: false,
            },
        )
        .unwrap()
        .grid
        .unwrap()
        .iter()
        .map(|v| DeviceFloat::to_f64(*v))
        .collect();
    let cpu_grid = cpu.grid.unwrap();
    let (e_grid, at_grid) = worst(&gpu_grid, cpu_grid.as_slice().unwrap(), &node_scale, floor);
    // A position's scale: du/dp times the sum over the corners of |v . g| <= 8 max|v| sum|g|.
    let pos_scale: Vec<f64> = (0..n)
        .flat_map(|s| {
            let gsum: f64 = up[s * SPEC.channels..(s + 1) * SPEC.channels]
                .iter()
                .map(|x| x.abs())
                .sum();
            (0..3).map(move |a| {
                let du = (SPEC.nodes[a] - 1) as f64 / (SPEC.max[a] - SPEC.min[a]);
                du * 8.0 * vmax * gsum
            })
        })
        .collect();
    let cpu_pos = cpu.positions.unwrap();
    let (e_pos, at_pos) = worst(&gpu_pos, cpu_pos.as_slice().unwrap(), &pos_scale, floor);
    println!(
        "{} grid field, {n} positions: max scaled error output {e_out:.2e}@{at_out} (bitwise the CPU op's: {same_bits}), grid gradient {e_grid:.2e}@{at_grid}, position gradient {e_pos:.2e}@{at_pos}",
        std::any::type_name::<F>()
    );
    assert!(
        e_out <= tol && e_grid <= tol && e_pos <= tol,
        "{e_out} {e_grid} {e_pos}"
    );
    assert!(same_bits, "the forward should have the CPU op's bits");
}

#[test]
fn the_grid_field_agrees_with_the_cpu_op() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let grid = CudaGrid::new(&gpu, SPEC).unwrap();
    check_grid::<f32>(&grid, 1e-6, 1e-30);
    check_grid::<f64>(&grid, 1e-12, 1e-290);
}

#[test]
fn bad_grids_and_nan_positions_are_errors() {
    // Spec checks need no device: a bad spec is refused before anything is compiled.
    if let Some(gpu) = device_for_tests().unwrap() {
        for bad in [
            GridSpec {
                nodes: [1, 4, 3],
                ..SPEC
            },
            GridSpec { channels: 0, ..SPEC },
            GridSpec {
                max: [-1.0, 1.0, 0.5],
                ..SPEC
            },
            GridSpec {
                min: [f64::NAN, 0.0, 0.0],
                ..SPEC
            },
        ] {
            assert!(
                matches!(CudaGrid::new(&gpu, bad), Err(CudaError::InvalidGrid(_))),
                "{bad:?}"
            );
        }
        let grid = CudaGrid::new(&gpu, SPEC).unwrap();
        let values = vec![0.5f32; SPEC.values()];
        assert!(matches!(
            grid.evaluate(&values, &[0.0, f32::NAN, 0.0]),
            Err(CudaError::InvalidSample)
        ));
        assert!(matches!(
            grid.evaluate(&values, &[0.0, 0.0]),
            Err(CudaError::Shape { .. })
        ));
        assert!(matches!(
            grid.evaluate(&values[1..], &[0.0; 3]),
            Err(CudaError::Shape { .. })
        ));
        let act = CudaDensityColor::new(&gpu, 0.0).unwrap();
        assert!(matches!(
            act.evaluate(&[0.0f32, f32::NAN], 2),
            Err(CudaError::InvalidSample)
        ));
        assert!(matches!(act.evaluate(&[0.0f32; 3], 2), Err(CudaError::Shape { .. })));
        assert!(matches!(
            CudaDensityColor::new(&gpu, f64::INFINITY),
            Err(CudaError::InvalidShift(_))
        ));
    }
}

fn check_activation<F: Float + DeviceFloat>(act: &CudaDensityColor, shift: f64, tol: f64) {
    let op = DensityColor::new(shift).unwrap();
    let k = 4;
    let mut r = rng(13);
    // Across the range, the saturated tails and the infinities included.
    let mut raw: Vec<f64> = (0..4000 * k).map(|_| r.gen_range(-30.0..30.0)).collect();
    raw.extend([0.0, 50.0, -800.0, 1e-8, -1e-8, 700.0, -700.0, 40.0]);
    raw.extend([f64::INFINITY, f64::NEG_INFINITY, 20.0, -20.0]);
    let n = raw.len() / k;
    let rf = cast::<F>(&raw);
    let rv = ArrayView2::from_shape((n, k), &rf).unwrap();
    let cpu = op.evaluate(rv).unwrap();
    let gpu = act.evaluate(&rf, k).unwrap();
    let rel = |v: &[F]| -> Vec<f64> { v.iter().map(|x| DeviceFloat::to_f64(*x).abs()).collect() };
    let floor = if F::SUFFIX == "f32" { 1e-37 } else { 1e-307 };
    let (e_s, at_s) = worst(
        &gpu.sigma,
        cpu.sigma.as_slice().unwrap(),
        &rel(cpu.sigma.as_slice().unwrap()),
        floor,
    );
    let (e_c, at_c) = worst(
        &gpu.color,
        cpu.color.as_slice().unwrap(),
        &rel(cpu.color.as_slice().unwrap()),
        floor,
    );
    let gs: Vec<F> = cast(&(0..n).map(|_| r.gen_range(-1.0..1.0)).collect::<Vec<_>>());
    let gc: Vec<F> = cast(&(0..n * (k - 1)).map(|_| r.gen_range(-1.0..1.0)).collect::<Vec<_>>());
    let upstream = ActivatedGrads {
        sigma: Some(ndarray::ArrayView1::from(&gs[..])),
        color: Some(ArrayView2::from_shape((n, k - 1), &gc).unwrap()),
    };
    let cpu_g = op.vjp(rv, &upstream).unwrap();
    let gpu_g = act.vjp(&rf, k, Some(&gs), Some(&gc)).unwrap();
    let (e_g, at_g) = worst(
        &gpu_g,
        cpu_g.as_slice().unwrap(),
        &rel(cpu_g.as_slice().unwrap()),
        floor,
    );
    // Absent upstream gradients read as zeros.
    let only_sigma = act.vjp(&rf, k, Some(&gs), None).unwrap();
    assert!(only_sigma
        .iter()
        .enumerate()
        .all(|(i, v)| i % k == 0 || DeviceFloat::to_f64(*v) == 0.0));
    println!(
        "{} activation (shift {shift}), {n} rows: max relative error sigma {e_s:.2e}@{at_s}, colour {e_c:.2e}@{at_c}, raw gradient {e_g:.2e}@{at_g}",
        std::any::type_name::<F>()
    );
    assert!(e_s <= tol && e_c <= tol && e_g <= tol, "{e_s} {e_c} {e_g}");
}

#[test]
fn the_activation_agrees_with_the_cpu_op() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    for shift in [0.0, -4.0] {
        let act = CudaDensityColor::new(&gpu, shift).unwrap();
        check_activation::<f32>(&act, shift, 1e-6);
        check_activation::<f64>(&act, shift, 1e-12);
    }
}

/// Unit directions: random ones, the axes both ways, and the diagonals.
fn unit_directions(n: usize) -> Vec<f64> {
    let mut r = rng(29);
    let mut d = Vec::new();
    for a in 0..3 {
        for sign in [1.0, -1.0] {
            d.extend((0..3).map(|b| if a == b { sign } else { 0.0 }));
        }
    }
    let k = 1.0 / 3f64.sqrt();
    d.extend([k, k, k, -k, k, -k]);
    while d.len() < 3 * n {
        let v: [f64; 3] = std::array::from_fn(|_| r.gen_range(-1.0..1.0));
        let len = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if len > 1e-3 {
            d.extend(v.iter().map(|x| x / len));
        }
    }
    d.truncate(3 * n);
    d
}

fn check_sh<F: Float + DeviceFloat>(gpu: &fogray_cuda::CudaComposite, degree: usize, shift: f64, tol: f64) {
    let sh = CudaShDensityColor::new(gpu, shift, degree).unwrap();
    let k = sh.channels();
    assert_eq!(k, 1 + 3 * (degree + 1) * (degree + 1));
    let n = 3000;
    let mut r = rng(31 + degree as u64);
    // Sums across the sigmoid's range and its saturated tails; densities from -800 to 800.
    let mut raw: Vec<f64> = (0..n * k).map(|_| r.gen_range(-30.0..30.0)).collect();
    for (i, v) in [0.0, 50.0, -800.0, 1e-8, -1e-8, 700.0, -700.0, 800.0]
        .into_iter()
        .enumerate()
    {
        raw[i * k] = v;
        raw[i * k + 1] = v;
    }
    let dirs = unit_directions(n);
    let (rf, df) = (cast::<F>(&raw), cast::<F>(&dirs));
    let rv = ArrayView2::from_shape((n, k), &rf).unwrap();
    let dv = ArrayView2::from_shape((n, 3), &df).unwrap();
    let density = DensityColor::new(shift).unwrap();
    let colour = ShColor::new(degree).unwrap();
    let cpu_sigma = density.density(rv).unwrap();
    let cpu_color = colour.evaluate(rv.slice(ndarray::s![.., 1..]), dv).unwrap();
    let out = sh.evaluate(&rf, &df).unwrap();
    let rel = |v: &[F]| -> Vec<f64> { v.iter().map(|x| DeviceFloat::to_f64(*x).abs()).collect() };
    let floor = if F::SUFFIX == "f32" { 1e-37 } else { 1e-307 };
    let cs = cpu_sigma.as_slice().unwrap();
    let cc = cpu_color.as_slice().unwrap();
    let (e_s, at_s) = worst(&out.sigma, cs, &rel(cs), floor);
    let (e_c, at_c) = worst(&out.color, cc, &rel(cc), floor);
    let gs: Vec<F> = cast(&(0..n).map(|_| r.gen_range(-1.0..1.0)).collect::<Vec<_>>());
    let gc: Vec<F> = cast(&(0..3 * n).map(|_| r.gen_range(-1.0..1.0)).collect::<Vec<_>>());
    let gcv = ArrayView2::from_shape((n, 3), &gc).unwrap();
    // The CPU gradient: the density's column from the activation (no colour upstream), the
    // coefficients' from the spherical harmonics.
    let mut cpu_g = density
        .vjp(
            rv,
            &ActivatedGrads {
                sigma: Some(ndarray::ArrayView1::from(&gs[..])),
                color: None,
            },
        )
        .unwrap();
    let coeffs = colour.vjp(rv.slice(ndarray::s![.., 1..]), dv, gcv).unwrap();
    cpu_g.slice_mut(ndarray::s![.., 1..]).assign(&coeffs);
    let gpu_g = sh.vjp(&rf, &df, &gs, &gc).unwrap();
    let cg = cpu_g.as_slice().unwrap();
    let (e_g, at_g) = worst(&gpu_g, cg, &rel(cg), floor);
    println!(
        "{} spherical harmonics degree {degree} (shift {shift}), {n} rows: max relative error sigma {e_s:.2e}@{at_s}, colour {e_c:.2e}@{at_c}, raw gradient {e_g:.2e}@{at_g}",
        std::any::type_name::<F>()
    );
    assert!(e_s <= tol && e_c <= tol && e_g <= tol, "{e_s} {e_c} {e_g}");
}

#[test]
fn the_spherical_harmonics_activation_agrees_with_the_cpu_ops() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    for degree in 0..=3 {
        check_sh::<f32>(&gpu, degree, -4.0, 1e-6);
        check_sh::<f64>(&gpu, degree, -4.0, 1e-12);
    }
    check_sh::<f64>(&gpu, 1, 0.0, 1e-12);
    assert!(matches!(
        CudaShDensityColor::new(&gpu, 0.0, 4),
        Err(CudaError::InvalidSettings(_))
    ));
    assert!(matches!(
        CudaShDensityColor::new(&gpu, f64::NAN, 1),
        Err(CudaError::InvalidShift(_))
    ));
    // A NaN coefficient is reported.
    let sh = CudaShDensityColor::new(&gpu, 0.0, 1).unwrap();
    let mut raw = vec![0.5f32; 13];
    raw[7] = f32::NAN;
    assert!(matches!(
        sh.evaluate(&raw, &[0.0, 0.0, 1.0]),
        Err(CudaError::InvalidSample)
    ));
    assert!(matches!(
        sh.evaluate(&raw[..12], &[0.0, 0.0, 1.0]),
        Err(CudaError::Shape { .. })
    ));
}
