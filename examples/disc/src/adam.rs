//! Adam on one parameter, as the lesson's widget runs it.

use clap::Args;

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

/// The running state of one Adam descent.
#[derive(Debug, Clone, Copy, Default)]
pub struct AdamState {
    m: f64,
    v: f64,
    t: i32,
}

impl AdamState {
    /// One step: the new parameter for gradient `g` at `x`, with learning rate `lr`.
    pub fn step(&mut self, opts: &Adam, x: f64, g: f64, lr: f64) -> f64 {
        self.t += 1;
        self.m = opts.beta1 * self.m + (1.0 - opts.beta1) * g;
        self.v = opts.beta2 * self.v + (1.0 - opts.beta2) * g * g;
        let m_hat = self.m / (1.0 - opts.beta1.powi(self.t));
        let v_hat = self.v / (1.0 - opts.beta2.powi(self.t));
        x - lr * m_hat / (v_hat.sqrt() + opts.adam_eps)
    }
}

/// Runs `opts.steps` steps from `start` with the gradient `grad(x)`; returns the path
/// (start included). Stops early with an error if the gradient fails.
pub fn descend<E>(opts: &Adam, start: f64, mut grad: impl FnMut(f64) -> Result<f64, E>) -> Result<Vec<f64>, E> {
    let mut state = AdamState::default();
    let mut path = vec![start];
    let mut x = start;
    for _ in 0..opts.steps {
        x = state.step(opts, x, grad(x)?, opts.lr);
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
        let mut s = AdamState::default();
        let x = s.step(&opts, 1.0, 3.0, 0.05);
        assert!((x - 0.95).abs() < 1e-9);
        // A zero gradient never moves (the hard renderer's case).
        let path = descend::<()>(&opts, -2.8, |_| Ok(0.0)).unwrap();
        assert!(path.iter().all(|&p| p == -2.8));
        // It finds the minimum of a parabola.
        let path = descend::<()>(&Adam { steps: 500, ..opts }, 2.0, |x| Ok(2.0 * (x - 0.5))).unwrap();
        assert!((path.last().unwrap() - 0.5).abs() < 1e-2);
    }
}
