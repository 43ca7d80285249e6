//! Element-wise activation functions and their derivatives.

use serde::{Deserialize, Serialize};

use super::Scalar;
use stagerl_base::multiversion;

/// An element-wise activation y = f(z).
///
/// The derivative is expressed through the output y, so that the backward pass needs only the
/// cached layer outputs: ReLU f'(z) = [y > 0] (the derivative at z = 0 is taken as 0, as in
/// PyTorch), Tanh f'(z) = 1 - y^2, Identity f'(z) = 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Activation {
    /// y = z.
    Identity,
    /// y = max(z, 0).
    Relu,
    /// y = tanh(z).
    Tanh,
}

impl Activation {
    /// Applies the activation in place: `x[i] = f(x[i])`.
    #[inline]
    pub fn apply<T: Scalar>(self, x: &mut [T]) {
        match self {
            Activation::Identity => {}
            Activation::Relu => x.iter_mut().for_each(|v| *v = v.max(T::ZERO)),
            Activation::Tanh => x.iter_mut().for_each(|v| *v = v.tanh()),
        }
    }

    /// Adds the bias row to every row of `y` (`rows x bias.len()`) and applies the activation,
    /// in one pass: `y[r][j] = f(y[r][j] + bias[j])`.
    #[inline]
    pub fn add_bias_apply<T: Scalar>(self, y: &mut [T], bias: &[T]) {
        bias_apply_kernel(self, y, bias);
    }

    /// [`Activation::backward`] fused with the bias gradient: turns `g` = dL/dy into dL/dz in
    /// place and adds its column sums to `bias_grad` (`g` is `rows x bias_grad.len()`).
    #[inline]
    pub fn backward_sum<T: Scalar>(self, y: &[T], g: &mut [T], bias_grad: &mut [T]) {
        backward_sum_kernel(self, y, g, bias_grad);
    }

    /// Turns dL/dy into dL/dz in place, given the outputs y: `g[i] *= f'(z[i])`.
    #[inline]
    pub fn backward<T: Scalar>(self, y: &[T], g: &mut [T]) {
        backward_kernel(self, y, g);
    }
}

multiversion! {
    /// The loop of [`Activation::add_bias_apply`].
    fn bias_apply_kernel / bias_apply_kernel_at<T: Scalar>(act: Activation, y: &mut [T], bias: &[T]) {
        let cols = bias.len();
        if cols == 0 {
            return;
        }
        let rows = y.chunks_exact_mut(cols);
        match act {
            Activation::Identity => rows.for_each(|r| {
                r.iter_mut().zip(bias).for_each(|(v, &b)| *v += b);
            }),
            Activation::Relu => rows.for_each(|r| {
                r.iter_mut().zip(bias).for_each(|(v, &b)| *v = (*v + b).max(T::ZERO));
            }),
            Activation::Tanh => rows.for_each(|r| {
                r.iter_mut().zip(bias).for_each(|(v, &b)| *v = (*v + b).tanh());
            }),
        }
    }
}

multiversion! {
    /// The loop of [`Activation::backward_sum`].
    fn backward_sum_kernel / backward_sum_kernel_at<T: Scalar>(act: Activation, y: &[T], g: &mut [T], bias_grad: &mut [T]) {
        debug_assert_eq!(y.len(), g.len());
        let cols = bias_grad.len();
        if cols == 0 {
            return;
        }
        let rows = g.chunks_exact_mut(cols).zip(y.chunks_exact(cols));
        match act {
            Activation::Identity => rows.for_each(|(g, _)| {
                bias_grad.iter_mut().zip(g.iter()).for_each(|(s, &g)| *s += g);
            }),
            Activation::Relu => rows.for_each(|(g, y)| {
                for ((s, g), &y) in bias_grad.iter_mut().zip(g).zip(y) {
                    *g = if y > T::ZERO { *g } else { T::ZERO };
                    *s += *g;
                }
            }),
            Activation::Tanh => rows.for_each(|(g, y)| {
                for ((s, g), &y) in bias_grad.iter_mut().zip(g).zip(y) {
                    *g *= T::ONE - y * y;
                    *s += *g;
                }
            }),
        }
    }
}

multiversion! {
    /// The loop of [`Activation::backward`].
    fn backward_kernel / backward_kernel_at<T: Scalar>(act: Activation, y: &[T], g: &mut [T]) {
        debug_assert_eq!(y.len(), g.len());
        match act {
            Activation::Identity => {}
            Activation::Relu => {
                g.iter_mut().zip(y).for_each(|(g, &y)| *g = if y > T::ZERO { *g } else { T::ZERO })
            }
            Activation::Tanh => g.iter_mut().zip(y).for_each(|(g, &y)| *g *= T::ONE - y * y),
        }
    }
}
