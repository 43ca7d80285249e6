//! The batch-renormalised multilayer perceptron of CrossQ (Bhatt et al., ICLR 2024), as sbx's
//! `sbx/crossq/policies.py` builds its critic and its actor: a [`BatchRenorm`] on the input,
//! then per hidden layer `x W^T + b`, ReLU, [`BatchRenorm`]; then the output layer.
//!
//! With layers `l = 0 .. L-1` (`L = sizes.len() - 1`) and norms `k = 0 .. L-1` (norm `k` before
//! layer `k`, over `sizes[k]` features):
//! 1. training pass on `x_0 = x`: `h_k = BRN_k(x_k)` (batch statistics, running statistics
//!    updated: [`BatchRenorm::forward_train`]), `x_{k+1} = relu(h_k W_k^T + b_k)` for the hidden
//!    layers, the output `y = h_{L-1} W_{L-1}^T + b_{L-1}`;
//! 2. backward from `g = dL/dy`: per layer from the last, `dW_k += g^T h_k`, `db_k += sum g`,
//!    `dL/dh_k = g W_k`, through `BRN_k` ([`BatchRenorm::backward`]: its scale and bias
//!    gradients, `dL/dx_k`), then through the ReLU (`x_k > 0`) to the layer below;
//! 3. inference (running statistics) is affine per norm, `BRN_k(x) = a_k x + c_k` with
//!    `a_k = scale_k / sqrt(ra_var_k + eps)`, `c_k = bias_k - a_k ra_mean_k`, so it folds into
//!    the next layer: `W'_k = W_k diag(a_k)`, `b'_k = b_k + W_k c_k` ([`BrnMlp::fold_into`], in
//!    f64): a plain [`Mlp`] of the same sizes (ReLU hidden) computes the network's inference.
//!
//! Parameters: one flat vector, the layers' (as [`Mlp`]'s: `layer{l}.weight`, `layer{l}.bias`)
//! then per norm its scale (started at 1) and bias (at 0) (`bn{k}.scale`, `bn{k}.bias`). The
//! running statistics live in [`BrnMlp::norms`]. After [`BrnMlp::reserve`] at the largest batch,
//! passes allocate nothing.

use std::ops::Range;

use super::ops::grow;
use super::{Activation, BatchRenorm, BatchRenormSettings, Linear, Mlp, RunningStats, Scalar, TensorInfo};
use crate::base::rng::Rng;

/// A batch-renormalised MLP (see the module's documentation).
#[derive(Clone, Debug)]
pub struct BrnMlp<T: Scalar> {
    sizes: Vec<usize>,
    layers: Vec<Linear>,
    /// Where the norms' scales and biases start in the flat vector.
    bn_offset: usize,
    /// The norms, one before each layer (their running statistics are learned state).
    pub norms: Vec<BatchRenorm<T>>,
    params: Vec<T>,
    grads: Vec<T>,
    /// Batch of the last training pass, and whether one ran.
    batch: usize,
    ready: bool,
    /// Per norm: its input `x_k` and its output `h_k` of the last training pass.
    x: Vec<Vec<T>>,
    h: Vec<Vec<T>>,
    out: Vec<T>,
    /// Gradient buffers (`batch x widest`).
    ga: Vec<T>,
    gb: Vec<T>,
}

impl<T: Scalar> BrnMlp<T> {
    /// A network of layer widths `sizes` (at least two, all positive), its layers drawn from
    /// `rng` as [`Mlp::new`] draws them (PyTorch's initialisation), its norms with `settings`.
    ///
    /// # Panics
    /// If `sizes` has fewer than two entries or a zero entry.
    pub fn new(sizes: &[usize], settings: BatchRenormSettings, rng: &mut Rng) -> Self {
        assert!(sizes.len() >= 2 && sizes.iter().all(|&s| s > 0), "BrnMlp: sizes");
        let mut layers = Vec::with_capacity(sizes.len() - 1);
        let mut offset = 0;
        for w in sizes.windows(2) {
            let layer = Linear::new(w[0], w[1], offset);
            offset += layer.param_len();
            layers.push(layer);
        }
        let bn_offset = offset;
        let widths = &sizes[..sizes.len() - 1];
        let mut params = vec![T::ZERO; offset + 2 * widths.iter().sum::<usize>()];
        for layer in &layers {
            layer.init(&mut params, rng);
        }
        let mut at = bn_offset;
        for &w in widths {
            params[at..at + w].fill(T::ONE);
            at += 2 * w;
        }
        BrnMlp {
            sizes: sizes.to_vec(),
            norms: widths.iter().map(|&w| BatchRenorm::new(w, settings)).collect(),
            bn_offset,
            grads: vec![T::ZERO; params.len()],
            params,
            batch: 0,
            ready: false,
            x: vec![Vec::new(); widths.len()],
            h: vec![Vec::new(); widths.len()],
            out: Vec::new(),
            ga: Vec::new(),
            gb: Vec::new(),
            layers,
        }
    }

    /// Grows the buffers for training passes of up to `batch` rows.
    pub fn reserve(&mut self, batch: usize) {
        let widest = self.sizes.iter().copied().max().unwrap_or(0);
        for (k, &w) in self.sizes[..self.sizes.len() - 1].iter().enumerate() {
            grow(&mut self.x[k], batch * w);
            grow(&mut self.h[k], batch * w);
        }
        let n_out = batch * self.out_features();
        grow(&mut self.out, n_out);
        grow(&mut self.ga, batch * widest);
        grow(&mut self.gb, batch * widest);
    }

    /// Layer widths, input first.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// Output features.
    pub fn out_features(&self) -> usize {
        self.sizes[self.sizes.len() - 1]
    }

    /// Number of parameters.
    pub fn num_params(&self) -> usize {
        self.params.len()
    }

    /// The flat parameter vector.
    pub fn params(&self) -> &[T] {
        &self.params
    }

    /// The flat parameter vector, mutable.
    pub fn params_mut(&mut self) -> &mut [T] {
        &mut self.params
    }

    /// The flat gradient vector.
    pub fn grads(&self) -> &[T] {
        &self.grads
    }

    /// The flat gradient vector, mutable.
    pub fn grads_mut(&mut self) -> &mut [T] {
        &mut self.grads
    }

    /// Parameters and gradients together, for an optimiser step.
    pub fn params_and_grads(&mut self) -> (&mut [T], &[T]) {
        (&mut self.params, &self.grads)
    }

    /// Sets every gradient to 0.
    pub fn zero_grad(&mut self) {
        self.grads.fill(T::ZERO);
    }

    /// Norm `k`'s scale and bias in the flat vector.
    fn bn_ranges(&self, k: usize) -> (Range<usize>, Range<usize>) {
        let start = self.bn_offset + 2 * self.sizes[..k].iter().sum::<usize>();
        let w = self.sizes[k];
        (start..start + w, start + w..start + 2 * w)
    }

    /// The named tensors in flat-vector order: the layers' as [`Mlp::tensors`], then
    /// `bn{k}.scale`, `bn{k}.bias`.
    pub fn tensors(&self) -> Vec<TensorInfo> {
        let mut out = Vec::with_capacity(4 * self.layers.len());
        for (i, l) in self.layers.iter().enumerate() {
            let (w, b) = (l.weight_range().start, l.bias_range().start);
            let shape = vec![l.out_features, l.in_features];
            out.push(TensorInfo { name: format!("layer{i}.weight"), shape, offset: w });
            out.push(TensorInfo { name: format!("layer{i}.bias"), shape: vec![l.out_features], offset: b });
        }
        for k in 0..self.norms.len() {
            let (s, b) = self.bn_ranges(k);
            let shape = vec![s.len()];
            out.push(TensorInfo { name: format!("bn{k}.scale"), shape: shape.clone(), offset: s.start });
            out.push(TensorInfo { name: format!("bn{k}.bias"), shape, offset: b.start });
        }
        out
    }

    /// The norms' running statistics, in order (for a checkpoint).
    pub fn running_stats(&self) -> Vec<RunningStats> {
        self.norms.iter().map(|n| n.stats.clone()).collect()
    }

    /// Restores what [`BrnMlp::running_stats`] returned; an error (naming what differs) if the
    /// number of norms, a feature count or a value does not fit (a variance must be >= 0).
    pub fn set_running_stats(&mut self, stats: &[RunningStats]) -> Result<(), String> {
        if stats.len() != self.norms.len() {
            return Err(format!(
                "{} batch-renorm layers, this network has {}",
                stats.len(),
                self.norms.len()
            ));
        }
        for (k, (n, s)) in self.norms.iter().zip(stats).enumerate() {
            if s.mean.len() != n.len() || s.var.len() != n.len() {
                return Err(format!(
                    "bn{k}: {} means and {} variances, this network's layer has {} features",
                    s.mean.len(),
                    s.var.len(),
                    n.len()
                ));
            }
            let bad =
                s.mean.iter().any(|m| !m.is_finite()) || s.var.iter().any(|v| !(v.is_finite() && *v >= 0.0));
            if bad {
                return Err(format!("bn{k}: a running mean or variance is not finite (or a variance < 0)"));
            }
        }
        for (n, s) in self.norms.iter_mut().zip(stats) {
            n.stats.mean.copy_from_slice(&s.mean);
            n.stats.var.copy_from_slice(&s.var);
            n.stats.steps = s.steps;
        }
        Ok(())
    }

    /// Step 1: a training pass on `x` (`batch x in`); returns the output (`batch x out`).
    ///
    /// # Panics
    /// If `x.len() != batch * in` or `batch == 0`.
    pub fn forward_train(&mut self, x: &[T], batch: usize) -> &[T] {
        assert!(batch > 0 && x.len() == batch * self.sizes[0], "BrnMlp::forward_train: input size");
        self.reserve(batch);
        self.x[0][..x.len()].copy_from_slice(x);
        let n_layers = self.layers.len();
        for k in 0..n_layers {
            let (w_in, w_out) = (self.sizes[k], self.sizes[k + 1]);
            let (scale, bias) = self.bn_ranges(k);
            let (s, b) = (&self.params[scale], &self.params[bias]);
            self.norms[k].forward_train(&self.x[k][..batch * w_in], batch, (s, b), &mut self.h[k]);
            let h = &self.h[k][..batch * w_in];
            if k + 1 < n_layers {
                let next = &mut self.x[k + 1][..batch * w_out];
                self.layers[k].forward_act(&self.params, h, batch, next, Activation::Relu);
            } else {
                self.layers[k].forward(&self.params, h, batch, &mut self.out[..batch * w_out]);
            }
        }
        self.batch = batch;
        self.ready = true;
        &self.out[..batch * self.out_features()]
    }

    /// Output of the last training pass (`batch x out`).
    pub fn output(&self) -> &[T] {
        &self.out[..self.batch * self.out_features()]
    }

    /// Step 2: back-propagates `grad_out` = dL/d(output) of the last training pass and adds
    /// dL/d(params) to the gradient vector.
    ///
    /// # Panics
    /// If no training pass preceded or `grad_out` has the wrong size.
    pub fn backward(&mut self, grad_out: &[T]) {
        assert!(self.ready, "BrnMlp backward without a training pass");
        let batch = self.batch;
        assert_eq!(grad_out.len(), batch * self.out_features(), "BrnMlp backward: grad_out size");
        self.ga[..grad_out.len()].copy_from_slice(grad_out);
        for k in (0..self.layers.len()).rev() {
            let (w_in, w_out) = (self.sizes[k], self.sizes[k + 1]);
            let layer = self.layers[k];
            let (scale, bias) = self.bn_ranges(k);
            let (g, dh) = (&self.ga[..batch * w_out], &mut self.gb[..batch * w_in]);
            layer.backward_params(&mut self.grads, &self.h[k][..batch * w_in], g, batch);
            layer.backward_input(&self.params, g, batch, dh);
            let (ds, db) = self.grads[scale.start..bias.end].split_at_mut(scale.len());
            let x = &self.x[k][..batch * w_in];
            let dx = &mut self.ga[..batch * w_in];
            self.norms[k].backward((x, &*dh), batch, &self.params[scale], dx, Some((ds, db)));
            if k > 0 {
                Activation::Relu.backward(x, dx);
            }
        }
    }

    /// Step 3: writes the inference network into `out`, a plain [`Mlp`] of the same sizes
    /// (its hidden activation ReLU): no allocation.
    ///
    /// # Panics
    /// If `out`'s sizes differ, or it has layer normalisation.
    pub fn fold_into(&self, out: &mut Mlp<T>) {
        assert_eq!(out.sizes(), &self.sizes[..], "BrnMlp::fold_into: sizes differ");
        assert_eq!(out.num_params(), self.layers.iter().map(Linear::param_len).sum::<usize>());
        let dst = out.params_mut();
        for (k, layer) in self.layers.iter().enumerate() {
            let (scale, bias) = self.bn_ranges(k);
            let n = &self.norms[k];
            let (n_in, w, b) = (layer.in_features, layer.weight_range(), layer.bias_range());
            for o in 0..layer.out_features {
                let mut acc = self.params[b.start + o].to_f64();
                for j in 0..n_in {
                    let a = self.params[scale.start + j].to_f64() / (n.stats.var[j] + n.settings.eps).sqrt();
                    let c = self.params[bias.start + j].to_f64() - a * n.stats.mean[j];
                    let wij = self.params[w.start + o * n_in + j].to_f64();
                    dst[w.start + o * n_in + j] = T::from_f64(wij * a);
                    acc += wij * c;
                }
                dst[b.start + o] = T::from_f64(acc);
            }
        }
    }
}
