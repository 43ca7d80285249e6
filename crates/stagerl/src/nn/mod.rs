//! A small, allocation-free multilayer-perceptron engine for the RL agents.
//!
//! - [`Scalar`]: the element type, `f32` for training, `f64` for the gradient checks.
//! - [`Linear`] and [`Mlp`]: fully connected layers over ONE flat parameter vector and ONE flat
//!   gradient vector per network (same layout, described by [`Mlp::tensors`]), so that Adam,
//!   Polyak averaging, norms, NaN guards and checkpoints are single loops over slices.
//! - [`SquashedGaussian`]: SAC's tanh-squashed Gaussian policy head, with its backward pass.
//! - [`Adam`], [`polyak_update`], [`mse_loss`], [`clip_grad_norm`], [`first_non_finite`] and
//!   a few slice helpers.
//!
//! Conventions: activations are row-major `batch x features`; weights are `[out, in]` as in
//! PyTorch. Matrix products are `gemm::gemm` with `Parallelism::None` (single thread,
//! deterministic); buffers only grow, so after a warm-up pass at the largest batch the engine's
//! own forward, backward and optimiser code allocates nothing (gemm may still use its own
//! packing scratch memory for large products).

mod activation;
mod adam;
mod gaussian;
mod linear;
mod loss;
mod matmul;
mod mlp;
mod ops;
mod scalar;

#[cfg(test)]
mod tests;

pub use activation::Activation;
pub use adam::Adam;
pub use gaussian::{LogStdBound, SquashedGaussian};
pub use linear::Linear;
pub use loss::{mse, mse_loss};
pub use mlp::{Mlp, TensorInfo, Workspace};
pub use ops::{
    add_assign, axpy, clip_grad_norm, concat_cols, copy_cols, first_non_finite, l2_norm,
    polyak_update, scale, sum_of_squares,
};
pub use scalar::{tanh_f32, Scalar};
