//! The Adam optimiser (Kingma and Ba), as `torch.optim.Adam` without weight decay or amsgrad.

use serde::{Deserialize, Serialize};

use super::Scalar;
use stagerl_base::multiversion;

/// Adam over one flat parameter slice.
///
/// At step t (1-based), for each parameter p with gradient g:
/// ```text
/// m = beta1 m + (1 - beta1) g
/// v = beta2 v + (1 - beta2) g^2
/// p -= (lr / (1 - beta1^t)) m / (sqrt(v) / sqrt(1 - beta2^t) + eps)
/// ```
/// which is PyTorch's bias-corrected update. The moments `m`, `v` and the step count are public
/// and the whole optimiser is serde-serialisable, for checkpoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam<T> {
    /// Learning rate.
    pub lr: f64,
    /// Decay of the first moment (PyTorch default 0.9).
    pub beta1: f64,
    /// Decay of the second moment (PyTorch default 0.999).
    pub beta2: f64,
    /// Denominator floor (PyTorch default 1e-8).
    pub eps: f64,
    /// Steps taken so far.
    pub step: u64,
    /// First moment estimate, one per parameter.
    pub m: Vec<T>,
    /// Second moment estimate, one per parameter.
    pub v: Vec<T>,
}

impl<T: Scalar> Adam<T> {
    /// Adam for `num_params` parameters with learning rate `lr` and PyTorch's defaults
    /// (beta1 0.9, beta2 0.999, eps 1e-8); moments start at 0.
    pub fn new(num_params: usize, lr: f64) -> Self {
        Self::with_betas(num_params, lr, 0.9, 0.999, 1e-8)
    }

    /// Adam with explicit hyperparameters.
    pub fn with_betas(num_params: usize, lr: f64, beta1: f64, beta2: f64, eps: f64) -> Self {
        Adam { lr, beta1, beta2, eps, step: 0, m: vec![T::ZERO; num_params], v: vec![T::ZERO; num_params] }
    }

    /// Number of parameters this optimiser was made for.
    pub fn num_params(&self) -> usize {
        self.m.len()
    }

    /// One update of `params` with gradients `grads`.
    ///
    /// # Panics
    /// If the lengths differ from [`Adam::num_params`].
    pub fn step(&mut self, params: &mut [T], grads: &[T]) {
        let n = self.m.len();
        assert_eq!(params.len(), n, "Adam::step: params length");
        assert_eq!(grads.len(), n, "Adam::step: grads length");
        assert_eq!(self.v.len(), n, "Adam::step: second moment length");
        self.step += 1;
        let t = self.step as f64;
        let bias1 = 1.0 - self.beta1.powf(t);
        let bias2 = 1.0 - self.beta2.powf(t);
        let step_size = T::from_f64(self.lr / bias1);
        let inv_sqrt_bias2 = T::from_f64(1.0 / bias2.sqrt());
        let (b1, b2) = (T::from_f64(self.beta1), T::from_f64(self.beta2));
        let (c1, c2) = (T::from_f64(1.0 - self.beta1), T::from_f64(1.0 - self.beta2));
        let eps = T::from_f64(self.eps);
        let coefs = Coefs { b1, b2, c1, c2, step_size, inv_sqrt_bias2, eps };
        adam_kernel(params, grads, &mut self.m, &mut self.v, coefs);
    }

    /// Forgets the moments and the step count.
    pub fn reset(&mut self) {
        self.step = 0;
        self.m.iter_mut().for_each(|x| *x = T::ZERO);
        self.v.iter_mut().for_each(|x| *x = T::ZERO);
    }
}

/// The constants of one Adam step (see [`Adam::step`]).
#[derive(Clone, Copy)]
pub(crate) struct Coefs<T> {
    pub b1: T,
    pub b2: T,
    pub c1: T,
    pub c2: T,
    pub step_size: T,
    pub inv_sqrt_bias2: T,
    pub eps: T,
}

multiversion! {
    /// The element loop of [`Adam::step`].
    fn adam_kernel / adam_kernel_at<T: Scalar>(params: &mut [T], grads: &[T], m: &mut [T], v: &mut [T], c: Coefs<T>) {
        for (((p, &g), m), v) in params.iter_mut().zip(grads).zip(m.iter_mut()).zip(v.iter_mut()) {
            *m = c.b1 * *m + c.c1 * g;
            *v = c.b2 * *v + c.c2 * g * g;
            *p -= c.step_size * *m / (v.sqrt() * c.inv_sqrt_bias2 + c.eps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_steps_match_hand_computation() {
        // p0 = 1, lr = 0.1, g1 = 0.5, g2 = -0.25.
        // Step 1: m = 0.05, v = 0.00025, m^ = 0.5, sqrt(v^) = 0.5,
        //         p1 = 1 - 0.1 * 0.5 / (0.5 + 1e-8).
        // Step 2: m = 0.9 * 0.05 + 0.1 * (-0.25) = 0.02,
        //         v = 0.999 * 0.00025 + 0.001 * 0.0625 = 0.00031225,
        //         p2 = p1 - (0.1 / 0.19) * 0.02 / (sqrt(0.00031225) / sqrt(0.001999) + 1e-8).
        let mut adam = Adam::<f64>::new(1, 0.1);
        let mut p = [1.0f64];
        adam.step(&mut p, &[0.5]);
        let p1 = 1.0 - 0.1 * 0.5 / (0.5 + 1e-8);
        assert!((p[0] - p1).abs() < 1e-15, "{} vs {}", p[0], p1);
        assert!((p[0] - 0.900_000_002).abs() < 1e-12);
        assert!((adam.m[0] - 0.05).abs() < 1e-15 && (adam.v[0] - 0.00025).abs() < 1e-17);
        adam.step(&mut p, &[-0.25]);
        assert!((adam.m[0] - 0.02).abs() < 1e-16);
        assert!((adam.v[0] - 0.000_312_25).abs() < 1e-18);
        let p2 = p1 - (0.1 / 0.19) * 0.02 / ((0.000_312_25f64).sqrt() / (0.001_999f64).sqrt() + 1e-8);
        assert!((p[0] - p2).abs() < 1e-14, "{} vs {}", p[0], p2);
        // Decimal value: 0.900000002 - 0.0266337... = 0.8733663...
        assert!((p[0] - 0.873_366_298_7).abs() < 1e-9, "{}", p[0]);
        assert_eq!(adam.step, 2);
    }

    #[test]
    fn minimises_a_quadratic() {
        // f(p) = sum_i c_i (p_i - t_i)^2.
        let t = [3.0f64, -1.0, 0.5, 10.0];
        let c = [1.0f64, 10.0, 0.1, 2.0];
        let mut p = [0.0f64; 4];
        let mut g = [0.0f64; 4];
        let f = |p: &[f64]| -> f64 { (0..4).map(|i| c[i] * (p[i] - t[i]).powi(2)).sum() };
        let f0 = f(&p);
        let mut adam = Adam::new(4, 0.05);
        for _ in 0..2000 {
            for i in 0..4 {
                g[i] = 2.0 * c[i] * (p[i] - t[i]);
            }
            adam.step(&mut p, &g);
        }
        assert!(f(&p) < 1e-6 * f0, "f = {} from {}", f(&p), f0);
    }

    #[test]
    fn serde_round_trip() {
        let mut adam = Adam::<f32>::new(3, 1e-3);
        let mut p = [1.0f32, 2.0, 3.0];
        adam.step(&mut p, &[0.1, -0.2, 0.3]);
        let s = serde_json::to_string(&adam).unwrap();
        let back: Adam<f32> = serde_json::from_str(&s).unwrap();
        assert_eq!(back, adam);
    }
}
