//! `fogray-lab bench --op grid`: lookups per second of the fused grid field (1 thread and all)
//! and of its taped twin, forward + backward into the grid and forward alone, in f32 and
//! f64, each beside its error against a plain f64 loop on the same lookups and its peak
//! extra memory.

use std::hint::black_box;

use fogray_ops::grid::twin;
use fogray_ops::{GridBox, GridField, GridGradientBuffers, GridWanted};
use fogray_tape::{Float, Tape};
use ndarray::{Array2, ArrayD, IxDyn};
use rand::{Rng, SeedableRng};
use serde::Serialize;

use crate::bench::{median_secs, time_runs, within, Memory, Timing};
use crate::error::LabError;
use crate::reference::errors;

/// Nodes per axis of the workloads' cubic grids.
pub const GRIDS: [usize; 2] = [128, 64];
/// Channels per node.
const CHANNELS: usize = 4;
/// Lookups per run of the fused op.
pub const LOOKUPS: usize = 1 << 22;
/// Lookups per run of the taped twin: a quarter, since its values and gradients take about
/// a hundred times the op's memory (the rates are per lookup either way).
const TAPED_LOOKUPS: usize = LOOKUPS / 4;

/// One measurement (one JSON object of `{"results": [...]}`).
#[derive(Debug, Clone, Serialize)]
pub struct GridMeasurement {
    /// Always `"grid"`.
    pub op: &'static str,
    /// `"fused"` or `"taped"`.
    pub method: &'static str,
    /// `"f32"` or `"f64"`.
    pub precision: &'static str,
    /// Threads of the rayon pool the row ran on.
    pub threads: usize,
    /// Nodes per axis (the grid is `grid^3 x channels`).
    pub grid: usize,
    /// Values per node.
    pub channels: usize,
    /// Lookups per run.
    pub lookups: usize,
    /// Forward and backward into the grid values, from the median run.
    pub lookups_per_sec: f64,
    /// Interquartile range over the median of the forward+backward run times.
    pub lookups_per_sec_spread: f64,
    /// Forward and backward in a training loop's steady state (the same bits): fused through
    /// `evaluate_into` / `vjp_into` into an output and a gradient buffer kept across runs;
    /// taped on one tape cleared before each run, whose pool lends the ops the buffers of the
    /// run before.
    pub lookups_per_sec_reused: f64,
    /// The forward alone, from the median run.
    pub lookups_per_sec_forward: f64,
    /// Worst element-wise error of the output, relative to the size of its terms.
    pub err_output: f64,
    /// Worst element-wise error of dL/dgrid, relative to the size of its terms.
    pub err_grad_grid: f64,
    /// `||g - g_ref|| / ||g_ref||` of dL/dgrid.
    pub err_grad_grid_norm: f64,
    /// Peak bytes allocated during forward and backward, beyond the inputs.
    pub peak_extra_bytes: usize,
}

/// Grid values ~ U[-1, 1], positions uniform in the unit cube, dL/doutput ~ U[-1, 1], all
/// f32-representable so that both precisions see the same inputs.
struct Data {
    field: GridField,
    grid: Vec<f64>,
    positions: Vec<f64>,
    upstream: Vec<f64>,
}

fn data(nodes: usize) -> Result<Data, LabError> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2026);
    let mut u = |lo: f64, hi: f64| f64::from(rng.gen_range(lo..hi) as f32);
    let bbox = GridBox::new(&[0.0; 3], &[1.0; 3])?;
    let field = GridField::new(bbox, &[nodes, nodes, nodes, CHANNELS])?;
    Ok(Data {
        grid: (0..nodes.pow(3) * CHANNELS).map(|_| u(-1.0, 1.0)).collect(),
        positions: (0..LOOKUPS * 3).map(|_| u(0.0, 1.0)).collect(),
        upstream: (0..LOOKUPS * CHANNELS).map(|_| u(-1.0, 1.0)).collect(),
        field,
    })
}

/// The first `n` lookups' output and dL/dgrid by the textbook formula, one lookup at a time
/// in f64, with the size of the terms behind each value (for element-wise relative errors).
struct Reference {
    output: Vec<f64>,
    output_scale: Vec<f64>,
    grad: Vec<f64>,
    grad_scale: Vec<f64>,
}

fn reference(d: &Data, n: usize) -> Reference {
    let nodes = d.field.nodes()[0];
    let cells = (nodes - 1) as f64;
    let mut r = Reference {
        output: vec![0.0; n * CHANNELS],
        output_scale: vec![0.0; n * CHANNELS],
        grad: vec![0.0; d.grid.len()],
        grad_scale: vec![0.0; d.grid.len()],
    };
    for s in 0..n {
        let p = &d.positions[3 * s..3 * s + 3];
        let u: Vec<f64> = p.iter().map(|x| x * cells).collect();
        let cell: Vec<usize> = u.iter().map(|u| (u.floor() as usize).min(nodes - 2)).collect();
        for corner in 0..8 {
            let mut w = 1.0;
            let mut node = 0;
            for a in 0..3 {
                let upper = corner >> a & 1;
                let t = u[a] - cell[a] as f64;
                w *= if upper == 1 { t } else { 1.0 - t };
                node = node * nodes + cell[a] + upper;
            }
            for c in 0..CHANNELS {
                let (v, g) = (d.grid[node * CHANNELS + c], d.upstream[s * CHANNELS + c]);
                r.output[s * CHANNELS + c] += w * v;
                r.output_scale[s * CHANNELS + c] += (w * v).abs();
                r.grad[node * CHANNELS + c] += w * g;
                r.grad_scale[node * CHANNELS + c] += (w * g).abs();
            }
        }
    }
    r
}

/// The inputs in precision F.
struct Typed<F: Float> {
    grid: ArrayD<F>,
    positions: Array2<F>,
    upstream: ArrayD<F>,
}

fn typed<F: Float>(d: &Data, n: usize) -> Result<Typed<F>, LabError> {
    let cast = |v: &[f64]| v.iter().map(|&x| F::lit(x)).collect::<Vec<F>>();
    Ok(Typed {
        grid: ArrayD::from_shape_vec(IxDyn(d.field.shape()), cast(&d.grid))?,
        positions: Array2::from_shape_vec((n, 3), cast(&d.positions[..3 * n]))?,
        upstream: ArrayD::from_shape_vec(vec![n, CHANNELS], cast(&d.upstream[..n * CHANNELS]))?,
    })
}

const GRID_ONLY: GridWanted = GridWanted {
    grid: true,
    positions: false,
};

fn to_f64<F: Float>(v: &ArrayD<F>) -> Vec<f64> {
    v.iter().map(|x| x.as_f64()).collect()
}

/// The output and dL/dgrid of one run.
struct Values {
    output: Vec<f64>,
    grad: Vec<f64>,
}

/// [`Values`] and the run's peak extra bytes.
struct Outcome {
    values: Values,
    peak_extra: usize,
}

fn fused_step<F: Float>(field: &GridField, x: &Typed<F>, backward: bool) -> Result<Option<Values>, LabError> {
    let p = x.positions.view().into_dyn();
    let out = field.evaluate(&x.grid.view(), &p)?;
    if !backward {
        black_box(out);
        return Ok(None);
    }
    let g = field.vjp(&x.grid.view(), &p, &x.upstream.view(), GRID_ONLY)?;
    let grad = g.grid.ok_or(LabError::Missing("no grid gradient"))?;
    Ok(Some(Values {
        output: to_f64(&out),
        grad: to_f64(&grad),
    }))
}

/// The output and dL/dgrid buffers kept across fused runs.
struct Buffers<F: Float> {
    output: ArrayD<F>,
    grad: ArrayD<F>,
}

impl<F: Float> Buffers<F> {
    fn new(x: &Typed<F>) -> Self {
        Buffers {
            output: ArrayD::zeros(x.upstream.shape()),
            grad: ArrayD::zeros(x.grid.shape()),
        }
    }
}

/// [`fused_step`], forward and backward, through the `_into` calls into `b`.
fn fused_step_into<F: Float>(field: &GridField, x: &Typed<F>, b: &mut Buffers<F>) -> Result<(), LabError> {
    let p = x.positions.view().into_dyn();
    field.evaluate_into(&x.grid.view(), &p, &mut b.output.view_mut())?;
    let mut gradients = GridGradientBuffers {
        grid: Some(b.grad.view_mut()),
        positions: None,
    };
    field.vjp_into(&x.grid.view(), &p, &x.upstream.view(), &mut gradients)?;
    black_box(&b.grad);
    Ok(())
}

/// [`taped_step`] on one tape kept across runs: cleared first, its gradients handed back to it
/// after use (a training loop's steady state).
fn taped_step_reused<F: Float>(field: &GridField, x: &Typed<F>, tape: &mut Tape<F>) -> Result<(), LabError> {
    tape.clear();
    let (grid, positions) = put_inputs(tape, x);
    let out = twin::lookup(tape, field, grid, positions)?;
    let g = tape.backward_with(out, x.upstream.clone())?;
    black_box(g.get(grid));
    tape.recycle(g);
    Ok(())
}

/// A new tape with the grid as a param and the positions as a constant: the part of a taped
/// run that is not the op, timed separately and subtracted.
fn tape_with_inputs<F: Float>(x: &Typed<F>) -> (Tape<F>, fogray_tape::Var, fogray_tape::Var) {
    let mut tape = Tape::new();
    let (grid, positions) = put_inputs(&mut tape, x);
    (tape, grid, positions)
}

/// The grid as a param and the positions as a constant on `tape`.
fn put_inputs<F: Float>(tape: &mut Tape<F>, x: &Typed<F>) -> (fogray_tape::Var, fogray_tape::Var) {
    (tape.param(x.grid.clone()), tape.constant(x.positions.clone()))
}

fn taped_step<F: Float>(field: &GridField, x: &Typed<F>, backward: bool) -> Result<Option<Values>, LabError> {
    let (mut tape, grid, positions) = tape_with_inputs(x);
    let out = twin::lookup(&mut tape, field, grid, positions)?;
    if !backward {
        black_box(tape);
        return Ok(None);
    }
    let g = tape.backward_with(out, x.upstream.clone())?;
    let grad = g.get(grid).ok_or(LabError::Missing("no grid gradient"))?.to_owned();
    Ok(Some(Values {
        output: to_f64(&tape.value(out)?.to_owned()),
        grad: to_f64(&grad),
    }))
}

/// One forward + backward of `step`, measured for its peak extra memory and its values.
fn measured_run(
    mem: &dyn Memory,
    step: impl FnOnce() -> Result<Option<Values>, LabError>,
) -> Result<Outcome, LabError> {
    mem.reset();
    let values = step()?.ok_or(LabError::Missing("no values"))?;
    Ok(Outcome {
        values,
        peak_extra: mem.peak_since_reset(),
    })
}

/// Everything measured of one method on one workload, before it becomes a row.
struct Run {
    method: &'static str,
    threads: usize,
    lookups: usize,
    both: Timing,
    reused: f64,
    forward: f64,
    outcome: Outcome,
}

/// Runs every measurement of one grid size in precision F.
fn measure<F: Float>(
    d: &Data,
    refs: &(Reference, Reference),
    reps: usize,
    mem: &dyn Memory,
    out: &mut Vec<GridMeasurement>,
    log: &mut dyn FnMut(&GridMeasurement),
) -> Result<(), LabError> {
    let field = &d.field;
    let mut runs = Vec::new();
    let x = typed::<F>(d, LOOKUPS)?;
    let all = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let counts = if all > 1 { vec![1, all] } else { vec![1] };
    for threads in counts {
        let pool = (threads == 1).then_some(&one);
        let both = within(pool, || time_runs(reps, || fused_step(field, &x, true).map(drop)))?;
        let forward = within(pool, || median_secs(reps, || fused_step(field, &x, false).map(drop)))?;
        let mut buffers = Buffers::new(&x);
        let reused = within(pool, || {
            // Buffers never written are fresh pages: touch them first, also in --quick.
            fused_step_into(field, &x, &mut buffers)?;
            median_secs(reps, || fused_step_into(field, &x, &mut buffers))
        })?;
        drop(buffers);
        let outcome = within(pool, || measured_run(mem, || fused_step(field, &x, true)))?;
        runs.push(Run {
            method: "fused",
            threads,
            lookups: LOOKUPS,
            both,
            reused,
            forward,
            outcome,
        });
    }
    drop(x);
    let x = typed::<F>(d, TAPED_LOOKUPS)?;
    let reps = reps.min(3);
    let setup = median_secs(reps, || {
        black_box(tape_with_inputs(&x));
        Ok(())
    })?;
    let both = time_runs(reps, || taped_step(field, &x, true).map(drop))?;
    let forward = median_secs(reps, || taped_step(field, &x, false).map(drop))? - setup;
    let mut tape = Tape::new();
    // The first run fills the pool (fresh pages): not timed, also in --quick.
    taped_step_reused(field, &x, &mut tape)?;
    let reused = median_secs(reps, || taped_step_reused(field, &x, &mut tape))? - setup;
    drop(tape);
    runs.push(Run {
        method: "taped",
        // The global pool: the tape's element-wise ops use all its threads.
        threads: all,
        lookups: TAPED_LOOKUPS,
        both: Timing {
            median: (both.median - setup).max(1e-9),
            ..both
        },
        reused: reused.max(1e-9),
        forward: forward.max(1e-9),
        outcome: measured_run(mem, || taped_step(field, &x, true))?,
    });
    for r in runs {
        let reference = if r.lookups == LOOKUPS { &refs.0 } else { &refs.1 };
        let (err_output, _) = errors(&r.outcome.values.output, &reference.output, &reference.output_scale);
        let (err_grad_grid, err_grad_grid_norm) =
            errors(&r.outcome.values.grad, &reference.grad, &reference.grad_scale);
        let n = r.lookups as f64;
        let m = GridMeasurement {
            op: "grid",
            method: r.method,
            precision: F::NAME,
            threads: r.threads,
            grid: field.nodes()[0],
            channels: CHANNELS,
            lookups: r.lookups,
            lookups_per_sec: n / r.both.median,
            lookups_per_sec_spread: r.both.spread,
            lookups_per_sec_reused: n / r.reused,
            lookups_per_sec_forward: n / r.forward,
            err_output,
            err_grad_grid,
            err_grad_grid_norm,
            peak_extra_bytes: r.outcome.peak_extra,
        };
        log(&m);
        out.push(m);
    }
    Ok(())
}

/// Runs the grid bench over `grids` (nodes per axis); `log` sees each measurement as it is
/// made.
pub fn run(
    grids: &[usize],
    quick: bool,
    mem: &dyn Memory,
    log: &mut dyn FnMut(&GridMeasurement),
) -> Result<Vec<GridMeasurement>, LabError> {
    let reps = if quick { 1 } else { 5 };
    let mut out = Vec::new();
    for &nodes in grids {
        let d = data(nodes)?;
        let refs = (reference(&d, LOOKUPS), reference(&d, TAPED_LOOKUPS));
        measure::<f32>(&d, &refs, reps, mem, &mut out, log)?;
        measure::<f64>(&d, &refs, reps, mem, &mut out, log)?;
    }
    Ok(out)
}

/// The text report: one line per measurement, then the fused/taped ratios.
pub fn table(results: &[GridMeasurement]) -> String {
    let mut s = format!(
        "{:<6} {:<4} {:>3} {:>10} {:>8} {:>10} {:>7} {:>10} {:>10} {:>10} {:>10} {:>10} {:>8}\n",
        "method",
        "prec",
        "thr",
        "grid",
        "lookups",
        "M/s f+b",
        "spread",
        "reused",
        "M/s fwd",
        "err out",
        "err dgrid",
        "dgrid norm",
        "peak MB"
    );
    for m in results {
        s += &format!(
            "{:<6} {:<4} {:>3} {:>10} {:>8} {:>10.2} {:>6.0}% {:>10.2} {:>10.2} {:>10.1e} {:>10.1e} {:>10.1e} {:>8.1}\n",
            m.method,
            m.precision,
            m.threads,
            format!("{0}^3x{1}", m.grid, m.channels),
            m.lookups,
            m.lookups_per_sec / 1e6,
            m.lookups_per_sec_spread * 100.0,
            m.lookups_per_sec_reused / 1e6,
            m.lookups_per_sec_forward / 1e6,
            m.err_output,
            m.err_grad_grid,
            m.err_grad_grid_norm,
            m.peak_extra_bytes as f64 / 1e6
        );
    }
    s += "\nfused against the taped twin (all threads):\n";
    for m in results
        .iter()
        .filter(|m| m.method == "fused" && m.threads == rayon::current_num_threads())
    {
        let twin = results
            .iter()
            .find(|t| t.method == "taped" && t.precision == m.precision && t.grid == m.grid);
        if let Some(t) = twin {
            s += &format!(
                "  {} {}^3x{}: {:.1}x faster forward+backward ({:.1}x when both reuse their buffers), {:.1}x forward\n",
                m.precision,
                m.grid,
                m.channels,
                m.lookups_per_sec / t.lookups_per_sec,
                m.lookups_per_sec_reused / t.lookups_per_sec_reused,
                m.lookups_per_sec_forward / t.lookups_per_sec_forward
            );
        }
    }
    s
}
