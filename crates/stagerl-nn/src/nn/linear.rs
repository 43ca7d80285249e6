//! The fully connected layer y = x W^T + b, operating on a slice of a network's flat parameters.

use std::ops::Range;

use super::matmul;
use super::{Activation, Scalar};
use crate::base::par;
use crate::base::rng::Rng;

/// Batch rows per piece when a product is split over threads ([`par::split`]): a multiple of
/// the kernels' row tiles.
const ROW_ALIGN: usize = 8;

/// Multiply-adds below which a product runs on one thread (hidden 64 stays serial: its products
/// are too short to gain from a second thread, whose results must also travel between caches).
const PAR_MIN_MACS: usize = 1 << 22;

/// A fully connected layer: `y = x W^T + b`.
///
/// Shapes (row-major, PyTorch's convention): input `x` is `batch x in_features`, weight `W` is
/// `out_features x in_features`, bias `b` is `out_features`, output `y` is `batch x out_features`.
///
/// The layer owns no storage: its weight and bias live in a network's flat parameter vector at
/// `offset` (weight first, `out * in` values, then bias, `out` values), and its gradients at the
/// same offset of the flat gradient vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Linear {
    /// Input features.
    pub in_features: usize,
    /// Output features.
    pub out_features: usize,
    /// Index of the first weight in the flat parameter (and gradient) vector.
    pub offset: usize,
}

impl Linear {
    /// A layer `in_features -> out_features` whose parameters start at `offset`.
    pub fn new(in_features: usize, out_features: usize, offset: usize) -> Self {
        Linear { in_features, out_features, offset }
    }

    /// Number of parameters: `out * in + out`.
    #[inline]
    pub fn param_len(&self) -> usize {
        self.out_features * (self.in_features + 1)
    }

    /// Range of the weight (row-major `out x in`) in the flat vector.
    #[inline]
    pub fn weight_range(&self) -> Range<usize> {
        self.offset..self.offset + self.out_features * self.in_features
    }

    /// Range of the bias (`out`) in the flat vector.
    #[inline]
    pub fn bias_range(&self) -> Range<usize> {
        let start = self.offset + self.out_features * self.in_features;
        start..start + self.out_features
    }

    /// PyTorch's default initialisation (`nn.Linear.reset_parameters`): every weight and bias
    /// drawn from U(-1/sqrt(in), 1/sqrt(in)), weights first in row-major order, then biases.
    pub fn init<T: Scalar>(&self, params: &mut [T], rng: &mut Rng) {
        let bound = 1.0 / (self.in_features as f64).sqrt();
        for p in &mut params[self.offset..self.offset + self.param_len()] {
            *p = T::from_f64(rng.uniform_range(-bound, bound));
        }
    }

    /// Forward pass: `y = x W^T + b`, i.e. `y[b, o] = sum over i of x[b, i] W[o, i]` (one fused
    /// multiply-add chain in increasing `i`; the exact order: `super::matmul`) `+ bias[o]`.
    ///
    /// `params` is the whole flat parameter vector; `x` holds at least `batch * in` values,
    /// `y` at least `batch * out` values (extra values are left untouched).
    pub fn forward<T: Scalar>(&self, params: &[T], x: &[T], batch: usize, y: &mut [T]) {
        self.forward_act(params, x, batch, y, Activation::Identity);
    }

    /// Forward pass with an activation: `y = f(x W^T + b)`, the same values as
    /// [`Linear::forward_no_bias`] followed by [`Activation::add_bias_apply`] (the bias and
    /// `Identity` or `Relu` are applied as the product's tiles are stored).
    pub fn forward_act<T: Scalar>(&self, params: &[T], x: &[T], batch: usize, y: &mut [T], f: Activation) {
        self.forward_rows(params, x, batch, y, Some((&params[self.bias_range()], f)));
    }

    /// `y = x W^T` (with the bias and activation of `bias_act`), its batch rows split over this
    /// thread's pool when the product is large ([`par::split_rows_mut`]; the same values).
    fn forward_rows<T: Scalar>(
        &self,
        params: &[T],
        x: &[T],
        batch: usize,
        y: &mut [T],
        bias_act: Option<(&[T], Activation)>,
    ) {
        let (n_in, n_out) = (self.in_features, self.out_features);
        let w = &params[self.weight_range()];
        par::split_rows_mut(y, batch, n_out, ROW_ALIGN, n_in * n_out, PAR_MIN_MACS, &|r, y| {
            matmul::forward((r.len(), n_out, n_in), y, &x[r.start * n_in..r.end * n_in], w, bias_act)
        });
    }

    /// The product alone, `y = x W^T` (the caller adds the bias, possibly fused with an
    /// activation: see [`Activation::add_bias_apply`], or use [`Linear::forward_act`]).
    pub fn forward_no_bias<T: Scalar>(&self, params: &[T], x: &[T], batch: usize, y: &mut [T]) {
        self.forward_rows(params, x, batch, y, None);
    }

    /// Accumulates the parameter gradients for upstream gradient `dy = dL/dy` (`batch x out`):
    /// `dW += dy^T x` and `db += sum over the batch of dy`.
    ///
    /// `grads` is the whole flat gradient vector, `x` the input the forward pass saw.
    pub fn backward_params<T: Scalar>(&self, grads: &mut [T], x: &[T], dy: &[T], batch: usize) {
        let dy = &dy[..batch * self.out_features];
        let gb = &mut grads[self.bias_range()];
        for row in dy.chunks_exact(self.out_features) {
            gb.iter_mut().zip(row).for_each(|(g, &d)| *g += d);
        }
        self.backward_weight(grads, x, dy, batch);
    }

    /// The weight part of [`Linear::backward_params`] alone: `dW += dy^T x`, i.e.
    /// `dW[o, i] += sum over b of dy[b, o] x[b, i]` (one chain from the old value, in increasing
    /// `b`).
    pub fn backward_weight<T: Scalar>(&self, grads: &mut [T], x: &[T], dy: &[T], batch: usize) {
        let (n_in, n_out) = (self.in_features, self.out_features);
        matmul::backward_weight((n_out, n_in, batch), &mut grads[self.weight_range()], dy, x);
    }

    /// Gradient with respect to the input: `dx = dy W` (`batch x in`), overwriting `dx`.
    pub fn backward_input<T: Scalar>(&self, params: &[T], dy: &[T], batch: usize, dx: &mut [T]) {
        self.backward_input_cols(params, dy, batch, 0..self.in_features, dx);
    }

    /// [`Linear::backward_input`] fused with the backward pass of the activation `f` whose
    /// outputs `ys` (`batch x in`) were this layer's input: `dx = (dy W) * f'` as
    /// [`Activation::backward`] computes it, i.e. dL/dz of the previous layer; with
    /// `bias_grad` (the previous layer's bias gradient, `in` values) also its column sums, as
    /// [`Activation::backward_sum`] adds them. The same values as the separate calls.
    pub fn backward_input_act<T: Scalar>(
        &self,
        params: &[T],
        dy: &[T],
        batch: usize,
        dx: &mut [T],
        (ys, f, bias_grad): (&[T], Activation, Option<&mut [T]>),
    ) {
        let (n_in, n_out) = (self.in_features, self.out_features);
        let deriv = matmul::Deriv { ys, f, bias_grad };
        matmul::backward_input(
            (batch, n_in, n_out),
            dx,
            dy,
            (&params[self.weight_range()], n_in),
            Some(deriv),
        );
    }

    /// Gradient with respect to the input columns `cols` only: `dx = dy W[:, cols]`
    /// (`batch x cols.len()`), overwriting `dx`, i.e. `dx[b, j] = sum over o of dy[b, o]
    /// W[o, cols.start + j]` (one chain in increasing `o`); e.g. dQ/da when the input is
    /// `[obs | action]`.
    ///
    /// # Panics
    /// If `cols` is not inside `0..in_features`.
    pub fn backward_input_cols<T: Scalar>(
        &self,
        params: &[T],
        dy: &[T],
        batch: usize,
        cols: Range<usize>,
        dx: &mut [T],
    ) {
        let (n_in, n_out) = (self.in_features, self.out_features);
        assert!(cols.start <= cols.end && cols.end <= n_in, "Linear: input columns out of range");
        let (width, w) = (cols.len(), &params[self.weight_range()][cols.start..]);
        // Batch rows apart (each row's values are its own; the same values on any split).
        par::split_rows_mut(dx, batch, width, ROW_ALIGN, width * n_out, PAR_MIN_MACS, &|r, dx| {
            let dy = &dy[r.start * n_out..r.end * n_out];
            matmul::backward_input((r.len(), width, n_out), dx, dy, (w, n_in), None)
        });
    }
}
