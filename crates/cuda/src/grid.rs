//! The dense 3-D grid field on the device: trilinear lookup of `C` channels per node (channels
//! last) at packed positions, and its backward into the grid and the positions, with the
//! conventions of `fogray_ops::GridField` (see `kernels/grid.cu`).

use std::sync::Arc;

use cudarc::driver::{CudaFunction, CudaSlice, CudaStream, DeviceRepr, PushKernelArg};

use crate::buffers::{check_len, launch_config, put, too_many};
use crate::composite::{CudaComposite, DeviceFloat};
use crate::error::CudaError;
use crate::kernel::compile_grid;

/// The box and lattice as the kernels take them (`Geometry` in `kernels/grid.cu`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct Geometry {
    min: [f64; 3],
    max: [f64; 3],
    scale: [f64; 3],
    end: [f64; 3],
    last: [i64; 3],
    strides: [u64; 3],
    corners: [u64; 8],
}

// SAFETY: a plain `#[repr(C)]` struct of 8-byte numbers, laid out as the kernels' `Geometry`.
unsafe impl DeviceRepr for Geometry {}

/// A dense grid over an axis-aligned box: `nodes` per axis (at least 2), `channels` per node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    /// The box's lower corner.
    pub min: [f64; 3],
    /// The box's upper corner (above `min` on every axis).
    pub max: [f64; 3],
    /// Nodes per axis, aligned with the box's faces.
    pub nodes: [usize; 3],
    /// Values per node.
    pub channels: usize,
}

impl GridSpec {
    /// The grid's value count, `nodes[0] nodes[1] nodes[2] channels`.
    pub fn values(&self) -> usize {
        self.nodes.iter().product::<usize>() * self.channels
    }

    fn geometry(&self) -> Result<Geometry, CudaError> {
        let bad = |why: String| Err(CudaError::InvalidGrid(why));
        for a in 0..3 {
            let (lo, hi) = (self.min[a], self.max[a]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(format!("axis {a}: the box [{lo}, {hi}] must be finite with min < max"));
            }
            if self.nodes[a] < 2 {
                return bad(format!("axis {a}: {} nodes (at least 2)", self.nodes[a]));
            }
        }
        if self.channels == 0 {
            return bad("0 channels".into());
        }
        let [_, n1, n2] = self.nodes;
        let strides = [(n1 * n2) as u64, n2 as u64, 1];
        let mut corners = [0u64; 8];
        for (k, c) in corners.iter_mut().enumerate() {
            *c = (0..3).filter(|&a| k >> (2 - a) & 1 == 1).map(|a| strides[a]).sum();
        }
        Ok(Geometry {
            min: self.min,
            max: self.max,
            scale: std::array::from_fn(|a| (self.nodes[a] - 1) as f64 / (self.max[a] - self.min[a])),
            end: std::array::from_fn(|a| (self.nodes[a] - 1) as f64),
            last: std::array::from_fn(|a| (self.nodes[a] - 2) as i64),
            strides,
            corners,
        })
    }
}

#[derive(Clone)]
struct GridKernels {
    forward: CudaFunction,
    scatter: CudaFunction,
    round: CudaFunction,
    position_gradient: CudaFunction,
}

/// The grid field's kernels for one grid, on a [`CudaComposite`]'s device and stream.
pub struct CudaGrid {
    stream: Arc<CudaStream>,
    spec: GridSpec,
    geometry: Geometry,
    f32: GridKernels,
    f64: GridKernels,
}

impl std::fmt::Debug for CudaGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CudaGrid").field("spec", &self.spec).finish()
    }
}

impl CudaGrid {
    /// Compiles the grid kernels for `gpu`'s device; launches go to its stream.
    ///
    /// Errors: [`CudaError::InvalidGrid`] for a box or lattice that is not one, and NVRTC's or
    /// the driver's errors.
    pub fn new(gpu: &CudaComposite, spec: GridSpec) -> Result<Self, CudaError> {
        let geometry = spec.geometry()?;
        let module = gpu.context().load_module(compile_grid(gpu.compute_capability())?)?;
        let load = |suffix: &str| -> Result<GridKernels, CudaError> {
            Ok(GridKernels {
                forward: module.load_function(&format!("grid_forward_{suffix}"))?,
                scatter: module.load_function(&format!("grid_scatter_{suffix}"))?,
                round: module.load_function(&format!("grid_round_{suffix}"))?,
                position_gradient: module.load_function(&format!("grid_position_gradient_{suffix}"))?,
            })
        };
        Ok(CudaGrid {
            stream: gpu.stream().clone(),
            spec,
            geometry,
            f32: load("f32")?,
            f64: load("f64")?,
        })
    }

    /// The same kernels for another box or lattice (nothing compiled again).
    ///
    /// Errors: [`CudaError::InvalidGrid`] for a box or lattice that is not one.
    pub fn for_spec(&self, spec: GridSpec) -> Result<Self, CudaError> {
        Ok(CudaGrid {
            stream: self.stream.clone(),
            spec,
            geometry: spec.geometry()?,
            f32: self.f32.clone(),
            f64: self.f64.clone(),
        })
    }

    /// The grid's box and lattice.
    pub fn spec(&self) -> &GridSpec {
        &self.spec
    }

    fn kernels<F: DeviceFloat>(&self) -> &GridKernels {
        if F::SUFFIX == "f32" {
            &self.f32
        } else {
            &self.f64
        }
    }

    /// Launches the lookup of `grid` (the spec's values) at `positions` (`[n, 3]`) into `out`
    /// (`[n, C]`); sets `invalid` (one word, zeroed by the caller) for a NaN coordinate.
    pub fn launch_lookup<F: DeviceFloat>(
        &self,
        grid: &CudaSlice<F>,
        positions: &CudaSlice<F>,
        n: usize,
        out: &mut CudaSlice<F>,
        invalid: &mut CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        let ch = self.spec.channels;
        check_len("grid values", self.spec.values(), grid.len())?;
        check_len("positions ([n, 3])", 3 * n, positions.len().min(3 * n))?;
        check_len("lookup output ([n, C])", n * ch, out.len().min(n * ch))?;
        too_many(n)?;
        if n == 0 {
            return Ok(());
        }
        let (n64, ch64) = (n as u64, ch as u64);
        let mut launch = self.stream.launch_builder(&self.kernels::<F>().forward);
        launch
            .arg(&self.geometry)
            .arg(grid)
            .arg(positions)
            .arg(&n64)
            .arg(&ch64)
            .arg(out)
            .arg(invalid);
        // SAFETY: the kernel's arguments in its order and types; `grid` holds the spec's values
        // (its corner offsets stay inside for a position in the box), `positions` and `out` at
        // least `n` rows (checked above); threads past `n` return.
        unsafe { launch.launch(launch_config(n)) }?;
        Ok(())
    }

    /// Launches the scatter of `upstream = dL/dout` (`[n, C]`) at `positions` (`[n, 3]`) into
    /// the f64 accumulator `acc` (the spec's values), adding to what it holds: the grid
    /// gradient's sum before [`CudaGrid::launch_backward`] rounds it (for callers that zero
    /// and round it themselves, as a training step's optimiser does).
    pub fn launch_scatter<F: DeviceFloat>(
        &self,
        positions: &CudaSlice<F>,
        upstream: &CudaSlice<F>,
        n: usize,
        acc: &mut CudaSlice<f64>,
    ) -> Result<(), CudaError> {
        let ch = self.spec.channels;
        check_len("grid gradient accumulator", self.spec.values(), acc.len())?;
        check_len("positions ([n, 3])", 3 * n, positions.len().min(3 * n))?;
        check_len("upstream ([n, C])", n * ch, upstream.len().min(n * ch))?;
        too_many(n)?;
        if n == 0 {
            return Ok(());
        }
        let (n64, ch64) = (n as u64, ch as u64);
        let mut scatter = self.stream.launch_builder(&self.kernels::<F>().scatter);
        scatter
            .arg(&self.geometry)
            .arg(positions)
            .arg(upstream)
            .arg(&n64)
            .arg(&ch64)
            .arg(acc);
        // SAFETY: as in `launch_lookup`; `acc` holds the spec's values.
        unsafe { scatter.launch(launch_config(n)) }?;
        Ok(())
    }

    /// Launches the backward: into `grad_grid` (the spec's values, every one written) through
    /// the f64 accumulator `acc` (the spec's values), and, if given, `grad_positions` (`[n,
    /// 3]`), for `upstream = dL/dout` (`[n, C]`).
    #[allow(clippy::too_many_arguments)]
    pub fn launch_backward<F: DeviceFloat>(
        &self,
        grid: &CudaSlice<F>,
        positions: &CudaSlice<F>,
        upstream: &CudaSlice<F>,
        n: usize,
        acc: &mut CudaSlice<f64>,
        grad_grid: &mut CudaSlice<F>,
        grad_positions: Option<&mut CudaSlice<F>>,
    ) -> Result<(), CudaError> {
        let ch = self.spec.channels;
        let values = self.spec.values();
        check_len("grid values", values, grid.len())?;
        check_len("grid gradient", values, grad_grid.len())?;
        check_len("grid gradient accumulator", values, acc.len())?;
        check_len("positions ([n, 3])", 3 * n, positions.len().min(3 * n))?;
        check_len("upstream ([n, C])", n * ch, upstream.len().min(n * ch))?;
        too_many(n.max(values))?;
        let (n64, ch64, len) = (n as u64, ch as u64, values as u64);
        let k = self.kernels::<F>();
        self.stream.memset_zeros(acc)?;
        self.launch_scatter(positions, upstream, n, acc)?;
        let mut round = self.stream.launch_builder(&k.round);
        round.arg(&*acc).arg(&len).arg(grad_grid);
        // SAFETY: both buffers hold `len` values (checked above).
        unsafe { round.launch(launch_config(values)) }?;
        if let Some(out) = grad_positions {
            check_len("position gradient ([n, 3])", 3 * n, out.len().min(3 * n))?;
            if n > 0 {
                let mut pos = self.stream.launch_builder(&k.position_gradient);
                pos.arg(&self.geometry)
                    .arg(grid)
                    .arg(positions)
                    .arg(upstream)
                    .arg(&n64)
                    .arg(&ch64)
                    .arg(out);
                // SAFETY: as in `launch_lookup`.
                unsafe { pos.launch(launch_config(n)) }?;
            }
        }
        Ok(())
    }

    /// The lookup on host data: `grid` (the spec's values), `positions` (`[n, 3]`) to
    /// `[n, C]`. Errors: shapes, or [`CudaError::InvalidSample`] for a NaN coordinate.
    pub fn evaluate<F: DeviceFloat>(&self, grid: &[F], positions: &[F]) -> Result<Vec<F>, CudaError> {
        let n = self.rows(grid, positions)?;
        let s = &self.stream;
        let (g, p) = (put(s, grid)?, put(s, positions)?);
        let mut out = s.alloc_zeros::<F>((n * self.spec.channels).max(1))?;
        let mut invalid = s.alloc_zeros::<u32>(1)?;
        self.launch_lookup(&g, &p, n, &mut out, &mut invalid)?;
        if s.clone_dtoh(&invalid)?[0] != 0 {
            return Err(CudaError::InvalidSample);
        }
        let mut v = s.clone_dtoh(&out)?;
        v.truncate(n * self.spec.channels);
        Ok(v)
    }

    /// The gradients on host data, `(dL/dgrid, dL/dpositions)`, for `upstream = dL/dout`.
    pub fn vjp<F: DeviceFloat>(
        &self,
        grid: &[F],
        positions: &[F],
        upstream: &[F],
    ) -> Result<(Vec<F>, Vec<F>), CudaError> {
        let n = self.rows(grid, positions)?;
        check_len("upstream ([n, C])", n * self.spec.channels, upstream.len())?;
        let s = &self.stream;
        let (g, p, u) = (put(s, grid)?, put(s, positions)?, put(s, upstream)?);
        let mut acc = s.alloc_zeros::<f64>(grid.len())?;
        let mut gg = s.alloc_zeros::<F>(grid.len())?;
        let mut gp = s.alloc_zeros::<F>((3 * n).max(1))?;
        self.launch_backward(&g, &p, &u, n, &mut acc, &mut gg, Some(&mut gp))?;
        let mut pos = s.clone_dtoh(&gp)?;
        pos.truncate(3 * n);
        Ok((s.clone_dtoh(&gg)?, pos))
    }

    fn rows<F>(&self, grid: &[F], positions: &[F]) -> Result<usize, CudaError> {
        check_len("grid values", self.spec.values(), grid.len())?;
        if positions.len() % 3 != 0 {
            return Err(CudaError::Shape {
                what: "positions ([n, 3])",
                expected: positions.len() / 3 * 3,
                got: positions.len(),
            });
        }
        Ok(positions.len() / 3)
    }
}
