//! `gradcheck`: the tape's gradient of any closure against finite differences in f64.
//!
//! Full mode perturbs every input element; fast mode compares directional derivatives
//! `v^T J u` along seeded random directions `u`, for inputs too large to perturb one by one.
//! A non-scalar output is projected on a fixed random `v` (ones for a scalar output).
//! Differences are central, except where an input's [`Domain`] ends within a step: there
//! they are one-sided and step inward only, so a function defined on `x >= 0` is checked at 0.
//!
//! ```
//! use fogray_tape::gradcheck::{gradcheck, Domain, GradcheckOptions};
//! use ndarray::arr1;
//!
//! // x^2 written as sqrt(x)^4, which is NaN below 0: at x = 0 a central difference would
//! // read sqrt(-h); the domain makes it a one-sided one. (And at x = 4, a central one.)
//! let opts = GradcheckOptions {
//!     names: vec!["density".into()],
//!     domains: vec![Domain::at_least(0.0)],
//!     ..Default::default()
//! };
//! let report = gradcheck(
//!     |t, v| {
//!         let root = t.sqrt(v[0])?;
//!         let y = t.powi(root, 4)?;
//!         t.sum(y)
//!     },
//!     &[arr1(&[0.0, 4.0]).into_dyn()],
//!     &opts,
//! )?;
//! report.check(1e-6, 1e-6).unwrap();
//! let at_zero = &report.entries[0];
//! assert!(report.locate(at_zero).starts_with("input \"density\" at [0], one-sided"));
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

mod domain;
mod report;

pub use domain::{Difference, Domain};
pub use report::{GradcheckEntry, GradcheckReport};

use ndarray::{ArrayD, Dimension, IxDyn, Zip};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::error::{Result, TapeError};
use crate::tape::Tape;
use crate::var::Var;

/// Settings of [`gradcheck`]; the tolerances and step are PyTorch's, which were designed for
/// f64.
#[derive(Debug, Clone, PartialEq)]
pub struct GradcheckOptions {
    /// Step of the finite differences, relative to `max(1, |x|)` (fast mode: along a
    /// direction of unit norm over all inputs). Default 1e-6.
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
    /// The inputs' names, in order, for the report (`input "sigma" at [3]`); inputs past the
    /// end of the list are named by their index. Default empty.
    pub names: Vec<String>,
    /// Where each input (in order) may be evaluated; inputs past the end of the list are
    /// unbounded. An element within a step of an end of its domain is differenced one-sidedly
    /// (see [`Difference`]), and in fast mode the random directions step inward there.
    /// Default empty: central differences everywhere.
    pub domains: Vec<Domain>,
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
            names: Vec::new(),
            domains: Vec::new(),
        }
    }
}

impl GradcheckOptions {
    fn domain(&self, input: usize) -> Domain {
        self.domains.get(input).copied().unwrap_or(Domain::REAL)
    }

    fn name(&self, input: usize) -> String {
        match self.names.get(input) {
            Some(name) => format!("input \"{name}\""),
            None => format!("input {input}"),
        }
    }

    fn validate(&self, inputs: usize) -> Result<()> {
        if self.eps.is_nan() || self.eps <= 0.0 {
            return Err(invalid(format!("eps must be positive, got {}", self.eps)));
        }
        for (what, len) in [("names", self.names.len()), ("domains", self.domains.len())] {
            if len > inputs {
                return Err(invalid(format!("{what} has {len} entries for {inputs} inputs")));
            }
        }
        for (i, d) in self.domains.iter().enumerate() {
            d.validate(&self.name(i))?;
        }
        Ok(())
    }
}

fn invalid(reason: String) -> TapeError {
    TapeError::InvalidArgument {
        op: "gradcheck",
        reason,
    }
}

/// Compares the gradient that the tape computes for `f` at `inputs` with finite differences,
/// and reports the disagreements (it does not decide pass or fail: call
/// [`GradcheckReport::check`] for that).
///
/// `f` receives a fresh tape and one param per input, and returns the output; it is called
/// many times and must be deterministic. A non-scalar output is projected on a fixed random
/// `v` (the scalar checked is `v . f(x)`). Full mode costs two (one-sided: two, plus one
/// shared) calls of `f` per input element; fast mode two per direction.
///
/// Errors: those of `f` (first at `inputs` themselves, so an input `f` rejects gets `f`'s own
/// message) or of the backward sweep; options that make no sense (`eps <= 0`, more names or
/// domains than inputs, an empty domain); an element outside its domain or in one narrower
/// than two steps.
pub fn gradcheck<Func>(f: Func, inputs: &[ArrayD<f64>], opts: &GradcheckOptions) -> Result<GradcheckReport>
where
    Func: Fn(&mut Tape<f64>, &[Var]) -> Result<Var>,
{
    opts.validate(inputs.len())?;
    let mut rng = StdRng::seed_from_u64(opts.seed);
    let (projection, analytic, reentrancy_diff) = analytic(&f, inputs, &mut rng)?;

    // v . f(x) for perturbed inputs, on one reused tape.
    let mut scratch = Tape::new();
    let mut projected = |xs: Vec<ArrayD<f64>>| -> Result<f64> {
        scratch.clear();
        let vs: Vec<Var> = xs.into_iter().map(|x| scratch.constant(x)).collect();
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
    let entries = if opts.fast {
        directional(&mut projected, inputs, &analytic, opts, &mut rng)?
    } else {
        elementwise(&mut projected, inputs, &analytic, opts)?
    };
    Ok(GradcheckReport {
        checked: entries.len(),
        entries,
        reentrancy_diff,
        atol: opts.atol,
        rtol: opts.rtol,
        names: opts.names.clone(),
    })
}

/// The projection `v`, the tape's gradient of `v . f` at `inputs`, and the largest difference
/// between two backward sweeps over the same tape (dropped before the differences start).
fn analytic<Func>(f: &Func, inputs: &[ArrayD<f64>], rng: &mut StdRng) -> Result<(ArrayD<f64>, Vec<ArrayD<f64>>, f64)>
where
    Func: Fn(&mut Tape<f64>, &[Var]) -> Result<Var>,
{
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
    Ok((projection, analytic, reentrancy_diff))
}

/// Full mode: every element, with the difference its domain allows.
fn elementwise(
    projected: &mut impl FnMut(Vec<ArrayD<f64>>) -> Result<f64>,
    inputs: &[ArrayD<f64>],
    analytic: &[ArrayD<f64>],
    opts: &GradcheckOptions,
) -> Result<Vec<GradcheckEntry>> {
    let mut at_inputs = None;
    let mut entries = Vec::new();
    let mut xs: Vec<ArrayD<f64>> = inputs.to_vec();
    for (i, x) in inputs.iter().enumerate() {
        let domain = opts.domain(i);
        for (ix, &x0) in x.indexed_iter() {
            let h = opts.eps * x0.abs().max(1.0);
            let difference = domain.difference(x0, h, || format!("{} at {:?}", opts.name(i), ix.slice()))?;
            let [a, b] = difference.offsets();
            xs[i][&ix] = x0 + a * h;
            let f1 = projected(xs.clone())?;
            xs[i][&ix] = x0 + b * h;
            let f2 = projected(xs.clone())?;
            xs[i][&ix] = x0;
            let f0 = match (difference.one_sided(), at_inputs) {
                (false, _) => 0.0,
                (true, Some(f0)) => f0,
                (true, None) => *at_inputs.insert(projected(inputs.to_vec())?),
            };
            entries.push(GradcheckEntry {
                input: Some(i),
                index: ix.slice().to_vec(),
                numeric: difference.estimate(f0, f1, f2, h),
                analytic: analytic[i][&ix],
                difference,
            });
        }
    }
    Ok(entries)
}

/// Fast mode: directional derivatives along seeded random directions of unit norm. Each
/// direction is split in two: the elements whose central step `x +- h d` stays inside their
/// domain take the central difference (one entry), and the elements whose step would leave it
/// (those at or near an end) are checked along a second direction through them alone, stepping
/// inward, by the one-sided formula (a second entry with the same number, only where there are
/// such elements). A direction that moved every element inward would be one-sided through all
/// of them: its steps of the many elements near an end add up coherently, and the difference's
/// error, which grows with the cube of that sum, can exceed the tolerance on a correct op.
fn directional(
    projected: &mut impl FnMut(Vec<ArrayD<f64>>) -> Result<f64>,
    inputs: &[ArrayD<f64>],
    analytic: &[ArrayD<f64>],
    opts: &GradcheckOptions,
    rng: &mut StdRng,
) -> Result<Vec<GradcheckEntry>> {
    // Directions have unit norm, so the step moves the inputs by eps in all (a step relative to
    // the largest input would move a long input's every element by it, far beyond where a
    // difference is accurate); an element's raw direction is scaled by max(1, |x|), so that
    // large values move in proportion.
    let h = opts.eps;
    // Which way each element may move by up to 2h, if it is near an end: +1 or -1, else 0.
    let mut signs: Vec<ArrayD<i8>> = Vec::with_capacity(inputs.len());
    for (i, x) in inputs.iter().enumerate() {
        let domain = opts.domain(i);
        let mut s = ArrayD::zeros(x.raw_dim());
        for (ix, &x0) in x.indexed_iter() {
            let sign = domain.inward_sign(x0, h, || format!("{} at {:?}", opts.name(i), ix.slice()))?;
            s[&ix] = sign.map_or(0, |v| v as i8);
        }
        signs.push(s);
    }
    let mut f0 = None;
    let shifted = |dirs: &[ArrayD<f64>], step: f64| -> Vec<ArrayD<f64>> {
        inputs
            .iter()
            .zip(dirs)
            .map(|(x, d)| Zip::from(x).and(d).map_collect(|&x, &d| x + step * d))
            .collect()
    };
    let mut entries = Vec::with_capacity(opts.projections);
    for k in 0..opts.projections {
        let raw: Vec<ArrayD<f64>> = inputs
            .iter()
            .map(|x| x.mapv(|x| rng.gen_range(-1.0..1.0) * x.abs().max(1.0)))
            .collect();
        let norm = unit_norm(&raw);
        // The central part: every element whose step h d stays inside its domain.
        let mut central = raw.clone();
        let mut boundary: Vec<ArrayD<f64>> = raw.iter().map(|d| ArrayD::zeros(d.raw_dim())).collect();
        for (i, x) in inputs.iter().enumerate() {
            let domain = opts.domain(i);
            Zip::from(&mut central[i])
                .and(&mut boundary[i])
                .and(x)
                .and(&signs[i])
                .for_each(|c, b, &x, &s| {
                    let step = h * *c / norm;
                    if s != 0 && !(domain.contains(x - step) && domain.contains(x + step)) {
                        *b = f64::from(s) * c.abs();
                        *c = 0.0;
                    }
                });
        }
        for (dirs, difference) in [(central, Difference::Central), (boundary, Difference::Forward)] {
            let norm = unit_norm(&dirs);
            if norm == 0.0 {
                continue;
            }
            let dirs: Vec<ArrayD<f64>> = dirs.into_iter().map(|d| d / norm).collect();
            let at_inputs = match (difference.one_sided(), f0) {
                (false, _) => 0.0,
                (true, Some(v)) => v,
                (true, None) => *f0.insert(projected(inputs.to_vec())?),
            };
            let [a, b] = difference.offsets();
            let f1 = projected(shifted(&dirs, a * h))?;
            let f2 = projected(shifted(&dirs, b * h))?;
            entries.push(GradcheckEntry {
                input: None,
                index: vec![k],
                numeric: difference.estimate(at_inputs, f1, f2, h),
                analytic: analytic
                    .iter()
                    .zip(&dirs)
                    .map(|(g, d)| Zip::from(g).and(d).fold(0.0, |acc, &g, &d| acc + g * d))
                    .sum(),
                difference,
            });
        }
    }
    Ok(entries)
}

/// The Euclidean norm of `dirs` taken as one vector.
fn unit_norm(dirs: &[ArrayD<f64>]) -> f64 {
    dirs.iter().flat_map(|d| d.iter()).map(|u| u * u).sum::<f64>().sqrt()
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

    /// y = x e^-x, defined (by fiat, as a density is) only for x >= 0: the forward rejects a
    /// negative input, as the composite does. dy/dx = (1 - x) e^-x.
    #[derive(Debug)]
    struct DecayOnHalfLine;

    impl CustomOp<f64> for DecayOnHalfLine {
        type Saved = ();
        fn name(&self) -> &'static str {
            "decay_on_half_line"
        }
        fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> std::result::Result<(Vec<ArrayD<f64>>, ()), OpError> {
            if let Some(x) = inputs[0].iter().find(|&&x| x < 0.0) {
                return Err(OpError::InvalidArgument(format!("x = {x} is negative")));
            }
            Ok((vec![inputs[0].mapv(|x| x * (-x).exp())], ()))
        }
        fn backward(
            &self,
            ctx: &BackwardCtx<'_, f64, ()>,
            grads: &[Option<ArrayViewD<'_, f64>>],
        ) -> std::result::Result<Vec<Option<ArrayD<f64>>>, OpError> {
            Ok(vec![grads[0]
                .as_ref()
                .map(|g| g * &ctx.input(0).mapv(|x| (1.0 - x) * (-x).exp()))])
        }
    }

    fn half_line(x: &[f64], opts: &GradcheckOptions) -> Result<GradcheckReport> {
        let x = ArrayD::from_shape_vec(vec![x.len()], x.to_vec()).unwrap();
        gradcheck(
            |t, v| {
                let y = t.apply1(DecayOnHalfLine, &[v[0]])?;
                t.sum(y)
            },
            &[x],
            opts,
        )
    }

    #[test]
    fn at_the_bound_the_difference_is_one_sided_and_matches_the_exact_derivative() {
        let xs = [0.0, 5e-7, 0.5, 3.0];
        // Without a domain, the central difference steps to -1e-6 and the op refuses.
        let e = half_line(&xs, &GradcheckOptions::default()).unwrap_err();
        assert!(e.to_string().contains("is negative"), "{e}");
        let opts = GradcheckOptions {
            domains: vec![Domain::at_least(0.0)],
            ..Default::default()
        };
        let report = half_line(&xs, &opts).unwrap();
        for (e, &x) in report.entries.iter().zip(&xs) {
            let exact = (1.0 - x) * (-x).exp();
            // Second-order formulas: truncation ~ h^2 |f'''| ~ 1e-12, rounding ~ 1e-16 / 1e-6.
            assert!((e.numeric - exact).abs() < 1e-8, "x = {x}: {} vs {exact}", e.numeric);
            let want = if x < 1e-6 {
                Difference::Forward
            } else {
                Difference::Central
            };
            assert_eq!(e.difference, want, "x = {x}");
        }
        report.check(1e-8, 0.0).unwrap();
        // An upper bound at x: the backward formula, equally exact.
        let upper = GradcheckOptions {
            domains: vec![Domain { lower: 0.0, upper: 0.5 }],
            ..Default::default()
        };
        let report = half_line(&[0.5], &upper).unwrap();
        assert_eq!(report.entries[0].difference, Difference::Backward);
        assert!((report.entries[0].numeric - 0.5 * (-0.5f64).exp()).abs() < 1e-8);
        // Fast mode steps inward from the bound too, and agrees.
        let fast = GradcheckOptions {
            fast: true,
            ..opts.clone()
        };
        let report = half_line(&xs, &fast).unwrap();
        // Each direction: a central entry through the elements away from 0, and a one-sided
        // one through those whose step would cross it (x = 0 at least).
        let kinds: Vec<Difference> = report.entries.iter().map(|e| e.difference).collect();
        assert_eq!(kinds.len(), 16, "{kinds:?}");
        assert!(
            kinds.chunks(2).all(|p| p == [Difference::Central, Difference::Forward]),
            "{kinds:?}"
        );
        report.check(1e-8, 1e-8).unwrap();
        // Outside the domain the op speaks first (its own message); a domain narrower than
        // two steps is refused.
        let e = half_line(&[-1.0], &opts).unwrap_err();
        assert!(e.to_string().contains("is negative"), "{e}");
        let narrow = GradcheckOptions {
            domains: vec![Domain {
                lower: 0.0,
                upper: 1e-7,
            }],
            ..Default::default()
        };
        let e = half_line(&[0.0], &narrow).unwrap_err();
        assert!(e.to_string().contains("narrower"), "{e}");
    }

    #[test]
    fn the_report_names_inputs_as_the_caller_does() {
        let opts = GradcheckOptions {
            names: vec!["weight".into()],
            ..Default::default()
        };
        let f = |t: &mut Tape<f64>, v: &[Var]| {
            let a = t.apply1(WrongSquare, &[v[0]])?;
            let b = t.mul(a, v[1])?;
            t.sum(b)
        };
        let inputs = [input(), input()];
        let report = gradcheck(f, &inputs, &opts).unwrap();
        let text = report.check(1e-5, 1e-3).unwrap_err().to_string();
        assert!(text.contains("input \"weight\" at [2]"), "{text}");
        assert!(!text.contains("Some(") && !text.contains("None"), "{text}");
        let second = report.entries.iter().find(|e| e.input == Some(1)).unwrap();
        assert_eq!(report.locate(second), "input 1 at [0]");
        let fast = GradcheckOptions { fast: true, ..opts };
        let report = gradcheck(f, &inputs, &fast).unwrap();
        assert_eq!(report.locate(&report.entries[3]), "direction 3 (all inputs)");
        let too_many = GradcheckOptions {
            names: vec!["a".into(); 3],
            ..Default::default()
        };
        assert!(gradcheck(f, &inputs, &too_many).is_err());
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
