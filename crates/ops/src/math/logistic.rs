//! `softplus`, `sigmoid` and the sigmoid's slope, branch-free on top of [`exp_neg`], in the
//! forms that cannot overflow or cancel. With `e = exp(-|x|)`, which is in `[0, 1]`:
//!
//! - `softplus(x) = max(x, 0) + ln(1 + e)`: never overflows (`ln(1 + exp(x))` is infinite from
//!   `x = 710`), is `x` to the last bit for large `x`, and keeps every digit of the tail
//!   `exp(x)` for very negative `x`;
//! - `sigmoid(x) = exp(min(x, 0)) / (1 + e)` (the numerator is 1 or `e`): exactly 0 and 1
//!   where saturated, full relative accuracy in the lower tail;
//! - `sigmoid'(x) = e / (1 + e)^2`: never `y (1 - y)`, which is 0 once `y` rounds to 1
//!   (`x = 37.5` in f64) though the true slope is not; `softplus' = sigmoid`.
//!
//! `ln(1 + e)` on `[0, 1]` is `2 atanh(s)` with `s = e / (2 + e)` in `[0, 1/3]`: its odd series
//! `2 s (1 + s^2/3 + s^4/5 + ...)` converges by a factor `1/9` a term, with no table and no
//! range reduction, and is exact in relative terms down to the subnormals (no `1 + e` is
//! rounded before the logarithm). The double tier sums it to `s^30` (first omitted term below
//! `1.6e-17` relative) and recovers the roundings of `2 + e`, `1 + e` and the divisions with
//! exact residuals (fused multiply-adds). Against the same forms through the C library (whose
//! own roundings are part of the distance), over the whole range, subnormals included, the
//! tests below bound softplus and sigmoid to 2 ulp, the slope to 4 ulp, and `ln(1 + e)` on
//! `[0, 1]` to 1 ulp of `ln_1p`. The `SINGLE` tier, for f32 data, stops at `s^16`
//! (`1.4e-10` relative) and skips the compensations: rounded to f32, the results are
//! within 0.51 f32 ulp of the exact values (correctly rounded but within 1e-9 of a tie).

use super::exp::exp_neg;

/// `1 / (2k + 1)` for `k = 1..=15`: the series `atanh(s) / s = 1 + sum_k s^(2k) / (2k + 1)`.
const ODD_RECIPROCALS: [f64; 15] = [
    1.0 / 3.0,
    1.0 / 5.0,
    1.0 / 7.0,
    1.0 / 9.0,
    1.0 / 11.0,
    1.0 / 13.0,
    1.0 / 15.0,
    1.0 / 17.0,
    1.0 / 19.0,
    1.0 / 21.0,
    1.0 / 23.0,
    1.0 / 25.0,
    1.0 / 27.0,
    1.0 / 29.0,
    1.0 / 31.0,
];

/// `P(z) = sum_k z^(k-1) / (2k + 1)` for `z in [0, 1/9]` by Estrin's scheme: 8 terms
/// (`SINGLE`) or 15.
#[inline(always)]
fn atanh_series<const SINGLE: bool>(z: f64) -> f64 {
    let c = &ODD_RECIPROCALS;
    let (z2, z4) = (z * z, (z * z) * (z * z));
    let p01 = c[1].mul_add(z, c[0]);
    let p23 = c[3].mul_add(z, c[2]);
    let p45 = c[5].mul_add(z, c[4]);
    let p67 = c[7].mul_add(z, c[6]);
    let q0 = p23.mul_add(z2, p01);
    let q1 = p67.mul_add(z2, p45);
    if SINGLE {
        q1.mul_add(z4, q0)
    } else {
        let p89 = c[9].mul_add(z, c[8]);
        let p1011 = c[11].mul_add(z, c[10]);
        let p1213 = c[13].mul_add(z, c[12]);
        let q2 = p1011.mul_add(z2, p89);
        let q3 = c[14].mul_add(z2, p1213);
        let r0 = q1.mul_add(z4, q0);
        let r1 = q3.mul_add(z4, q2);
        r1.mul_add(z4 * z4, r0)
    }
}

/// `ln(1 + e)` for `e` in `[0, 1]`, with full relative accuracy (see the module docs).
#[inline(always)]
pub(crate) fn ln_1p_unit<const SINGLE: bool>(e: f64) -> f64 {
    // u = 2s = e t with t = 2 / (2 + e): no halving, so a subnormal e comes back whole.
    let d = 2.0 + e;
    let t = 2.0 / d;
    let u = e * t;
    let z = 0.25 * (u * u);
    let p = atanh_series::<SINGLE>(z);
    if SINGLE {
        return (u * z).mul_add(p, u);
    }
    // What the roundings of d, t and u lost, exactly: d - 2 is exact (d in [2, 3]), and so
    // are the residuals 2 - t d and e t - u of a correctly rounded division and product.
    let d_err = e - (d - 2.0);
    let residual = (-t).mul_add(d, 2.0);
    // 2 / (d + d_err) - t, to first order; 1 / d is t / 2.
    let t_lo = (t * d_err - residual) * (-0.5 * t);
    let u_err = e.mul_add(t, -u);
    (u * z).mul_add(p, e.mul_add(t_lo, u_err)) + u
}

/// `1 / (1 + e)` for `e` in `[0, 1]` as an unevaluated sum `(hi, lo)` (`lo = 0` for `SINGLE`).
#[inline(always)]
fn reciprocal_one_plus<const SINGLE: bool>(e: f64) -> (f64, f64) {
    let d = 1.0 + e;
    let inv = 1.0 / d;
    if SINGLE {
        return (inv, 0.0);
    }
    // As in ln_1p_unit: d - 1 is exact (d in [1, 2]), 1 - inv d is the division's residual.
    let d_err = e - (d - 1.0);
    let residual = (-inv).mul_add(d, 1.0);
    (inv, (residual - inv * d_err) * inv)
}

/// `exp(-|x|)`, the decay every form below is built on; infinities give 0. Its callers may
/// keep it and pass it to the `_decayed` forms, which then need no exponential.
#[inline(always)]
pub(crate) fn decay<const SINGLE: bool>(x: f64) -> f64 {
    exp_neg::<SINGLE>(x.abs())
}

/// `ln(1 + exp(x))` (NaN gives a meaningless value: the callers validate). The kernels call
/// [`softplus_decayed`] with the decay they computed; this is the same composition, measured
/// by the tests below.
#[cfg(test)]
#[inline(always)]
pub(crate) fn softplus<const SINGLE: bool>(x: f64) -> f64 {
    softplus_decayed::<SINGLE>(x, decay::<SINGLE>(x))
}

/// [`softplus`] from `x` and its [`decay`] `e`.
#[inline(always)]
pub(crate) fn softplus_decayed<const SINGLE: bool>(x: f64, e: f64) -> f64 {
    x.max(0.0) + ln_1p_unit::<SINGLE>(e)
}

/// `1 / (1 + exp(-x))`, exactly 0 or 1 where saturated. (The kernels call the `_decayed`
/// forms with the decay they computed; these compositions are what the tests below measure.)
#[cfg(test)]
#[inline(always)]
pub(crate) fn sigmoid<const SINGLE: bool>(x: f64) -> f64 {
    sigmoid_decayed::<SINGLE>(x, decay::<SINGLE>(x))
}

/// [`sigmoid`] from `x` and its [`decay`] `e`.
#[inline(always)]
pub(crate) fn sigmoid_decayed<const SINGLE: bool>(x: f64, e: f64) -> f64 {
    let (inv, inv_lo) = reciprocal_one_plus::<SINGLE>(e);
    let numerator = if x >= 0.0 { 1.0 } else { e };
    numerator.mul_add(inv, numerator * inv_lo)
}

/// `sigmoid'(x) = e / (1 + e)^2` with `e = exp(-|x|)` (the slope is even in `x`).
#[cfg(test)]
#[inline(always)]
pub(crate) fn sigmoid_slope<const SINGLE: bool>(x: f64) -> f64 {
    sigmoid_slope_decayed::<SINGLE>(decay::<SINGLE>(x))
}

/// [`sigmoid_slope`] from the [`decay`] `e` of its argument alone.
#[inline(always)]
pub(crate) fn sigmoid_slope_decayed<const SINGLE: bool>(e: f64) -> f64 {
    let (inv, inv_lo) = reciprocal_one_plus::<SINGLE>(e);
    let square = inv * inv;
    if SINGLE {
        return e * square;
    }
    let square_lo = inv.mul_add(inv, -square) + 2.0 * inv * inv_lo;
    e.mul_add(square, e * square_lo)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place of the reference (f64).
    fn ulps(got: f64, want: f64) -> f64 {
        if got == want {
            return 0.0;
        }
        let ulp = if want == 0.0 {
            f64::from_bits(1)
        } else {
            f64::from_bits(want.abs().to_bits() + 1) - want.abs()
        };
        (got - want).abs() / ulp
    }

    /// Distance in f32 ulps of `got` (an f32) from the f64 `want`.
    fn ulps32(got: f32, want: f64) -> f64 {
        let w = want as f32;
        let ulp = if w == 0.0 {
            f64::from(f32::from_bits(1))
        } else {
            f64::from(f32::from_bits(w.abs().to_bits() + 1) - w.abs())
        };
        (f64::from(got) - want).abs() / ulp
    }

    /// Arguments over the whole range, both signs: every scale from 1e-300 to 1e4, dense
    /// steps through [-60, 60], the ends of the exponential's range, zero and infinities.
    fn arguments() -> Vec<f64> {
        let mut xs = vec![0.0, 700.0, 708.0, 709.8, 720.0, 745.0, 746.0, 800.0, 1e4, f64::INFINITY];
        let mut e = -300.0f64;
        while e < 4.0 {
            xs.push(10f64.powf(e));
            e += 0.011;
        }
        for k in 0..=24_000 {
            xs.push(f64::from(k) * 0.0025 + 1e-7);
        }
        let negatives: Vec<f64> = xs.iter().map(|x| -x).collect();
        xs.extend(negatives);
        xs
    }

    /// The textbook forms through the C library, evaluated where they are stable.
    fn softplus_libm(x: f64) -> f64 {
        x.max(0.0) + (-x.abs()).exp().ln_1p()
    }
    fn sigmoid_libm(x: f64) -> f64 {
        x.min(0.0).exp() / (1.0 + (-x.abs()).exp())
    }
    fn slope_libm(x: f64) -> f64 {
        let e = (-x.abs()).exp();
        e / ((1.0 + e) * (1.0 + e))
    }

    fn worst(f: impl Fn(f64) -> f64, reference: impl Fn(f64) -> f64) -> (f64, f64) {
        arguments()
            .into_iter()
            .map(|x| (ulps(f(x), reference(x)), x))
            .fold((0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a })
    }

    #[test]
    fn ln_1p_unit_is_within_1_ulp_of_libm_on_the_unit_interval_and_keeps_subnormals() {
        let mut es: Vec<f64> = (0..=100_000).map(|k| f64::from(k) * 1e-5).collect();
        es.extend((0..2000).map(|k| 10f64.powf(-f64::from(k) * 0.16)));
        es.extend([f64::from_bits(1), f64::from_bits(3), f64::MIN_POSITIVE, 1.0]);
        let (mut worst, mut at) = (0.0, 0.0);
        for e in es {
            let u = ulps(ln_1p_unit::<false>(e), e.ln_1p());
            if u > worst {
                (worst, at) = (u, e);
            }
        }
        assert!(worst <= 1.0, "worst {worst} ulp at e = {at:e}");
        // A subnormal e comes back bit for bit (a halving would drop its last bit).
        for bits in [1u64, 3, 12_345, 0x000f_ffff_ffff_ffff] {
            let e = f64::from_bits(bits);
            assert_eq!(ln_1p_unit::<false>(e), e);
            assert_eq!(ln_1p_unit::<true>(e), e);
        }
        assert_eq!(ln_1p_unit::<false>(0.0), 0.0);
    }

    #[test]
    fn softplus_is_within_2_ulp_of_libm_over_the_whole_range() {
        let (u, x) = worst(softplus::<false>, softplus_libm);
        assert!(u <= 2.0, "worst {u} ulp at x = {x:e}");
        assert_eq!(softplus::<false>(1e4), 1e4);
        assert_eq!(softplus::<false>(-1e4), 0.0);
        assert_eq!(softplus::<false>(f64::INFINITY), f64::INFINITY);
        assert_eq!(softplus::<false>(f64::NEG_INFINITY), 0.0);
        assert!(ulps(softplus::<false>(0.0), std::f64::consts::LN_2) <= 1.0);
        // The tail: softplus(-740) = exp(-740), a subnormal, to within a unit of its last place.
        assert!((softplus::<false>(-740.0) - (-740f64).exp()).abs() <= f64::from_bits(1));
        assert!(softplus::<false>(-740.0) > 0.0);
    }

    #[test]
    fn the_naive_softplus_overflows_where_the_stable_one_is_exact() {
        // ln(1 + exp(100)) in f32 is infinite; in f64 from x = 710.
        assert!((1.0 + 100f32.exp()).ln().is_infinite());
        assert!((1.0 + 710f64.exp()).ln().is_infinite());
        assert_eq!(softplus::<true>(100.0) as f32, 100.0);
        assert_eq!(softplus::<false>(710.0), 710.0);
        // And 1 + exp(-40) rounds to 1: the naive form returns 0 for softplus(-40) = 4.2e-18.
        assert_eq!((1.0 + (-40f64).exp()).ln(), 0.0);
        assert!(ulps(softplus::<false>(-40.0), (-40f64).exp().ln_1p()) <= 1.0);
    }

    #[test]
    fn sigmoid_is_within_2_ulp_of_libm_and_saturates_exactly() {
        let (u, x) = worst(sigmoid::<false>, sigmoid_libm);
        assert!(u <= 2.0, "worst {u} ulp at x = {x:e}");
        assert_eq!(sigmoid::<false>(0.0), 0.5);
        assert_eq!(sigmoid::<false>(-0.0), 0.5);
        assert_eq!(sigmoid::<false>(1e4), 1.0);
        assert_eq!(sigmoid::<false>(-1e4), 0.0);
        assert_eq!(sigmoid::<false>(f64::NEG_INFINITY), 0.0);
        assert_eq!(sigmoid::<false>(f64::INFINITY), 1.0);
        // The lower tail keeps its relative accuracy: sigmoid(-700) = exp(-700) (1 - ...).
        assert!(ulps(sigmoid::<false>(-700.0), (-700f64).exp()) <= 2.0);
    }

    #[test]
    fn the_slope_is_within_4_ulp_of_libm_where_y_one_minus_y_is_zero() {
        // The reference's own roundings (exp, 1 + e, its square, the division) are most of it.
        let (u, x) = worst(sigmoid_slope::<false>, slope_libm);
        assert!(u <= 4.0, "worst {u} ulp at x = {x:e}");
        assert_eq!(sigmoid_slope::<false>(0.0), 0.25);
        assert_eq!(sigmoid_slope::<false>(f64::INFINITY), 0.0);
        // At x = 40, y = sigmoid(x) rounds to 1 and y (1 - y) is 0; the slope is 4.2e-18.
        let y = sigmoid::<false>(40.0);
        assert_eq!(y * (1.0 - y), 0.0);
        let slope = sigmoid_slope::<false>(40.0);
        assert!(ulps(slope, (-40f64).exp() / (1.0 + (-40f64).exp()).powi(2)) <= 2.0);
        assert!(slope > 4.2e-18 && slope < 4.3e-18);
        // It is even.
        assert_eq!(sigmoid_slope::<false>(-3.25), sigmoid_slope::<false>(3.25));
    }

    #[test]
    fn the_single_tier_is_within_1_f32_ulp_of_the_exact_values() {
        let mut worst = [(0.0f64, 0.0f64); 3];
        for x in arguments() {
            let xf = x as f32;
            let x = f64::from(xf);
            let pairs = [
                (softplus::<true>(x) as f32, softplus_libm(x)),
                (sigmoid::<true>(x) as f32, sigmoid_libm(x)),
                (sigmoid_slope::<true>(x) as f32, slope_libm(x)),
            ];
            for (w, (got, want)) in worst.iter_mut().zip(pairs) {
                let u = ulps32(got, want);
                if u > w.0 {
                    *w = (u, x);
                }
            }
        }
        for (name, (u, x)) in ["softplus", "sigmoid", "slope"].iter().zip(worst) {
            // f64 references are exact for this purpose: 0.5 ulp of rounding plus 1e-9 relative.
            assert!(u <= 0.51, "{name}: worst {u} f32 ulp at x = {x:e}");
        }
        assert_eq!(softplus::<true>(0.0) as f32, std::f32::consts::LN_2);
        assert_eq!(sigmoid::<true>(0.0) as f32, 0.5);
        assert_eq!(softplus::<true>(1e4) as f32, 1e4);
    }
}
