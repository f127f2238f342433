//! The per-sample colour loops, with the channel count a compile-time constant for the usual
//! 1, 2, 3 and 4 channels (unrolled, no inner loop), and a general version for any other.
//! Every version sums in the same order, so the results do not depend on which one runs.

use fogray_tape::Float;

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

/// `acc[c] += sum_k w[k] color[k][c]` over `k < w.len()`; `color` is `[>= w.len()][acc.len()]`.
/// Even and odd samples are summed apart and then added, which halves the chain of dependent
/// additions (the loop's bound) and rounds no worse.
pub(crate) fn weighted_column_sums<F: Float>(color: &[F], w: &[f64], acc: &mut [f64]) {
    by_channels!(acc.len(), column_sums::<F>(color, w, acc));
}

fn column_sums<F: Float, const CH: usize>(color: &[F], w: &[f64], acc: &mut [f64]) {
    let ch = count::<CH>(acc.len());
    if ch == 0 {
        return;
    }
    let mut even = [0.0f64; 4];
    let mut odd = [0.0f64; 4];
    if ch > 4 {
        // The general case keeps one sum per channel; the order is still even, odd, total.
        for c in 0..ch {
            let (mut e, mut o) = (0.0, 0.0);
            for (pair, wk) in color.chunks_exact(2 * ch).zip(w.chunks_exact(2)) {
                e += wk[0] * pair[c].as_f64();
                o += wk[1] * pair[ch + c].as_f64();
            }
            acc[c] += finish(e, o, color, w, ch, c);
        }
        return;
    }
    for (pair, wk) in color.chunks_exact(2 * ch).zip(w.chunks_exact(2)) {
        for c in 0..ch {
            even[c] += wk[0] * pair[c].as_f64();
            odd[c] += wk[1] * pair[ch + c].as_f64();
        }
    }
    for c in 0..ch {
        acc[c] += finish(even[c], odd[c], color, w, ch, c);
    }
}

/// `even + odd`, plus the last sample when the count is odd.
#[inline(always)]
fn finish<F: Float>(even: f64, odd: f64, color: &[F], w: &[f64], ch: usize, c: usize) -> f64 {
    let last = w.len() - w.len() % 2;
    let tail = w.get(last).map_or(0.0, |&wk| wk * color[last * ch + c].as_f64());
    (even + tail) + odd
}

/// `out[k] += sum_c g[c] color[k][c]` for `k < out.len()`; `color` is `[>= out.len()][g.len()]`.
pub(crate) fn add_row_dots<F: Float>(color: &[F], g: &[f64], out: &mut [f64]) {
    by_channels!(g.len(), row_dots::<F>(color, g, out));
}

fn row_dots<F: Float, const CH: usize>(color: &[F], g: &[f64], out: &mut [f64]) {
    let ch = count::<CH>(g.len());
    if ch == 0 {
        return;
    }
    for (o, row) in out.iter_mut().zip(color.chunks_exact(ch)) {
        let mut s = 0.0;
        for c in 0..ch {
            s += g[c] * row[c].as_f64();
        }
        *o += s;
    }
}

/// `out[k][c] = w[k] g[c]` for `k < w.len()`; `out` is `[>= w.len()][g.len()]`.
pub(crate) fn outer_product<F: Float>(w: &[f64], g: &[f64], out: &mut [F]) {
    by_channels!(g.len(), outer::<F>(w, g, out));
}

fn outer<F: Float, const CH: usize>(w: &[f64], g: &[f64], out: &mut [F]) {
    let ch = count::<CH>(g.len());
    if ch == 0 {
        return;
    }
    for (row, &wk) in out.chunks_exact_mut(ch).zip(w) {
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
            let len = 5;
            let color: Vec<f64> = (0..len * ch).map(|i| (i as f64 * 0.37).sin()).collect();
            let w: Vec<f64> = (0..len).map(|k| 0.1 + k as f64).collect();
            let g: Vec<f64> = (0..ch).map(|c| 1.0 - c as f64 * 0.5).collect();

            let mut acc = vec![0.5; ch];
            weighted_column_sums(&color, &w, &mut acc);
            for (c, &a) in acc.iter().enumerate() {
                let term = |k: usize| w[k] * color[k * ch + c];
                let even: f64 = (0..len).step_by(2).map(term).sum();
                let odd: f64 = (1..len).step_by(2).map(term).sum();
                assert_eq!(a, 0.5 + (even + odd), "ch {ch} column {c}");
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
