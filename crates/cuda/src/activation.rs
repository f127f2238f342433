//! The density/colour activation on the device: raw rows `[n, k]` (density first, then
//! `k - 1` colour channels) to `sigma = softplus(raw_0 + shift)` `[n]` and
//! `color = sigmoid(raw_1..k)` `[n, k - 1]`, and its backward, with the forms of
//! `fogray_ops::activation::DensityColor` (see `kernels/grid.cu`).

use std::sync::Arc;

use cudarc::driver::{CudaFunction, CudaSlice, CudaStream, PushKernelArg};

use crate::buffers::{check_len, launch_config, put, too_many};
use crate::composite::{CudaComposite, DeviceFloat};
use crate::error::CudaError;
use crate::kernel::compile_grid;

/// The activation's kernels on a [`CudaComposite`]'s device and stream.
pub struct CudaDensityColor {
    stream: Arc<CudaStream>,
    shift: f64,
    kernels: [(CudaFunction, CudaFunction); 2],
}

impl std::fmt::Debug for CudaDensityColor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CudaDensityColor").field("shift", &self.shift).finish()
    }
}

/// The activation's outputs on the host.
#[derive(Debug, Clone, PartialEq)]
pub struct HostActivated<F> {
    /// `[n]`.
    pub sigma: Vec<F>,
    /// `[n, k - 1]`, row-major.
    pub color: Vec<F>,
}

impl CudaDensityColor {
    /// Compiles the kernels for `gpu`'s device, with the density's `shift` (finite).
    pub fn new(gpu: &CudaComposite, shift: f64) -> Result<Self, CudaError> {
        if !shift.is_finite() {
            return Err(CudaError::InvalidShift(shift));
        }
        let module = gpu.context().load_module(compile_grid(gpu.compute_capability())?)?;
        let load = |suffix: &str| -> Result<(CudaFunction, CudaFunction), CudaError> {
            Ok((
                module.load_function(&format!("density_color_forward_{suffix}"))?,
                module.load_function(&format!("density_color_backward_{suffix}"))?,
            ))
        };
        Ok(CudaDensityColor {
            stream: gpu.stream().clone(),
            shift,
            kernels: [load("f32")?, load("f64")?],
        })
    }

    fn kernels<F: DeviceFloat>(&self) -> &(CudaFunction, CudaFunction) {
        &self.kernels[usize::from(F::SUFFIX != "f32")]
    }

    fn rows<F>(raw: &[F], k: usize) -> Result<usize, CudaError> {
        if k < 2 || raw.len() % k != 0 {
            return Err(CudaError::Shape {
                what: "raw values ([n, k], k >= 2: density and at least one colour)",
                expected: raw.len() / k.max(2) * k.max(2),
                got: raw.len(),
            });
        }
        let n = raw.len() / k;
        too_many(n)?;
        Ok(n)
    }

    /// Launches the activation of `raw` (`[n, k]`) into `sigma` (`[n]`) and `color`
    /// (`[n, k - 1]`); sets `invalid` (one word, zeroed by the caller) for a NaN raw value.
    pub fn launch_forward<F: DeviceFloat>(
        &self,
        raw: &CudaSlice<F>,
        n: usize,
        k: usize,
        sigma: &mut CudaSlice<F>,
        color: &mut CudaSlice<F>,
        invalid: &mut CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        if k < 2 {
            return Err(CudaError::Shape {
                what: "raw values per row (density and at least one colour)",
                expected: 2,
                got: k,
            });
        }
        check_len("raw values ([n, k])", n * k, raw.len().min(n * k))?;
        check_len("sigma ([n])", n, sigma.len().min(n))?;
        check_len("colour ([n, k - 1])", n * (k - 1), color.len().min(n * (k - 1)))?;
        too_many(n)?;
        if n == 0 {
            return Ok(());
        }
        let (n64, k64) = (n as u64, k as u64);
        let mut launch = self.stream.launch_builder(&self.kernels::<F>().0);
        launch
            .arg(raw)
            .arg(&n64)
            .arg(&k64)
            .arg(&self.shift)
            .arg(sigma)
            .arg(color)
            .arg(invalid);
        // SAFETY: the kernel's arguments in its order and types; each buffer holds at least the
        // values the kernel indexes for `n` rows (checked above); threads past `n` return.
        unsafe { launch.launch(launch_config(n)) }?;
        Ok(())
    }

    /// Launches the backward: `d_raw` (`[n, k]`, every value written) from `d_sigma` (`[n]`)
    /// and `d_color` (`[n, k - 1]`), each optional (absent: zero).
    #[allow(clippy::too_many_arguments)]
    pub fn launch_backward<F: DeviceFloat>(
        &self,
        raw: &CudaSlice<F>,
        n: usize,
        k: usize,
        d_sigma: Option<&CudaSlice<F>>,
        d_color: Option<&CudaSlice<F>>,
        d_raw: &mut CudaSlice<F>,
    ) -> Result<(), CudaError> {
        check_len("raw values ([n, k])", n * k, raw.len().min(n * k))?;
        if let Some(g) = d_sigma {
            check_len("dL/dsigma ([n])", n, g.len().min(n))?;
        }
        if let Some(g) = d_color {
            check_len("dL/dcolor ([n, k - 1])", n * (k - 1), g.len().min(n * (k - 1)))?;
        }
        check_len("dL/draw ([n, k])", n * k, d_raw.len().min(n * k))?;
        too_many(n)?;
        if n == 0 {
            return Ok(());
        }
        let (n64, k64) = (n as u64, k as u64);
        let (has_s, has_c) = (i32::from(d_sigma.is_some()), i32::from(d_color.is_some()));
        let mut launch = self.stream.launch_builder(&self.kernels::<F>().1);
        launch
            .arg(raw)
            .arg(&n64)
            .arg(&k64)
            .arg(&self.shift)
            // An absent gradient is not read; any buffer stands in for it.
            .arg(d_sigma.unwrap_or(raw))
            .arg(&has_s)
            .arg(d_color.unwrap_or(raw))
            .arg(&has_c)
            .arg(d_raw);
        // SAFETY: as in `launch_forward`; a gradient is read only when its flag says it is
        // there, with n (sigma) or n (k - 1) (colour) values (checked above).
        unsafe { launch.launch(launch_config(n)) }?;
        Ok(())
    }

    /// The activation of host rows `raw` (`[n, k]`). Errors: shapes, or
    /// [`CudaError::InvalidSample`] for a NaN raw value.
    pub fn evaluate<F: DeviceFloat>(&self, raw: &[F], k: usize) -> Result<HostActivated<F>, CudaError> {
        let n = Self::rows(raw, k)?;
        let s = &self.stream;
        let r = put(s, raw)?;
        let mut sigma = s.alloc_zeros::<F>(n.max(1))?;
        let mut color = s.alloc_zeros::<F>((n * (k - 1)).max(1))?;
        let mut invalid = s.alloc_zeros::<u32>(1)?;
        self.launch_forward(&r, n, k, &mut sigma, &mut color, &mut invalid)?;
        if s.clone_dtoh(&invalid)?[0] != 0 {
            return Err(CudaError::InvalidSample);
        }
        let (mut sigma, mut color) = (s.clone_dtoh(&sigma)?, s.clone_dtoh(&color)?);
        sigma.truncate(n);
        color.truncate(n * (k - 1));
        Ok(HostActivated { sigma, color })
    }

    /// `dL/draw` (`[n, k]`) for `dL/dsigma` (`[n]`) and `dL/dcolor` (`[n, k - 1]`), each
    /// optional (absent: zero).
    pub fn vjp<F: DeviceFloat>(
        &self,
        raw: &[F],
        k: usize,
        d_sigma: Option<&[F]>,
        d_color: Option<&[F]>,
    ) -> Result<Vec<F>, CudaError> {
        let n = Self::rows(raw, k)?;
        if let Some(g) = d_sigma {
            check_len("dL/dsigma ([n])", n, g.len())?;
        }
        if let Some(g) = d_color {
            check_len("dL/dcolor ([n, k - 1])", n * (k - 1), g.len())?;
        }
        let s = &self.stream;
        let r = put(s, raw)?;
        let gs = d_sigma.map(|g| put(s, g)).transpose()?;
        let gc = d_color.map(|g| put(s, g)).transpose()?;
        let mut out = s.alloc_zeros::<F>(raw.len().max(1))?;
        self.launch_backward(&r, n, k, gs.as_ref(), gc.as_ref(), &mut out)?;
        let mut v = s.clone_dtoh(&out)?;
        v.truncate(raw.len());
        Ok(v)
    }
}
