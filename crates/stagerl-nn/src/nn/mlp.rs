//! The multilayer perceptron: a stack of [`Linear`] layers over one flat parameter vector.

use std::ops::Range;

use super::norm::{self, HiddenNorm};
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
    /// With a [`HiddenNorm`], per hidden layer: the dropout mask of the last training pass
    /// (empty when it dropped nothing), layer normalisation's `xhat` and `1 / std` per row.
    mask: Vec<Vec<T>>,
    xhat: Vec<Vec<T>>,
    inv_std: Vec<Vec<T>>,
    /// Whether the last training pass drew a dropout mask.
    dropped: bool,
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
    /// Dropout and layer normalisation after the hidden layers (DroQ's critics), whose scales
    /// and biases follow the layers' parameters from `ln_offset` on.
    norm: Option<HiddenNorm>,
    ln_offset: usize,
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
        Self::with_norm(sizes, hidden, output, None, rng)
    }

    /// [`Mlp::new`] with dropout and layer normalisation between every hidden layer's product
    /// and its activation ([`super::norm`]); the layers are drawn from `rng` as by
    /// [`Mlp::new`], layer normalisation's scales start at 1 and its biases at 0.
    pub fn with_norm(
        sizes: &[usize],
        hidden: Activation,
        output: Activation,
        norm: Option<HiddenNorm>,
        rng: &mut Rng,
    ) -> Self {
        assert!(sizes.len() >= 2, "Mlp needs at least an input and an output size");
        assert!(sizes.iter().all(|&s| s > 0), "Mlp sizes must be positive");
        let mut layers = Vec::with_capacity(sizes.len() - 1);
        let mut offset = 0;
        for w in sizes.windows(2) {
            let layer = Linear::new(w[0], w[1], offset);
            offset += layer.param_len();
            layers.push(layer);
        }
        let ln_offset = offset;
        let hidden_widths: usize = sizes[1..sizes.len() - 1].iter().sum();
        if norm.is_some_and(|n| n.layer_norm) {
            offset += 2 * hidden_widths;
        }
        let mut params = vec![T::ZERO; offset];
        for layer in &layers {
            layer.init(&mut params, rng);
        }
        if norm.is_some_and(|n| n.layer_norm) {
            // Scales 1, biases 0: the scales come first per layer (see `ln_ranges`).
            let mut at = ln_offset;
            for &h in &sizes[1..sizes.len() - 1] {
                params[at..at + h].fill(T::ONE);
                at += 2 * h;
            }
        }
        let hidden_layers = layers.len() - 1;
        let workspace = Workspace {
            acts: vec![Vec::new(); layers.len()],
            mask: vec![Vec::new(); hidden_layers],
            xhat: vec![Vec::new(); hidden_layers],
            inv_std: vec![Vec::new(); hidden_layers],
            ..Workspace::default()
        };
        Mlp {
            sizes: sizes.to_vec(),
            layers,
            hidden,
            output,
            norm,
            ln_offset,
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
        if self.norm.is_some() {
            for (l, &h) in self.sizes[1..self.sizes.len() - 1].iter().enumerate() {
                grow(&mut ws.mask[l], batch * h);
                grow(&mut ws.xhat[l], batch * h);
                grow(&mut ws.inv_std[l], batch);
            }
        }
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

    /// Dropout and layer normalisation after the hidden layers, if any.
    pub fn hidden_norm(&self) -> Option<HiddenNorm> {
        self.norm
    }

    /// The ranges of hidden layer `l`'s layer-normalisation scale and bias in the flat vector.
    fn ln_ranges(ln_offset: usize, sizes: &[usize], l: usize) -> (Range<usize>, Range<usize>) {
        let start = ln_offset + 2 * sizes[1..=l].iter().sum::<usize>() - 2 * sizes[l + 1];
        let h = sizes[l + 1];
        (start..start + h, start + h..start + 2 * h)
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
        if self.norm.is_some_and(|n| n.layer_norm) {
            for l in 0..self.layers.len() - 1 {
                let (scale, bias) = Self::ln_ranges(self.ln_offset, &self.sizes, l);
                let h = scale.len();
                out.push(TensorInfo { name: format!("ln{l}.scale"), shape: vec![h], offset: scale.start });
                out.push(TensorInfo { name: format!("ln{l}.bias"), shape: vec![h], offset: bias.start });
            }
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
        self.forward_inner(x, batch, None)
    }

    /// [`Mlp::forward`] with dropout after the hidden layers (a network with a
    /// [`HiddenNorm`] of `dropout > 0`), its masks drawn from `rng`; as [`Mlp::forward`]
    /// otherwise (no draw).
    pub fn forward_dropout(&mut self, x: &[T], batch: usize, rng: &mut Rng) -> &[T] {
        self.forward_inner(x, batch, Some(rng))
    }

    fn forward_inner(&mut self, x: &[T], batch: usize, rng: Option<&mut Rng>) -> &[T] {
        assert_eq!(x.len(), batch * self.in_features(), "Mlp::forward: input size");
        let Mlp { layers, hidden, output, params, train: ws, norm, ln_offset, sizes, .. } = self;
        grow(&mut ws.input, x.len());
        ws.input[..x.len()].copy_from_slice(x);
        let norm_at = norm.map(|n| (n, *ln_offset, &sizes[..]));
        let net = Net { layers, hidden: *hidden, output: *output, params, norm: norm_at };
        ws.dropped = false;
        match *norm {
            None => net.forward(&ws.input[..x.len()], batch, &mut ws.acts),
            Some(n) => {
                let rng = rng.filter(|_| n.dropout > 0.0);
                ws.dropped = rng.is_some();
                let cache =
                    NormCache { mask: &mut ws.mask, xhat: &mut ws.xhat, inv_std: &mut ws.inv_std, rng };
                net.forward_normed(&ws.input[..x.len()], batch, &mut ws.acts, Some(cache));
            }
        }
        ws.batch = batch;
        ws.ready = true;
        self.output()
    }

    fn net(&self) -> Net<'_, T> {
        Net {
            layers: &self.layers,
            hidden: self.hidden,
            output: self.output,
            params: &self.params,
            norm: self.norm.map(|n| (n, self.ln_offset, &self.sizes[..])),
        }
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
        let Mlp { layers, hidden, output, params, infer, norm, ln_offset, sizes, .. } = self;
        let norm = norm.map(|n| (n, *ln_offset, &sizes[..]));
        Net { layers, hidden: *hidden, output: *output, params, norm }.predict(x, batch, infer)
    }

    /// Inference on `x` (`batch x in`) into a caller-owned workspace, so that `&self` suffices.
    pub fn predict_with<'w>(&self, x: &[T], batch: usize, ws: &'w mut Workspace<T>) -> &'w [T] {
        self.net().predict(x, batch, ws)
    }

    /// Back-propagation: dL/dz_l = dL/dy_l * f'(z_l); dW_l += dz_l^T x_l; db_l += sum dz_l;
    /// dL/dx_l = dz_l W_l. Returns dL/dx for the input columns `input_cols` (empty if `None`).
    fn backprop(&mut self, grad_out: &[T], param_grads: bool, input_cols: Option<Range<usize>>) -> &[T] {
        assert!(self.train.ready, "Mlp backward without a forward pass");
        if self.norm.is_some() {
            return self.backprop_normed(grad_out, param_grads, input_cols);
        }
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
    /// The hidden layers' dropout and normalisation, where their parameters start, the sizes.
    norm: Option<(HiddenNorm, usize, &'a [usize])>,
}

/// What a training pass through normalised hidden layers keeps for the backward pass, and the
/// random stream of its dropout (none: no dropout).
struct NormCache<'a, T> {
    mask: &'a mut [Vec<T>],
    xhat: &'a mut [Vec<T>],
    inv_std: &'a mut [Vec<T>],
    rng: Option<&'a mut Rng>,
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
        if self.norm.is_some() {
            self.forward_normed(x, batch, &mut ws.acts, None);
        } else {
            self.forward(x, batch, &mut ws.acts);
        }
        ws.batch = batch;
        let n = batch * layers[layers.len() - 1].out_features;
        &ws.acts[layers.len() - 1][..n]
    }
}

impl<T: Scalar> Net<'_, T> {
    /// [`Net::forward`] with dropout and layer normalisation after the hidden layers
    /// ([`super::norm`]): `y = f(LN(drop(x W^T + b)))`; the output layer as usual. With `cache`
    /// (a training pass) the masks and normalisation statistics are kept, and dropout runs when
    /// its stream is given.
    fn forward_normed(self, x: &[T], batch: usize, acts: &mut [Vec<T>], mut cache: Option<NormCache<'_, T>>) {
        let (hn, ln_offset, sizes) = self.norm.expect("a normalised network");
        let n_layers = self.layers.len();
        for (l, layer) in self.layers.iter().enumerate() {
            let (done, rest) = acts.split_at_mut(l);
            let input: &[T] = if l == 0 { x } else { &done[l - 1] };
            let out = &mut rest[0];
            let n = batch * layer.out_features;
            grow(out, n);
            if l + 1 == n_layers {
                layer.forward_act(self.params, input, batch, &mut out[..n], self.output);
                continue;
            }
            layer.forward(self.params, input, batch, &mut out[..n]);
            let h = layer.out_features;
            if let Some(c) = cache.as_mut() {
                if let Some(rng) = c.rng.as_deref_mut() {
                    grow(&mut c.mask[l], n);
                    norm::dropout_forward(&mut out[..n], &mut c.mask[l][..n], hn.dropout, rng);
                }
            }
            if hn.layer_norm {
                let (scale, bias) = Mlp::<T>::ln_ranges(ln_offset, sizes, l);
                let (scale, bias) = (&self.params[scale], &self.params[bias]);
                match cache.as_mut() {
                    Some(c) => {
                        grow(&mut c.xhat[l], n);
                        grow(&mut c.inv_std[l], batch);
                        let keep = Some((&mut c.xhat[l][..n], &mut c.inv_std[l][..batch]));
                        norm::layer_norm_forward(&mut out[..n], h, scale, bias, keep);
                    }
                    None => norm::layer_norm_forward(&mut out[..n], h, scale, bias, None),
                }
            }
            self.hidden.apply(&mut out[..n]);
        }
    }
}

impl<T: Scalar> Mlp<T> {
    /// [`Mlp::backprop`] through normalised hidden layers, unfused: per layer from the last,
    /// the activation's derivative, layer normalisation's backward pass, the dropout mask, then
    /// the bias and weight gradients and dL/dx.
    fn backprop_normed(
        &mut self,
        grad_out: &[T],
        param_grads: bool,
        input_cols: Option<Range<usize>>,
    ) -> &[T] {
        let hn = self.norm.expect("a normalised network");
        let batch = self.train.batch;
        let n_layers = self.layers.len();
        assert_eq!(grad_out.len(), batch * self.out_features(), "Mlp backward: grad_out size");
        let widest = self.sizes.iter().copied().max().unwrap_or(0);
        let Mlp { layers, params, grads, train: ws, sizes, ln_offset, hidden, output, .. } = self;
        grow(&mut ws.grad_a, batch * widest);
        grow(&mut ws.grad_b, batch * widest);
        let in_width = input_cols.as_ref().map_or(0, |c| c.len());
        grow(&mut ws.grad_in, batch * in_width);
        let (mut cur, mut next) = (&mut ws.grad_a, &mut ws.grad_b);
        cur[..grad_out.len()].copy_from_slice(grad_out);
        for l in (0..n_layers).rev() {
            let layer = layers[l];
            let n_out = batch * layer.out_features;
            let g = &mut cur[..n_out];
            if l + 1 == n_layers {
                output.backward(&ws.acts[l][..n_out], g);
            } else {
                hidden.backward(&ws.acts[l][..n_out], g);
                if hn.layer_norm {
                    let (scale, bias) = Self::ln_ranges(*ln_offset, sizes, l);
                    let stats = (&ws.xhat[l][..n_out], &ws.inv_std[l][..batch]);
                    let pg = if param_grads {
                        let (ds, db) = grads[scale.start..bias.end].split_at_mut(scale.len());
                        Some((ds, db))
                    } else {
                        None
                    };
                    norm::layer_norm_backward(g, layer.out_features, stats, &params[scale], pg);
                }
                if ws.dropped {
                    for (v, &m) in g.iter_mut().zip(&ws.mask[l][..n_out]) {
                        *v *= m;
                    }
                }
            }
            if param_grads {
                norm::add_column_sums(g, &mut grads[layer.bias_range()]);
                let x: &[T] = if l == 0 { &ws.input } else { &ws.acts[l - 1] };
                layer.backward_weight(grads, x, g, batch);
            }
            if l > 0 {
                layer.backward_input(params, g, batch, &mut next[..batch * layer.in_features]);
                std::mem::swap(&mut cur, &mut next);
            } else if let Some(cols) = input_cols.clone() {
                layer.backward_input_cols(params, g, batch, cols, &mut ws.grad_in);
            }
        }
        &ws.grad_in[..batch * in_width]
    }
}
