//! The multilayer perceptron: a stack of [`Linear`] layers over one flat parameter vector.

use std::ops::Range;

use super::ops::{grow, polyak_update};
use super::{Activation, Linear, Scalar};
use crate::base::rng::Rng;

/// Name, shape and place of one tensor inside a network's flat parameter vector (for
/// checkpoints): e.g. `layer0.weight` with shape `[out, in]`, `layer0.bias` with shape `[out]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TensorInfo {
    /// `layer{i}.weight` or `layer{i}.bias`.
    pub name: String,
    /// Row-major shape: `[out, in]` for weights, `[out]` for biases.
    pub shape: Vec<usize>,
    /// Index of the first element in the flat vector.
    pub offset: usize,
}

impl TensorInfo {
    /// Number of elements (product of the shape).
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    /// Whether the tensor has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Range of the tensor in the flat vector.
    pub fn range(&self) -> Range<usize> {
        self.offset..self.offset + self.len()
    }
}

/// Buffers of one forward (and backward) pass, reused across calls.
///
/// They only grow: a pass at a batch no larger than any seen before allocates nothing.
/// An [`Mlp`] holds two (one for training, which backward reads, one for [`Mlp::predict`]); more
/// can be made with [`Workspace::default`] for [`Mlp::predict_with`].
#[derive(Clone, Debug, Default)]
pub struct Workspace<T> {
    /// Batch size of the last forward pass.
    batch: usize,
    /// Whether a training forward pass has filled the caches.
    ready: bool,
    /// Copy of the last training input (`batch x in`), needed for the first layer's weight gradient.
    input: Vec<T>,
    /// Post-activation output of each layer (`batch x out_l`).
    acts: Vec<Vec<T>>,
    /// Ping-pong buffers for dL/dy while back-propagating.
    grad_a: Vec<T>,
    grad_b: Vec<T>,
    /// dL/dx of the last backward pass (`batch x in`).
    grad_in: Vec<T>,
}

/// A multilayer perceptron `sizes[0] -> sizes[1] -> ... -> sizes[L]` with activation `hidden`
/// after every layer but the last and `output` after the last.
///
/// All activations are row-major `batch x features`. The network owns one flat parameter vector
/// (layer 0 weight `[out, in]` row-major, layer 0 bias, layer 1 weight, ...) and one gradient
/// vector of the same layout; see [`Mlp::tensors`].
///
/// Training: [`Mlp::forward`] caches what the backward pass needs, then one or more of
/// [`Mlp::backward`], [`Mlp::backward_with_input_grad`], [`Mlp::input_grad`] or
/// [`Mlp::input_grad_cols`] back-propagate an upstream gradient dL/d(output). Parameter
/// gradients accumulate until [`Mlp::zero_grad`]. Inference ([`Mlp::predict`],
/// [`Mlp::predict_with`]) uses other buffers and leaves the training cache as it was.
///
/// Buffers grow to the largest batch seen and are then reused; [`Mlp::reserve`] grows them ahead.
#[derive(Clone, Debug)]
pub struct Mlp<T: Scalar> {
    sizes: Vec<usize>,
    layers: Vec<Linear>,
    hidden: Activation,
    output: Activation,
    params: Vec<T>,
    grads: Vec<T>,
    train: Workspace<T>,
    infer: Workspace<T>,
}

impl<T: Scalar> Mlp<T> {
    /// A network with layer widths `sizes` (at least two entries, all positive), initialised as
    /// PyTorch's `nn.Linear` (see [`Linear::init`]) from `rng`, layer by layer.
    ///
    /// # Panics
    /// If `sizes` has fewer than two entries or a zero entry.
    pub fn new(sizes: &[usize], hidden: Activation, output: Activation, rng: &mut Rng) -> Self {
        assert!(sizes.len() >= 2, "Mlp needs at least an input and an output size");
        assert!(sizes.iter().all(|&s| s > 0), "Mlp sizes must be positive");
        let mut layers = Vec::with_capacity(sizes.len() - 1);
        let mut offset = 0;
        for w in sizes.windows(2) {
            let layer = Linear::new(w[0], w[1], offset);
            offset += layer.param_len();
            layers.push(layer);
        }
        let mut params = vec![T::ZERO; offset];
        for layer in &layers {
            layer.init(&mut params, rng);
        }
        let workspace = Workspace { acts: vec![Vec::new(); layers.len()], ..Workspace::default() };
        Mlp {
            sizes: sizes.to_vec(),
            layers,
            hidden,
            output,
            grads: vec![T::ZERO; offset],
            params,
            train: workspace.clone(),
            infer: workspace,
        }
    }

    /// Grows the training and inference buffers for batches up to `batch`, so that later passes
    /// at such batches allocate nothing in this crate's code.
    pub fn reserve(&mut self, batch: usize) {
        let widest = self.sizes.iter().copied().max().unwrap_or(0);
        for ws in [&mut self.train, &mut self.infer] {
            for (acts, layer) in ws.acts.iter_mut().zip(&self.layers) {
                grow(acts, batch * layer.out_features);
            }
        }
        let ws = &mut self.train;
        grow(&mut ws.input, batch * self.sizes[0]);
        grow(&mut ws.grad_a, batch * widest);
        grow(&mut ws.grad_b, batch * widest);
        grow(&mut ws.grad_in, batch * self.sizes[0]);
    }

    /// Layer widths, input first.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// Input features.
    pub fn in_features(&self) -> usize {
        self.sizes[0]
    }

    /// Output features.
    pub fn out_features(&self) -> usize {
        self.sizes[self.sizes.len() - 1]
    }

    /// The layers, in order.
    pub fn layers(&self) -> &[Linear] {
        &self.layers
    }

    /// Activation after the hidden layers.
    pub fn hidden_activation(&self) -> Activation {
        self.hidden
    }

    /// Activation after the last layer.
    pub fn output_activation(&self) -> Activation {
        self.output
    }

    /// Number of parameters.
    pub fn num_params(&self) -> usize {
        self.params.len()
    }

    /// The flat parameter vector.
    pub fn params(&self) -> &[T] {
        &self.params
    }

    /// The flat parameter vector, mutable (optimiser steps, loading checkpoints).
    pub fn params_mut(&mut self) -> &mut [T] {
        &mut self.params
    }

    /// The flat gradient vector (same layout as the parameters).
    pub fn grads(&self) -> &[T] {
        &self.grads
    }

    /// The flat gradient vector, mutable (clipping, scaling).
    pub fn grads_mut(&mut self) -> &mut [T] {
        &mut self.grads
    }

    /// Parameters and gradients together, for an optimiser step: `adam.step(p, g)`.
    pub fn params_and_grads(&mut self) -> (&mut [T], &[T]) {
        (&mut self.params, &self.grads)
    }

    /// Sets every gradient to 0.
    pub fn zero_grad(&mut self) {
        self.grads.iter_mut().for_each(|g| *g = T::ZERO);
    }

    /// The named tensors in flat-vector order: `layer{i}.weight [out, in]`, `layer{i}.bias [out]`.
    pub fn tensors(&self) -> Vec<TensorInfo> {
        let mut out = Vec::with_capacity(2 * self.layers.len());
        for (i, l) in self.layers.iter().enumerate() {
            out.push(TensorInfo {
                name: format!("layer{i}.weight"),
                shape: vec![l.out_features, l.in_features],
                offset: l.weight_range().start,
            });
            out.push(TensorInfo {
                name: format!("layer{i}.bias"),
                shape: vec![l.out_features],
                offset: l.bias_range().start,
            });
        }
        out
    }

    /// Copies the parameters of `other` (same sizes) into `self` (hard target update).
    ///
    /// # Panics
    /// If the sizes differ.
    pub fn copy_params_from(&mut self, other: &Self) {
        assert_eq!(self.sizes, other.sizes, "copy_params_from: sizes differ");
        self.params.copy_from_slice(&other.params);
    }

    /// Polyak (soft target) update from `source` (same sizes):
    /// `self = (1 - tau) * self + tau * source`.
    ///
    /// # Panics
    /// If the sizes differ.
    pub fn polyak_from(&mut self, source: &Self, tau: T) {
        assert_eq!(self.sizes, source.sizes, "polyak_from: sizes differ");
        polyak_update(&mut self.params, &source.params, tau);
    }

    /// Training forward pass on `x` (`batch x in`, row-major); returns the output
    /// (`batch x out`) and caches what the backward pass needs.
    ///
    /// # Panics
    /// If `x.len() != batch * in`.
    pub fn forward(&mut self, x: &[T], batch: usize) -> &[T] {
        assert_eq!(x.len(), batch * self.in_features(), "Mlp::forward: input size");
        let ws = &mut self.train;
        grow(&mut ws.input, x.len());
        ws.input[..x.len()].copy_from_slice(x);
        let net =
            Net { layers: &self.layers, hidden: self.hidden, output: self.output, params: &self.params };
        net.forward(&ws.input[..x.len()], batch, &mut ws.acts);
        ws.batch = batch;
        ws.ready = true;
        self.output()
    }

    /// Output of the last training forward pass (`batch x out`).
    pub fn output(&self) -> &[T] {
        let ws = &self.train;
        let n = ws.batch * self.out_features();
        ws.acts.last().map_or(&[], |a| &a[..n.min(a.len())])
    }

    /// Batch size of the last training forward pass.
    pub fn batch(&self) -> usize {
        self.train.batch
    }

    /// Back-propagates `grad_out` = dL/d(output) (`batch x out`, the batch of the last
    /// [`Mlp::forward`]) and accumulates dL/d(params) into the gradient vector.
    ///
    /// # Panics
    /// If no forward pass preceded or `grad_out` has the wrong size.
    pub fn backward(&mut self, grad_out: &[T]) {
        self.backprop(grad_out, true, None);
    }

    /// As [`Mlp::backward`], and also returns dL/d(input) (`batch x in`).
    pub fn backward_with_input_grad(&mut self, grad_out: &[T]) -> &[T] {
        let cols = 0..self.in_features();
        self.backprop(grad_out, true, Some(cols))
    }

    /// Returns dL/d(input) (`batch x in`) for `grad_out` = dL/d(output) without touching the
    /// parameter gradients (e.g. dQ/da through a critic for an actor update).
    pub fn input_grad(&mut self, grad_out: &[T]) -> &[T] {
        let cols = 0..self.in_features();
        self.backprop(grad_out, false, Some(cols))
    }

    /// As [`Mlp::input_grad`] for the input columns `cols` only (`batch x cols.len()`), e.g.
    /// dQ/da for a critic whose input is `[obs | action]`: `input_grad_cols(g, obs..obs + act)`.
    /// Cheaper than the full input gradient, and needs no column extraction afterwards.
    ///
    /// # Panics
    /// As [`Mlp::backward`], or if `cols` is not inside `0..in_features`.
    pub fn input_grad_cols(&mut self, grad_out: &[T], cols: Range<usize>) -> &[T] {
        self.backprop(grad_out, false, Some(cols))
    }

    /// Inference on `x` (`batch x in`) using the network's own inference buffers; the training
    /// cache is left untouched. Returns `batch x out`.
    pub fn predict(&mut self, x: &[T], batch: usize) -> &[T] {
        let Mlp { layers, hidden, output, params, infer, .. } = self;
        Net { layers, hidden: *hidden, output: *output, params }.predict(x, batch, infer)
    }

    /// Inference on `x` (`batch x in`) into a caller-owned workspace, so that `&self` suffices.
    pub fn predict_with<'w>(&self, x: &[T], batch: usize, ws: &'w mut Workspace<T>) -> &'w [T] {
        let net =
            Net { layers: &self.layers, hidden: self.hidden, output: self.output, params: &self.params };
        net.predict(x, batch, ws)
    }

    /// Back-propagation: dL/dz_l = dL/dy_l * f'(z_l); dW_l += dz_l^T x_l; db_l += sum dz_l;
    /// dL/dx_l = dz_l W_l. Returns dL/dx for the input columns `input_cols` (empty if `None`).
    fn backprop(&mut self, grad_out: &[T], param_grads: bool, input_cols: Option<Range<usize>>) -> &[T] {
        assert!(self.train.ready, "Mlp backward without a forward pass");
        let batch = self.train.batch;
        let n_layers = self.layers.len();
        assert_eq!(grad_out.len(), batch * self.out_features(), "Mlp backward: grad_out size");
        let widest = self.sizes.iter().copied().max().unwrap_or(0);
        let activations: [Activation; 2] = [self.hidden, self.output];
        let Mlp { layers, params, grads, train: ws, .. } = self;
        grow(&mut ws.grad_a, batch * widest);
        grow(&mut ws.grad_b, batch * widest);
        let in_width = input_cols.as_ref().map_or(0, |c| c.len());
        grow(&mut ws.grad_in, batch * in_width);
        let (mut cur, mut next) = (&mut ws.grad_a, &mut ws.grad_b);
        cur[..grad_out.len()].copy_from_slice(grad_out);
        // Whether `cur` already holds dL/dz (the activation's backward pass fused into the
        // previous step's input gradient).
        let mut through_act = false;
        for l in (0..n_layers).rev() {
            let layer = layers[l];
            let n_out = batch * layer.out_features;
            let act = activations[usize::from(l + 1 == n_layers)];
            let x: &[T] = if l == 0 { &ws.input } else { &ws.acts[l - 1] };
            if !through_act && param_grads {
                act.backward_sum(&ws.acts[l][..n_out], &mut cur[..n_out], &mut grads[layer.bias_range()]);
            } else if !through_act {
                act.backward(&ws.acts[l][..n_out], &mut cur[..n_out]);
            }
            if param_grads {
                layer.backward_weight(grads, x, cur, batch);
            }
            if l > 0 {
                // dL/dz of layer l - 1, whose activation is the hidden one.
                let bias_grad = param_grads.then(|| &mut grads[layers[l - 1].bias_range()]);
                let ys = &ws.acts[l - 1][..batch * layer.in_features];
                layer.backward_input_act(params, cur, batch, next, (ys, activations[0], bias_grad));
                std::mem::swap(&mut cur, &mut next);
                through_act = true;
            } else if let Some(cols) = input_cols.clone() {
                layer.backward_input_cols(params, cur, batch, cols, &mut ws.grad_in);
            }
        }
        &ws.grad_in[..batch * in_width]
    }
}

/// The layers, activations and parameters a forward pass needs.
#[derive(Clone, Copy)]
struct Net<'a, T> {
    layers: &'a [Linear],
    hidden: Activation,
    output: Activation,
    params: &'a [T],
}

impl<T: Scalar> Net<'_, T> {
    /// Forward through every layer, writing layer outputs into `acts` (grown as needed).
    fn forward(self, x: &[T], batch: usize, acts: &mut [Vec<T>]) {
        let n_layers = self.layers.len();
        for (l, layer) in self.layers.iter().enumerate() {
            let (done, rest) = acts.split_at_mut(l);
            let input: &[T] = if l == 0 { x } else { &done[l - 1] };
            let out = &mut rest[0];
            let n = batch * layer.out_features;
            grow(out, n);
            let act = if l + 1 == n_layers { self.output } else { self.hidden };
            layer.forward_act(self.params, input, batch, &mut out[..n], act);
        }
    }

    /// Inference into `ws`; returns `batch x out`.
    fn predict<'w>(self, x: &[T], batch: usize, ws: &'w mut Workspace<T>) -> &'w [T] {
        let layers = self.layers;
        assert_eq!(x.len(), batch * layers[0].in_features, "Mlp::predict: input size");
        if ws.acts.len() != layers.len() {
            ws.acts.resize(layers.len(), Vec::new());
        }
        self.forward(x, batch, &mut ws.acts);
        ws.batch = batch;
        let n = batch * layers[layers.len() - 1].out_features;
        &ws.acts[layers.len() - 1][..n]
    }
}
