//! The per-sample colour loops, with the channel count a compile-time constant for the usual
//! 1, 2, 3 and 4 channels (unrolled, no inner loop), and a general version for any other.
//! Every version sums in the same order, so the results do not depend on which one runs.

use fogray_tape::Float;

#[cfg(target_arch = "x86_64")]
use super::rows_x86;

/// Calls `$body` with `$n` a `const` channel count when `$ch` is 1 to 4, else with `0`, which
/// the generic functions read as "use the run-time count".
macro_rules! by_channels {
    ($ch:expr, $f:ident ::<$F:ty>($($arg:expr),*)) => {
        match $ch {
            1 => $f::<$F, 1>($($arg),*),
            2 => $f::<$F, 2>($($arg),*),
            3 => $f::<$F, 3>($($arg),*),
            4 => $f::<$F, 4>($($arg),*),
            _ => $f::<$F, 0>($($arg),*),
        }
    };
}

/// `CH`, or the run-time count when `CH` is 0.
#[inline(always)]
fn count<const CH: usize>(ch: usize) -> usize {
    if CH == 0 {
        ch
    } else {
        CH
    }
}

/// Interleaved partial sums per channel in [`weighted_column_sums`].
const LANES: usize = 4;

/// `acc[c] += sum_k w[k] color[k][c]` over `k < w.len()`; `color` is `[>= w.len()][acc.len()]`.
/// Sample `k` goes to partial sum `k % 4` by a fused multiply-add, and the partial sums are
/// added pairwise at the end: the chain of dependent operations (the loop's bound) is a
/// quarter of the ray, and the sum rounds no worse than the one-at-a-time sum.
#[inline(always)]
pub(crate) fn weighted_column_sums<F: Float>(color: &[F], w: &[f64], acc: &mut [f64]) {
    by_channels!(acc.len(), column_sums::<F>(color, w, acc));
}

#[inline(always)]
fn column_sums<F: Float, const CH: usize>(color: &[F], w: &[f64], acc: &mut [f64]) {
    let ch = count::<CH>(acc.len());
    if ch == 0 {
        return;
    }
    let full = w.len() - w.len() % LANES;
    if ch > 4 {
        // The general case, one channel at a time, in the same order.
        for c in 0..ch {
            let mut part = [0.0f64; LANES];
            for (k, &wk) in w.iter().enumerate() {
                part[k % LANES] = wk.mul_add(color[k * ch + c].as_f64(), part[k % LANES]);
            }
            acc[c] += (part[0] + part[1]) + (part[2] + part[3]);
        }
        return;
    }
    let mut part = [[0.0f64; 4]; LANES];
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if CH == 3 && rows_x86::available() {
        // SAFETY: `available` has checked that this CPU runs the kernel.
        let flat = unsafe { rows_x86::column_sums3(color, w, full / LANES) };
        for (i, p) in part.iter_mut().enumerate() {
            p[..3].copy_from_slice(&flat[i * 3..i * 3 + 3]);
        }
        done = full;
    }
    let groups = color[done * ch..full * ch].chunks_exact(LANES * ch);
    for (rows, wk) in groups.zip(w[done..full].chunks_exact(LANES)) {
        for (i, p) in part.iter_mut().enumerate() {
            for c in 0..ch {
                p[c] = wk[i].mul_add(rows[i * ch + c].as_f64(), p[c]);
            }
        }
    }
    for (i, &wk) in w[full..].iter().enumerate() {
        for c in 0..ch {
            part[i][c] = wk.mul_add(color[(full + i) * ch + c].as_f64(), part[i][c]);
        }
    }
    for c in 0..ch {
        acc[c] += (part[0][c] + part[1][c]) + (part[2][c] + part[3][c]);
    }
}

/// `out[k] += sum_c g[c] color[k][c]` for `k < out.len()`; `color` is `[>= out.len()][g.len()]`.
#[inline(always)]
pub(crate) fn add_row_dots<F: Float>(color: &[F], g: &[f64], out: &mut [f64]) {
    by_channels!(g.len(), row_dots::<F>(color, g, out));
}

#[inline(always)]
fn row_dots<F: Float, const CH: usize>(color: &[F], g: &[f64], out: &mut [f64]) {
    let ch = count::<CH>(g.len());
    if ch == 0 {
        return;
    }
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if CH == 3 && rows_x86::available() {
        done = out.len() - out.len() % 4;
        // SAFETY: `available` has checked that this CPU runs the kernel.
        unsafe { rows_x86::row_dots3(color, [g[0], g[1], g[2]], out, done / 4) };
    }
    for (o, row) in out[done..].iter_mut().zip(color[done * ch..].chunks_exact(ch)) {
        let mut s = 0.0;
        for c in 0..ch {
            s += g[c] * row[c].as_f64();
        }
        *o += s;
    }
}

/// `out[k][c] = w[k] g[c]` for `k < w.len()`; `out` is `[>= w.len()][g.len()]`.
#[inline(always)]
pub(crate) fn outer_product<F: Float>(w: &[f64], g: &[f64], out: &mut [F]) {
    by_channels!(g.len(), outer::<F>(w, g, out));
}

#[inline(always)]
fn outer<F: Float, const CH: usize>(w: &[f64], g: &[f64], out: &mut [F]) {
    let ch = count::<CH>(g.len());
    if ch == 0 {
        return;
    }
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if CH == 3 && rows_x86::available() {
        done = w.len() - w.len() % 4;
        // SAFETY: `available` has checked that this CPU runs the kernel.
        unsafe { rows_x86::outer3(w, [g[0], g[1], g[2]], out, done / 4) };
    }
    for (row, &wk) in out[done * ch..].chunks_exact_mut(ch).zip(&w[done..]) {
        for c in 0..ch {
            row[c] = F::lit(wk * g[c]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every channel count, specialised or not, against the loops written out by hand.
    #[test]
    fn every_channel_count_matches_the_plain_loops() {
        for ch in 0..7 {
            for len in [0, 1, 3, 5, 8, 11] {
                let color: Vec<f64> = (0..len * ch).map(|i| (i as f64 * 0.37).sin()).collect();
                let w: Vec<f64> = (0..len).map(|k| 0.1 + k as f64).collect();
                let g: Vec<f64> = (0..ch).map(|c| 1.0 - c as f64 * 0.5).collect();

                let mut acc = vec![0.5; ch];
                weighted_column_sums(&color, &w, &mut acc);
                for (c, &a) in acc.iter().enumerate() {
                    let lane = |i: usize| {
                        (i..len)
                            .step_by(4)
                            .fold(0.0f64, |s, k| w[k].mul_add(color[k * ch + c], s))
                    };
                    let want = 0.5 + ((lane(0) + lane(1)) + (lane(2) + lane(3)));
                    assert_eq!(a, want, "ch {ch} column {c}");
                }

                let mut dots = vec![1.0; len];
                add_row_dots(&color, &g, &mut dots);
                for (k, &d) in dots.iter().enumerate() {
                    let want = 1.0 + (0..ch).map(|c| g[c] * color[k * ch + c]).sum::<f64>();
                    assert_eq!(d, want, "ch {ch} row {k}");
                }

                let mut out = vec![0.0f32; len * ch];
                outer_product(&w, &g, &mut out);
                for k in 0..len {
                    for c in 0..ch {
                        assert_eq!(out[k * ch + c], (w[k] * g[c]) as f32);
                    }
                }
            }
        }
    }
}
