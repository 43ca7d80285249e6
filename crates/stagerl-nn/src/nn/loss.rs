//! Losses with their gradients.

use super::Scalar;

/// Mean-squared error `L = (1/n) sum_i (pred_i - target_i)^2` over all `n` elements (PyTorch's
/// `F.mse_loss` with mean reduction); writes `grad_i = dL/dpred_i = 2 (pred_i - target_i) / n`
/// and returns L.
///
/// # Panics
/// If the lengths differ.
pub fn mse_loss<T: Scalar>(pred: &[T], target: &[T], grad: &mut [T]) -> T {
    assert_eq!(pred.len(), target.len(), "mse_loss: lengths differ");
    assert_eq!(pred.len(), grad.len(), "mse_loss: grad length");
    if pred.is_empty() {
        return T::ZERO;
    }
    let inv_n = T::ONE / T::from_usize(pred.len());
    let two_inv_n = inv_n + inv_n;
    let mut sum = T::ZERO;
    for ((g, &p), &t) in grad.iter_mut().zip(pred).zip(target) {
        let d = p - t;
        sum += d * d;
        *g = two_inv_n * d;
    }
    sum * inv_n
}

/// Mean-squared error without the gradient.
pub fn mse<T: Scalar>(pred: &[T], target: &[T]) -> T {
    assert_eq!(pred.len(), target.len(), "mse: lengths differ");
    if pred.is_empty() {
        return T::ZERO;
    }
    let sum: T = pred.iter().zip(target).map(|(&p, &t)| (p - t) * (p - t)).sum();
    sum / T::from_usize(pred.len())
}
