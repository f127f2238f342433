//! Density and view-dependent colour on the device: raw rows `[n, 1 + 3 B]` (density, then
//! each colour channel's `B = (degree + 1)^2` spherical-harmonics coefficients) seen along
//! unit directions `[n, 3]` to `sigma = softplus(raw_0 + shift)` `[n]` and
//! `color_c = sigmoid(sum_b raw[1 + c B + b] Y_b(d))` `[n, 3]`, and its backward, with the
//! basis and forms of `fogray_ops::ShColor` and `fogray_ops::activation::DensityColor` (see
//! `kernels/grid.cu`). The directions are constants: they get no gradient.

use std::sync::Arc;

use cudarc::driver::{CudaFunction, CudaSlice, CudaStream, PushKernelArg};

use crate::activation::HostActivated;
use crate::buffers::{check_len, launch_config, put, too_many};
use crate::composite::{CudaComposite, DeviceFloat};
use crate::error::CudaError;
use crate::kernel::compile_grid;

/// The highest degree of the basis.
pub const MAX_SH_DEGREE: usize = 3;

/// The spherical-harmonics activation's kernels on a [`CudaComposite`]'s device and stream.
pub struct CudaShDensityColor {
    stream: Arc<CudaStream>,
    shift: f64,
    degree: usize,
    kernels: [(CudaFunction, CudaFunction); 2],
}

impl std::fmt::Debug for CudaShDensityColor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CudaShDensityColor")
            .field("shift", &self.shift)
            .field("degree", &self.degree)
            .finish()
    }
}

impl CudaShDensityColor {
    /// Compiles the kernels for `gpu`'s device, with the density's `shift` (finite) and the
    /// basis's `degree` (0 to [`MAX_SH_DEGREE`]).
    ///
    /// Errors: [`CudaError::InvalidShift`], [`CudaError::InvalidSettings`] for a degree above
    /// 3, and NVRTC's or the driver's.
    pub fn new(gpu: &CudaComposite, shift: f64, degree: usize) -> Result<Self, CudaError> {
        if !shift.is_finite() {
            return Err(CudaError::InvalidShift(shift));
        }
        if degree > MAX_SH_DEGREE {
            return Err(CudaError::InvalidSettings(format!(
                "spherical harmonics of degree {degree} (at most {MAX_SH_DEGREE})"
            )));
        }
        let module = gpu.context().load_module(compile_grid(gpu.compute_capability())?)?;
        let load = |suffix: &str| -> Result<(CudaFunction, CudaFunction), CudaError> {
            Ok((
                module.load_function(&format!("sh_density_color_forward_{suffix}"))?,
                module.load_function(&format!("sh_density_color_backward_{suffix}"))?,
            ))
        };
        Ok(CudaShDensityColor {
            stream: gpu.stream().clone(),
            shift,
            degree,
            kernels: [load("f32")?, load("f64")?],
        })
    }

    /// Basis functions per colour channel, `(degree + 1)^2`.
    pub fn basis_count(&self) -> usize {
        (self.degree + 1) * (self.degree + 1)
    }

    /// Raw values per row, `1 + 3 (degree + 1)^2`.
    pub fn channels(&self) -> usize {
        1 + 3 * self.basis_count()
    }

    fn kernels<F: DeviceFloat>(&self) -> &(CudaFunction, CudaFunction) {
        &self.kernels[usize::from(F::SUFFIX != "f32")]
    }

    fn check_rows<F>(&self, raw: &CudaSlice<F>, directions: &CudaSlice<F>, n: usize) -> Result<(), CudaError> {
        let k = self.channels();
        check_len("raw values ([n, 1 + 3 B])", n * k, raw.len().min(n * k))?;
        check_len("directions ([n, 3])", 3 * n, directions.len().min(3 * n))?;
        too_many(n)
    }

    /// Launches the activation of `raw` (`[n, 1 + 3 B]`) seen along `directions` (`[n, 3]`)
    /// into `sigma` (`[n]`) and `color` (`[n, 3]`); sets `invalid` (one word, zeroed by the
    /// caller) for a NaN raw value or direction.
    pub fn launch_forward<F: DeviceFloat>(
        &self,
        raw: &CudaSlice<F>,
        directions: &CudaSlice<F>,
        n: usize,
        sigma: &mut CudaSlice<F>,
        color: &mut CudaSlice<F>,
        invalid: &mut CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        self.check_rows(raw, directions, n)?;
        check_len("sigma ([n])", n, sigma.len().min(n))?;
        check_len("colour ([n, 3])", 3 * n, color.len().min(3 * n))?;
        if n == 0 {
            return Ok(());
        }
        let (n64, b64) = (n as u64, self.basis_count() as u64);
        let mut launch = self.stream.launch_builder(&self.kernels::<F>().0);
        launch
            .arg(raw)
            .arg(directions)
            .arg(&n64)
            .arg(&b64)
            .arg(&self.shift)
            .arg(sigma)
            .arg(color)
            .arg(invalid);
        // SAFETY: the kernel's arguments in its order and types; each buffer holds at least the
        // values the kernel indexes for `n` rows (checked above); threads past `n` return.
        unsafe { launch.launch(launch_config(n)) }?;
        Ok(())
    }

    /// Launches the backward: `d_raw` (`[n, 1 + 3 B]`, every value written) from `d_sigma`
    /// (`[n]`) and `d_color` (`[n, 3]`).
    #[allow(clippy::too_many_arguments)]
    pub fn launch_backward<F: DeviceFloat>(
        &self,
        raw: &CudaSlice<F>,
        directions: &CudaSlice<F>,
        n: usize,
        d_sigma: &CudaSlice<F>,
        d_color: &CudaSlice<F>,
        d_raw: &mut CudaSlice<F>,
    ) -> Result<(), CudaError> {
        self.check_rows(raw, directions, n)?;
        let k = self.channels();
        check_len("dL/dsigma ([n])", n, d_sigma.len().min(n))?;
        check_len("dL/dcolor ([n, 3])", 3 * n, d_color.len().min(3 * n))?;
        check_len("dL/draw ([n, 1 + 3 B])", n * k, d_raw.len().min(n * k))?;
        if n == 0 {
            return Ok(());
        }
        let (n64, b64) = (n as u64, self.basis_count() as u64);
        let mut launch = self.stream.launch_builder(&self.kernels::<F>().1);
        launch
            .arg(raw)
            .arg(directions)
            .arg(&n64)
            .arg(&b64)
            .arg(&self.shift)
            .arg(d_sigma)
            .arg(d_color)
            .arg(d_raw);
        // SAFETY: as in `launch_forward`, with `n` and `3 n` upstream values (checked above).
        unsafe { launch.launch(launch_config(n)) }?;
        Ok(())
    }

    fn host_rows<F>(&self, raw: &[F], directions: &[F]) -> Result<usize, CudaError> {
        let k = self.channels();
        let n = directions.len() / 3;
        if directions.len() != 3 * n {
            return Err(CudaError::Shape {
                what: "directions ([n, 3])",
                expected: 3 * n,
                got: directions.len(),
            });
        }
        check_len("raw values ([n, 1 + 3 B])", n * k, raw.len())?;
        Ok(n)
    }

    /// The activation of host rows `raw` (`[n, 1 + 3 B]`) along `directions` (`[n, 3]`).
    /// Errors: shapes, or [`CudaError::InvalidSample`] for a NaN value.
    pub fn evaluate<F: DeviceFloat>(&self, raw: &[F], directions: &[F]) -> Result<HostActivated<F>, CudaError> {
        let n = self.host_rows(raw, directions)?;
        let s = &self.stream;
        let (r, d) = (put(s, raw)?, put(s, directions)?);
        let mut sigma = s.alloc_zeros::<F>(n.max(1))?;
        let mut color = s.alloc_zeros::<F>((3 * n).max(1))?;
        let mut invalid = s.alloc_zeros::<u32>(1)?;
        self.launch_forward(&r, &d, n, &mut sigma, &mut color, &mut invalid)?;
        if s.clone_dtoh(&invalid)?[0] != 0 {
            return Err(CudaError::InvalidSample);
        }
        let (mut sigma, mut color) = (s.clone_dtoh(&sigma)?, s.clone_dtoh(&color)?);
        sigma.truncate(n);
        color.truncate(3 * n);
        Ok(HostActivated { sigma, color })
    }

    /// `dL/draw` (`[n, 1 + 3 B]`) for `dL/dsigma` (`[n]`) and `dL/dcolor` (`[n, 3]`).
    pub fn vjp<F: DeviceFloat>(
        &self,
        raw: &[F],
        directions: &[F],
        d_sigma: &[F],
        d_color: &[F],
    ) -> Result<Vec<F>, CudaError> {
        let n = self.host_rows(raw, directions)?;
        check_len("dL/dsigma ([n])", n, d_sigma.len())?;
        check_len("dL/dcolor ([n, 3])", 3 * n, d_color.len())?;
        let s = &self.stream;
        let (r, d) = (put(s, raw)?, put(s, directions)?);
        let (gs, gc) = (put(s, d_sigma)?, put(s, d_color)?);
        let mut out = s.alloc_zeros::<F>(raw.len().max(1))?;
        self.launch_backward(&r, &d, n, &gs, &gc, &mut out)?;
        let mut v = s.clone_dtoh(&out)?;
        v.truncate(raw.len());
        Ok(v)
    }
}
