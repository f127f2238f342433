//! The three-channel colour loops of `rows` in AVX2 with fused multiply-add, four samples at a
//! time: their twelve values are three registers of four f64, and every lane does exactly the
//! scalar loop's operations, in its order, on one sample and channel, so every result is
//! bitwise the scalar loop's (tested against it below). Compiled for AVX2, the scalar loops
//! vectorise across a row's three channels only (a pair of lanes and a single one); written
//! out like this they use all four lanes and need no per-sample broadcast.
//!
//! The kernels are `unsafe fn`s, to be called where [`available`] holds: a safe function with
//! target features needs Rust 1.86, and the workspace supports 1.85.
//!
//! Lane layout of four samples `k..k+4` of `[k][c]` data: register 0 holds `(k, 0) (k, 1)
//! (k, 2) (k+1, 0)`, register 1 `(k+1, 1) (k+1, 2) (k+2, 0) (k+2, 1)`, register 2 `(k+2, 2)
//! (k+3, 0) (k+3, 1) (k+3, 2)`.

use std::arch::x86_64::{
    __m256d, _mm256_add_pd, _mm256_blend_pd, _mm256_cvtpd_ps, _mm256_cvtps_pd, _mm256_fmadd_pd, _mm256_loadu_pd,
    _mm256_mul_pd, _mm256_permute4x64_pd, _mm256_setr_pd, _mm256_setzero_pd, _mm256_storeu_pd, _mm_loadu_ps,
    _mm_storeu_ps,
};

use fogray_tape::Float;

/// Whether this CPU has AVX2 and FMA (the standard library caches the answer, so this is a
/// load and a test per call).
#[inline(always)]
pub(super) fn available() -> bool {
    is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
}

/// Whether `F` is `f32` (the crate's `Float` is sealed to `f32` and `f64`).
#[inline(always)]
fn is_f32<F: Float>() -> bool {
    std::mem::size_of::<F>() == 4
}

/// Four values widened to f64.
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn load4<F: Float>(four: &[F; 4]) -> __m256d {
    if is_f32::<F>() {
        // SAFETY: `four` holds 4 values of `F`, which is f32 here (see `is_f32`).
        unsafe { _mm256_cvtps_pd(_mm_loadu_ps(four.as_ptr().cast::<f32>())) }
    } else {
        // SAFETY: `four` holds 4 values of `F`, which is f64 here.
        unsafe { _mm256_loadu_pd(four.as_ptr().cast::<f64>()) }
    }
}

/// `four = x`, each value rounded to `F` to nearest (as `F::lit` does).
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn store4<F: Float>(four: &mut [F; 4], x: __m256d) {
    if is_f32::<F>() {
        // SAFETY: `four` holds 4 values of `F`, which is f32 here.
        unsafe { _mm_storeu_ps(four.as_mut_ptr().cast::<f32>(), _mm256_cvtpd_ps(x)) }
    } else {
        // SAFETY: `four` holds 4 values of `F`, which is f64 here.
        unsafe { _mm256_storeu_pd(four.as_mut_ptr().cast::<f64>(), x) }
    }
}

/// Values `4 i .. 4 i + 4` of `v`.
#[inline(always)]
fn quarter<T>(v: &[T], i: usize) -> &[T; 4] {
    v[4 * i..4 * i + 4].try_into().expect("four values")
}

/// Values `4 i .. 4 i + 4` of `v`, to write.
#[inline(always)]
fn quarter_mut<T>(v: &mut [T], i: usize) -> &mut [T; 4] {
    (&mut v[4 * i..4 * i + 4]).try_into().expect("four values")
}

/// Four samples' weights spread over the lane layout (each sample's weight in its three
/// channels' lanes).
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn spread_weights(w: &[f64; 4]) -> [__m256d; 3] {
    let four = load4(w);
    [
        _mm256_permute4x64_pd::<0b01_00_00_00>(four),
        _mm256_permute4x64_pd::<0b10_10_01_01>(four),
        _mm256_permute4x64_pd::<0b11_11_11_10>(four),
    ]
}

/// The per-channel values `g` repeated over the lane layout.
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn spread_channels(g: [f64; 3]) -> [__m256d; 3] {
    let [a, b, c] = g;
    [
        _mm256_setr_pd(a, b, c, a),
        _mm256_setr_pd(b, c, a, b),
        _mm256_setr_pd(c, a, b, c),
    ]
}

/// The partial sums `part[i][c] = sum over k = i mod 4 of w[k] color[k][c]`, by fused
/// multiply-adds in sample order, over the first `groups * 4` samples; `flat[i * 3 + c]` is
/// `part[i][c]`. Panics if `color` or `w` is shorter than that.
///
/// # Safety
/// The CPU must have AVX2 and FMA ([`available`]).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn column_sums3<F: Float>(color: &[F], w: &[f64], groups: usize) -> [f64; 12] {
    let (color, w) = (&color[..groups * 12], &w[..groups * 4]);
    let mut acc = [_mm256_setzero_pd(); 3];
    for (rows, w) in color.chunks_exact(12).zip(w.chunks_exact(4)) {
        let spread = spread_weights(quarter(w, 0));
        for (r, (a, ws)) in acc.iter_mut().zip(spread).enumerate() {
            *a = _mm256_fmadd_pd(ws, load4(quarter(rows, r)), *a);
        }
    }
    let mut flat = [0.0f64; 12];
    for (r, a) in acc.into_iter().enumerate() {
        store4(quarter_mut(&mut flat, r), a);
    }
    flat
}

/// `out[k] += ((0 + g[0] color[k][0]) + g[1] color[k][1]) + g[2] color[k][2]` for
/// `k < groups * 4`, each product rounded before it is added, as the scalar loop does. Panics
/// if `color` or `out` is shorter than that.
///
/// # Safety
/// The CPU must have AVX2 and FMA ([`available`]).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn row_dots3<F: Float>(color: &[F], g: [f64; 3], out: &mut [f64], groups: usize) {
    let (color, out) = (&color[..groups * 12], &mut out[..groups * 4]);
    let spread = spread_channels(g);
    for (rows, out) in color.chunks_exact(12).zip(out.chunks_exact_mut(4)) {
        // No closures here: a closure would not inherit this function's target features.
        let p0 = _mm256_mul_pd(load4(quarter(rows, 0)), spread[0]);
        let p1 = _mm256_mul_pd(load4(quarter(rows, 1)), spread[1]);
        let p2 = _mm256_mul_pd(load4(quarter(rows, 2)), spread[2]);
        // Each channel's four products in sample order (see the module's lane layout).
        let c0 = _mm256_blend_pd::<0b0010>(_mm256_blend_pd::<0b0100>(p0, p1), p2);
        let c0 = _mm256_permute4x64_pd::<0b01_10_11_00>(c0);
        let c1 = _mm256_blend_pd::<0b0100>(_mm256_blend_pd::<0b1001>(p0, p1), p2);
        let c1 = _mm256_permute4x64_pd::<0b10_11_00_01>(c1);
        let c2 = _mm256_blend_pd::<0b1001>(_mm256_blend_pd::<0b0010>(p0, p1), p2);
        let c2 = _mm256_permute4x64_pd::<0b11_00_01_10>(c2);
        let sum = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(_mm256_setzero_pd(), c0), c1), c2);
        let out = quarter_mut(out, 0);
        store4(out, _mm256_add_pd(load4(out), sum));
    }
}

/// `out[k][c] = w[k] g[c]` rounded to `F`, for `k < groups * 4`. Panics if `w` or `out` is
/// shorter than that.
///
/// # Safety
/// The CPU must have AVX2 and FMA ([`available`]).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn outer3<F: Float>(w: &[f64], g: [f64; 3], out: &mut [F], groups: usize) {
    let (w, out) = (&w[..groups * 4], &mut out[..groups * 12]);
    let channels = spread_channels(g);
    for (w, out) in w.chunks_exact(4).zip(out.chunks_exact_mut(12)) {
        let weights = spread_weights(quarter(w, 0));
        for (r, (ws, cs)) in weights.into_iter().zip(channels).enumerate() {
            store4(quarter_mut(out, r), _mm256_mul_pd(ws, cs));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values of every sign and many magnitudes, signed zeros among them, so that a lane that
    /// summed in another order or fused a product would show in the bits.
    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut state = seed;
        (0..n)
            .map(|i| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (state >> 11) as f64 / (1u64 << 53) as f64;
                match i % 11 {
                    3 => -0.0,
                    7 => 0.0,
                    _ => (u - 0.4) * 10f64.powi((i % 5) as i32 * 3 - 6),
                }
            })
            .collect()
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn check<F: Float>() {
        if !available() {
            return;
        }
        for groups in 0..5 {
            let n = groups * 4;
            let color: Vec<F> = values(n * 3 + 5, 1).into_iter().map(F::lit).collect();
            let w = values(n + 2, 2);
            let g = [0.75, -1.5e-3, 2.0e4];

            let flat = unsafe { column_sums3(&color, &w, groups) };
            let mut want = [0.0f64; 12];
            for k in 0..n {
                for c in 0..3 {
                    let p = &mut want[(k % 4) * 3 + c];
                    *p = w[k].mul_add(color[k * 3 + c].as_f64(), *p);
                }
            }
            assert_eq!(bits(&flat), bits(&want), "{} column sums, {groups} groups", F::NAME);

            let start = values(n + 1, 3);
            let mut got = start.clone();
            unsafe { row_dots3(&color, g, &mut got, groups) };
            let mut want = start;
            for (k, o) in want[..n].iter_mut().enumerate() {
                let mut s = 0.0;
                for c in 0..3 {
                    s += g[c] * color[k * 3 + c].as_f64();
                }
                *o += s;
            }
            assert_eq!(bits(&got), bits(&want), "{} row dots, {groups} groups", F::NAME);

            let mut got = vec![F::lit(9.0); n * 3 + 1];
            unsafe { outer3(&w, g, &mut got, groups) };
            let mut want = vec![F::lit(9.0); n * 3 + 1];
            for k in 0..n {
                for c in 0..3 {
                    want[k * 3 + c] = F::lit(w[k] * g[c]);
                }
            }
            let as_bits = |v: &[F]| v.iter().map(|x| x.as_f64().to_bits()).collect::<Vec<_>>();
            assert_eq!(
                as_bits(&got),
                as_bits(&want),
                "{} outer products, {groups} groups",
                F::NAME
            );
        }
    }

    #[test]
    fn every_lane_gives_the_scalar_loops_bits_in_both_precisions() {
        check::<f32>();
        check::<f64>();
    }
}
