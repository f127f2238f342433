//! Element-wise functions of one input: each is a pair (f, df) in one table.
//!
//! Conventions at kinks: `abs'(0) = 0`, `relu'(0) = 0`, and `clamp` passes the gradient
//! where `lo <= x <= hi` (inclusive, as PyTorch). Derivatives follow the strong-zero rule
//! (a zero upstream gradient contributes exactly zero).

use ndarray::{ArrayD, ArrayViewD};

use super::strong_mul;
use crate::buffer::{map1, map3};
use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// Which element-wise function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UnaryFn<F> {
    /// `-x`; derivative -1.
    Neg,
    /// `e^x`; derivative e^x (the output).
    Exp,
    /// `e^x - 1` without cancellation near 0; derivative e^x.
    Expm1,
    /// natural log; derivative 1/x.
    Ln,
    /// `ln(1 + x)` without cancellation near 0; derivative 1/(1 + x).
    Ln1p,
    /// square root; derivative 1/(2 sqrt x) (infinite at 0: the strong-zero rule applies).
    Sqrt,
    /// `x^n`; derivative n x^(n-1).
    Powi(i32),
    /// `x^2`; derivative 2x.
    Square,
    /// `|x|`; derivative sign(x), 0 at 0.
    Abs,
    /// `max(x, 0)`; derivative 1 for x > 0, else 0.
    Relu,
    /// `min(max(x, lo), hi)`; derivative 1 for lo <= x <= hi, else 0.
    Clamp(F, F),
    /// `x + c`; derivative 1.
    AddScalar(F),
    /// `x * c`; derivative c.
    MulScalar(F),
    /// `x / c`; derivative 1/c.
    DivScalar(F),
    /// `c - x`; derivative -1.
    RsubScalar(F),
}

impl<F: Float> UnaryFn<F> {
    fn name(self) -> &'static str {
        match self {
            UnaryFn::Neg => "neg",
            UnaryFn::Exp => "exp",
            UnaryFn::Expm1 => "expm1",
            UnaryFn::Ln => "ln",
            UnaryFn::Ln1p => "ln_1p",
            UnaryFn::Sqrt => "sqrt",
            UnaryFn::Powi(_) => "powi",
            UnaryFn::Square => "square",
            UnaryFn::Abs => "abs",
            UnaryFn::Relu => "relu",
            UnaryFn::Clamp(..) => "clamp",
            UnaryFn::AddScalar(_) => "add_scalar",
            UnaryFn::MulScalar(_) => "mul_scalar",
            UnaryFn::DivScalar(_) => "div_scalar",
            UnaryFn::RsubScalar(_) => "rsub_scalar",
        }
    }

    fn f(self, x: F) -> F {
        match self {
            UnaryFn::Neg => -x,
            UnaryFn::Exp => x.exp(),
            UnaryFn::Expm1 => x.exp_m1(),
            UnaryFn::Ln => x.ln(),
            UnaryFn::Ln1p => x.ln_1p(),
            UnaryFn::Sqrt => x.sqrt(),
            UnaryFn::Powi(n) => x.powi(n),
            UnaryFn::Square => x * x,
            UnaryFn::Abs => x.abs(),
            UnaryFn::Relu => x.max(F::zero()),
            UnaryFn::Clamp(lo, hi) => x.max(lo).min(hi),
            UnaryFn::AddScalar(c) => x + c,
            UnaryFn::MulScalar(c) => x * c,
            UnaryFn::DivScalar(c) => x / c,
            UnaryFn::RsubScalar(c) => c - x,
        }
    }

    /// The derivative at `x`, given the output `y = f(x)` where that is cheaper.
    fn df(self, x: F, y: F) -> F {
        let one = F::one();
        match self {
            UnaryFn::Neg | UnaryFn::RsubScalar(_) => -one,
            UnaryFn::Exp => y,
            UnaryFn::Expm1 => x.exp(),
            UnaryFn::Ln => one / x,
            UnaryFn::Ln1p => one / (one + x),
            UnaryFn::Sqrt => F::lit(0.5) / y,
            UnaryFn::Powi(0) => F::zero(),
            UnaryFn::Powi(n) => F::lit(f64::from(n)) * x.powi(n - 1),
            UnaryFn::Square => x + x,
            UnaryFn::Abs | UnaryFn::Relu if x == F::zero() => F::zero(),
            UnaryFn::Abs => x.signum(),
            UnaryFn::Relu => {
                if x > F::zero() {
                    one
                } else {
                    F::zero()
                }
            }
            UnaryFn::Clamp(lo, hi) => {
                if lo <= x && x <= hi {
                    one
                } else {
                    F::zero()
                }
            }
            UnaryFn::AddScalar(_) => one,
            UnaryFn::MulScalar(c) => c,
            UnaryFn::DivScalar(c) => one / c,
        }
    }
}

/// An element-wise op of one input (see [`UnaryFn`]).
#[derive(Debug, Clone, Copy)]
pub struct Unary<F>(pub UnaryFn<F>);

impl<F: Float> CustomOp<F> for Unary<F> {
    type Saved = ();

    fn name(&self) -> &'static str {
        self.0.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let x = only_input(inputs)?;
        if let UnaryFn::Clamp(lo, hi) = self.0 {
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return Err(OpError::InvalidArgument(format!("needs lo <= hi, got [{lo}, {hi}]")));
            }
        }
        let f = self.0;
        Ok((vec![map1(x, |x| f.f(x))], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let f = self.0;
        elementwise_backward(ctx, grads, |x, y| f.df(x, y))
    }
}

/// The backward of an element-wise function of one input: `g * df(x, y)` under the strong-zero
/// rule, from the derivative `df` at the input `x` given the output `y`.
pub(crate) fn elementwise_backward<F: Float, S>(
    ctx: &BackwardCtx<'_, F, S>,
    grads: &[Option<ArrayViewD<'_, F>>],
    df: impl Fn(F, F) -> F + Sync,
) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
    let Some(g) = &grads[0] else { return Ok(vec![None]) };
    let gx = map3(g, &ctx.input(0), &ctx.output(0), |g, x, y| strong_mul(g, df(x, y)));
    Ok(vec![Some(gx)])
}

/// The one input of an element-wise function, or the error that names how many were given.
pub(crate) fn only_input<'a, 'b, F: Float>(inputs: &'a [ArrayViewD<'b, F>]) -> Result<&'a ArrayViewD<'b, F>, OpError> {
    match inputs {
        [x] => Ok(x),
        _ => Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len()))),
    }
}

impl<F: Float> Tape<F> {
    fn unary(&mut self, x: Var, f: UnaryFn<F>) -> Result<Var> {
        self.apply1(Unary(f), &[x])
    }
    /// `-x`.
    pub fn neg(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Neg)
    }
    /// `e^x`.
    pub fn exp(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Exp)
    }
    /// `e^x - 1`, accurate near 0 (use `-expm1(-tau)` for an opacity).
    pub fn expm1(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Expm1)
    }
    /// Natural logarithm (NaN below 0, -inf at 0, as IEEE).
    pub fn ln(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Ln)
    }
    /// `ln(1 + x)`, accurate near 0.
    pub fn ln_1p(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Ln1p)
    }
    /// Square root; its infinite derivative at 0 is masked by a zero upstream gradient.
    pub fn sqrt(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Sqrt)
    }
    /// `x^n` for an integer `n`.
    pub fn powi(&mut self, x: Var, n: i32) -> Result<Var> {
        self.unary(x, UnaryFn::Powi(n))
    }
    /// `x^2`.
    pub fn square(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Square)
    }
    /// `|x|` (derivative 0 at 0).
    pub fn abs(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Abs)
    }
    /// `max(x, 0)` (derivative 0 at 0).
    pub fn relu(&mut self, x: Var) -> Result<Var> {
        self.unary(x, UnaryFn::Relu)
    }
    /// `min(max(x, lo), hi)`; errors if `lo > hi` or either is NaN.
    pub fn clamp(&mut self, x: Var, lo: F, hi: F) -> Result<Var> {
        self.unary(x, UnaryFn::Clamp(lo, hi))
    }
    /// `x + c`.
    pub fn add_scalar(&mut self, x: Var, c: F) -> Result<Var> {
        self.unary(x, UnaryFn::AddScalar(c))
    }
    /// `x - c`.
    pub fn sub_scalar(&mut self, x: Var, c: F) -> Result<Var> {
        self.unary(x, UnaryFn::AddScalar(-c))
    }
    /// `x * c`.
    pub fn mul_scalar(&mut self, x: Var, c: F) -> Result<Var> {
        self.unary(x, UnaryFn::MulScalar(c))
    }
    /// `x / c`.
    pub fn div_scalar(&mut self, x: Var, c: F) -> Result<Var> {
        self.unary(x, UnaryFn::DivScalar(c))
    }
    /// `c - x` (for example `1 - alpha`).
    pub fn rsub_scalar(&mut self, x: Var, c: F) -> Result<Var> {
        self.unary(x, UnaryFn::RsubScalar(c))
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{assert_gradcheck, values_close};
    use crate::{Tape, TapeError};
    use ndarray::{arr1, ArrayD};

    type Op = fn(&mut Tape<f64>, crate::Var) -> crate::Result<crate::Var>;

    /// Each op with values computed by hand (formula in the comment) at x = (0.5, 2).
    #[test]
    fn values_match_formulas_in_f32_and_f64() {
        let cases: Vec<(&str, Op, [f64; 2])> = vec![
            ("neg", |t, x| t.neg(x), [-0.5, -2.0]),
            // e^0.5 = 1.6487212707, e^2 = 7.3890560989
            ("exp", |t, x| t.exp(x), [1.648_721_270_700_128, 7.389_056_098_930_65]),
            (
                "expm1",
                |t, x| t.expm1(x),
                [0.648_721_270_700_128, 6.389_056_098_930_65],
            ),
            // ln 0.5 = -0.6931471806, ln 2 = 0.6931471806
            ("ln", |t, x| t.ln(x), [-std::f64::consts::LN_2, std::f64::consts::LN_2]),
            // ln 1.5 = 0.4054651081, ln 3 = 1.0986122887
            (
                "ln_1p",
                |t, x| t.ln_1p(x),
                [0.405_465_108_108_164_4, 1.098_612_288_668_11],
            ),
            (
                "sqrt",
                |t, x| t.sqrt(x),
                [std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::SQRT_2],
            ),
            ("powi3", |t, x| t.powi(x, 3), [0.125, 8.0]),
            ("square", |t, x| t.square(x), [0.25, 4.0]),
            ("clamp", |t, x| t.clamp(x, 0.0, 1.0), [0.5, 1.0]),
            ("add_scalar", |t, x| t.add_scalar(x, 1.5), [2.0, 3.5]),
            ("sub_scalar", |t, x| t.sub_scalar(x, 1.5), [-1.0, 0.5]),
            ("mul_scalar", |t, x| t.mul_scalar(x, 3.0), [1.5, 6.0]),
            ("div_scalar", |t, x| t.div_scalar(x, 4.0), [0.125, 0.5]),
            ("rsub_scalar", |t, x| t.rsub_scalar(x, 1.0), [0.5, -1.0]),
        ];
        for (name, op, want) in cases {
            let mut t = Tape::<f64>::new();
            let x = t.param(arr1(&[0.5, 2.0]));
            let y = op(&mut t, x).unwrap();
            values_close(name, t.value(y).unwrap(), &want, 1e-15);
            // The same op in f32 through the same generic code.
            let mut t32 = Tape::<f32>::new();
            let x32 = t32.param(arr1(&[0.5f32, 2.0]));
            let mut t64 = Tape::<f64>::new();
            let x64 = t64.param(arr1(&[0.5, 2.0]));
            let y64 = op(&mut t64, x64).unwrap();
            let y32 = f32_twin(name, &mut t32, x32);
            let v32: Vec<f64> = t32.value(y32).unwrap().iter().map(|&v| f64::from(v)).collect();
            values_close(name, t64.value(y64).unwrap(), &v32, 1e-6);
        }
    }

    fn f32_twin(name: &str, t: &mut Tape<f32>, x: crate::Var) -> crate::Var {
        match name {
            "neg" => t.neg(x),
            "exp" => t.exp(x),
            "expm1" => t.expm1(x),
            "ln" => t.ln(x),
            "ln_1p" => t.ln_1p(x),
            "sqrt" => t.sqrt(x),
            "powi3" => t.powi(x, 3),
            "square" => t.square(x),
            "clamp" => t.clamp(x, 0.0, 1.0),
            "add_scalar" => t.add_scalar(x, 1.5),
            "sub_scalar" => t.sub_scalar(x, 1.5),
            "mul_scalar" => t.mul_scalar(x, 3.0),
            "div_scalar" => t.div_scalar(x, 4.0),
            "rsub_scalar" => t.rsub_scalar(x, 1.0),
            other => panic!("no f32 twin for {other}"),
        }
        .unwrap()
    }

    #[test]
    fn abs_and_relu_at_the_kink_and_beyond() {
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[-1.5, 0.0, 2.0]));
        let a = t.abs(x).unwrap();
        let r = t.relu(x).unwrap();
        values_close("abs", t.value(a).unwrap(), &[1.5, 0.0, 2.0], 0.0);
        values_close("relu", t.value(r).unwrap(), &[0.0, 0.0, 2.0], 0.0);
        let s = t.add(a, r).unwrap();
        let y = t.sum(s).unwrap();
        // d/dx (|x| + relu x) = sign(x) + [x > 0] = (-1, 0, 2), with 0 at the kink by convention.
        let g = t.backward(y).unwrap();
        values_close("d(abs+relu)", g.get(x).unwrap(), &[-1.0, 0.0, 2.0], 0.0);
    }

    #[test]
    fn clamp_passes_gradient_inclusively_and_rejects_inverted_bounds() {
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[-1.0, 0.0, 0.5, 1.0, 2.0]));
        let c = t.clamp(x, 0.0, 1.0).unwrap();
        let y = t.sum(c).unwrap();
        let g = t.backward(y).unwrap();
        values_close("dclamp", g.get(x).unwrap(), &[0.0, 1.0, 1.0, 1.0, 0.0], 0.0);
        let before = t.len();
        assert!(matches!(
            t.clamp(x, 1.0, 0.0),
            Err(TapeError::InvalidArgument { op: "clamp", .. })
        ));
        assert_eq!(t.len(), before, "a failed op leaves the tape unchanged");
    }

    #[test]
    fn expm1_and_ln_1p_keep_digits_where_the_naive_forms_cancel() {
        // At x = 1e-10: e^x - 1 = 1.00000000005e-10; exp(x) - 1 in f64 gives 1.000000082740371e-10.
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[1e-10]));
        let y = t.expm1(x).unwrap();
        let naive = (1e-10f64).exp() - 1.0;
        let exact = 1.000_000_000_05e-10;
        assert!(((t.value(y).unwrap()[[0]] - exact) / exact).abs() < 1e-15);
        assert!(
            ((naive - exact) / exact).abs() > 1e-8,
            "the naive form must really fail here"
        );
        let l = t.ln_1p(x).unwrap();
        // ln(1 + 1e-10) = 1e-10 - 5e-21.
        assert!(((t.value(l).unwrap()[[0]] - 0.999_999_999_95e-10) / 1e-10).abs() < 1e-15);
    }

    #[test]
    fn strong_zero_masks_an_infinite_local_derivative() {
        // y = sum(0 * sqrt(x)) at x = 0: d sqrt/dx = inf there, yet the upstream gradient is 0,
        // so the contribution must be exactly 0 (IEEE would give 0 * inf = NaN).
        let mut t = Tape::<f64>::new();
        let x = t.param(arr1(&[0.0, 4.0]));
        let s = t.sqrt(x).unwrap();
        let g = t
            .backward_with(s, ArrayD::from_shape_vec(vec![2], vec![0.0, 1.0]).unwrap())
            .unwrap();
        // d sqrt(4) = 1/(2*2) = 0.25
        values_close("strong zero", g.get(x).unwrap(), &[0.0, 0.25], 0.0);
    }

    #[test]
    fn every_unary_op_passes_gradcheck_in_f64() {
        let ops: Vec<(&str, Op)> = vec![
            ("neg", |t, x| t.neg(x)),
            ("exp", |t, x| t.exp(x)),
            ("expm1", |t, x| t.expm1(x)),
            ("ln", |t, x| t.ln(x)),
            ("ln_1p", |t, x| t.ln_1p(x)),
            ("sqrt", |t, x| t.sqrt(x)),
            ("powi", |t, x| t.powi(x, 3)),
            ("powi_neg", |t, x| t.powi(x, -2)),
            ("square", |t, x| t.square(x)),
            ("abs", |t, x| t.abs(x)),
            ("relu", |t, x| t.relu(x)),
            ("clamp", |t, x| t.clamp(x, 0.4, 1.1)),
            ("add_scalar", |t, x| t.add_scalar(x, 2.0)),
            ("mul_scalar", |t, x| t.mul_scalar(x, -3.0)),
            ("div_scalar", |t, x| t.div_scalar(x, 7.0)),
            ("rsub_scalar", |t, x| t.rsub_scalar(x, 1.0)),
        ];
        // Points away from kinks and clamp bounds, where finite differences are valid.
        let x = ArrayD::from_shape_vec(vec![2, 2], vec![0.3, 0.7, 1.3, 2.1]).unwrap();
        for (name, op) in ops {
            assert_gradcheck(name, std::slice::from_ref(&x), move |t, v| {
                let y = op(t, v[0])?;
                Ok(y)
            });
        }
    }
}
