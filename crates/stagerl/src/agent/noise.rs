//! Exploration noise for the deterministic policies (DDPG, TD3).

use serde::{Deserialize, Serialize};

use super::NoiseKind;
use crate::base::rng::Rng;

/// Gaussian or Ornstein-Uhlenbeck action noise, in action units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActionNoise {
    kind: NoiseKind,
    sigma: f64,
    theta: f64,
    /// The OU process state, one per action dimension.
    state: Vec<f64>,
}

impl ActionNoise {
    pub fn new(kind: NoiseKind, sigma: f64, theta: f64, act_dim: usize) -> Self {
        ActionNoise { kind, sigma, theta, state: vec![0.0; act_dim] }
    }

    /// Restart the process (OU: state back to 0).
    pub fn reset(&mut self) {
        self.state.fill(0.0);
    }

    /// Add one noise sample to `action` and clip it to [-1, 1].
    ///
    /// Gaussian: `a + sigma n`. OU (unit time step, mean 0):
    /// `x <- x - theta x + sigma n`, then `a + x`.
    pub fn perturb(&mut self, rng: &mut Rng, action: &mut [f32]) {
        for (a, x) in action.iter_mut().zip(self.state.iter_mut()) {
            let n = rng.normal();
            let e = match self.kind {
                NoiseKind::Gaussian => self.sigma * n,
                NoiseKind::Ou => {
                    *x += -self.theta * *x + self.sigma * n;
                    *x
                }
            };
            *a = (f64::from(*a) + e).clamp(-1.0, 1.0) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_has_the_asked_spread_and_ou_is_correlated() {
        let mut rng = Rng::new(4);
        let mut g = ActionNoise::new(NoiseKind::Gaussian, 0.1, 0.15, 1);
        let mut ou = ActionNoise::new(NoiseKind::Ou, 0.1, 0.15, 1);
        let n = 20000;
        let (mut s2, mut prev, mut lag1, mut var) = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..n {
            let mut a = [0.0f32];
            g.perturb(&mut rng, &mut a);
            s2 += f64::from(a[0]).powi(2);
            let mut b = [0.0f32];
            ou.perturb(&mut rng, &mut b);
            let x = f64::from(b[0]);
            lag1 += x * prev;
            var += x * x;
            prev = x;
        }
        assert!(((s2 / n as f64).sqrt() - 0.1).abs() < 0.005);
        // OU lag-1 autocorrelation is 1 - theta = 0.85.
        assert!((lag1 / var - 0.85).abs() < 0.03, "{}", lag1 / var);
        ou.reset();
        assert_eq!(ou.state, vec![0.0]);
    }
}
