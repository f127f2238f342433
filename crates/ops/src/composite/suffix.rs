//! The backward's one sequential chain, "what sample k adds minus what it hides":
//! `d_k = T_{k+1} (v_k - R_{k+1})` with `R_k = (1 - alpha_k) R_{k+1} + alpha_k v_k`, back to
//! front from `R_len` (the background's value). `R` is a true suffix quantity, never a
//! difference of prefix sums.
//!
//! Taken two samples at a time: `R_k = (e_k e_{k+1}) R_{k+2} + (e_k u_{k+1} + u_k)` with
//! `e = 1 - alpha`, `u = alpha v`, so the chain carries one multiply and one add per two
//! samples, and `R_{k+1}` comes off the chain. `1 - alpha` is exact to 1e-16 absolute, all
//! that a factor of a bounded `R` needs; an opaque sample (`e = 0`) still cuts the chain exactly.

/// Fills `out[k] = T_{k+1} (v_k - R_{k+1})` for `k < out.len()`, given `trans[..=len]`,
/// `alpha[..len]`, `value[..len]` and `behind = R_len`.
pub(crate) fn adds_minus_hides(trans: &[f64], alpha: &[f64], value: &[f64], mut behind: f64, out: &mut [f64]) {
    let len = out.len();
    let (trans, alpha, value) = (&trans[..=len], &alpha[..len], &value[..len]);
    let mut k = len;
    while k >= 2 {
        let (i, j) = (k - 1, k - 2);
        let (ui, uj) = (alpha[i] * value[i], alpha[j] * value[j]);
        let (ei, ej) = (1.0 - alpha[i], 1.0 - alpha[j]);
        out[i] = trans[k] * (value[i] - behind);
        let behind_i = behind * ei + ui;
        out[j] = trans[i] * (value[j] - behind_i);
        behind = behind * (ei * ej) + (ej * ui + uj);
        k = j;
    }
    if k == 1 {
        out[0] = trans[1] * (value[0] - behind);
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
    fn pairs_agree_with_the_plain_recurrence_for_every_length_and_opaque_samples() {
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
