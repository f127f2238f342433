//! `exp(-x)` and `-expm1(-x)` for `x >= 0`, written so that a loop over a slice vectorises.
//!
//! The composite needs both for every sample (transmittance from the running optical depth,
//! alpha from the sample's own), the field activations `exp(-|x|)` for every raw value, and
//! the C library's scalar calls were most of their time. One
//! range reduction serves both: `-x = n ln2 + r` with `|r| <= ln2 / 2`, then
//! `p = expm1(r)` by its Taylor series to `r^13`, evaluated by Estrin's scheme (the first omitted term is below
//! `1.2e-17 |r|`), then
//!
//! - `exp(-x) = 2^n (1 + p)`: no cancellation, for any `x`;
//! - `-expm1(-x) = (1 - 2^n) - 2^n p`: for `n = 0` this is `-p` itself, so a small optical
//!   depth keeps every digit (the reason for expm1 at all); for `n < 0` the result is above
//!   0.29 and the subtraction loses nothing.
//!
//! Measured against the C library (tests below, over the whole domain): at most 2 ulp apart.
//! f32 data take a shorter series (to `r^8`, within 7e-10 relative: far below their own
//! rounding of 6e-8), the `SINGLE` tier.
//! No branches and no table; fused multiply-adds throughout (the slice functions are compiled
//! for AVX-512 and AVX2 with FMA, chosen at run time; the baseline build without FMA
//! computes the same values through the C library's `fma`, slowly).

/// `1.5 * 2^52`: adding it rounds to an integer held in the low bits of the mantissa.
const SHIFTER: f64 = 6_755_399_441_055_744.0;
/// `ln 2` split so that `n * LN2_HI` is exact for `|n| < 2^20` (fdlibm's split).
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// `1 / k!` for `k = 2..=13`, lowest first.
const INV_FACTORIAL: [f64; 12] = [
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5_040.0,
    1.0 / 40_320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
    1.0 / 6_227_020_800.0,
];
/// `exp(-746)` is below half the least subnormal: every larger `x` gives 0.
const EXP_CLAMP: f64 = 746.0;
/// `-expm1(-40)` rounds to 1: every larger `x` gives 1, and `2^n` stays a normal number.
const EXPM1_CLAMP: f64 = 40.0;
/// The exponent is built for `n + BIAS_SHIFT` and scaled back by `2^-BIAS_SHIFT`, so that a
/// subnormal result is rounded once, correctly, by the last multiplication.
const BIAS_SHIFT: i64 = 64;

/// `(n, expm1(r))` for `-x = n ln2 + r`; `x` must already be clamped to `[0, 746]`. With
/// `SINGLE`, the series stops at `r^8` (see [`exp_neg`]).
#[inline(always)]
fn reduce<const SINGLE: bool>(x: f64) -> (i64, f64) {
    let shifted = (-x).mul_add(std::f64::consts::LOG2_E, SHIFTER);
    let n_float = shifted - SHIFTER;
    // The integer sits in the low mantissa bits; the difference of the bit patterns is n.
    let n = (shifted.to_bits() as i64).wrapping_sub(SHIFTER.to_bits() as i64);
    let r = n_float.mul_add(-LN2_LO, n_float.mul_add(-LN2_HI, -x));
    // q(r) = sum_k r^k / (k + 2)! by Estrin's scheme: a few dependent steps instead of
    // Horner's dozen, so that the short slices of one ray are not bound by latency.
    // (Written out: a closure would not inherit the vectorised callers' target features.)
    let c = &INV_FACTORIAL;
    let (r2, r4) = (r * r, (r * r) * (r * r));
    let p01 = c[1].mul_add(r, c[0]);
    let p23 = c[3].mul_add(r, c[2]);
    let p45 = c[5].mul_add(r, c[4]);
    let q03 = p23.mul_add(r2, p01);
    let q = if SINGLE {
        // Up to r^8 / 8!.
        c[6].mul_add(r2, p45).mul_add(r4, q03)
    } else {
        let p67 = c[7].mul_add(r, c[6]);
        let p89 = c[9].mul_add(r, c[8]);
        let p1011 = c[11].mul_add(r, c[10]);
        let q47 = p67.mul_add(r2, p45);
        let q811 = p1011.mul_add(r2, p89);
        q811.mul_add(r4, q47).mul_add(r4, q03)
    };
    (n, r2.mul_add(q, r))
}

/// `2^(n + BIAS_SHIFT)`, for `n + BIAS_SHIFT` in the normal exponent range.
#[inline(always)]
fn pow2_shifted(n: i64) -> f64 {
    f64::from_bits((n.wrapping_add(BIAS_SHIFT + 1023) as u64) << 52)
}

/// `exp(-x)` for `x >= 0` (NaN and negative `x` give a finite, meaningless value: the caller
/// validates). Inlined into the vectorised loops below.
///
/// `SINGLE` is the tier for f32 data: the series stops at `r^8`, whose first omitted term is
/// below `5.9e-10` relative (`7e-10` for `-expm1`, whose `1 - 2^n` step amplifies it a little
/// near 0.3; a hundredth of an f32 rounding; tested), for a third fewer operations; the result
/// is still an f64, and every sum stays in f64.
#[inline(always)]
pub(crate) fn exp_neg<const SINGLE: bool>(x: f64) -> f64 {
    let (n, p) = reduce::<SINGLE>(x.clamp(0.0, EXP_CLAMP));
    (pow2_shifted(n) * (1.0 + p)) * f64::from_bits(((1023 - BIAS_SHIFT) as u64) << 52)
}

/// `-expm1(-x) = 1 - exp(-x)` for `x >= 0`, with full relative accuracy at small `x`
/// (`SINGLE`: as for [`exp_neg`]).
#[inline(always)]
pub(crate) fn one_minus_exp_neg<const SINGLE: bool>(x: f64) -> f64 {
    let (n, p) = reduce::<SINGLE>(x.clamp(0.0, EXPM1_CLAMP));
    let scale = f64::from_bits((n.wrapping_add(1023) as u64) << 52);
    (-scale).mul_add(p, 1.0 - scale)
}

/// Whether data of type `F` take the `SINGLE` tier (f32: its error is far below an f32
/// rounding); known at compile time.
#[inline(always)]
pub(crate) fn single_tier<F>() -> bool {
    std::mem::size_of::<F>() < std::mem::size_of::<f64>()
}

/// `out[k] = exp(-x[k])` for every `k`; the slices have equal lengths. Inlined into the
/// composite's kernels, which are compiled for the vector units (FMA, AVX2 or AVX-512).
#[inline(always)]
pub(crate) fn exp_neg_slice<const SINGLE: bool>(x: &[f64], out: &mut [f64]) {
    for (o, &v) in out.iter_mut().zip(x) {
        *o = exp_neg::<SINGLE>(v);
    }
}

/// `out[k] = -expm1(-x[k])` for every `k`; the slices have equal lengths (as
/// [`exp_neg_slice`]).
#[inline(always)]
pub(crate) fn one_minus_exp_neg_slice<const SINGLE: bool>(x: &[f64], out: &mut [f64]) {
    for (o, &v) in out.iter_mut().zip(x) {
        *o = one_minus_exp_neg::<SINGLE>(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place (of the reference).
    fn ulps(got: f64, want: f64) -> f64 {
        if got == want {
            return 0.0;
        }
        let ulp = if want == 0.0 {
            f64::from_bits(1)
        } else {
            let next = f64::from_bits(want.abs().to_bits() + 1);
            next - want.abs()
        };
        (got - want).abs() / ulp
    }

    /// Arguments over the whole domain: dense near 0, every scale from 1e-300 to 1e3, the
    /// points where the reduction changes n, and the clamps.
    fn arguments() -> Vec<f64> {
        let mut xs = vec![
            0.0, 1e-300, 1e-17, 0.5, 1.0, 40.0, 700.0, 708.4, 720.0, 744.0, 745.1, 746.0, 1e3, 1e30,
        ];
        let mut e = -300.0f64;
        while e < 3.0 {
            xs.push(10f64.powf(e));
            e += 0.0037;
        }
        for k in 0..=2000 {
            xs.push(f64::from(k) * 0.0251);
            let half = std::f64::consts::LN_2 * (f64::from(k) + 0.5);
            xs.extend([
                half,
                f64::from_bits(half.to_bits() + 1),
                f64::from_bits(half.to_bits() - 1),
            ]);
        }
        xs
    }

    #[test]
    fn exp_neg_is_within_2_ulp_of_libm_including_subnormals() {
        let mut worst = (0.0, 0.0);
        for x in arguments() {
            let u = ulps(exp_neg::<false>(x), (-x).exp());
            if u > worst.0 {
                worst = (u, x);
            }
        }
        assert!(worst.0 <= 2.0, "worst {} ulp at x = {:e}", worst.0, worst.1);
        assert_eq!(exp_neg::<false>(0.0), 1.0);
        assert_eq!(exp_neg::<false>(1e30), 0.0);
        assert_eq!(exp_neg::<false>(f64::INFINITY), 0.0);
        // Subnormal results are rounded, not flushed: exp(-740) = 4.2e-322.
        assert!((exp_neg::<false>(740.0) / (-740f64).exp() - 1.0).abs() < 0.02);
        assert!(exp_neg::<false>(740.0) > 0.0);
    }

    #[test]
    fn one_minus_exp_neg_keeps_relative_accuracy_where_one_minus_exp_fails() {
        let mut worst = (0.0, 0.0);
        for x in arguments() {
            let u = ulps(one_minus_exp_neg::<false>(x), -(-x).exp_m1());
            if u > worst.0 {
                worst = (u, x);
            }
        }
        assert!(worst.0 <= 2.0, "worst {} ulp at x = {:e}", worst.0, worst.1);
        // The naive form loses everything at an optical depth of 1e-17; this one keeps it.
        assert_eq!(1.0 - (-1e-17f64).exp(), 0.0);
        assert!((one_minus_exp_neg::<false>(1e-17) / 1e-17 - 1.0).abs() < 1e-15);
        assert_eq!(
            one_minus_exp_neg::<false>(0.0).to_bits(),
            0.0f64.to_bits(),
            "+0, not -0"
        );
        assert_eq!(one_minus_exp_neg::<false>(1e30), 1.0);
        assert_eq!(one_minus_exp_neg::<false>(f64::INFINITY), 1.0);
    }

    #[test]
    fn slice_versions_match_the_scalar_kernel_bitwise() {
        let xs = arguments();
        let (mut a, mut b) = (vec![0.0; xs.len()], vec![0.0; xs.len()]);
        exp_neg_slice::<false>(&xs, &mut a);
        one_minus_exp_neg_slice::<false>(&xs, &mut b);
        for (i, &x) in xs.iter().enumerate() {
            assert_eq!(a[i].to_bits(), exp_neg::<false>(x).to_bits(), "exp at {x:e}");
            assert_eq!(
                b[i].to_bits(),
                one_minus_exp_neg::<false>(x).to_bits(),
                "expm1 at {x:e}"
            );
        }
    }

    #[test]
    fn the_single_tier_is_within_7e_10_relative_of_libm_and_keeps_tiny_arguments() {
        let (mut worst_exp, mut worst_expm1) = (0.0f64, 0.0f64);
        for x in arguments() {
            let want = (-x).exp();
            if want > f64::MIN_POSITIVE {
                worst_exp = worst_exp.max((exp_neg::<true>(x) / want - 1.0).abs());
            }
            let want = -(-x).exp_m1();
            if want > 0.0 {
                worst_expm1 = worst_expm1.max((one_minus_exp_neg::<true>(x) / want - 1.0).abs());
            }
        }
        // The bound is the first omitted term, r^8 / 9! < 5.9e-10 relative at |r| = ln2 / 2;
        // 1 - 2^n (1 + p) amplifies it by up to 1.2 where the result is near 0.3.
        assert!(worst_exp < 6e-10, "exp: {worst_exp:e}");
        assert!(worst_expm1 < 7e-10, "expm1: {worst_expm1:e}");
        // It is not the double tier under another name.
        assert!(worst_exp > 1e-12, "{worst_exp:e}");
        assert_eq!(one_minus_exp_neg::<true>(1e-17), 1e-17);
        assert_eq!(exp_neg::<true>(0.0), 1.0);
        assert_eq!(one_minus_exp_neg::<true>(1e30), 1.0);
    }
}
