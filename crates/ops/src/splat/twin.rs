//! The projection written with tape primitives only: every quantity of
//! [`project`](super::project) a column `[n]` of its own, built from slices, products, sums,
//! `exp`, `sqrt`, `powi` and `clamp`, about two hundred records where the fused path has one
//! pass. Its gradients come from the tape's own rules, so it checks the hand-written backward
//! of [`project_vjp`](super::project_vjp) to rounding, where finite differences only reach
//! their step's accuracy. The radius is an integer and has no twin. (The rasteriser has no
//! taped twin: a per-pixel, data-dependent list of splats with early stopping is not a
//! composition of array primitives; it is checked against a plain reference and finite
//! differences instead.)

use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, ArrayD, Ix2, IxDyn};

use super::camera::SplatCamera;
use super::check::params;
use super::project::{DILATION, NEAR};
use crate::rays::PinholeCamera;

/// The projection's outputs on a tape: 2-D means `[n, 2]`, conics `[n, 3]` (zeros for culled
/// splats, with no gradient) and depths `[n]` (the camera-frame `z` of every splat).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProjectionVars {
    /// `[n, 2]`.
    pub mean2d: Var,
    /// `[n, 3]`.
    pub conic: Var,
    /// `[n]`.
    pub depth: Var,
}

/// A small builder over a tape: linear combinations and products of `[n]` columns.
struct Cols<'t, F: Float> {
    tape: &'t mut Tape<F>,
    n: usize,
}

impl<F: Float> Cols<'_, F> {
    fn col(&mut self, x: Var, j: usize) -> Result<Var, TapeError> {
        let c = self.tape.slice(x, 1, j, j + 1)?;
        self.tape.reshape(c, &[self.n])
    }
    fn mul(&mut self, a: Var, b: Var) -> Result<Var, TapeError> {
        self.tape.mul(a, b)
    }
    fn add(&mut self, a: Var, b: Var) -> Result<Var, TapeError> {
        self.tape.add(a, b)
    }
    fn sub(&mut self, a: Var, b: Var) -> Result<Var, TapeError> {
        self.tape.sub(a, b)
    }
    fn scale(&mut self, a: Var, k: f64) -> Result<Var, TapeError> {
        self.tape.mul_scalar(a, F::lit(k))
    }
    /// `sum_k coef_k x_k + constant`.
    fn lin(&mut self, terms: &[(f64, Var)], constant: f64) -> Result<Var, TapeError> {
        let mut acc = self.scale(terms[0].1, terms[0].0)?;
        for &(k, x) in &terms[1..] {
            let t = self.scale(x, k)?;
            acc = self.add(acc, t)?;
        }
        if constant != 0.0 {
            acc = self.tape.add_scalar(acc, F::lit(constant))?;
        }
        Ok(acc)
    }
    /// `sum_k a_k b_k`.
    fn dot(&mut self, pairs: &[(Var, Var)]) -> Result<Var, TapeError> {
        let mut acc = self.mul(pairs[0].0, pairs[0].1)?;
        for &(a, b) in &pairs[1..] {
            let t = self.mul(a, b)?;
            acc = self.add(acc, t)?;
        }
        Ok(acc)
    }
    /// The columns as `[n, k]`.
    fn stack(&mut self, cols: &[Var]) -> Result<Var, TapeError> {
        let shaped: Vec<Var> = cols
            .iter()
            .map(|&c| self.tape.reshape(c, &[self.n, 1]))
            .collect::<Result<_, _>>()?;
        self.tape.concat(&shaped, 1)
    }
}

/// The rotation of the quaternion columns `[w, x, y, z]`, normalised first.
fn rotation<F: Float>(c: &mut Cols<'_, F>, q: [Var; 4]) -> Result<[[Var; 3]; 3], TapeError> {
    let norm2 = c.dot(&[(q[0], q[0]), (q[1], q[1]), (q[2], q[2]), (q[3], q[3])])?;
    let norm = c.tape.sqrt(norm2)?;
    let mut u = q;
    for v in &mut u {
        *v = c.tape.div(*v, norm)?;
    }
    let [w, x, y, z] = u;
    let sq = |c: &mut Cols<'_, F>, a: Var| c.mul(a, a);
    let (xx, yy, zz) = (sq(c, x)?, sq(c, y)?, sq(c, z)?);
    let (xy, xz, yz) = (c.mul(x, y)?, c.mul(x, z)?, c.mul(y, z)?);
    let (wx, wy, wz) = (c.mul(w, x)?, c.mul(w, y)?, c.mul(w, z)?);
    Ok([
        [
            c.lin(&[(-2.0, yy), (-2.0, zz)], 1.0)?,
            c.lin(&[(2.0, xy), (-2.0, wz)], 0.0)?,
            c.lin(&[(2.0, xz), (2.0, wy)], 0.0)?,
        ],
        [
            c.lin(&[(2.0, xy), (2.0, wz)], 0.0)?,
            c.lin(&[(-2.0, xx), (-2.0, zz)], 1.0)?,
            c.lin(&[(2.0, yz), (-2.0, wx)], 0.0)?,
        ],
        [
            c.lin(&[(2.0, xz), (-2.0, wy)], 0.0)?,
            c.lin(&[(2.0, yz), (2.0, wx)], 0.0)?,
            c.lin(&[(-2.0, xx), (-2.0, yy)], 1.0)?,
        ],
    ])
}

/// Records the projection of `means` `[n, 3]`, `log_scales` `[n, 3]` and `quats` `[n, 4]`
/// into `camera` with the tape's own ops (see the [module docs](self)). A splat exactly on
/// the camera plane (`z = 0`) gets NaN gradients here (its masked-off branch holds `1 / z`,
/// and zero times infinity is NaN); the fused backward never evaluates it.
///
/// Errors: those of [`project`](super::project) (the [`OpsError`](crate::OpsError) inside
/// [`TapeError::Op`]), a stale handle.
pub fn projection<F: Float>(
    tape: &mut Tape<F>,
    camera: &PinholeCamera,
    means: Var,
    log_scales: Var,
    quats: Var,
) -> Result<ProjectionVars, TapeError> {
    let cam = SplatCamera::new(camera)?;
    let n = {
        let view2 = |v: Var| -> Result<_, TapeError> {
            let x = tape.value(v)?;
            let shape = x.shape().to_vec();
            x.into_dimensionality::<Ix2>().map_err(|_| {
                crate::OpsError::shape(crate::Op::Splat, "twin input", "2 dimensions", format!("{shape:?}")).into()
            })
        };
        params(&view2(means)?, &view2(log_scales)?, &view2(quats)?)?.len()
    };
    let c = &mut Cols { tape, n };
    let m = [c.col(means, 0)?, c.col(means, 1)?, c.col(means, 2)?];
    let w = cam.w;
    let pc: Vec<Var> = (0..3)
        .map(|i| c.lin(&[(w[i][0], m[0]), (w[i][1], m[1]), (w[i][2], m[2])], cam.t[i]))
        .collect::<Result<_, _>>()?;
    let (x, y, z) = (pc[0], pc[1], pc[2]);
    let rz = c.tape.powi(z, -1)?;
    let (xr, yr) = (c.mul(x, rz)?, c.mul(y, rz)?);
    let u = c.lin(&[(cam.fx, xr)], cam.cx)?;
    let v = c.lin(&[(cam.fy, yr)], cam.cy)?;

    let q = [c.col(quats, 0)?, c.col(quats, 1)?, c.col(quats, 2)?, c.col(quats, 3)?];
    let rot = rotation(c, q)?;
    let mut s = [c.col(log_scales, 0)?, c.col(log_scales, 1)?, c.col(log_scales, 2)?];
    for v in &mut s {
        *v = c.tape.exp(*v)?;
    }
    let mut mm = rot;
    for row in &mut mm {
        for (e, sj) in row.iter_mut().zip(s) {
            *e = c.mul(*e, sj)?;
        }
    }
    // Sigma = M M^T, then V = W Sigma W^T, each entry a combination of Sigma's.
    let mut sigma = [[m[0]; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            sigma[a][b] = c.dot(&[(mm[a][0], mm[b][0]), (mm[a][1], mm[b][1]), (mm[a][2], mm[b][2])])?;
        }
    }
    let mut vv = [[m[0]; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            let terms: Vec<(f64, Var)> = (0..9)
                .map(|k| (w[a][k / 3] * w[b][k % 3], sigma[k / 3][k % 3]))
                .collect();
            vv[a][b] = c.lin(&terms, 0.0)?;
        }
    }
    let cu = c.tape.clamp(xr, F::lit(-cam.lim_x.1), F::lit(cam.lim_x.0))?;
    let cv = c.tape.clamp(yr, F::lit(-cam.lim_y.1), F::lit(cam.lim_y.0))?;
    let j00 = c.scale(rz, cam.fx)?;
    let j11 = c.scale(rz, cam.fy)?;
    let cur = c.mul(cu, rz)?;
    let j02 = c.scale(cur, -cam.fx)?;
    let cvr = c.mul(cv, rz)?;
    let j12 = c.scale(cvr, -cam.fy)?;
    // C = J V J^T with J = [[j00, 0, j02], [0, j11, j12]].
    let quad = |c: &mut Cols<'_, F>, ja: [(usize, Var); 2], jb: [(usize, Var); 2]| -> Result<Var, TapeError> {
        let mut pairs = Vec::new();
        for (p, a) in ja {
            for (r, b) in jb {
                let ab = c.mul(a, b)?;
                pairs.push((ab, vv[p][r]));
            }
        }
        c.dot(&pairs)
    };
    let c00 = quad(c, [(0, j00), (2, j02)], [(0, j00), (2, j02)])?;
    let c01 = quad(c, [(0, j00), (2, j02)], [(1, j11), (2, j12)])?;
    let c11 = quad(c, [(1, j11), (2, j12)], [(1, j11), (2, j12)])?;
    let c00 = c.tape.add_scalar(c00, F::lit(DILATION))?;
    let c11 = c.tape.add_scalar(c11, F::lit(DILATION))?;
    let d = c.dot(&[(c00, c11)])?;
    let off = c.mul(c01, c01)?;
    let det = c.sub(d, off)?;
    let conic = [c.tape.div(c11, det)?, c.tape.div(c01, det)?, c.tape.div(c00, det)?];
    let conic = [conic[0], c.scale(conic[1], -1.0)?, conic[2]];

    // Culled splats: zeros with no gradient, as the fused projection gives them.
    let keep: Vec<bool> = {
        let zv = c.tape.value(z)?.to_owned();
        let dv = c.tape.value(det)?.to_owned();
        zv.iter()
            .zip(dv.iter())
            .map(|(z, d)| z.as_f64() >= NEAR && d.as_f64() > 0.0 && d.is_finite())
            .collect()
    };
    let zeros = c.tape.constant(Array1::<F>::zeros(n));
    let mask = ArrayD::from_shape_vec(IxDyn(&[n]), keep).map_err(|e| TapeError::InvalidArgument {
        op: "splat_twin",
        reason: e.to_string(),
    })?;
    let mut masked = Vec::new();
    for col in [u, v, conic[0], conic[1], conic[2]] {
        masked.push(c.tape.select(mask.clone(), col, zeros)?);
    }
    Ok(ProjectionVars {
        mean2d: c.stack(&masked[..2])?,
        conic: c.stack(&masked[2..])?,
        depth: z,
    })
}
