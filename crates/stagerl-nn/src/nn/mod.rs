//! A small, allocation-free multilayer-perceptron engine for the RL agents.
//!
//! - [`Scalar`]: the element type, `f32` for training, `f64` for the gradient checks.
//! - [`Linear`] and [`Mlp`]: fully connected layers over ONE flat parameter vector and ONE flat
//!   gradient vector per network (same layout, described by [`Mlp::tensors`]), so that Adam,
//!   Polyak averaging, norms, NaN guards and checkpoints are single loops over slices.
//! - [`BrnMlp`]: CrossQ's batch-renormalised MLP ([`BatchRenorm`] before every layer), which
//!   folds into a plain [`Mlp`] for inference.
//! - [`SquashedGaussian`]: SAC's tanh-squashed Gaussian policy head, with its backward pass.
//! - [`Adam`], [`polyak_update`], [`mse_loss`], [`clip_grad_norm`], [`first_non_finite`] and
//!   a few slice helpers.
//!
//! Conventions: activations are row-major `batch x features`; weights are `[out, in]` as in
//! PyTorch. Matrix products run the engine's own kernels (`matmul`: single thread, run-time SIMD
//! dispatch, every output element one fused multiply-add chain in a documented order, so the
//! same bits at every SIMD level); buffers only grow, so after a warm-up pass at the largest
//! batch the forward, backward and optimiser code allocates nothing (the products use stack
//! buffers only).
//!
//! # Example: a critic regression and a DDPG-style actor update
//! ```
//! # // The paths of the `stagerl` crate, which re-exports this one (this crate's tests cannot use it).
//! # mod stagerl { pub use stagerl_base::base; pub use stagerl_nn::nn; }
//! use stagerl::nn::{concat_cols, mse_loss, Activation, Adam, Mlp};
//! use stagerl::base::rng::Rng;
//!
//! let (obs, act, batch) = (4, 2, 8);
//! let mut rng = Rng::new(0);
//! let mut actor = Mlp::<f32>::new(&[obs, 16, act], Activation::Relu, Activation::Tanh, &mut rng);
//! let mut critic =
//!     Mlp::<f32>::new(&[obs + act, 16, 1], Activation::Relu, Activation::Identity, &mut rng);
//! let (mut actor_opt, mut critic_opt) =
//!     (Adam::new(actor.num_params(), 1e-3), Adam::new(critic.num_params(), 1e-3));
//! let o: Vec<f32> = (0..batch * obs).map(|_| rng.normal() as f32).collect();
//! let a: Vec<f32> = (0..batch * act).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
//! let target = vec![1.0f32; batch];
//!
//! // Critic: minimise mean (Q(o, a) - target)^2.
//! let mut input = vec![0.0; batch * (obs + act)];
//! concat_cols(&o, obs, &a, act, batch, &mut input);
//! let mut dq = vec![0.0; batch];
//! let q = critic.forward(&input, batch);
//! let _loss = mse_loss(q, &target, &mut dq);
//! critic.zero_grad();
//! critic.backward(&dq);
//! let (p, g) = critic.params_and_grads();
//! critic_opt.step(p, g);
//!
//! // Actor: maximise mean Q(o, pi(o)), i.e. descend on -Q through dQ/da.
//! let pi = actor.forward(&o, batch);
//! concat_cols(&o, obs, pi, act, batch, &mut input);
//! critic.forward(&input, batch);
//! let d_q = vec![-1.0 / batch as f32; batch];
//! let d_a = critic.input_grad_cols(&d_q, obs..obs + act); // critic gradients untouched
//! actor.zero_grad();
//! actor.backward(d_a);
//! let (p, g) = actor.params_and_grads();
//! actor_opt.step(p, g);
//! ```

mod activation;
mod adam;
mod batch_renorm;
mod brn_mlp;
mod gaussian;
mod linear;
mod loss;
mod matmul;
mod mlp;
mod norm;
mod ops;
mod scalar;

#[cfg(test)]
mod tests;

pub use activation::Activation;
pub use adam::Adam;
pub use batch_renorm::{BatchRenorm, BatchRenormSettings, RunningStats};
pub use brn_mlp::BrnMlp;
pub use gaussian::{LogStdBound, SquashedGaussian};
pub use linear::Linear;
pub use loss::{mse, mse_loss};
pub use mlp::{Mlp, TensorInfo, Workspace};
pub use norm::{HiddenNorm, LN_EPS};
pub use ops::{
    add_assign, axpy, clip_grad_norm, concat_cols, copy_cols, copy_row, first_non_finite, l2_norm,
    polyak_update, scale, sum_of_squares,
};
pub use scalar::Scalar;
