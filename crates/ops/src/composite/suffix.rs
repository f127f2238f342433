//! The backward's one sequential chain, "what sample k adds minus what it hides":
//! `d_k = T_{k+1} (v_k - R_{k+1})` with `R_k = (1 - alpha_k) R_{k+1} + alpha_k v_k`, back to
//! front from `R_len` (the background's value). `R` is a true suffix quantity, never a
//! difference of prefix sums.
//!
//! Taken four samples at a time: `R_k = (e_k e_{k+1} e_{k+2} e_{k+3}) R_{k+4} + A_k` with
//! `e = 1 - alpha`, `u = alpha v` and `A_k = e_k (e_{k+1} (e_{k+2} u_{k+3} + u_{k+2}) +
//! u_{k+1}) + u_k`, so the chain carries one fused multiply-add per four samples, and
//! `R_{k+1..k+3}` come off the chain (the loop runs in code compiled with FMA; elsewhere the
//! same values come from the C library's `fma`). `1 - alpha` is exact to 1e-16 absolute, all
//! that a factor of a bounded `R` needs; an opaque sample (`e = 0`) still cuts the chain exactly.

/// Fills `out[k] = T_{k+1} (v_k - R_{k+1})` for `k < out.len()`, given `trans[..=len]`,
/// `alpha[..len]`, `value[..len]` and `behind = R_len`.
#[inline(always)]
pub(crate) fn adds_minus_hides(trans: &[f64], alpha: &[f64], value: &[f64], mut behind: f64, out: &mut [f64]) {
    let len = out.len();
    let (trans, alpha, value) = (&trans[..=len], &alpha[..len], &value[..len]);
    let mut k = len;
    // Four samples a step: R_{k+3}, R_{k+2}, R_{k+1} come off the chain, each one multiply-add
    // from R_{k+4}; the chain itself carries one fused multiply-add per four samples.
    while k >= 4 {
        let (a, b, c, d) = (k - 4, k - 3, k - 2, k - 1);
        let (ua, ub, uc, ud) = (
            alpha[a] * value[a],
            alpha[b] * value[b],
            alpha[c] * value[c],
            alpha[d] * value[d],
        );
        let (ea, eb, ec, ed) = (1.0 - alpha[a], 1.0 - alpha[b], 1.0 - alpha[c], 1.0 - alpha[d]);
        // R_j = E_j R_k + A_j for j = d, c, b, a (products and sums of the later samples).
        let (e_cd, a_c) = (ec * ed, ec.mul_add(ud, uc));
        let (e_bd, a_b) = (eb * e_cd, eb.mul_add(a_c, ub));
        let (e_ad, a_a) = (ea * e_bd, ea.mul_add(a_b, ua));
        let r_d = behind.mul_add(ed, ud);
        let r_c = behind.mul_add(e_cd, a_c);
        let r_b = behind.mul_add(e_bd, a_b);
        out[d] = trans[k] * (value[d] - behind);
        out[c] = trans[d] * (value[c] - r_d);
        out[b] = trans[c] * (value[b] - r_c);
        out[a] = trans[b] * (value[a] - r_b);
        behind = behind.mul_add(e_ad, a_a);
        k = a;
    }
    while k >= 1 {
        let i = k - 1;
        out[i] = trans[k] * (value[i] - behind);
        behind = alpha[i].mul_add(value[i] - behind, behind);
        k = i;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recurrence one sample at a time, as the module docs write it.
    fn one_at_a_time(trans: &[f64], alpha: &[f64], value: &[f64], mut behind: f64) -> Vec<f64> {
        let mut out = vec![0.0; alpha.len()];
        for k in (0..alpha.len()).rev() {
            out[k] = trans[k + 1] * (value[k] - behind);
            behind += alpha[k] * (value[k] - behind);
        }
        out
    }

    #[test]
    fn four_sample_steps_agree_with_the_plain_recurrence_for_every_length_and_opaque_samples() {
        for len in 0..40 {
            let alpha: Vec<f64> = (0..len)
                .map(|k| match k % 7 {
                    0 => 1.0,
                    1 => 0.0,
                    2 => 1e-17,
                    _ => ((k * 37 % 11) as f64 / 11.0).min(0.999),
                })
                .collect();
            let value: Vec<f64> = (0..len).map(|k| ((k * 13 % 5) as f64 - 2.0) * 0.7).collect();
            let mut trans = vec![1.0];
            for &a in &alpha {
                let last: f64 = trans[trans.len() - 1];
                trans.push(last * (1.0 - a));
            }
            let want = one_at_a_time(&trans, &alpha, &value, 0.3);
            let mut got = vec![f64::NAN; len];
            adds_minus_hides(&trans, &alpha, &value, 0.3, &mut got);
            for k in 0..len {
                // Terms are O(1): an absolute bound a few roundings wide.
                assert!(
                    (got[k] - want[k]).abs() <= 1e-15,
                    "len {len} k {k}: {} vs {}",
                    got[k],
                    want[k]
                );
            }
        }
    }
}
