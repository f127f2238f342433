//! Adam on one parameter, as the lesson's widget runs it: the tape's `optim::Adam` on a 0-d
//! parameter, the offset `x`, whose gradient the soft or the hard renderer gives as a number.
//! What is the disc's own: the flags, and the loop that asks the renderer for the gradient.

use clap::Args;
use fogray::tape::optim::{self, AdamConfig, ParamGradients};
use fogray::tape::params::Params;
use fogray::tape::TapeError;
use ndarray::arr0;

/// Adam's settings; the defaults are the lesson's.
#[derive(Debug, Clone, Copy, Args)]
pub struct Adam {
    /// Learning rate.
    #[arg(long, default_value_t = 0.05)]
    pub lr: f64,
    /// First-moment decay.
    #[arg(long, default_value_t = 0.9)]
    pub beta1: f64,
    /// Second-moment decay.
    #[arg(long, default_value_t = 0.999)]
    pub beta2: f64,
    /// Denominator guard.
    #[arg(long, default_value_t = 1e-8)]
    pub adam_eps: f64,
    /// Number of steps.
    #[arg(long, default_value_t = 80)]
    pub steps: usize,
}

impl Default for Adam {
    fn default() -> Self {
        Adam {
            lr: 0.05,
            beta1: 0.9,
            beta2: 0.999,
            adam_eps: 1e-8,
            steps: 80,
        }
    }
}

impl Adam {
    /// The optimiser's settings.
    pub fn config(&self) -> AdamConfig {
        AdamConfig {
            lr: self.lr,
            beta1: self.beta1,
            beta2: self.beta2,
            eps: self.adam_eps,
        }
    }

    /// `self.steps` steps at the fixed learning rate `self.lr` with the gradient `grad(x)`.
    pub fn descend(
        &self,
        start: f64,
        mut grad: impl FnMut(f64) -> Result<f64, TapeError>,
    ) -> Result<Vec<f64>, TapeError> {
        descend(self.config(), start, self.steps, |_, x| Ok((grad(x)?, self.lr)))
    }
}

/// Runs `steps` steps of Adam (with `config`'s moments and guard) on the offset from `start`;
/// step `k` (from 0) asks `step(k, x)` for the gradient at the offset `x` and the learning rate
/// to take. Returns the path, start included. Stops with an error if a setting is out of
/// range, or the gradient fails or is not finite.
pub fn descend(
    config: AdamConfig,
    start: f64,
    steps: usize,
    mut step: impl FnMut(usize, f64) -> Result<(f64, f64), TapeError>,
) -> Result<Vec<f64>, TapeError> {
    let mut params = Params::new();
    let x = params.add("x", arr0(start))?;
    let mut adam = optim::Adam::new(config)?;
    let mut path = Vec::with_capacity(steps + 1);
    path.push(start);
    for k in 0..steps {
        let (g, lr) = step(k, path[k])?;
        adam.set_lr(lr)?;
        let mut grads = ParamGradients::new();
        grads.insert(&params, x, arr0(g))?;
        adam.step(&mut params, &grads)?;
        path.push(params.get(x)?[[]]);
    }
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_follow_adams_closed_form() {
        // With a constant gradient g the bias-corrected moments are exactly g and g^2, so every
        // step moves by lr * g / (|g| + eps): lr against the gradient's sign, at each step's lr.
        let config = Adam::default().config();
        let lrs = [0.1, 0.2, 0.05];
        let path = descend(config, 1.0, 3, |k, _| Ok((3.0, lrs[k]))).unwrap();
        for (x, want) in path.iter().zip([1.0, 0.9, 0.7, 0.65]) {
            assert!((x - want).abs() < 1e-8, "{path:?}");
        }
        // A zero gradient never moves (the hard renderer's case).
        let path = Adam::default().descend(-2.8, |_| Ok(0.0)).unwrap();
        assert_eq!(path.len(), 81);
        assert!(path.iter().all(|&p| p == -2.8));
        // It finds the minimum of the parabola (x - 0.5)^2.
        let path = Adam {
            steps: 500,
            ..Adam::default()
        }
        .descend(2.0, |x| Ok(2.0 * (x - 0.5)))
        .unwrap();
        assert!((path.last().unwrap() - 0.5).abs() < 1e-2);
        // Settings out of range are an error, not a diverging descent.
        let bad = Adam {
            beta1: 1.0,
            ..Adam::default()
        };
        assert!(bad.descend(0.0, |_| Ok(1.0)).is_err());
        assert!(descend(config, 0.0, 1, |_, _| Ok((1.0, -0.1))).is_err());
        assert!(descend(config, 0.0, 1, |_, _| Ok((f64::NAN, 0.1))).is_err());
    }
}
