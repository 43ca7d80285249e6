//! A safety shield (`[task.shield]`): before each joint-velocity command is applied, it is
//! changed as little as possible so that no checked pair (arm-obstacle, arm-floor, arm-arm)
//! comes closer than a margin within the step, and the motion that results is verified over the
//! whole step; when no such command exists, or the verification fails, the arm stops.
//!
//! For joint values `q`, a command `c` (rad/s; m/s for prismatic joints) and the period `dt`:
//! 1. bounds `lo_i = max(-vmax_i, (qlo_i - q_i) / dt)`, `hi_i = min(vmax_i, (qhi_i - q_i) / dt)`
//!    (speed and position limits), and the command the arm would carry out, `c' = clip(c, lo, hi)`;
//! 2. for each checked pair within `influence_m` (signed distance `d`, closest points `p_A`,
//!    `p_B`, direction `n`: [`super::collision::distance`]) the velocity damper
//!    `n^T (J_A(p_A) - J_B(p_B)) x dt >= -gain (d - m)`, with `m = margin_m`
//!    (`self_margin_m` for arm-arm pairs), `J(p)` the point Jacobian of `p` on its link
//!    (`z_i x (p - o_i)` for a revolute joint `i` that carries it, `z_i` for a prismatic one, 0
//!    for the others and for the floor and obstacles); with `gain = 1` the linearised distance
//!    after the step is at least `m`;
//! 3. if `c'` satisfies every damper it is kept as it is; otherwise `x = argmin |x - c'|^2`
//!    subject to the dampers and `lo <= x <= hi` ([`qp`], Goldfarb-Idnani); no such `x`: stop;
//! 4. verification of the motion `q(t) = q + t dq`, `t in [0, 1]`, `dq = clip(q + x dt) - q`
//!    (exactly what the arm does), by conservative advancement: joint `i` moves a point `p` of
//!    shape `k` at `|dq_i|` times its distance to the joint's axis (1 for a prismatic joint),
//!    and that distance, which only the joints after `i` change, stays below
//!    `rho_ki = min(lever_ki, a_ki + r_k + sum_{i < j} lever_kj |dq_j|)` over the step
//!    (`a_ki` the distance of the shape's bounding-sphere centre from the axis at `q`, `r_k`
//!    its radius, `lever_ki` the pose-free bound of [`ArmCollider::levers`]); so a point of
//!    shape `k` moves at most `D_k = sum_i rho_ki |dq_i|` over the step; a pair with the
//!    floor or an obstacle at most `D = D_A`, two arm shapes at most `D = sum_{l < i <= u}
//!    rho_Ui |dq_i|` relative to each other (joints up to the earlier shape's segment `l` move
//!    both rigidly; `U` is the shape of the later segment `u`), so a pair at distance `d(t)` stays above
//!    `d(t) - D s` until `t + s`. Each pair must stay above `h = min(m, d(0)) / 2` (`d(t) >= h`
//!    at every sample, the next sample at `t + (d(t) - h) / D`, done past `t = 1`); a pair
//!    farther than `h + D` at the start (bounding spheres first) is verified at once. The
//!    certificate holds between samples, so it is continuous, not sub-stepped. A pair already
//!    in contact at the start (a start pose the shield did not make) is not certified; its
//!    damper pushes it apart;
//! 5. verification failed, or more than [`MAX_SAMPLES`] samples: stop (`x = 0`). Stopping is
//!    safe when the current pose is: nothing moves;
//! 6. the record: a changed command is an intervention (a stop is one too), its size
//!    `|x - c'|` (rad/s); the mean and the largest over interventions.
//!
//! Deterministic (a fixed order of pairs and constraints). No allocation after
//! [`Shield::new`] (but for a scene with more obstacles than any before).
//!
//! Only the kinematic simulation can be shielded: the dynamic one does not carry out a command
//! exactly, so step 4's motion would not be the arm's.

pub mod qp;

use serde::{Deserialize, Serialize};

use super::collision::distance::{Closest, Pair};
use super::collision::ArmCollider;
use crate::robot::{Chain, JointKind};
use crate::{Error, Result};

/// Samples of step 4 before the shield gives up and stops the arm.
pub const MAX_SAMPLES: usize = 200;

/// `[task.shield]`: the safety shield (see the module docs). Off by default.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ShieldConfig {
    /// Filter every command (`--shield` on `plan`, `eval`, `train`).
    pub enabled: bool,
    /// The distance kept from obstacles and the floor, metres (default 0.02).
    pub margin_m: f64,
    /// The distance kept between the arm's own links, metres (default 0.002: the shapes of
    /// non-adjacent links of some arms come within a few millimetres at their home pose).
    pub self_margin_m: f64,
    /// Pairs closer than this get a constraint, metres (default 0.15).
    pub influence_m: f64,
    /// The share of the distance above the margin a pair may close in one step, (0, 1]
    /// (default 1).
    pub gain: f64,
}

impl Default for ShieldConfig {
    fn default() -> Self {
        ShieldConfig { enabled: false, margin_m: 0.02, self_margin_m: 0.002, influence_m: 0.15, gain: 1.0 }
    }
}

impl ShieldConfig {
    /// Check the values (errors name the field, the value and what is allowed).
    pub fn validate(&self) -> Result<()> {
        let f = |name: &str| format!("task.shield.{name}");
        if !(self.margin_m > 0.0 && self.margin_m <= 1.0) {
            return Err(Error::config(f("margin_m"), self.margin_m, "a distance in (0, 1] metres"));
        }
        if !(self.self_margin_m > 0.0 && self.self_margin_m <= 0.1) {
            return Err(Error::config(
                f("self_margin_m"),
                self.self_margin_m,
                "a distance in (0, 0.1] metres",
            ));
        }
        let floor = self.margin_m.max(self.self_margin_m);
        if !(self.influence_m.is_finite() && self.influence_m > floor && self.influence_m <= 10.0) {
            return Err(Error::config(
                f("influence_m"),
                self.influence_m,
                format!(
                    "a distance in metres greater than margin_m and self_margin_m ({floor}) and at most 10"
                ),
            ));
        }
        if !(self.gain > 0.0 && self.gain <= 1.0) {
            return Err(Error::config(f("gain"), self.gain, "a number in (0, 1]"));
        }
        Ok(())
    }
}

/// What the shield did, over a span of steps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ShieldStats {
    /// Commands filtered.
    pub steps: u64,
    /// Commands changed (stops included).
    pub interventions: u64,
    /// Commands replaced by zero velocity.
    pub stops: u64,
    /// Sum of `|x - c'|` over interventions, rad/s.
    pub change_sum_rad_per_s: f64,
    /// Largest `|x - c'|`, rad/s.
    pub max_change_rad_per_s: f64,
}

impl ShieldStats {
    /// The mean change of an intervention, rad/s (0 without one).
    pub fn mean_change_rad_per_s(&self) -> f64 {
        match self.interventions {
            0 => 0.0,
            k => self.change_sum_rad_per_s / k as f64,
        }
    }

    /// Add `other`'s steps to these.
    pub fn merge(&mut self, other: &ShieldStats) {
        self.steps += other.steps;
        self.interventions += other.interventions;
        self.stops += other.stops;
        self.change_sum_rad_per_s += other.change_sum_rad_per_s;
        self.max_change_rad_per_s = self.max_change_rad_per_s.max(other.max_change_rad_per_s);
    }

    fn record(&mut self, verdict: Verdict, change: f64) {
        self.steps += 1;
        if verdict != Verdict::Kept {
            self.interventions += 1;
            self.stops += u64::from(verdict == Verdict::Stopped);
            self.change_sum_rad_per_s += change;
            self.max_change_rad_per_s = self.max_change_rad_per_s.max(change);
        }
    }
}

/// [`ShieldStats`] as the output of `plan` and `eval` writes them (`shield_*` keys).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ShieldSummary {
    pub shield_steps: u64,
    pub shield_interventions: u64,
    pub shield_stops: u64,
    pub shield_mean_change_rad_per_s: f64,
    pub shield_max_change_rad_per_s: f64,
}

impl From<ShieldStats> for ShieldSummary {
    fn from(s: ShieldStats) -> Self {
        ShieldSummary {
            shield_steps: s.steps,
            shield_interventions: s.interventions,
            shield_stops: s.stops,
            shield_mean_change_rad_per_s: s.mean_change_rad_per_s(),
            shield_max_change_rad_per_s: s.max_change_rad_per_s,
        }
    }
}

/// What the shield did to one command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Left as it was.
    Kept,
    /// Changed to the nearest safe command.
    Changed,
    /// Replaced by zero velocity.
    Stopped,
}

/// A pair being verified (step 4): the pair, its threshold `h` and its motion bound `D`, m.
#[derive(Clone, Copy, Debug)]
struct Watched {
    pair: Pair,
    threshold_m: f64,
    motion_m: f64,
}

/// The shield of one arm, with its scratch.
#[derive(Clone, Debug)]
pub struct Shield {
    config: ShieldConfig,
    prismatic: Vec<bool>,
    /// `levers[k * dof + i]`: see [`ArmCollider::levers`].
    levers: Vec<f64>,
    pairs: Vec<Pair>,
    /// The signed distance of each of `pairs` at `q` where step 2 computed it (`None`: not
    /// computed; `Some(None)`: no answer), for step 4 at the same placement.
    known: Vec<Option<Option<f64>>>,
    /// The lower bound of each of `pairs` at `q` (step 2's, for step 4).
    bounds: Vec<f64>,
    /// The arm shapes of the pairs a sample of step 4 looks at.
    needed: Vec<bool>,
    near: Vec<(Pair, Closest)>,
    watched: Vec<Watched>,
    qp: qp::Qp,
    row: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    wanted: Vec<f64>,
    x: Vec<f64>,
    dq: Vec<f64>,
    q_t: Vec<f64>,
    /// `reach[k * dof + i] = rho_ki |dq_i|` of step 4.
    reach: Vec<f64>,
    motion: Vec<f64>,
    total: ShieldStats,
    episode: ShieldStats,
    /// The change of the last filtered command, rad/s (0: kept).
    last_change: f64,
}

impl Shield {
    /// The shield of `chain` checked by `collider` (whose obstacles may change later).
    pub fn new(chain: &Chain, collider: &mut ArmCollider, config: ShieldConfig) -> Shield {
        let n = chain.dof();
        let max_pairs = collider.max_pairs(16);
        Shield {
            config,
            prismatic: chain.joints().iter().map(|j| j.kind == JointKind::Prismatic).collect(),
            levers: collider.levers(chain),
            pairs: Vec::with_capacity(max_pairs),
            known: Vec::with_capacity(max_pairs),
            bounds: Vec::with_capacity(max_pairs),
            needed: vec![false; collider.len()],
            near: Vec::with_capacity(max_pairs),
            watched: Vec::with_capacity(max_pairs),
            qp: qp::Qp::new(n, max_pairs + 2 * n),
            row: vec![0.0; n],
            lo: vec![0.0; n],
            hi: vec![0.0; n],
            wanted: vec![0.0; n],
            x: vec![0.0; n],
            dq: vec![0.0; n],
            q_t: vec![0.0; n],
            reach: vec![0.0; collider.len() * n],
            motion: vec![0.0; collider.len()],
            total: ShieldStats::default(),
            episode: ShieldStats::default(),
            last_change: 0.0,
        }
    }

    pub fn config(&self) -> &ShieldConfig {
        &self.config
    }

    /// What it did since it was made.
    pub fn stats(&self) -> &ShieldStats {
        &self.total
    }

    /// What it did since [`Shield::begin_episode`].
    pub fn episode_stats(&self) -> &ShieldStats {
        &self.episode
    }

    /// How much the last [`Shield::filter`] changed its command, rad/s: `|x - c'|` of step 6
    /// (the Euclidean norm over the joints) when it intervened, else 0. The environment charges
    /// it with `reward.shield_penalty`.
    pub fn last_change_rad_per_s(&self) -> f64 {
        self.last_change
    }

    /// Continue an episode whose counts were `stats` (a resumed run's).
    pub fn resume_episode(&mut self, stats: ShieldStats) {
        self.episode = stats;
    }

    /// Start counting a new episode.
    pub fn begin_episode(&mut self) {
        self.episode = ShieldStats::default();
    }

    /// Forget everything counted.
    pub fn reset_stats(&mut self) {
        self.total = ShieldStats::default();
        self.episode = ShieldStats::default();
    }

    /// Filter `command` (rad/s, one per joint, within the speed limits) for a step of `dt_s`
    /// from joint values `q` (steps 1-6): on return it is the command to apply, unchanged when
    /// the verdict is [`Verdict::Kept`]. `collider` is left placed anywhere.
    pub fn filter(
        &mut self,
        chain: &Chain,
        collider: &mut ArmCollider,
        q: &[f64],
        command: &mut [f64],
        dt_s: f64,
    ) -> Verdict {
        let n = q.len();
        // Step 1.
        let (qlo, qhi, vmax) = (chain.lower_limits(), chain.upper_limits(), chain.velocity_limits());
        for i in 0..n {
            self.lo[i] = (-vmax[i]).max((qlo[i] - q[i]) / dt_s).min(0.0);
            self.hi[i] = vmax[i].min((qhi[i] - q[i]) / dt_s).max(0.0);
            self.wanted[i] = command[i].clamp(self.lo[i], self.hi[i]);
        }
        // Steps 2-3.
        collider.checked_pairs(&mut self.pairs);
        collider.place_at(chain, q);
        let mut verdict = match self.constrain(collider, dt_s) {
            true => Verdict::Kept,
            false => {
                self.qp.push_bounds(&self.lo, &self.hi);
                match self.qp.solve(&self.wanted, &mut self.x) {
                    Ok(()) => {
                        for i in 0..n {
                            self.x[i] = self.x[i].clamp(self.lo[i], self.hi[i]);
                        }
                        Verdict::Changed
                    }
                    Err(_) => Verdict::Stopped,
                }
            }
        };
        if verdict == Verdict::Kept {
            self.x.copy_from_slice(command);
        }
        // Steps 4-5.
        if verdict != Verdict::Stopped && !self.verify(chain, collider, q, dt_s) {
            verdict = Verdict::Stopped;
        }
        if verdict == Verdict::Stopped {
            self.x.fill(0.0);
        }
        // Step 6.
        let change = (0..n).map(|i| (self.x[i] - self.wanted[i]).powi(2)).sum::<f64>().sqrt();
        if verdict != Verdict::Kept && change == 0.0 {
            verdict = Verdict::Kept;
        }
        if verdict != Verdict::Kept {
            command.copy_from_slice(&self.x);
        }
        self.total.record(verdict, change);
        self.episode.record(verdict, change);
        self.last_change = if verdict == Verdict::Kept { 0.0 } else { change };
        verdict
    }

    /// Step 2 (the arm placed at `q`): the dampers of the pairs within reach into the QP;
    /// whether the wanted command satisfies them all.
    fn constrain(&mut self, collider: &ArmCollider, dt_s: f64) -> bool {
        let c = self.config;
        self.near.clear();
        self.known.clear();
        self.bounds.clear();
        for &p in &self.pairs {
            let mut known = None;
            let bound = collider.lower_bound(p);
            self.bounds.push(bound);
            if bound < c.influence_m {
                let cl = collider.closest(p);
                known = Some(cl.map(|cl| cl.distance_m));
                if let Some(cl) = cl.filter(|cl| cl.distance_m < c.influence_m) {
                    self.near.push((p, cl));
                }
            }
            self.known.push(known);
        }
        self.qp.clear();
        let mut satisfied = true;
        for k in 0..self.near.len() {
            let (p, cl) = self.near[k];
            self.jacobian_row(collider, p, &cl);
            if self.row.iter().map(|v| v * v).sum::<f64>() < 1e-18 {
                // No joint changes this distance (a shape of the root).
                continue;
            }
            let margin = self.margin(p);
            let rhs = -c.gain * (cl.distance_m - margin) / dt_s;
            self.qp.push(&self.row, rhs);
            let r = self.qp.rows() - 1;
            satisfied &= self.qp.slack(r, &self.wanted) >= 0.0;
        }
        satisfied
    }

    /// The margin of a pair: `self_margin_m` between arm shapes, `margin_m` otherwise.
    fn margin(&self, p: Pair) -> f64 {
        match p {
            Pair::SelfPair { .. } => self.config.self_margin_m,
            _ => self.config.margin_m,
        }
    }

    /// `self.row = n^T (J_A(p_A) - J_B(p_B))` at the placement.
    fn jacobian_row(&mut self, collider: &ArmCollider, p: Pair, cl: &Closest) {
        self.row.fill(0.0);
        self.add_point(collider, p.shape_a(), cl.point_a_m, cl.normal, 1.0);
        if let Some(b) = p.shape_b() {
            self.add_point(collider, b, cl.point_b_m, cl.normal, -1.0);
        }
    }

    fn add_point(&mut self, collider: &ArmCollider, k: usize, p: [f64; 3], n: [f64; 3], sign: f64) {
        let Some(seg) = collider.segment_of(k) else { return };
        for (i, f) in collider.placed_frames()[..=seg].iter().enumerate() {
            let z = [f[2], f[6], f[10]];
            let v = if self.prismatic[i] {
                z
            } else {
                let r = [p[0] - f[3], p[1] - f[7], p[2] - f[11]];
                [z[1] * r[2] - z[2] * r[1], z[2] * r[0] - z[0] * r[2], z[0] * r[1] - z[1] * r[0]]
            };
            self.row[i] += sign * (n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
        }
    }

    /// Steps 4-5 for the command `self.x` (the arm placed at `q`): whether the motion over the
    /// step keeps every pair above its threshold.
    fn verify(&mut self, chain: &Chain, collider: &mut ArmCollider, q: &[f64], dt_s: f64) -> bool {
        let n = q.len();
        let (qlo, qhi) = (chain.lower_limits(), chain.upper_limits());
        for i in 0..n {
            self.dq[i] = (q[i] + self.x[i] * dt_s).clamp(qlo[i], qhi[i]) - q[i];
        }
        self.reach_bounds(collider);
        for (k, m) in self.motion.iter_mut().enumerate() {
            *m = self.reach[k * n..(k + 1) * n].iter().sum();
        }
        self.watched.clear();
        for (j, &pair) in self.pairs.iter().enumerate() {
            let motion_m = match pair.shape_b() {
                None => self.motion[pair.shape_a()],
                Some(b) => self.relative_motion(collider, pair.shape_a(), b),
            };
            let margin = self.margin(pair);
            if self.bounds[j] - motion_m >= 0.5 * margin {
                continue;
            }
            // Step 2 saw the same placement.
            let known = self.known[j].unwrap_or_else(|| collider.distance(pair));
            let Some(d0) = known else { return false };
            if d0 <= 0.0 {
                continue;
            }
            let threshold_m = 0.5 * margin.min(d0);
            if d0 - motion_m < threshold_m {
                self.watched.push(Watched { pair, threshold_m, motion_m });
            }
        }
        self.advance(chain, collider, q)
    }

    /// The motion bound of arm shapes `a` and `b` relative to each other: their distance
    /// depends only on the joints between their segments (those before move both rigidly), so
    /// `D = sum_{l < i <= u} lever_ui |dq_i|` with `u` the shape of the later segment.
    fn relative_motion(&self, collider: &ArmCollider, a: usize, b: usize) -> f64 {
        let n = self.dq.len();
        let seg = |k: usize| collider.segment_of(k).map_or(-1, |s| s as i64);
        let (lower, upper) = if seg(a) < seg(b) { (a, b) } else { (b, a) };
        let (from, to) = ((seg(lower) + 1) as usize, seg(upper) as usize);
        self.reach[upper * n + from..=upper * n + to].iter().sum()
    }

    /// `self.reach` for `self.dq` (the arm placed at `q`): `rho_ki |dq_i|` of step 4.
    fn reach_bounds(&mut self, collider: &ArmCollider) {
        let n = self.dq.len();
        let frames = collider.placed_frames();
        for k in 0..self.motion.len() {
            let reach = &mut self.reach[k * n..(k + 1) * n];
            reach.fill(0.0);
            let Some(seg) = collider.segment_of(k) else { continue };
            let (c, r) = collider.bounding_sphere(k);
            let levers = &self.levers[k * n..(k + 1) * n];
            // sum_{i < j <= seg} lever_kj |dq_j|: how far the joints after i move the shape.
            let mut after = 0.0;
            for i in (0..=seg).rev() {
                let dq = self.dq[i].abs();
                if dq != 0.0 {
                    let rho = if self.prismatic[i] {
                        1.0
                    } else {
                        let f = &frames[i];
                        let (z, d) = ([f[2], f[6], f[10]], [c[0] - f[3], c[1] - f[7], c[2] - f[11]]);
                        let x =
                            [z[1] * d[2] - z[2] * d[1], z[2] * d[0] - z[0] * d[2], z[0] * d[1] - z[1] * d[0]];
                        levers[i].min((x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt() + r + after)
                    };
                    reach[i] = rho * dq;
                    after += levers[i] * dq;
                }
            }
        }
    }

    /// Step 4's samples over the watched pairs.
    fn advance(&mut self, chain: &Chain, collider: &mut ArmCollider, q: &[f64]) -> bool {
        let mut t = 0.0;
        for sample in 0..MAX_SAMPLES {
            if self.watched.is_empty() {
                return true;
            }
            if sample > 0 {
                for (i, v) in self.q_t.iter_mut().enumerate() {
                    *v = q[i] + t * self.dq[i];
                }
                // Only the shapes of the pairs still watched.
                self.needed.fill(false);
                for w in &self.watched {
                    self.needed[w.pair.shape_a()] = true;
                    if let Some(b) = w.pair.shape_b() {
                        self.needed[b] = true;
                    }
                }
                collider.place_some_at(chain, &self.q_t, &self.needed);
            }
            let mut step = f64::INFINITY;
            let mut k = 0;
            while k < self.watched.len() {
                let w = self.watched[k];
                let Some(d) = collider.distance(w.pair) else { return false };
                if d.is_nan() || d < w.threshold_m {
                    return false;
                }
                let reach = (d - w.threshold_m) / w.motion_m;
                if t + reach >= 1.0 {
                    self.watched.swap_remove(k);
                } else {
                    step = step.min(reach);
                    k += 1;
                }
            }
            t += step;
        }
        self.watched.is_empty()
    }
}

#[cfg(test)]
mod tests;
