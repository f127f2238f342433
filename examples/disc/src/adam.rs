//! Adam on one parameter, as the lesson's widget runs it: the tape's `optim::Adam` on a 0-d
//! parameter, the offset `x`, whose gradient the soft or the hard renderer gives as a number.

use clap::Args;
use fogray::tape::optim::{self, AdamConfig, ParamGradients};
use fogray::tape::params::{ParamId, Params};
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
}

/// One Adam descent of the offset: the parameter and the optimiser's moments.
#[derive(Debug)]
pub struct Descent {
    params: Params<f64>,
    x: ParamId,
    adam: optim::Adam<f64>,
}

impl Descent {
    /// A descent from `start`; an error if a setting is out of range.
    pub fn new(opts: &Adam, start: f64) -> Result<Self, TapeError> {
        let mut params = Params::new();
        let x = params.add("x", arr0(start))?;
        Ok(Descent {
            params,
            x,
            adam: optim::Adam::new(opts.config())?,
        })
    }

    /// The offset now.
    pub fn x(&self) -> Result<f64, TapeError> {
        Ok(self.params.get(self.x)?[[]])
    }

    /// One step for gradient `g` at learning rate `lr`; returns the new offset.
    pub fn step(&mut self, g: f64, lr: f64) -> Result<f64, TapeError> {
        self.adam.set_lr(lr)?;
        let mut grads = ParamGradients::new();
        grads.insert(&self.params, self.x, arr0(g))?;
        self.adam.step(&mut self.params, &grads)?;
        self.x()
    }
}

/// Runs `opts.steps` steps from `start` with the gradient `grad(x)`; returns the path
/// (start included). Stops early with an error if the gradient fails or is not finite.
pub fn descend(
    opts: &Adam,
    start: f64,
    mut grad: impl FnMut(f64) -> Result<f64, TapeError>,
) -> Result<Vec<f64>, TapeError> {
    let mut descent = Descent::new(opts, start)?;
    let mut path = vec![start];
    let mut x = start;
    for _ in 0..opts.steps {
        x = descent.step(grad(x)?, opts.lr)?;
        path.push(x);
    }
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_the_learning_rate_against_the_gradient() {
        // With bias correction the first step is lr * g / (|g| + eps) = lr * sign(g).
        let opts = Adam::default();
        let mut d = Descent::new(&opts, 1.0).unwrap();
        let x = d.step(3.0, 0.05).unwrap();
        assert!((x - 0.95).abs() < 1e-9);
        // A zero gradient never moves (the hard renderer's case).
        let path = descend(&opts, -2.8, |_| Ok(0.0)).unwrap();
        assert!(path.iter().all(|&p| p == -2.8));
        // It finds the minimum of a parabola.
        let path = descend(&Adam { steps: 500, ..opts }, 2.0, |x| Ok(2.0 * (x - 0.5))).unwrap();
        assert!((path.last().unwrap() - 0.5).abs() < 1e-2);
        // Settings out of range are an error, not a diverging descent.
        assert!(Descent::new(&Adam { beta1: 1.0, ..opts }, 0.0).is_err());
    }
}
