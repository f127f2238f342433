//! The composite without a tape ([`Composite::evaluate`], [`Composite::vjp`]) and as a
//! [`CustomOp`] of the tape: the only way it meets the tape is the same public interface any
//! user's op goes through.

use std::borrow::Cow;

use fogray_tape::buffer::{scratch, zeroed};
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{ArrayD, ArrayViewD, ArrayViewMutD, IxDyn};

use super::backward::{backward, InputGrads, Upstream, Wanted};
use super::config::{Background, Composite};
use super::forward::{forward, Outputs, Residuals};
use super::layout::{check_background, check_values, flatten, Flat};
use super::one_pass::one_pass;
use crate::error::CompositeError;

fn array<F: Float>(shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, CompositeError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| CompositeError::Shape {
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
) -> Result<&'a mut [F], CompositeError> {
    if b.shape() != shape {
        return Err(CompositeError::Shape {
            what,
            expected: format!("shape {shape:?}"),
            got: format!("shape {:?}", b.shape()),
        });
    }
    b.as_slice_mut().ok_or_else(|| CompositeError::Shape {
        what,
        expected: "a contiguous array in standard (row-major) order".into(),
        got: "a strided view".into(),
    })
}

/// The backward's arguments, checked: upstream gradients as flat slices, and which input
/// gradients can be non-zero.
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

    /// Which gradients the backward computes, given which are asked for (in input order);
    /// one asked for but not computed is zero (no upstream reaches it).
    fn wanted(&self, op: &Composite, asked: &[bool]) -> Wanted {
        wanted(op, asked, self.gc.is_some(), self.gd.is_some())
    }
}

/// Which gradients a backward computes, given which are asked for (in input order) and
/// whether the colour and the depth have an upstream gradient.
fn wanted(op: &Composite, asked: &[bool], color_upstream: bool, depth_upstream: bool) -> Wanted {
    let has_bg = op.background != Background::None;
    let t_at = 3 + usize::from(has_bg);
    Wanted {
        sigma: asked[0],
        delta: asked[1],
        color: asked[2] && color_upstream,
        background: has_bg && asked[3] && color_upstream,
        t: op.depth && asked[t_at] && depth_upstream,
    }
}

impl Composite {
    /// The output shapes, in the order of [`Composite::apply`].
    fn output_shapes(&self, ch: usize) -> Vec<Vec<usize>> {
        let (n, rays) = (self.samples(), self.rays());
        let mut shapes = vec![vec![rays, ch], vec![rays]];
        if self.depth {
            shapes.push(vec![rays]);
        }
        if self.weights {
            shapes.push(vec![n]);
        }
        if self.transmittance {
            shapes.push(vec![n]);
        }
        shapes
    }

    /// The forward into checked output slices (in the order of [`Composite::output_shapes`]).
    fn forward_into<F: Float>(&self, x: &Flat<'_, F>, outs: Vec<&mut [F]>) -> Result<Residuals<F>, CompositeError> {
        let (residuals, valid) = forward(self, x, self.outputs(outs));
        if !valid {
            // Find and name the first offending value.
            check_values(self, x)?;
        }
        Ok(residuals)
    }

    /// The output buffers (one per output, in order) as the kernels take them.
    fn outputs<'a, F: Float>(&self, outs: Vec<&'a mut [F]>) -> Outputs<'a, F> {
        let mut outs = outs.into_iter();
        let mut next = |on: bool| {
            if on {
                outs.next().unwrap_or_default()
            } else {
                Default::default()
            }
        };
        let (color, opacity) = (next(true), next(true));
        let (depth, weights, transmittance) = (next(self.depth), next(self.weights), next(self.transmittance));
        Outputs {
            color,
            opacity,
            depth,
            weights,
            transmittance,
        }
    }

    /// The forward pass without a tape: the outputs in the order of [`Composite::apply`]
    /// (colour, opacity, then depth, weights, transmittance as configured) and the residuals
    /// that [`Composite::vjp`] needs.
    ///
    /// `inputs` are sigma `[n]`, delta `[n]`, color `[n, ch]`, then the background unless
    /// [`Background::None`], then t with depth. Errors name the ray and sample at fault; no
    /// output is returned then.
    pub fn evaluate<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
    ) -> Result<(Vec<ArrayD<F>>, Residuals<F>), CompositeError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let shapes = self.output_shapes(x.ch);
        // forward_into overwrites every value (what evaluate_into promises), so no zeros first.
        let mut data: Vec<Vec<F>> = shapes.iter().map(|s| scratch(s.iter().product())).collect();
        let residuals = self.forward_into(&x, data.iter_mut().map(|d| &mut d[..]).collect())?;
        let outs = shapes
            .iter()
            .zip(data)
            .map(|(shape, d)| array(shape, d))
            .collect::<Result<_, _>>()?;
        Ok((outs, residuals))
    }

    /// [`Composite::evaluate`] into caller-owned buffers, one per output in the same order
    /// and of exactly its shape (contiguous, row-major), every value overwritten: a training
    /// loop that keeps its buffers allocates nothing per step but the residuals (one index
    /// per ray), and the kernel does not clear fresh pages for it.
    ///
    /// Errors in shapes (inputs or buffers) leave the buffers untouched; on an invalid input
    /// value (named in the error, as for [`Composite::evaluate`]) their contents are
    /// unspecified. The inputs are never modified.
    ///
    /// A training step that keeps its buffers (here two rays, RGB, a shared background, and
    /// gradients wanted for sigma and colour):
    ///
    /// ```
    /// use fogray_ops::{Background, Composite};
    /// use ndarray::{arr1, ArrayD};
    ///
    /// let op = Composite::new(&[0, 3, 5])?.background(Background::Shared);
    /// let sigma = arr1(&[0.5f32, 2.0, 8.0, 1.0, 0.0]).into_dyn();
    /// let delta = ArrayD::from_elem(vec![5], 0.5f32);
    /// let color = ArrayD::from_elem(vec![5, 3], 0.25f32);
    /// let background = arr1(&[1.0f32, 1.0, 1.0]).into_dyn();
    /// let inputs = [sigma.view(), delta.view(), color.view(), background.view()];
    /// let (mut c, mut opacity) = (ArrayD::zeros(vec![2, 3]), ArrayD::zeros(vec![2]));
    /// let (mut g_sigma, mut g_color) = (ArrayD::zeros(vec![5]), ArrayD::zeros(vec![5, 3]));
    /// let upstream = ArrayD::from_elem(vec![2, 3], 1.0f32); // dL/dC
    /// for _step in 0..3 {
    ///     let res = op.evaluate_into(&inputs, &mut [c.view_mut(), opacity.view_mut()])?;
    ///     let mut grads = [Some(g_sigma.view_mut()), None, Some(g_color.view_mut()), None];
    ///     op.vjp_into(&inputs, &res, &[Some(upstream.view()), None], &mut grads)?;
    /// }
    /// // The same numbers as the allocating calls.
    /// let (outs, res) = op.evaluate(&inputs)?;
    /// assert_eq!(outs[0], c);
    /// let g = op.vjp(&inputs, &res, &[Some(upstream.view()), None], &[true, false, true, false])?;
    /// assert_eq!(g[0].as_ref().unwrap(), &g_sigma);
    /// # Ok::<(), fogray_ops::CompositeError>(())
    /// ```
    pub fn evaluate_into<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
        outputs: &mut [ArrayViewMutD<'_, F>],
    ) -> Result<Residuals<F>, CompositeError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let slices = output_buffers(outputs, &self.output_shapes(x.ch))?;
        self.forward_into(&x, slices)
    }

    /// Checks the backward's arguments and returns the upstream gradients flat.
    fn prepare<'g, F: Float>(
        &self,
        x: &Flat<'_, F>,
        residuals: &Residuals<F>,
        grads: &'g [Option<ArrayViewD<'_, F>>],
    ) -> Result<Prepared<'g, F>, CompositeError> {
        let outputs = self.output_shapes(x.ch).len();
        let (n, rays, ch) = (self.samples(), self.rays(), x.ch);
        if grads.len() != outputs || residuals.stop.len() != rays {
            return Err(CompositeError::Shape {
                what: "vjp arguments",
                expected: format!("{outputs} upstream gradients, residuals of {rays} rays"),
                got: format!("{} gradients, residuals of {} rays", grads.len(), residuals.stop.len()),
            });
        }
        let mut slot = 2..grads.len();
        let mut next = |on: bool| if on { slot.next() } else { None };
        let (depth_at, weights_at, trans_at) = (next(self.depth), next(self.weights), next(self.transmittance));
        let pick = |at: Option<usize>| at.and_then(|i| flat(&grads[i]));
        let p = Prepared {
            gc: flat(&grads[0]),
            go: flat(&grads[1]),
            gd: pick(depth_at),
            gw: pick(weights_at),
            gt: pick(trans_at),
        };
        let expect = [
            (p.gc.as_deref(), rays * ch),
            (p.go.as_deref(), rays),
            (p.gd.as_deref(), rays),
            (p.gw.as_deref(), n),
            (p.gt.as_deref(), n),
        ];
        if let Some((g, len)) = expect.iter().find(|(g, len)| g.is_some_and(|g| g.len() != *len)) {
            return Err(CompositeError::Shape {
                what: "upstream gradient",
                expected: format!("{len} values"),
                got: format!("{}", g.map_or(0, <[F]>::len)),
            });
        }
        Ok(p)
    }

    /// The backward pass without a tape: gradients of the inputs (in the order of
    /// [`Composite::evaluate`]) from upstream gradients of the outputs (`None` for an unused
    /// output), for the inputs whose `needs` entry is true (`None` where no upstream reaches
    /// an input: its gradient is zero).
    ///
    /// `inputs` and `residuals` must be those of the matching [`Composite::evaluate`] call;
    /// shapes are checked, values are not checked again.
    pub fn vjp<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
        residuals: &Residuals<F>,
        grads: &[Option<ArrayViewD<'_, F>>],
        needs: &[bool],
    ) -> Result<Vec<Option<ArrayD<F>>>, CompositeError> {
        let x = flatten(self, inputs)?;
        if needs.len() != inputs.len() {
            return Err(CompositeError::Shape {
                what: "needs",
                expected: format!("{} flags", inputs.len()),
                got: format!("{}", needs.len()),
            });
        }
        let p = self.prepare(&x, residuals, grads)?;
        let want = p.wanted(self, needs);
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
        let mut out: Vec<Option<ArrayD<F>>> = vec![
            want.sigma.then(|| array(&[n], gs)).transpose()?,
            want.delta.then(|| array(&[n], gd)).transpose()?,
            want.color.then(|| array(&[n, ch], gc)).transpose()?,
        ];
        if self.background != Background::None {
            let bg = match self.background {
                Background::PerRay => want.background.then(|| array(&[rays, ch], gb)).transpose()?,
                _ => want.background.then(|| array(&[ch], sum_rows(&gb, ch))).transpose()?,
            };
            out.push(bg);
        }
        if self.depth {
            out.push(want.t.then(|| array(&[n], gt)).transpose()?);
        }
        Ok(out)
    }

    /// [`Composite::vjp`] into caller-owned buffers: `out` has one entry per input (in the
    /// order of [`Composite::evaluate`]), `Some` with a buffer of exactly that input's shape
    /// (contiguous, row-major) for each gradient wanted, every value overwritten (with zeros
    /// where no upstream reaches the input), `None` for the others.
    ///
    /// `inputs` and `residuals` must be those of the matching forward call. On error nothing
    /// is written.
    pub fn vjp_into<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
        residuals: &Residuals<F>,
        grads: &[Option<ArrayViewD<'_, F>>],
        out: &mut [Option<ArrayViewMutD<'_, F>>],
    ) -> Result<(), CompositeError> {
        let x = flatten(self, inputs)?;
        let p = self.prepare(&x, residuals, grads)?;
        let asked: Vec<bool> = out.iter().map(Option::is_some).collect();
        let slices = gradient_buffers(out, inputs)?;
        let want = p.wanted(self, &asked);
        self.gradients_into(&x, want, slices, |g| {
            backward(self, &x, residuals, &p.upstream(), want, g)
        });
        Ok(())
    }

    /// Runs `kernel` on the gradient buffers of `slices` (one per input, empty where not asked
    /// for) as the kernel wants them, then completes them: zeros where asked for but not
    /// wanted (no upstream reaches the input), and a shared background's gradient as the sum
    /// of the per-ray ones the kernel writes.
    fn gradients_into<F: Float>(
        &self,
        x: &Flat<'_, F>,
        want: Wanted,
        slices: Vec<&mut [F]>,
        kernel: impl FnOnce(InputGrads<'_, F>),
    ) {
        let mut slices = slices.into_iter();
        let mut next = || slices.next().unwrap_or_default();
        let (gs, gd, gc) = (next(), next(), next());
        let has_bg = self.background != Background::None;
        let gb = if has_bg { next() } else { Default::default() };
        let gt = if self.depth { next() } else { Default::default() };
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
    /// use fogray_ops::{Background, Composite};
    /// use ndarray::{arr1, arr2, ArrayD};
    ///
    /// let op = Composite::new(&[0, 3, 5])?.background(Background::Shared);
    /// let sigma = arr1(&[0.5f32, 2.0, 8.0, 1.0, 0.0]).into_dyn();
    /// let delta = ArrayD::from_elem(vec![5], 0.5f32);
    /// let color = ArrayD::from_elem(vec![5, 3], 0.25f32);
    /// let background = arr1(&[1.0f32, 1.0, 1.0]).into_dyn();
    /// let photo = arr2(&[[0.3f32, 0.3, 0.3], [0.9, 0.9, 0.9]]);
    /// let inputs = [sigma.view(), delta.view(), color.view(), background.view()];
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
    ///     &mut [c.view_mut(), opacity.view_mut()],
    ///     &mut [Some(g_sigma.view_mut()), None, Some(g_color.view_mut()), None],
    /// )?;
    /// // The same numbers as the forward, then the backward with dL/dC = 2 (C - photo).
    /// let (outs, res) = op.evaluate(&inputs)?;
    /// assert_eq!(outs[0], c);
    /// let dl_dc = ((&outs[0] - &photo.into_dyn()) * 2.0f32).into_dyn();
    /// let g = op.vjp(&inputs, &res, &[Some(dl_dc.view()), None], &[true, false, true, false])?;
    /// assert_eq!(g[0].as_ref().unwrap(), &g_sigma);
    /// # Ok::<(), fogray_ops::CompositeError>(())
    /// ```
    pub fn evaluate_vjp_into<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
        upstream: impl Fn(usize, &[F], &mut [F]) + Sync,
        outputs: &mut [ArrayViewMutD<'_, F>],
        grads: &mut [Option<ArrayViewMutD<'_, F>>],
    ) -> Result<(), CompositeError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let outs = output_buffers(outputs, &self.output_shapes(x.ch))?;
        let asked: Vec<bool> = grads.iter().map(Option::is_some).collect();
        let slices = gradient_buffers(grads, inputs)?;
        let want = wanted(self, &asked, true, false);
        let mut valid = true;
        self.gradients_into(&x, want, slices, |g| {
            valid = one_pass(self, &x, self.outputs(outs), g, want, &upstream);
        });
        if !valid {
            check_values(self, &x)?;
        }
        Ok(())
    }
}

/// The contiguous data of one output buffer per output, each of exactly its shape.
fn output_buffers<'a, F: Float>(
    outputs: &'a mut [ArrayViewMutD<'_, F>],
    shapes: &[Vec<usize>],
) -> Result<Vec<&'a mut [F]>, CompositeError> {
    if outputs.len() != shapes.len() {
        return Err(CompositeError::Shape {
            what: "output buffers",
            expected: format!("{} buffers", shapes.len()),
            got: format!("{}", outputs.len()),
        });
    }
    outputs
        .iter_mut()
        .zip(shapes)
        .map(|(b, shape)| buffer("output buffer", b, shape))
        .collect()
}

/// The contiguous data of each gradient buffer asked for (one entry per input, of its shape),
/// empty where `None`.
fn gradient_buffers<'a, F: Float>(
    out: &'a mut [Option<ArrayViewMutD<'_, F>>],
    inputs: &[ArrayViewD<'_, F>],
) -> Result<Vec<&'a mut [F]>, CompositeError> {
    if out.len() != inputs.len() {
        return Err(CompositeError::Shape {
            what: "gradient buffers",
            expected: format!("{} entries (one per input)", inputs.len()),
            got: format!("{}", out.len()),
        });
    }
    out.iter_mut()
        .zip(inputs)
        .map(|(b, input)| match b {
            Some(b) => buffer("gradient buffer", b, input.shape()),
            None => Ok(Default::default()),
        })
        .collect()
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

fn op_error(e: CompositeError) -> OpError {
    e.into()
}

impl<F: Float> CustomOp<F> for Composite {
    /// The stop index of each ray; the backward recomputes `T_k` and `alpha_k` from the
    /// inputs the tape keeps anyway.
    type Saved = Residuals<F>;

    fn name(&self) -> &'static str {
        "composite"
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, Residuals<F>), OpError> {
        self.evaluate(inputs).map_err(op_error)
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, Residuals<F>>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let inputs: Vec<ArrayViewD<'_, F>> = (0..ctx.num_inputs()).map(|i| ctx.input(i)).collect();
        let needs: Vec<bool> = (0..inputs.len()).map(|i| ctx.needs_input_grad(i)).collect();
        self.vjp(&inputs, ctx.saved(), grads, &needs).map_err(op_error)
    }

    fn saved_bytes(&self, saved: &Residuals<F>) -> usize {
        saved.stop.len() * std::mem::size_of::<usize>()
    }
}
