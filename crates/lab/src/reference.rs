//! An independent f64 reference for the benchmark's error columns: the lesson's formulas
//! written directly, with every running sum compensated (Neumaier), and the size of the terms
//! behind each dC/dsigma_k for element-wise relative errors.

use rayon::prelude::*;

/// Neumaier's compensated sum.
#[derive(Debug, Clone, Copy, Default)]
struct Compensated {
    sum: f64,
    carry: f64,
}

impl Compensated {
    fn add(&mut self, x: f64) {
        let t = self.sum + x;
        self.carry += if self.sum.abs() >= x.abs() {
            (self.sum - t) + x
        } else {
            (x - t) + self.sum
        };
        self.sum = t;
    }
    fn value(&self) -> f64 {
        self.sum + self.carry
    }
}

/// Packed rays in f64 with an upstream colour gradient.
pub struct Rays<'a> {
    /// Density per sample, `[n]`.
    pub sigma: &'a [f64],
    /// Sample length, `[n]`.
    pub delta: &'a [f64],
    /// `[n * ch]`.
    pub color: &'a [f64],
    /// Colour channels.
    pub ch: usize,
    /// `[R + 1]`: ray `r` owns samples `offsets[r]..offsets[r + 1]`.
    pub offsets: &'a [usize],
    /// Shared `[ch]`.
    pub background: &'a [f64],
    /// `[R * ch]`.
    pub grad_color: &'a [f64],
}

/// Reference colour `[R * ch]`, dL/dsigma `[n]`, and each dL/dsigma_k's term scale
/// `delta_k (T_{k+1} |v_k| + sum_{i>k} w_i |v_i| + T_end |v_bg|)` with `v = gC . c`.
pub struct Reference {
    /// `[R * ch]`.
    pub color: Vec<f64>,
    /// `[n]`.
    pub grad_sigma: Vec<f64>,
    /// `[n]`: the size of the terms behind each dL/dsigma_k.
    pub grad_scale: Vec<f64>,
}

fn one_ray(r: &Rays<'_>, ray: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (s, e, ch) = (r.offsets[ray], r.offsets[ray + 1], r.ch);
    let g = &r.grad_color[ray * ch..(ray + 1) * ch];
    let dot = |c: &[f64]| c.iter().zip(g).map(|(a, b)| a * b).sum::<f64>();
    let len = e - s;
    let mut depth = Compensated::default();
    let mut t = vec![0.0; len + 1];
    let mut w = vec![0.0; len];
    for k in 0..len {
        t[k] = (-depth.value()).exp();
        let tau = r.sigma[s + k] * r.delta[s + k];
        w[k] = t[k] * -(-tau).exp_m1();
        depth.add(tau);
    }
    t[len] = (-depth.value()).exp();
    let mut color = vec![Compensated::default(); ch];
    for (k, &wk) in w.iter().enumerate() {
        for (c, acc) in color.iter_mut().enumerate() {
            acc.add(wk * r.color[(s + k) * ch + c]);
        }
    }
    let color: Vec<f64> = color
        .iter()
        .zip(r.background)
        .map(|(acc, bg)| acc.value() + t[len] * bg)
        .collect();
    let v_bg = dot(r.background);
    let mut hidden = Compensated::default();
    hidden.add(t[len] * v_bg);
    let mut hidden_abs = t[len] * v_bg.abs();
    let mut grad = vec![0.0; len];
    let mut scale = vec![0.0; len];
    for k in (0..len).rev() {
        let v = dot(&r.color[(s + k) * ch..(s + k + 1) * ch]);
        grad[k] = r.delta[s + k] * (t[k + 1] * v - hidden.value());
        scale[k] = r.delta[s + k] * (t[k + 1] * v.abs() + hidden_abs);
        hidden.add(w[k] * v);
        hidden_abs += w[k] * v.abs();
    }
    (color, grad, scale)
}

/// Computes the reference, in parallel over rays.
pub fn reference(r: &Rays<'_>) -> Reference {
    let per_ray: Vec<_> = (0..r.offsets.len() - 1)
        .into_par_iter()
        .map(|ray| one_ray(r, ray))
        .collect();
    let mut out = Reference {
        color: Vec::new(),
        grad_sigma: Vec::new(),
        grad_scale: Vec::new(),
    };
    for (c, g, s) in per_ray {
        out.color.extend(c);
        out.grad_sigma.extend(g);
        out.grad_scale.extend(s);
    }
    out
}

/// Element-wise: `max |a - b| / scale` (scale floored at 1e-300); norm-wise: `||a - b|| / ||b||`.
pub fn errors(got: &[f64], want: &[f64], scale: &[f64]) -> (f64, f64) {
    let mut worst = 0.0f64;
    let (mut diff2, mut ref2) = (0.0, 0.0);
    for ((g, w), s) in got.iter().zip(want).zip(scale) {
        let d = g - w;
        let e = d.abs() / s.max(1e-300);
        worst = if e.is_nan() { f64::INFINITY } else { worst.max(e) };
        diff2 += d * d;
        ref2 += w * w;
    }
    (
        worst,
        if ref2 > 0.0 {
            (diff2 / ref2).sqrt()
        } else {
            diff2.sqrt()
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lesson_ray() {
        let r = Rays {
            sigma: &[0.0, 0.5, 2.0, 8.0],
            delta: &[0.5; 4],
            color: &[0.9, 0.2, 0.9, 0.4],
            ch: 1,
            offsets: &[0, 4],
            background: &[1.0],
            grad_color: &[1.0],
        };
        let out = reference(&r);
        assert!((out.color[0] - 0.605).abs() < 5e-4);
        for (g, want) in out.grad_sigma.iter().zip([0.147, -0.203, 0.070, -0.002]) {
            assert!((g - want).abs() < 5e-4);
        }
        let mut c = Compensated::default();
        for x in [1e16, 1.0, -1e16] {
            c.add(x);
        }
        assert_eq!(c.value(), 1.0, "compensation keeps what plain summation loses");
    }
}
