//! `gradcheck`: the tape's gradient of any closure against central finite differences in f64.
//!
//! Full mode perturbs every input element; fast mode compares directional derivatives
//! `v^T J u` along seeded random directions `u`, for inputs too large to perturb one by one.
//! A non-scalar output is projected on a fixed random `v` (ones for a scalar output).

mod report;

pub use report::{GradcheckEntry, GradcheckReport};

use ndarray::{ArrayD, Dimension, IxDyn};
use rand::{Rng, SeedableRng};

use crate::error::{Result, TapeError};
use crate::tape::Tape;
use crate::var::Var;

/// Settings of [`gradcheck`]; the defaults are PyTorch's, which were designed for f64.
#[derive(Debug, Clone, PartialEq)]
pub struct GradcheckOptions {
    /// Step of the central difference, relative to `max(1, |x|)`. Default 1e-6.
    pub eps: f64,
    /// Absolute tolerance used by [`GradcheckReport::passes`] defaults. Default 1e-5.
    pub atol: f64,
    /// Relative tolerance. Default 1e-3.
    pub rtol: f64,
    /// Check random directional derivatives instead of every element. Default false.
    pub fast: bool,
    /// Number of random directions in fast mode. Default 8.
    pub projections: usize,
    /// Seed of the random projections. Default 0.
    pub seed: u64,
}

impl Default for GradcheckOptions {
    fn default() -> Self {
        GradcheckOptions {
            eps: 1e-6,
            atol: 1e-5,
            rtol: 1e-3,
            fast: false,
            projections: 8,
            seed: 0,
        }
    }
}

/// Compares the gradient that the tape computes for `f` at `inputs` with central finite
/// differences, and reports the disagreements (it does not decide pass or fail: call
/// [`GradcheckReport::check`] for that).
///
/// `f` receives a fresh tape and one param per input, and returns the output; it is called
/// many times and must be deterministic. Errors are those of `f` or of the backward sweep.
pub fn gradcheck<Func>(f: Func, inputs: &[ArrayD<f64>], opts: &GradcheckOptions) -> Result<GradcheckReport>
where
    Func: Fn(&mut Tape<f64>, &[Var]) -> Result<Var>,
{
    if opts.eps.is_nan() || opts.eps <= 0.0 {
        return Err(TapeError::InvalidArgument {
            op: "gradcheck",
            reason: format!("eps must be positive, got {}", opts.eps),
        });
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(opts.seed);
    let mut tape = Tape::new();
    let vars: Vec<Var> = inputs.iter().map(|x| tape.param(x.clone())).collect();
    let y = f(&mut tape, &vars)?;
    let y_shape = tape.shape(y)?.to_vec();
    let projection = if tape.value(y)?.len() == 1 {
        ArrayD::ones(IxDyn(&y_shape))
    } else {
        ArrayD::from_shape_fn(IxDyn(&y_shape), |_| rng.gen_range(-1.0..1.0))
    };
    let analytic_of = |tape: &Tape<f64>| -> Result<Vec<ArrayD<f64>>> {
        let grads = tape.backward_with(y, projection.clone())?;
        vars.iter().map(|&v| grads.get_or_zeros(tape, v)).collect()
    };
    let analytic = analytic_of(&tape)?;
    let again = analytic_of(&tape)?;
    let reentrancy_diff = analytic
        .iter()
        .zip(&again)
        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
        .fold(0.0, f64::max);

    // v . f(x) for perturbed inputs, on one reused tape.
    let mut scratch = Tape::new();
    let mut projected = |xs: &[ArrayD<f64>]| -> Result<f64> {
        scratch.clear();
        let vs: Vec<Var> = xs.iter().map(|x| scratch.constant(x.clone())).collect();
        let out = f(&mut scratch, &vs)?;
        let value = scratch.value(out)?;
        if value.shape() != projection.shape() {
            return Err(TapeError::ShapeMismatch {
                op: "gradcheck",
                lhs: projection.shape().to_vec(),
                rhs: value.shape().to_vec(),
            });
        }
        Ok(value.iter().zip(&projection).map(|(a, b)| a * b).sum())
    };

    let mut entries = Vec::new();
    let mut xs: Vec<ArrayD<f64>> = inputs.to_vec();
    if opts.fast {
        for k in 0..opts.projections {
            let dirs: Vec<ArrayD<f64>> = inputs.iter().map(|x| x.mapv(|_| rng.gen_range(-1.0..1.0))).collect();
            let scale = inputs.iter().flat_map(|x| x.iter()).fold(1.0f64, |m, v| m.max(v.abs()));
            let h = opts.eps * scale;
            let shifted = |sign: f64| -> Vec<ArrayD<f64>> {
                inputs.iter().zip(&dirs).map(|(x, d)| x + &(d * (sign * h))).collect()
            };
            let numeric = (projected(&shifted(1.0))? - projected(&shifted(-1.0))?) / (2.0 * h);
            let analytic_dir: f64 = analytic.iter().zip(&dirs).map(|(g, d)| (g * d).sum()).sum();
            entries.push(GradcheckEntry {
                input: None,
                index: vec![k],
                numeric,
                analytic: analytic_dir,
            });
        }
    } else {
        for i in 0..inputs.len() {
            let indices: Vec<IxDyn> = inputs[i].indexed_iter().map(|(ix, _)| ix).collect();
            for ix in indices {
                let x0 = inputs[i][&ix];
                let h = opts.eps * x0.abs().max(1.0);
                xs[i][&ix] = x0 + h;
                let plus = projected(&xs)?;
                xs[i][&ix] = x0 - h;
                let minus = projected(&xs)?;
                xs[i][&ix] = x0;
                entries.push(GradcheckEntry {
                    input: Some(i),
                    index: ix.slice().to_vec(),
                    numeric: (plus - minus) / (2.0 * h),
                    analytic: analytic[i][&ix],
                });
            }
        }
    }
    Ok(GradcheckReport {
        checked: entries.len(),
        entries,
        reentrancy_diff,
        atol: opts.atol,
        rtol: opts.rtol,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::custom::{BackwardCtx, CustomOp};
    use crate::error::OpError;
    use ndarray::ArrayViewD;

    /// y = x^2 with a deliberately wrong backward (3x instead of 2x): the negative control.
    #[derive(Debug)]
    struct WrongSquare;

    impl CustomOp<f64> for WrongSquare {
        type Saved = ();
        fn name(&self) -> &'static str {
            "wrong_square"
        }
        fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> std::result::Result<(Vec<ArrayD<f64>>, ()), OpError> {
            Ok((vec![inputs[0].mapv(|x| x * x)], ()))
        }
        fn backward(
            &self,
            ctx: &BackwardCtx<'_, f64, ()>,
            grads: &[Option<ArrayViewD<'_, f64>>],
        ) -> std::result::Result<Vec<Option<ArrayD<f64>>>, OpError> {
            Ok(vec![grads[0].as_ref().map(|g| g * &ctx.input(0).mapv(|x| 3.0 * x))])
        }
    }

    fn input() -> ArrayD<f64> {
        ArrayD::from_shape_vec(vec![3], vec![0.5, -1.25, 2.0]).unwrap()
    }

    #[test]
    fn negative_control_a_wrong_backward_is_caught_and_located() {
        let report = gradcheck(
            |t, v| t.apply1(WrongSquare, &[v[0]]),
            &[input()],
            &GradcheckOptions::default(),
        )
        .unwrap();
        assert!(report.check(1e-5, 1e-3).is_err());
        let worst = report.worst_abs().unwrap();
        // The error 3x - 2x = x is largest at x = 2 (index 2): numeric 4 (projected), analytic 6.
        assert_eq!(worst.index, vec![2]);
        assert_eq!(worst.input, Some(0));
        let ratio = worst.analytic / worst.numeric;
        assert!((ratio - 1.5).abs() < 1e-6, "analytic/numeric = {ratio}");
        // Fast mode catches it too.
        let fast = GradcheckOptions {
            fast: true,
            ..Default::default()
        };
        let report = gradcheck(|t, v| t.apply1(WrongSquare, &[v[0]]), &[input()], &fast).unwrap();
        assert!(report.check(1e-5, 1e-3).is_err());
    }

    #[test]
    fn a_right_backward_passes_in_both_modes() {
        let f = |t: &mut Tape<f64>, v: &[Var]| t.square(v[0]);
        let full = gradcheck(f, &[input()], &GradcheckOptions::default()).unwrap();
        full.check(1e-7, 1e-7).unwrap();
        assert_eq!(full.checked, 3);
        assert_eq!(full.reentrancy_diff, 0.0);
        let fast = gradcheck(
            f,
            &[input()],
            &GradcheckOptions {
                fast: true,
                projections: 5,
                ..Default::default()
            },
        )
        .unwrap();
        fast.check(1e-7, 1e-7).unwrap();
        assert_eq!(fast.checked, 5);
    }

    #[test]
    fn bad_eps_is_an_error() {
        let opts = GradcheckOptions {
            eps: 0.0,
            ..Default::default()
        };
        assert!(gradcheck(|t, v| t.square(v[0]), &[input()], &opts).is_err());
    }
}
