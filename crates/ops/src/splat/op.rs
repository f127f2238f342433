//! The fused op without a tape ([`SplatRender::render`], [`SplatRender::vjp`]) and as a
//! [`CustomOp`] of the tape: project, bin, rasterise forward; rasterise backward, then the
//! projection's, backward. Everything between the inputs and the image is f64.

use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{Array1, Array2, ArrayD, ArrayView1, ArrayView2, ArrayViewD, Ix1, Ix2};

use super::check::{expect_finite, expect_shape, params, rows, SplatParams};
use super::config::{SplatArrays, SplatRender};
use super::project::{project_params, Projection};
use super::project_backward::{project_backward, Upstream1};
use super::raster::{rasterize, Raster};
use super::raster_backward::rasterize_vjp;
use super::tiles::{bin, TileLists};
use crate::error::{At, Op, OpsError};
use crate::math::logistic::{decay, sigmoid_decayed, sigmoid_slope_decayed};

/// What the forward keeps for the backward: the widened inputs, the projection, the tiles'
/// lists and each pixel's transmittance and count.
#[derive(Debug)]
pub struct SplatSaved {
    params: SplatParams,
    logits: Vec<f64>,
    opacity: Vec<f64>,
    colors: Vec<[f64; 3]>,
    proj: Projection,
    tiles: TileLists,
    raster: Raster,
}

/// The gradients of a loss for the five inputs of [`SplatRender`].
#[derive(Debug, Clone, PartialEq)]
pub struct SplatGradients<F> {
    /// `dL/dmeans` `[n, 3]`.
    pub means: Array2<F>,
    /// `dL/dlog_scales` `[n, 3]`.
    pub log_scales: Array2<F>,
    /// `dL/dquats` `[n, 4]`.
    pub quats: Array2<F>,
    /// `dL/dopacity_logits` `[n]`.
    pub opacity_logits: Array1<F>,
    /// `dL/dcolors` `[n, 3]`.
    pub colors: Array2<F>,
}

fn matrix<F: Float, const K: usize>(rows: &[[f64; K]]) -> Array2<F> {
    Array2::from_shape_fn((rows.len(), K), |(i, j)| F::lit(rows[i][j]))
}

impl SplatRender {
    /// Checks and widens the inputs, then projects, bins and rasterises.
    fn run<F: Float>(&self, s: &SplatArrays<'_, F>) -> Result<SplatSaved, OpsError> {
        let params = params(&s.means, &s.log_scales, &s.quats)?;
        let n = params.len();
        if s.opacity_logits.len() != n {
            return Err(OpsError::shape(
                Op::Splat,
                "opacity logits",
                format!("[{n}]"),
                format!("{:?}", s.opacity_logits.shape()),
            ));
        }
        if let Some(row) = s.opacity_logits.iter().position(|v| !v.is_finite()) {
            let v = s.opacity_logits[row].as_f64();
            return Err(OpsError::domain(
                Op::Splat,
                At::Entry { row, column: 0 },
                "opacity logit",
                v,
                "must be finite",
            ));
        }
        expect_shape("colours", &s.colors, n, 3)?;
        expect_finite("colour", &s.colors)?;
        let logits: Vec<f64> = s.opacity_logits.iter().map(|v| v.as_f64()).collect();
        let opacity: Vec<f64> = logits
            .iter()
            .map(|&x| sigmoid_decayed::<false>(x, decay::<false>(x)))
            .collect();
        let colors = rows::<F, 3>(&s.colors);
        let proj = project_params(&self.camera, &params);
        let (w, h) = self.size();
        let tiles = bin(&proj, w, h, self.max_intersections)?;
        let raster = rasterize(&proj, &tiles, &opacity, &colors, self.background)?;
        Ok(SplatSaved {
            params,
            logits,
            opacity,
            colors,
            proj,
            tiles,
            raster,
        })
    }

    /// The backward from the saved forward and `dL/dimage` (checked `[h w][3]`).
    fn back<F: Float>(&self, s: &SplatSaved, g_image: &[[f64; 3]]) -> Result<SplatGradients<F>, OpsError> {
        let bg = self.background;
        let rg = rasterize_vjp(&s.proj, &s.tiles, &s.opacity, &s.colors, bg, &s.raster, g_image)?;
        let upstream: Vec<Upstream1> = (0..s.params.len())
            .map(|i| Upstream1 {
                mean2d: rg.mean2d[i],
                conic: rg.conic[i],
                depth: 0.0,
            })
            .collect();
        let pg = project_backward(&self.camera, &s.params, &upstream);
        let logit_grad = |i: usize| rg.opacity[i] * sigmoid_slope_decayed::<false>(decay::<false>(s.logits[i]));
        Ok(SplatGradients {
            means: matrix(&pg.iter().map(|g| g.0).collect::<Vec<_>>()),
            log_scales: matrix(&pg.iter().map(|g| g.1).collect::<Vec<_>>()),
            quats: matrix(&pg.iter().map(|g| g.2).collect::<Vec<_>>()),
            opacity_logits: Array1::from_shape_fn(s.params.len(), |i| F::lit(logit_grad(i))),
            colors: matrix(&rg.color),
        })
    }

    /// The image `[height * width, 3]` (row-major pixels) of `splats`.
    ///
    /// Errors: shapes that do not fit ([`OpsError::Shape`]), a NaN or infinite value or a zero
    /// quaternion ([`OpsError::Domain`]), more (splat, tile) pairs than the op's bound
    /// ([`OpsError::TooManyIntersections`]).
    pub fn render<F: Float>(&self, splats: SplatArrays<'_, F>) -> Result<Array2<F>, OpsError> {
        Ok(matrix(&self.run(&splats)?.raster.color))
    }

    /// The gradients of a loss for the five inputs, given `dL/dimage` `[height * width, 3]`.
    ///
    /// Errors: those of [`SplatRender::render`], and an image gradient of another shape.
    pub fn vjp<F: Float>(
        &self,
        splats: SplatArrays<'_, F>,
        g_image: ArrayView2<'_, F>,
    ) -> Result<SplatGradients<F>, OpsError> {
        let saved = self.run(&splats)?;
        let (w, h) = self.size();
        expect_shape("image gradient", &g_image, w * h, 3)?;
        self.back(&saved, &rows::<F, 3>(&g_image))
    }
}

fn view2<'a, F: Float>(what: &'static str, x: &ArrayViewD<'a, F>) -> Result<ArrayView2<'a, F>, OpError> {
    x.clone().into_dimensionality::<Ix2>().map_err(|_| {
        OpError::from(OpsError::shape(
            Op::Splat,
            what,
            "2 dimensions",
            format!("{:?}", x.shape()),
        ))
    })
}

fn view1<'a, F: Float>(what: &'static str, x: &ArrayViewD<'a, F>) -> Result<ArrayView1<'a, F>, OpError> {
    x.clone().into_dimensionality::<Ix1>().map_err(|_| {
        OpError::from(OpsError::shape(
            Op::Splat,
            what,
            "1 dimension",
            format!("{:?}", x.shape()),
        ))
    })
}

fn arrays<'a, F: Float>(inputs: &[ArrayViewD<'a, F>]) -> Result<SplatArrays<'a, F>, OpError> {
    let [means, log_scales, quats, logits, colors] = inputs else {
        return Err(OpError::InvalidArgument(format!(
            "takes 5 inputs, got {}",
            inputs.len()
        )));
    };
    Ok(SplatArrays {
        means: view2("means", means)?,
        log_scales: view2("log-scales", log_scales)?,
        quats: view2("quaternions", quats)?,
        opacity_logits: view1("opacity logits", logits)?,
        colors: view2("colours", colors)?,
    })
}

impl<F: Float> CustomOp<F> for SplatRender {
    type Saved = SplatSaved;

    fn name(&self) -> &'static str {
        Op::Splat.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, SplatSaved), OpError> {
        let saved = self.run(&arrays(inputs)?)?;
        let image = matrix::<F, 3>(&saved.raster.color).into_dyn();
        Ok((vec![image], saved))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, SplatSaved>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = grads.first().and_then(Option::as_ref) else {
            return Ok(vec![None; 5]);
        };
        let (w, h) = self.size();
        let g = view2("image gradient", g)?;
        expect_shape("image gradient", &g, w * h, 3)?;
        let out: SplatGradients<F> = self.back(ctx.saved(), &rows::<F, 3>(&g))?;
        let keep = |i: usize, a: ArrayD<F>| ctx.needs_input_grad(i).then_some(a);
        Ok(vec![
            keep(0, out.means.into_dyn()),
            keep(1, out.log_scales.into_dyn()),
            keep(2, out.quats.into_dyn()),
            keep(3, out.opacity_logits.into_dyn()),
            keep(4, out.colors.into_dyn()),
        ])
    }

    fn saved_bytes(&self, s: &SplatSaved) -> usize {
        let n = s.params.len();
        let pixels = s.raster.count.len();
        n * (8 * (3 + 3 + 4 + 1 + 1 + 3) + 8 * (2 + 1 + 3) + 4)
            + pixels * (8 * 3 + 8 + 4)
            + s.tiles.splats.len() * 4
            + s.tiles.offsets.len() * 8
    }
}
