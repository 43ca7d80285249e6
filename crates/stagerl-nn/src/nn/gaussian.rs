//! The tanh-squashed diagonal Gaussian policy head of SAC.
//!
//! The actor's raw output per sample is `[mean (act) | s (act)]`; `s` is mapped to the log
//! standard deviation `l` by a [`LogStdBound`]. With caller-supplied standard-normal noise
//! `eps`, the reparameterised sample and its log-density are
//! ```text
//! std = exp(l),  u = mean + std * eps,  a = tanh(u)
//! log p(a) = sum_j [ log N(u_j; mean_j, std_j) - log(1 - tanh(u_j)^2) ]
//! log N(u; mean, std) = -eps^2 / 2 - l - ln(2 pi) / 2
//! log(1 - tanh(u)^2)  = 2 (ln 2 - u - softplus(-2u))      (exact and stable for any u)
//! ```
//! SB3 and CleanRL use `log(1 - a^2 + 1e-6)` instead; the stable form has no epsilon and stays
//! finite when tanh(u) rounds to +-1. It is evaluated as `2 (ln 2 - |u| - ln(1 + e^-2|u|))`
//! (log(1 - tanh(u)^2) is even in u), where the logarithm's argument lies in (1, 2].
//!
//! Backward (eps held fixed), with `ga = dL/da`, `gp = dL/dlogp` of the sample's row:
//! ```text
//! dL/du    = ga (1 - a^2) + 2 a gp        (d/du of -log(1 - tanh(u)^2) is 2 tanh(u))
//! dL/dmean = dL/du
//! dL/dl    = dL/du * std * eps - gp
//! dL/ds    = dL/dl * dl/ds
//! ```

use serde::{Deserialize, Serialize};

use super::ops::{copy_row, grow};
use super::Scalar;
use stagerl_base::multiversion;

/// How the raw network output `s` becomes the log standard deviation `l`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LogStdBound {
    /// `l = clamp(s, min, max)` (SB3's SAC with min -20, max 2). The gradient is 1 for
    /// `min <= s <= max` and 0 outside, as `torch.clamp`'s.
    Clamp {
        /// Lower bound of the log standard deviation.
        min: f64,
        /// Upper bound of the log standard deviation.
        max: f64,
    },
    /// `l = min + (max - min) (tanh(s) + 1) / 2` (CleanRL's SAC with min -5, max 2); smooth, so
    /// the gradient never vanishes abruptly: `dl/ds = (max - min) (1 - tanh(s)^2) / 2`.
    Tanh {
        /// Lower bound of the log standard deviation.
        min: f64,
        /// Upper bound of the log standard deviation.
        max: f64,
    },
}

impl Default for LogStdBound {
    /// `Clamp { min: -20, max: 2 }`, as SB3.
    fn default() -> Self {
        LogStdBound::Clamp { min: -20.0, max: 2.0 }
    }
}

impl LogStdBound {
    /// `(l, dl/ds)` for raw value `s`.
    #[inline]
    pub fn apply<T: Scalar>(self, s: T) -> (T, T) {
        match self {
            LogStdBound::Clamp { min, max } => {
                let (lo, hi) = (T::from_f64(min), T::from_f64(max));
                if s < lo {
                    (lo, T::ZERO)
                } else if s > hi {
                    (hi, T::ZERO)
                } else {
                    (s, T::ONE)
                }
            }
            LogStdBound::Tanh { min, max } => {
                let half_range = T::from_f64(0.5 * (max - min));
                let t = s.tanh();
                (T::from_f64(min) + half_range * (t + T::ONE), half_range * (T::ONE - t * t))
            }
        }
    }
}

/// The squashed Gaussian head for `act_dim` actions, with its reusable (grow-only) buffers.
///
/// [`SquashedGaussian::forward`] samples and caches; [`SquashedGaussian::backward`] then maps
/// dL/da and dL/dlogp to dL/d(raw) for the actor's backward pass.
#[derive(Clone, Debug)]
pub struct SquashedGaussian<T> {
    act_dim: usize,
    bound: LogStdBound,
    batch: usize,
    ready: bool,
    /// std = exp(l), `batch x act`.
    std: Vec<T>,
    /// dl/ds, `batch x act`.
    dlog_std: Vec<T>,
    /// The noise of the last forward pass, `batch x act`.
    eps: Vec<T>,
    /// a = tanh(u), `batch x act`.
    action: Vec<T>,
    /// log p(a), `batch`.
    log_prob: Vec<T>,
    /// dL/d(raw), `batch x 2 act`.
    grad_raw: Vec<T>,
    /// Scratch of the forward pass, `batch x act` each: the means, the raw log-std values and
    /// each element's term of log p(a).
    mean: Vec<T>,
    s: Vec<T>,
    term: Vec<T>,
}

impl<T: Scalar> SquashedGaussian<T> {
    /// A head for `act_dim` actions (raw input width `2 * act_dim`).
    pub fn new(act_dim: usize, bound: LogStdBound) -> Self {
        SquashedGaussian {
            act_dim,
            bound,
            batch: 0,
            ready: false,
            std: Vec::new(),
            dlog_std: Vec::new(),
            eps: Vec::new(),
            action: Vec::new(),
            log_prob: Vec::new(),
            grad_raw: Vec::new(),
            mean: Vec::new(),
            s: Vec::new(),
            term: Vec::new(),
        }
    }

    /// Action dimension.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// The log-std mapping.
    pub fn bound(&self) -> LogStdBound {
        self.bound
    }

    /// Samples `a = tanh(mean + exp(l) eps)` from `raw` (`batch x 2 act`, rows `[mean | s]`) and
    /// noise `eps` (`batch x act`, standard normal); returns `(a, log p(a))` with shapes
    /// `batch x act` and `batch`, and caches them for [`SquashedGaussian::backward`].
    ///
    /// # Panics
    /// If a slice has the wrong length.
    pub fn forward(&mut self, raw: &[T], eps: &[T], batch: usize) -> (&[T], &[T]) {
        let act = self.act_dim;
        assert_eq!(raw.len(), batch * 2 * act, "SquashedGaussian: raw size");
        assert_eq!(eps.len(), batch * act, "SquashedGaussian: eps size");
        let n = batch * act;
        for buf in [&mut self.std, &mut self.dlog_std, &mut self.eps, &mut self.action] {
            grow(buf, n);
        }
        grow(&mut self.log_prob, batch);
        self.eps[..n].copy_from_slice(eps);
        // Rows [mean | s] split into two contiguous arrays, so that the element-wise pass below
        // runs over the whole batch at once (and vectorises).
        for buf in [&mut self.mean, &mut self.s, &mut self.term] {
            grow(buf, n);
        }
        for (r, row) in raw.chunks_exact(2 * act).enumerate() {
            copy_row(&mut self.mean[r * act..(r + 1) * act], &row[..act]);
            copy_row(&mut self.s[r * act..(r + 1) * act], &row[act..]);
        }
        let out = Sample {
            std: &mut self.std[..n],
            dlog_std: &mut self.dlog_std[..n],
            action: &mut self.action[..n],
            term: &mut self.term[..n],
        };
        sample_kernel(self.bound, &self.mean[..n], &self.s[..n], &eps[..n], out);
        // log p(a) of each row: its terms summed in order.
        for (lp, terms) in self.log_prob[..batch].iter_mut().zip(self.term[..n].chunks_exact(act)) {
            *lp = T::ZERO;
            for &t in terms {
                *lp += t;
            }
        }
        self.batch = batch;
        self.ready = true;
        (&self.action[..n], &self.log_prob[..batch])
    }

    /// Actions of the last forward pass (`batch x act`).
    pub fn action(&self) -> &[T] {
        &self.action[..self.batch * self.act_dim]
    }

    /// Log-probabilities of the last forward pass (`batch`).
    pub fn log_prob(&self) -> &[T] {
        &self.log_prob[..self.batch]
    }

    /// dL/d(raw) (`batch x 2 act`, rows `[dL/dmean | dL/ds]`) from `d_action = dL/da`
    /// (`batch x act`) and `d_log_prob = dL/dlogp` (`batch`), for the last forward pass.
    ///
    /// # Panics
    /// If no forward pass preceded or a slice has the wrong length.
    pub fn backward(&mut self, d_action: &[T], d_log_prob: &[T]) -> &[T] {
        assert!(self.ready, "SquashedGaussian::backward without a forward pass");
        let (act, batch) = (self.act_dim, self.batch);
        assert_eq!(d_action.len(), batch * act, "SquashedGaussian: d_action size");
        assert_eq!(d_log_prob.len(), batch, "SquashedGaussian: d_log_prob size");
        grow(&mut self.grad_raw, batch * 2 * act);
        let two = T::from_f64(2.0);
        let rows = self.grad_raw[..batch * 2 * act].chunks_exact_mut(2 * act).zip(d_log_prob);
        for (r, (g_row, &gp)) in rows.enumerate() {
            let (g_mean, g_s) = g_row.split_at_mut(act);
            for (j, i) in (r * act..(r + 1) * act).enumerate() {
                let a = self.action[i];
                let g_u = d_action[i] * (T::ONE - a * a) + two * a * gp;
                g_mean[j] = g_u;
                g_s[j] = (g_u * self.std[i] * self.eps[i] - gp) * self.dlog_std[i];
            }
        }
        &self.grad_raw[..batch * 2 * act]
    }

    /// The deterministic (evaluation) action `tanh(mean)` from `raw` (`batch x 2 act`) into
    /// `out` (`batch x act`).
    ///
    /// # Panics
    /// If a slice has the wrong length.
    pub fn deterministic(&self, raw: &[T], batch: usize, out: &mut [T]) {
        let act = self.act_dim;
        assert_eq!(raw.len(), batch * 2 * act, "SquashedGaussian: raw size");
        assert_eq!(out.len(), batch * act, "SquashedGaussian: out size");
        if act == 0 {
            return;
        }
        for (row, o) in raw.chunks_exact(2 * act).zip(out.chunks_exact_mut(act)) {
            o.iter_mut().zip(&row[..act]).for_each(|(o, &m)| *o = m.tanh());
        }
    }
}

/// The per-element outputs of [`sample_kernel`] (`batch x act` each).
pub(crate) struct Sample<'a, T> {
    pub std: &'a mut [T],
    pub dlog_std: &'a mut [T],
    pub action: &'a mut [T],
    /// The element's term of log p(a): `-eps^2 / 2 - l - ln(2 pi) / 2 - log(1 - tanh(u)^2)`.
    pub term: &'a mut [T],
}

multiversion! {
    /// The element-wise part of [`SquashedGaussian::forward`] (see the module docs).
    fn sample_kernel / sample_kernel_at<T: Scalar>(bound: LogStdBound, mean: &[T], s: &[T], eps: &[T], out: Sample<'_, T>) {
        let half_ln_2pi = T::from_f64(0.5 * (2.0 * std::f64::consts::PI).ln());
        let ln2 = T::from_f64(std::f64::consts::LN_2);
        let two = T::from_f64(2.0);
        let half = T::from_f64(0.5);
        let Sample { std, dlog_std, action, term } = out;
        let outs = std.iter_mut().zip(dlog_std.iter_mut()).zip(action.iter_mut()).zip(term.iter_mut());
        for (((&m, &s), &e), (((std, dl), a), t)) in mean.iter().zip(s).zip(eps).zip(outs) {
            let (l, dl_ds) = bound.apply(s);
            let sd = l.exp();
            let u = m + sd * e;
            let abs_u = u.abs();
            let softplus = ((-two * abs_u).exp() + T::ONE).ln(); // softplus(-2|u|)
            let log_one_minus_tanh2 = two * (ln2 - abs_u - softplus);
            *t = -half * e * e - l - half_ln_2pi - log_one_minus_tanh2;
            *std = sd;
            *dl = dl_ds;
            *a = u.tanh();
        }
    }
}
