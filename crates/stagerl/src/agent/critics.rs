//! An ensemble of `n` critics `Q_i: [obs | act] -> 1` (DDPG: 1, TD3 and SAC: 2, an ensemble
//! such as REDQ's: N) with their Polyak-averaged targets `Q_i'`, their Adam optimisers and their
//! buffers, and what the off-policy algorithms do with them:
//! 1. the target value `min_i Q_i'(s', a')` ([`Critics::target_min`], or
//!    [`TargetSide::min`] while the critics' forward pass runs, [`Critics::forward_alongside`]),
//!    over every target or over a random subset of them ([`Critics::choose_targets`], REDQ's);
//! 2. each critic minimises `mean (Q_i(s, a) - y)^2`, one Adam step ([`Critics::fit`],
//!    [`Critics::fit_forwarded`]);
//! 3. the actor's side: SAC's `min_i Q_i(s, a~)`, its gradient dQ/da through the critic of the
//!    smallest value of each row ([`Critics::forward_min`], [`Critics::input_grad_min`]); REDQ's
//!    `(1/N) sum_i Q_i(s, a~)` ([`Critics::forward_mean`], [`Critics::input_grad_mean`]); TD3's
//!    and DDPG's `Q_1(s, mu(s))` ([`Critics::forward_first`], [`Critics::input_grad_first`]);
//! 4. targets `theta_i' <- (1 - tau) theta_i' + tau theta_i` ([`Critics::polyak`]).
//!
//! The critics run at once, one task per critic on this thread's pool ([`crate::base::par`]):
//! each task writes its own critic and its own buffers only, and every value is computed by the
//! same operations in the same order as one after the other, so the results do not depend on
//! the number of threads.

use std::ops::Range;

use super::step;
use crate::base::par;
use crate::base::rng::Rng;
use crate::nn::{Activation, Adam, HiddenNorm, Mlp};

/// Checkpoint names of the critics of an ensemble, `[critic, its target, its optimiser]` each:
/// `q1` .. `q20` (an ensemble of `n` takes the first `n`).
pub const ENSEMBLE: &[[&str; 3]] = &[
    ["q1", "q1_target", "q1_opt"],
    ["q2", "q2_target", "q2_opt"],
    ["q3", "q3_target", "q3_opt"],
    ["q4", "q4_target", "q4_opt"],
    ["q5", "q5_target", "q5_opt"],
    ["q6", "q6_target", "q6_opt"],
    ["q7", "q7_target", "q7_opt"],
    ["q8", "q8_target", "q8_opt"],
    ["q9", "q9_target", "q9_opt"],
    ["q10", "q10_target", "q10_opt"],
    ["q11", "q11_target", "q11_opt"],
    ["q12", "q12_target", "q12_opt"],
    ["q13", "q13_target", "q13_opt"],
    ["q14", "q14_target", "q14_opt"],
    ["q15", "q15_target", "q15_opt"],
    ["q16", "q16_target", "q16_opt"],
    ["q17", "q17_target", "q17_opt"],
    ["q18", "q18_target", "q18_opt"],
    ["q19", "q19_target", "q19_opt"],
    ["q20", "q20_target", "q20_opt"],
];

/// Checkpoint names of the dropout streams of an ensemble's critics and of their targets
/// (`[critic's, target's]`), saved only when the critics drop out (DroQ's).
pub const DROPOUT_RNG: &[[&str; 2]] = &[
    ["q1_dropout_rng", "q1_target_dropout_rng"],
    ["q2_dropout_rng", "q2_target_dropout_rng"],
    ["q3_dropout_rng", "q3_target_dropout_rng"],
    ["q4_dropout_rng", "q4_target_dropout_rng"],
    ["q5_dropout_rng", "q5_target_dropout_rng"],
    ["q6_dropout_rng", "q6_target_dropout_rng"],
    ["q7_dropout_rng", "q7_target_dropout_rng"],
    ["q8_dropout_rng", "q8_target_dropout_rng"],
    ["q9_dropout_rng", "q9_target_dropout_rng"],
    ["q10_dropout_rng", "q10_target_dropout_rng"],
    ["q11_dropout_rng", "q11_target_dropout_rng"],
    ["q12_dropout_rng", "q12_target_dropout_rng"],
    ["q13_dropout_rng", "q13_target_dropout_rng"],
    ["q14_dropout_rng", "q14_target_dropout_rng"],
    ["q15_dropout_rng", "q15_target_dropout_rng"],
    ["q16_dropout_rng", "q16_target_dropout_rng"],
    ["q17_dropout_rng", "q17_target_dropout_rng"],
    ["q18_dropout_rng", "q18_target_dropout_rng"],
    ["q19_dropout_rng", "q19_target_dropout_rng"],
    ["q20_dropout_rng", "q20_target_dropout_rng"],
];

/// Checkpoint names of twin critics (TD3, SAC): `[critic, its target, its optimiser]` each.
pub const TWIN: &[[&str; 3]] = &[ENSEMBLE[0], ENSEMBLE[1]];

/// The critics, their targets, optimisers and buffers. The networks, targets and optimisers are
/// listed in the owning agent's learned parts (under [`Critics::names`]).
pub struct Critics {
    /// Checkpoint names per critic: `[critic, its target, its optimiser]`.
    names: &'static [[&'static str; 3]],
    /// The critics, their targets and their optimisers, `n` each (seen by the agents' lists of
    /// learned parts, `learned_parts!`, which iterate them).
    pub(super) nets: Vec<Mlp<f32>>,
    pub(super) targets: Vec<Mlp<f32>>,
    pub(super) opts: Vec<Adam<f32>>,
    /// Per critic: its target's values on the batch.
    target_q: Vec<Vec<f32>>,
    /// Per critic: its target's dropout stream (used only when the critics drop out).
    pub(super) target_drop: Vec<Rng>,
    /// The critics' dropout and layer normalisation (DroQ's), if any.
    norm: Option<HiddenNorm>,
    /// Per critic: whether its target takes part in the next target minimum (all, but for the
    /// one after [`Critics::choose_targets`]), and the draw's scratch.
    chosen: Vec<bool>,
    order: Vec<usize>,
    pub(super) scratch: Vec<Scratch>,
    /// The losses of the last fit, per critic.
    losses: Vec<f64>,
    /// Per row of the last [`Critics::forward_min`]: the critic of the smallest value, and it.
    argmin: Vec<u32>,
    min: Vec<f32>,
}

/// One critic's buffers for an update, and its dropout stream.
pub(super) struct Scratch {
    /// The dropout masks' random stream (used only when the critics drop out).
    pub(super) drop: Rng,
    /// dL/dQ_i per row (the fit's, then the actor side's).
    dq: Vec<f32>,
    /// dQ_i/da (actor side, `batch x act`).
    da: Vec<f32>,
    /// Its last loss.
    loss: f64,
}

impl Critics {
    /// One critic per entry of `names` (their checkpoint names, at least one), drawn from `init`
    /// in order, each an MLP of layer sizes `sizes` (ReLU, identity output) with an identical
    /// target and an Adam optimiser of learning rate `lr`; buffers for batches of `batch` rows
    /// and actions of `act_dim` values.
    pub fn new(
        names: &'static [[&'static str; 3]],
        sizes: &[usize],
        lr: f64,
        init: &mut Rng,
        batch: usize,
        act_dim: usize,
    ) -> Critics {
        Self::with_norm(names, sizes, lr, init, (batch, act_dim), None)
    }

    /// [`Critics::new`] with dropout and layer normalisation after the critics' hidden layers
    /// (DroQ's; [`HiddenNorm`]); with dropout, each critic and each target gets its own stream,
    /// seeded from `init` after the networks are drawn.
    pub fn with_norm(
        names: &'static [[&'static str; 3]],
        sizes: &[usize],
        lr: f64,
        init: &mut Rng,
        (batch, act_dim): (usize, usize),
        norm: Option<HiddenNorm>,
    ) -> Critics {
        let mut nets: Vec<Mlp<f32>> = names
            .iter()
            .map(|_| Mlp::with_norm(sizes, Activation::Relu, Activation::Identity, norm, init))
            .collect();
        // Buffers for the batch now: a target of an ensemble may be drawn for the first time
        // long after the first update, and must not allocate then.
        for q in &mut nets {
            q.reserve(batch);
        }
        let n = nets.len();
        let dropout = norm.is_some_and(|h| h.dropout > 0.0);
        let mut stream = || if dropout { Rng::new(init.next_u64()) } else { Rng::new(0) };
        let drops: Vec<Rng> = (0..n).map(|_| stream()).collect();
        let target_drop: Vec<Rng> = (0..n).map(|_| stream()).collect();
        let mut drops = drops.into_iter();
        Critics {
            target_drop,
            norm,
            names,
            opts: nets.iter().map(|q| Adam::new(q.num_params(), lr)).collect(),
            targets: nets.clone(),
            nets,
            target_q: vec![vec![0.0; batch]; n],
            chosen: vec![true; n],
            order: (0..n).collect(),
            scratch: (0..n)
                .map(|_| Scratch {
                    drop: drops.next().expect("one stream per critic"),
                    dq: vec![0.0; batch],
                    da: vec![0.0; batch * act_dim],
                    loss: 0.0,
                })
                .collect(),
            losses: vec![0.0; n],
            argmin: vec![0; batch],
            min: vec![0.0; batch],
        }
    }

    /// The number of critics.
    pub fn len(&self) -> usize {
        self.nets.len()
    }

    /// Checkpoint names per critic: `[critic, its target, its optimiser]`.
    pub fn names(&self) -> &'static [[&'static str; 3]] {
        self.names
    }

    /// Step 1: `out[r] = min_i Q_i'(input[r])` for the `b` rows of `input`, over the targets
    /// chosen by [`Critics::choose_targets`] if it was called since the last minimum, else over
    /// all of them.
    pub fn target_min(&mut self, input: &[f32], b: usize, out: &mut [f32]) {
        self.target_side().min(input, b, out)
    }

    fn target_side(&mut self) -> TargetSide<'_> {
        let Critics { targets, target_q, chosen, target_drop, .. } = self;
        TargetSide { targets, q: target_q, chosen, drop: target_drop }
    }

    /// Whether the critics drop out (their dropout streams are then part of the agent's state).
    pub fn drops_out(&self) -> bool {
        self.norm.is_some_and(|h| h.dropout > 0.0)
    }

    /// REDQ's in-target minimisation: the next target minimum is over `m` (1..=N) of the
    /// targets, drawn without replacement from `rng` (a partial Fisher-Yates shuffle of
    /// `0..N`: `m` draws of `below`). The unchosen targets are not evaluated. No allocation.
    pub fn choose_targets(&mut self, m: usize, rng: &mut Rng) {
        let n = self.len();
        assert!((1..=n).contains(&m), "choose_targets: {m} of {n} critics");
        for (i, o) in self.order.iter_mut().enumerate() {
            *o = i;
        }
        for i in 0..m {
            let j = i + rng.below((n - i) as u64) as usize;
            self.order.swap(i, j);
        }
        self.chosen.fill(false);
        for &k in &self.order[..m] {
            self.chosen[k] = true;
        }
    }

    /// The critics' forward pass on `input` (`b` rows, for [`Critics::fit_forwarded`]) at once
    /// with `f`, which gets the target side (on two threads with a pool; the same values).
    pub fn forward_alongside(&mut self, input: &[f32], b: usize, f: impl FnOnce(TargetSide<'_>) + Send) {
        let Critics { nets, targets, target_q, chosen, target_drop, .. } = self;
        let side = TargetSide { targets, q: target_q, chosen, drop: target_drop };
        par::join(
            move || f(side),
            || {
                for q in nets.iter_mut() {
                    q.forward(input, b);
                }
            },
        );
    }

    /// Step 2: one regression step of every critic towards `y` from its forward pass on `input`
    /// (`y.len()` rows). Returns the losses.
    pub fn fit(&mut self, input: &[f32], y: &[f32], max_grad_norm: f64) -> &[f64] {
        par::for_each_mut3(&mut self.nets, &mut self.opts, &mut self.scratch, &|_, q, opt, s| {
            q.forward_dropout(input, y.len(), &mut s.drop);
            s.loss = fit_forwarded(q, opt, y, &mut s.dq, max_grad_norm)
        });
        self.collect_losses()
    }

    /// [`Critics::fit`] after the forward pass of [`Critics::forward_alongside`]. `alongside`
    /// runs at once with the fit of a lone critic (DDPG: the actor's forward pass), else after
    /// the critics' fits. Returns the losses.
    pub fn fit_forwarded(
        &mut self,
        y: &[f32],
        max_grad_norm: f64,
        alongside: impl FnOnce() + Send,
    ) -> &[f64] {
        let Critics { nets, opts, scratch, .. } = self;
        if let ([q], [opt], [s]) = (&mut nets[..], &mut opts[..], &mut scratch[..]) {
            par::join(|| s.loss = fit_forwarded(q, opt, y, &mut s.dq, max_grad_norm), alongside);
        } else {
            par::for_each_mut3(nets, opts, scratch, &|_, q, opt, s| {
                s.loss = fit_forwarded(q, opt, y, &mut s.dq, max_grad_norm)
            });
            alongside();
        }
        self.collect_losses()
    }

    fn collect_losses(&mut self) -> &[f64] {
        for (l, s) in self.losses.iter_mut().zip(&self.scratch) {
            *l = s.loss;
        }
        &self.losses
    }

    /// Step 3 (SAC): `min_i Q_i(input[r])` for the `b` rows of `input`, each critic's forward
    /// pass kept for [`Critics::input_grad_min`]. Of equal values the first critic's is taken.
    pub fn forward_min(&mut self, input: &[f32], b: usize) -> &[f32] {
        par::for_each_mut(&mut self.nets, &mut self.scratch, &|_, q, s| {
            q.forward_dropout(input, b, &mut s.drop);
        });
        let (argmin, min) = (&mut self.argmin[..b], &mut self.min[..b]);
        let first = self.nets[0].output();
        argmin.fill(0);
        min.copy_from_slice(&first[..b]);
        for (k, q) in self.nets.iter().enumerate().skip(1) {
            for ((best, m), &v) in argmin.iter_mut().zip(min.iter_mut()).zip(q.output()) {
                // Kept while `m <= v` (not replaced when `v < m`): with two critics, Q_1 unless
                // `Q_1 <= Q_2` fails, as SAC's `min(Q1, Q2)` (NaN included).
                let keep = *m <= v;
                if !keep {
                    (*best, *m) = (k as u32, v);
                }
            }
        }
        &self.min[..b]
    }

    /// Step 3 (SAC): dQ/d(input columns `cols`) of the last [`Critics::forward_min`], the loss's
    /// gradient being `grad` on each row's smallest value: the sum over the critics of each
    /// one's input gradient, `grad` on its rows and 0 elsewhere (`b x cols.len()`).
    pub fn input_grad_min(&mut self, grad: f32, cols: Range<usize>) -> &[f32] {
        let b = self.nets[0].batch();
        let m = b * cols.len();
        let argmin = &self.argmin[..b];
        par::for_each_mut(&mut self.nets, &mut self.scratch, &|k, q, s| {
            for (g, &best) in s.dq[..b].iter_mut().zip(argmin) {
                *g = if best as usize == k { grad } else { 0.0 };
            }
            s.da[..m].copy_from_slice(q.input_grad_cols(&s.dq[..b], cols.clone()));
        });
        let (first, rest) = self.scratch.split_at_mut(1);
        let da = &mut first[0].da[..m];
        for s in rest {
            for (x, y) in da.iter_mut().zip(&s.da[..m]) {
                *x += y;
            }
        }
        da
    }

    /// Step 3 (REDQ): `(1/N) sum_i Q_i(input[r])` for the `b` rows of `input` (summed in the
    /// critics' order, then scaled), each critic's forward pass kept for
    /// [`Critics::input_grad_mean`].
    pub fn forward_mean(&mut self, input: &[f32], b: usize) -> &[f32] {
        par::for_each_mut(&mut self.nets, &mut self.scratch, &|_, q, s| {
            q.forward_dropout(input, b, &mut s.drop);
        });
        let mean = &mut self.min[..b];
        mean.copy_from_slice(&self.nets[0].output()[..b]);
        for q in &self.nets[1..] {
            for (m, &v) in mean.iter_mut().zip(q.output()) {
                *m += v;
            }
        }
        let inv_n = 1.0 / self.nets.len() as f32;
        for m in mean.iter_mut() {
            *m *= inv_n;
        }
        &self.min[..b]
    }

    /// Step 3 (REDQ): dQ/d(input columns `cols`) of the last [`Critics::forward_mean`], the
    /// loss's gradient being `grad` on each row's mean: the sum over the critics of each one's
    /// input gradient for `grad / N` on every row (`b x cols.len()`).
    pub fn input_grad_mean(&mut self, grad: f32, cols: Range<usize>) -> &[f32] {
        let b = self.nets[0].batch();
        let m = b * cols.len();
        let share = grad / self.nets.len() as f32;
        par::for_each_mut(&mut self.nets, &mut self.scratch, &|_, q, s| {
            s.dq[..b].fill(share);
            s.da[..m].copy_from_slice(q.input_grad_cols(&s.dq[..b], cols.clone()));
        });
        let (first, rest) = self.scratch.split_at_mut(1);
        let da = &mut first[0].da[..m];
        for s in rest {
            for (x, y) in da.iter_mut().zip(&s.da[..m]) {
                *x += y;
            }
        }
        da
    }

    /// Step 3 (TD3, DDPG): `Q_1(input[r])` for the `b` rows of `input`, its forward pass kept
    /// for [`Critics::input_grad_first`].
    pub fn forward_first(&mut self, input: &[f32], b: usize) -> &[f32] {
        self.nets[0].forward(input, b)
    }

    /// Step 3 (TD3, DDPG): dQ_1/d(input columns `cols`) of the last
    /// [`Critics::forward_first`], the loss's gradient being `grad` on each row.
    pub fn input_grad_first(&mut self, grad: f32, cols: Range<usize>) -> &[f32] {
        let b = self.nets[0].batch();
        let dq = &mut self.scratch[0].dq[..b];
        dq.fill(grad);
        self.nets[0].input_grad_cols(dq, cols)
    }

    /// Step 4: every target `theta_i' <- (1 - tau) theta_i' + tau theta_i`.
    pub fn polyak(&mut self, tau: f32) {
        par::for_each_mut(&mut self.targets, &mut self.nets, &|_, t, q| t.polyak_from(q, tau));
    }
}

/// The target critics and their buffers alone, lent to a task that runs at once with the
/// critics' forward pass ([`Critics::forward_alongside`]).
pub struct TargetSide<'a> {
    targets: &'a mut [Mlp<f32>],
    q: &'a mut [Vec<f32>],
    chosen: &'a mut [bool],
    drop: &'a mut [Rng],
}

impl TargetSide<'_> {
    /// `out[r] = min_i Q_i'(input[r])` for the `b` rows of `input`, over the chosen targets
    /// (in their order; then every target is chosen again).
    pub fn min(&mut self, input: &[f32], b: usize, out: &mut [f32]) {
        let chosen = &*self.chosen;
        par::for_each_mut3(self.targets, self.q, self.drop, &|k, t, q, drop| {
            // DroQ: the targets drop out too (a training pass, from their own streams).
            let dropout = t.hidden_norm().is_some_and(|h| h.dropout > 0.0);
            match (chosen[k], dropout) {
                (false, _) => {}
                (true, true) => q[..b].copy_from_slice(t.forward_dropout(input, b, drop)),
                (true, false) => q[..b].copy_from_slice(t.predict(input, b)),
            }
        });
        let out = &mut out[..b];
        let mut first = true;
        for (q, _) in self.q.iter().zip(chosen).filter(|(_, &c)| c) {
            if first {
                out.copy_from_slice(&q[..b]);
                first = false;
            } else {
                for (y, &q) in out.iter_mut().zip(&q[..b]) {
                    *y = y.min(q);
                }
            }
        }
        self.chosen.fill(true);
    }
}

/// The mean of the losses of [`Critics::fit`], summed in order.
pub fn mean(losses: &[f64]) -> f64 {
    let mut sum = 0.0;
    for l in losses {
        sum += l;
    }
    sum / losses.len() as f64
}

/// One regression step of a critic from its last forward pass towards the targets `y`: mean
/// squared error, backward, Adam. `dq` is scratch of at least `y.len()` values. Returns the loss.
fn fit_forwarded(
    q: &mut Mlp<f32>,
    opt: &mut Adam<f32>,
    y: &[f32],
    dq: &mut [f32],
    max_grad_norm: f64,
) -> f64 {
    let b = y.len();
    let loss = crate::nn::mse_loss(q.output(), y, &mut dq[..b]);
    q.zero_grad();
    q.backward(&dq[..b]);
    step(q, opt, max_grad_norm);
    f64::from(loss)
}

#[cfg(test)]
mod tests;
