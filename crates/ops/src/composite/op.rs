//! The composite without a tape ([`Composite::evaluate`], [`Composite::vjp`]) and as a
//! [`CustomOp`] of the tape: the only way it meets the tape is the same public interface any
//! user's op goes through.

use std::borrow::Cow;

use fogray_tape::buffer::{scratch, zeroed};
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{ArrayD, ArrayViewD, ArrayViewMutD, IxDyn};

use super::arrays::{CompositeArrays, CompositeOutputBuffers, CompositeOutputs};
use super::backward::{backward, InputGrads, Upstream, Wanted};
use super::config::{Background, Composite};
use super::forward::{forward, Outputs, Residuals};
use super::gradients::{CompositeGradientBuffers, CompositeGradients, CompositeUpstream, CompositeWanted};
use super::layout::{check_background, check_values, flatten, mismatch, Flat};
use super::one_pass::one_pass;
use super::tape_order;
use crate::error::{Op, OpsError};

fn array<F: Float>(shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, OpsError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| OpsError::Shape {
        op: Op::Composite,
        what: "output",
        expected: format!("{shape:?}"),
        got: e.to_string(),
    })
}

fn flat<'a, F: Float>(g: &'a Option<ArrayViewD<'_, F>>) -> Option<Cow<'a, [F]>> {
    g.as_ref().map(fogray_tape::buffer::flat)
}

/// The contiguous data of an output buffer of exactly `shape`, or why not.
fn buffer<'a, F: Float>(
    what: &'static str,
    b: &'a mut ArrayViewMutD<'_, F>,
    shape: &[usize],
) -> Result<&'a mut [F], OpsError> {
    if b.shape() != shape {
        return Err(OpsError::Shape {
            op: Op::Composite,
            what,
            expected: format!("shape {shape:?}"),
            got: format!("shape {:?}", b.shape()),
        });
    }
    b.as_slice_mut().ok_or_else(|| OpsError::Shape {
        op: Op::Composite,
        what,
        expected: "a contiguous array in standard (row-major) order".into(),
        got: "a strided view".into(),
    })
}

/// The upstream gradients, checked, as flat slices.
struct Prepared<'g, F: Float> {
    gc: Option<Cow<'g, [F]>>,
    go: Option<Cow<'g, [F]>>,
    gd: Option<Cow<'g, [F]>>,
    gw: Option<Cow<'g, [F]>>,
    gt: Option<Cow<'g, [F]>>,
}

impl<F: Float> Prepared<'_, F> {
    fn upstream(&self) -> Upstream<'_, F> {
        Upstream {
            color: self.gc.as_deref(),
            opacity: self.go.as_deref(),
            depth: self.gd.as_deref(),
            weights: self.gw.as_deref(),
            transmittance: self.gt.as_deref(),
        }
    }

    /// Which gradients the backward computes, given those asked for; one asked for but not
    /// computed is zero (no upstream reaches it).
    fn wanted(&self, asked: CompositeWanted) -> Wanted {
        wanted(asked, self.gc.is_some(), self.gd.is_some())
    }
}

/// Which gradients a backward computes, given those asked for (already checked against the
/// configuration) and whether the colour and the depth have an upstream gradient.
fn wanted(asked: CompositeWanted, color_upstream: bool, depth_upstream: bool) -> Wanted {
    Wanted {
        sigma: asked.sigma,
        delta: asked.delta,
        color: asked.color && color_upstream,
        background: asked.background && color_upstream,
        t: asked.t && depth_upstream,
    }
}

/// A background gradient only for an op with a background, a t gradient only with depth.
fn check_wanted(op: &Composite, asked: CompositeWanted) -> Result<(), OpsError> {
    if asked.background && op.background == Background::None {
        return Err(mismatch("background gradient", true));
    }
    if asked.t && !op.depth {
        return Err(mismatch("t gradient", true));
    }
    Ok(())
}

impl Composite {
    /// The forward into checked output slices.
    fn forward_into<F: Float>(&self, x: &Flat<'_, F>, outs: Outputs<'_, F>) -> Result<Residuals<F>, OpsError> {
        let (residuals, valid) = forward(self, x, outs);
        if !valid {
            // Find and name the first offending value.
            check_values(self, x)?;
        }
        Ok(residuals)
    }

    /// The contiguous data of each output buffer, each of exactly its output's shape, and
    /// present exactly when the op has that output.
    fn output_slices<'a, F: Float>(
        &self,
        buffers: &'a mut CompositeOutputBuffers<'_, F>,
        ch: usize,
    ) -> Result<Outputs<'a, F>, OpsError> {
        let (n, rays) = (self.samples(), self.rays());
        let CompositeOutputBuffers {
            color,
            opacity,
            depth,
            weights,
            transmittance,
        } = buffers;
        Ok(Outputs {
            color: buffer("colour buffer", color, &[rays, ch])?,
            opacity: buffer("opacity buffer", opacity, &[rays])?,
            depth: optional_buffer("depth buffer", self.depth, depth, &[rays])?,
            weights: optional_buffer("weights buffer", self.weights, weights, &[n])?,
            transmittance: optional_buffer("transmittance buffer", self.transmittance, transmittance, &[n])?,
        })
    }

    /// The forward pass without a tape: the outputs (colour, opacity, and depth, weights and
    /// transmittance as configured) and the residuals that [`Composite::vjp`] needs.
    ///
    /// `inputs` are as [`CompositeArrays`] describes: the background given exactly when the
    /// op has one, `t` exactly with depth. Errors name the ray and sample at fault; no output
    /// is returned then.
    pub fn evaluate<F: Float>(
        &self,
        inputs: &CompositeArrays<'_, F>,
    ) -> Result<(CompositeOutputs<F>, Residuals<F>), OpsError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let (n, rays, ch) = (self.samples(), self.rays(), x.ch);
        // forward_into overwrites every value (what evaluate_into promises), so no zeros first.
        let sized = |on: bool, len: usize| scratch::<F>(if on { len } else { 0 });
        let (mut color, mut opacity) = (scratch::<F>(rays * ch), scratch::<F>(rays));
        let mut depth = sized(self.depth, rays);
        let mut weights = sized(self.weights, n);
        let mut transmittance = sized(self.transmittance, n);
        let outs = Outputs {
            color: &mut color,
            opacity: &mut opacity,
            depth: &mut depth,
            weights: &mut weights,
            transmittance: &mut transmittance,
        };
        let residuals = self.forward_into(&x, outs)?;
        let optional = |on: bool, shape: &[usize], data: Vec<F>| on.then(|| array(shape, data)).transpose();
        let outputs = CompositeOutputs {
            color: array(&[rays, ch], color)?,
            opacity: array(&[rays], opacity)?,
            depth: optional(self.depth, &[rays], depth)?,
            weights: optional(self.weights, &[n], weights)?,
            transmittance: optional(self.transmittance, &[n], transmittance)?,
        };
        Ok((outputs, residuals))
    }

    /// [`Composite::evaluate`] into caller-owned buffers ([`CompositeOutputBuffers`]: one per
    /// output of the op, each of exactly its shape, contiguous, row-major), every value
    /// overwritten: a training loop that keeps its buffers allocates nothing per step but the
    /// residuals (one index per ray), and the kernel does not clear fresh pages for it.
    ///
    /// Errors in shapes (inputs or buffers) or a buffer missing or superfluous for the
    /// configuration leave the buffers untouched; on an invalid input value (named in the
    /// error, as for [`Composite::evaluate`]) their contents are unspecified. The inputs are
    /// never modified.
    ///
    /// A training step that keeps its buffers (here two rays, RGB, a shared background, and
    /// gradients wanted for sigma and colour):
    ///
    /// ```
    /// use fogray_ops::{
    ///     Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeOutputBuffers,
    ///     CompositeUpstream, CompositeWanted,
    /// };
    /// use ndarray::{arr1, ArrayD};
    ///
    /// let op = Composite::new(&[0, 3, 5])?.background(Background::Shared);
    /// let sigma = arr1(&[0.5f32, 2.0, 8.0, 1.0, 0.0]).into_dyn();
    /// let delta = ArrayD::from_elem(vec![5], 0.5f32);
    /// let color = ArrayD::from_elem(vec![5, 3], 0.25f32);
    /// let background = arr1(&[1.0f32, 1.0, 1.0]).into_dyn();
    /// let inputs = CompositeArrays::new(sigma.view(), delta.view(), color.view()).with_background(background.view());
    /// let (mut c, mut opacity) = (ArrayD::zeros(vec![2, 3]), ArrayD::zeros(vec![2]));
    /// let (mut g_sigma, mut g_color) = (ArrayD::zeros(vec![5]), ArrayD::zeros(vec![5, 3]));
    /// let dl_dc = ArrayD::from_elem(vec![2, 3], 1.0f32);
    /// let upstream = CompositeUpstream::color(dl_dc.view());
    /// for _step in 0..3 {
    ///     let res = op.evaluate_into(&inputs, &mut CompositeOutputBuffers::new(c.view_mut(), opacity.view_mut()))?;
    ///     let mut grads = CompositeGradientBuffers {
    ///         sigma: Some(g_sigma.view_mut()),
    ///         color: Some(g_color.view_mut()),
    ///         ..Default::default()
    ///     };
    ///     op.vjp_into(&inputs, &res, &upstream, &mut grads)?;
    /// }
    /// // The same numbers as the allocating calls.
    /// let (outs, res) = op.evaluate(&inputs)?;
    /// assert_eq!(outs.color, c);
    /// let wanted = CompositeWanted { sigma: true, color: true, ..Default::default() };
    /// let g = op.vjp(&inputs, &res, &upstream, wanted)?;
    /// assert_eq!(g.sigma.as_ref(), Some(&g_sigma));
    /// assert_eq!(g.delta, None);
    /// # Ok::<(), fogray_ops::OpsError>(())
    /// ```
    pub fn evaluate_into<F: Float>(
        &self,
        inputs: &CompositeArrays<'_, F>,
        outputs: &mut CompositeOutputBuffers<'_, F>,
    ) -> Result<Residuals<F>, OpsError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let slices = self.output_slices(outputs, x.ch)?;
        self.forward_into(&x, slices)
    }

    /// Checks the backward's arguments and returns the upstream gradients flat.
    fn prepare<'g, F: Float>(
        &self,
        x: &Flat<'_, F>,
        residuals: &Residuals<F>,
        upstream: &'g CompositeUpstream<'_, F>,
    ) -> Result<Prepared<'g, F>, OpsError> {
        let (n, rays, ch) = (self.samples(), self.rays(), x.ch);
        if residuals.stop.len() != rays {
            return Err(OpsError::Shape {
                op: Op::Composite,
                what: "residuals",
                expected: format!("residuals of {rays} rays"),
                got: format!("residuals of {} rays", residuals.stop.len()),
            });
        }
        let configured = [
            ("depth upstream gradient", self.depth, upstream.depth.is_some()),
            ("weights upstream gradient", self.weights, upstream.weights.is_some()),
            (
                "transmittance upstream gradient",
                self.transmittance,
                upstream.transmittance.is_some(),
            ),
        ];
        if let Some((what, _, _)) = configured.iter().find(|(_, on, given)| *given && !on) {
            return Err(mismatch(what, true));
        }
        let p = Prepared {
            gc: flat(&upstream.color),
            go: flat(&upstream.opacity),
            gd: flat(&upstream.depth),
            gw: flat(&upstream.weights),
            gt: flat(&upstream.transmittance),
        };
        let expect = [
            (p.gc.as_deref(), rays * ch),
            (p.go.as_deref(), rays),
            (p.gd.as_deref(), rays),
            (p.gw.as_deref(), n),
            (p.gt.as_deref(), n),
        ];
        if let Some((g, len)) = expect.iter().find(|(g, len)| g.is_some_and(|g| g.len() != *len)) {
            return Err(OpsError::Shape {
                op: Op::Composite,
                what: "upstream gradient",
                expected: format!("{len} values"),
                got: format!("{}", g.map_or(0, <[F]>::len)),
            });
        }
        Ok(p)
    }

    /// The backward pass without a tape: the gradients `wanted` of the inputs, from upstream
    /// gradients of the outputs. A gradient is `Some` exactly when it is wanted and an
    /// upstream gradient reaches it (the colour and background gradients need `dL/dC`, the t
    /// gradient `dL/ddepth`); it is zero otherwise.
    ///
    /// `inputs` and `residuals` must be those of the matching [`Composite::evaluate`] call;
    /// shapes are checked, values are not checked again. Errors: shapes, an upstream
    /// gradient for an output the op does not have, a background or t gradient wanted from
    /// an op without that input.
    pub fn vjp<F: Float>(
        &self,
        inputs: &CompositeArrays<'_, F>,
        residuals: &Residuals<F>,
        upstream: &CompositeUpstream<'_, F>,
        wanted: CompositeWanted,
    ) -> Result<CompositeGradients<F>, OpsError> {
        let x = flatten(self, inputs)?;
        check_wanted(self, wanted)?;
        let p = self.prepare(&x, residuals, upstream)?;
        let want = p.wanted(wanted);
        let (n, rays, ch) = (self.samples(), self.rays(), x.ch);
        // The backward overwrites every value of a wanted gradient (vjp_into's promise).
        let sized = |on: bool, len: usize| scratch::<F>(if on { len } else { 0 });
        let (mut gs, mut gd, mut gc) = (sized(want.sigma, n), sized(want.delta, n), sized(want.color, n * ch));
        let (mut gb, mut gt) = (sized(want.background, rays * ch), sized(want.t, n));
        let out = InputGrads {
            sigma: &mut gs,
            delta: &mut gd,
            color: &mut gc,
            background: &mut gb,
            t: &mut gt,
        };
        backward(self, &x, residuals, &p.upstream(), want, out);
        let background = match self.background {
            Background::PerRay => want.background.then(|| array(&[rays, ch], gb)),
            _ => want.background.then(|| array(&[ch], sum_rows(&gb, ch))),
        };
        Ok(CompositeGradients {
            sigma: want.sigma.then(|| array(&[n], gs)).transpose()?,
            delta: want.delta.then(|| array(&[n], gd)).transpose()?,
            color: want.color.then(|| array(&[n, ch], gc)).transpose()?,
            background: background.transpose()?,
            t: want.t.then(|| array(&[n], gt)).transpose()?,
        })
    }

    /// [`Composite::vjp`] into caller-owned buffers: `out` has a buffer of exactly its
    /// input's shape (contiguous, row-major) for each gradient wanted, every value
    /// overwritten (with zeros where no upstream reaches the input), `None` for the others.
    ///
    /// `inputs` and `residuals` must be those of the matching forward call. On error nothing
    /// is written.
    pub fn vjp_into<F: Float>(
        &self,
        inputs: &CompositeArrays<'_, F>,
        residuals: &Residuals<F>,
        upstream: &CompositeUpstream<'_, F>,
        out: &mut CompositeGradientBuffers<'_, F>,
    ) -> Result<(), OpsError> {
        let x = flatten(self, inputs)?;
        let asked = out.wanted();
        check_wanted(self, asked)?;
        let p = self.prepare(&x, residuals, upstream)?;
        let slices = gradient_slices(out, inputs)?;
        let want = p.wanted(asked);
        self.gradients_into(&x, want, slices, |g| {
            backward(self, &x, residuals, &p.upstream(), want, g)
        });
        Ok(())
    }

    /// Runs `kernel` on the gradient buffers `asked` (empty where not asked for) as the kernel
    /// wants them, then completes them: zeros where asked for but not wanted (no upstream
    /// reaches the input), and a shared background's gradient as the sum of the per-ray ones
    /// the kernel writes.
    fn gradients_into<F: Float>(
        &self,
        x: &Flat<'_, F>,
        want: Wanted,
        asked: InputGrads<'_, F>,
        kernel: impl FnOnce(InputGrads<'_, F>),
    ) {
        let InputGrads {
            sigma: gs,
            delta: gd,
            color: gc,
            background: gb,
            t: gt,
        } = asked;
        // The kernel writes a per-ray background gradient; a shared one is its sum.
        let rays = self.rays();
        let mut per_ray_bg = Vec::new();
        let background: &mut [F] = match self.background {
            Background::PerRay if want.background => &mut gb[..],
            _ if want.background => {
                per_ray_bg = zeroed(rays * x.ch);
                &mut per_ray_bg
            }
            _ => &mut [],
        };
        // sigma and delta are computed whenever asked; colour and t may be asked for with no
        // upstream to reach them, and are zero then.
        kernel(InputGrads {
            sigma: &mut gs[..],
            delta: &mut gd[..],
            color: if want.color { &mut gc[..] } else { &mut [] },
            background,
            t: if want.t { &mut gt[..] } else { &mut [] },
        });
        if !want.color {
            gc.fill(F::zero());
        }
        if !want.t {
            gt.fill(F::zero());
        }
        if self.background == Background::Shared && want.background {
            for (g, v) in gb.iter_mut().zip(sum_rows(&per_ray_bg, x.ch)) {
                *g = v;
            }
        } else if !want.background {
            gb.fill(F::zero());
        }
    }

    /// [`Composite::evaluate_into`], the gradient of a loss that sums a function of each ray's
    /// colour, and [`Composite::vjp_into`], in one pass per ray: what a training step with a
    /// photometric loss needs, faster than the two calls because the backward takes the
    /// attenuation the forward has just computed (no exponential is recomputed) and reads each
    /// ray's inputs while they are in cache.
    ///
    /// `upstream(ray, color, d_color)` receives a ray's index and its colour (`[ch]`, as
    /// written to the colour output) and writes `dL/dC` for it into `d_color` (zeros on entry);
    /// it is called once per ray, from several threads, in no particular order. The other
    /// outputs have no upstream gradient (their gradients are zero). `outputs` and `grads` are
    /// as for [`Composite::evaluate_into`] and [`Composite::vjp_into`], and the results are
    /// bitwise those of the two calls with the same upstream gradients.
    ///
    /// Errors in shapes leave the buffers untouched; on an invalid input value (named in the
    /// error, as for [`Composite::evaluate`]) `upstream` may have been called and the
    /// buffers' contents are unspecified. The inputs are never modified.
    ///
    /// ```
    /// use fogray_ops::{
    ///     Background, Composite, CompositeArrays, CompositeGradientBuffers, CompositeOutputBuffers,
    ///     CompositeUpstream, CompositeWanted,
    /// };
    /// use ndarray::{arr1, arr2, ArrayD};
    ///
    /// let op = Composite::new(&[0, 3, 5])?.background(Background::Shared);
    /// let sigma = arr1(&[0.5f32, 2.0, 8.0, 1.0, 0.0]).into_dyn();
    /// let delta = ArrayD::from_elem(vec![5], 0.5f32);
    /// let color = ArrayD::from_elem(vec![5, 3], 0.25f32);
    /// let background = arr1(&[1.0f32, 1.0, 1.0]).into_dyn();
    /// let photo = arr2(&[[0.3f32, 0.3, 0.3], [0.9, 0.9, 0.9]]);
    /// let inputs = CompositeArrays::new(sigma.view(), delta.view(), color.view()).with_background(background.view());
    /// let (mut c, mut opacity) = (ArrayD::zeros(vec![2, 3]), ArrayD::zeros(vec![2]));
    /// let (mut g_sigma, mut g_color) = (ArrayD::zeros(vec![5]), ArrayD::zeros(vec![5, 3]));
    /// // L = sum over rays and channels of (C - photo)^2.
    /// let upstream = |ray: usize, c: &[f32], d: &mut [f32]| {
    ///     for ((d, &c), &p) in d.iter_mut().zip(c).zip(photo.row(ray)) {
    ///         *d = 2.0 * (c - p);
    ///     }
    /// };
    /// op.evaluate_vjp_into(
    ///     &inputs,
    ///     upstream,
    ///     &mut CompositeOutputBuffers::new(c.view_mut(), opacity.view_mut()),
    ///     &mut CompositeGradientBuffers {
    ///         sigma: Some(g_sigma.view_mut()),
    ///         color: Some(g_color.view_mut()),
    ///         ..Default::default()
    ///     },
    /// )?;
    /// // The same numbers as the forward, then the backward with dL/dC = 2 (C - photo).
    /// let (outs, res) = op.evaluate(&inputs)?;
    /// assert_eq!(outs.color, c);
    /// let dl_dc = ((&outs.color - &photo.into_dyn()) * 2.0f32).into_dyn();
    /// let wanted = CompositeWanted { sigma: true, color: true, ..Default::default() };
    /// let g = op.vjp(&inputs, &res, &CompositeUpstream::color(dl_dc.view()), wanted)?;
    /// assert_eq!(g.sigma.as_ref(), Some(&g_sigma));
    /// # Ok::<(), fogray_ops::OpsError>(())
    /// ```
    pub fn evaluate_vjp_into<F: Float>(
        &self,
        inputs: &CompositeArrays<'_, F>,
        upstream: impl Fn(usize, &[F], &mut [F]) + Sync,
        outputs: &mut CompositeOutputBuffers<'_, F>,
        grads: &mut CompositeGradientBuffers<'_, F>,
    ) -> Result<(), OpsError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let asked = grads.wanted();
        check_wanted(self, asked)?;
        let outs = self.output_slices(outputs, x.ch)?;
        let slices = gradient_slices(grads, inputs)?;
        let want = wanted(asked, true, false);
        let mut valid = true;
        self.gradients_into(&x, want, slices, |g| {
            valid = one_pass(self, &x, outs, g, want, &upstream);
        });
        if !valid {
            check_values(self, &x)?;
        }
        Ok(())
    }
}

/// The contiguous data of an optional output buffer: present exactly when the op has the
/// output (`on`), of exactly `shape`; empty when absent.
fn optional_buffer<'a, F: Float>(
    what: &'static str,
    on: bool,
    b: &'a mut Option<ArrayViewMutD<'_, F>>,
    shape: &[usize],
) -> Result<&'a mut [F], OpsError> {
    match (on, b) {
        (true, Some(b)) => buffer(what, b, shape),
        (false, None) => Ok(Default::default()),
        (on, _) => Err(mismatch(what, !on)),
    }
}

/// The contiguous data of a gradient buffer asked for, of its input's shape; empty where not
/// asked for.
fn gradient_slice<'a, F: Float>(
    what: &'static str,
    b: &'a mut Option<ArrayViewMutD<'_, F>>,
    input: Option<&ArrayViewD<'_, F>>,
) -> Result<&'a mut [F], OpsError> {
    match (b, input) {
        (None, _) => Ok(Default::default()),
        (Some(b), Some(input)) => buffer(what, b, input.shape()),
        (Some(_), None) => Err(mismatch(what, true)),
    }
}

/// The contiguous data of each gradient buffer asked for (each of its input's shape), empty
/// where `None`.
fn gradient_slices<'a, F: Float>(
    out: &'a mut CompositeGradientBuffers<'_, F>,
    inputs: &CompositeArrays<'_, F>,
) -> Result<InputGrads<'a, F>, OpsError> {
    let CompositeGradientBuffers {
        sigma,
        delta,
        color,
        background,
        t,
    } = out;
    Ok(InputGrads {
        sigma: gradient_slice("sigma gradient buffer", sigma, Some(&inputs.sigma))?,
        delta: gradient_slice("delta gradient buffer", delta, Some(&inputs.delta))?,
        color: gradient_slice("colour gradient buffer", color, Some(&inputs.color))?,
        background: gradient_slice("background gradient buffer", background, inputs.background.as_ref())?,
        t: gradient_slice("t gradient buffer", t, inputs.t.as_ref())?,
    })
}

/// Column sums of `[rows][ch]`, in row order (so the result does not depend on the thread
/// count), in f64.
fn sum_rows<F: Float>(rows: &[F], ch: usize) -> Vec<F> {
    let mut total = vec![0.0f64; ch];
    for row in rows.chunks_exact(ch) {
        for (t, &v) in total.iter_mut().zip(row) {
            *t += v.as_f64();
        }
    }
    total.into_iter().map(F::lit).collect()
}

impl<F: Float> CustomOp<F> for Composite {
    /// The stop index of each ray; the backward recomputes `T_k` and `alpha_k` from the
    /// inputs the tape keeps anyway.
    type Saved = Residuals<F>;

    fn name(&self) -> &'static str {
        Op::Composite.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, Residuals<F>), OpError> {
        let inputs = tape_order::arrays(self, inputs)?;
        let (outputs, residuals) = self.evaluate(&inputs)?;
        Ok((tape_order::outputs_in_order(outputs), residuals))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, Residuals<F>>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let inputs: Vec<ArrayViewD<'_, F>> = (0..ctx.num_inputs()).map(|i| ctx.input(i)).collect();
        let needs: Vec<bool> = (0..inputs.len()).map(|i| ctx.needs_input_grad(i)).collect();
        let arrays = tape_order::arrays(self, &inputs)?;
        let wanted = tape_order::wanted(self, needs)?;
        let upstream = tape_order::upstream(self, grads)?;
        let g = self.vjp(&arrays, ctx.saved(), &upstream, wanted)?;
        Ok(tape_order::gradients_in_order(self, g))
    }

    fn saved_bytes(&self, saved: &Residuals<F>) -> usize {
        saved.stop.len() * std::mem::size_of::<usize>()
    }
}
