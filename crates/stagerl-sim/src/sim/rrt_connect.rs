//! The reference planner: RRT-Connect (Kuffner and LaValle, ICRA 2000), the bidirectional
//! rapidly-exploring random tree that OMPL and MoveIt use by default, in joint space.
//!
//! 1. Goals: collision-free inverse-kinematics solutions for the target position. Damped least
//!    squares on the position rows of the Jacobian, from the start pose first, then from
//!    uniformly random configurations (seeded restarts), each solution within
//!    [`IK_TOLERANCE_M`] of the target, inside the sampling box and clear of every contact the
//!    task checks; up to [`RrtConnect::goals`] of them root the goal tree.
//! 2. The sampling box: each joint's limits, narrowed to `start +- pi` (a revolute joint of
//!    range +-2 pi needs no more; the search stays in one turn of each joint).
//! 3. Search: from the start tree and the goal tree alternately, extend one tree by at most
//!    [`RrtConnect::step_rad`] (Euclidean, joint space) towards a uniform random sample, then
//!    connect the other tree greedily towards the new node; every new edge is checked
//!    continuously ([`ArmCollider::check_motion`]). A direct start-goal edge is tried first.
//! 4. Shortcutting: random pairs of waypoints are joined by a straight edge when it is free,
//!    dropping the waypoints between ([`RrtConnect::shortcuts`] attempts).
//! 5. Time: each straight segment is split into control steps so that no joint exceeds its
//!    speed limit (`ceil(max_i |dq_i| / (v_i dt))` steps), and the rollout tracks the waypoints
//!    one per step; the output is a plan like any other planner's.
//!
//! The search's checker sees every obstacle grown by [`MARGIN_M`] (half the motion check's
//! resolution): a contact between two checked poses of an edge reaches at most that deep, so a
//! path free of the grown obstacles is free of the real ones. Where the start pose is closer
//! to an obstacle than twice the margin, the margin is half that distance (the plan's
//! continuous report still judges the path against the real obstacles).
//!
//! Seeded and deterministic: one plan draws from `Rng::new(seed)`, whatever came before, so a
//! seed gives the same path unless the wall-time budget ends the search first. An unsolved
//! search (no collision-free goal, or the budget spent) returns no path and the reason.

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use std::time::Instant;

use crate::base::rng::Rng;
use crate::robot::Chain;
use crate::sim::collision::ArmCollider;
use crate::sim::scene::Obstacle;

/// How close an inverse-kinematics goal's tip is to the target, metres.
pub const IK_TOLERANCE_M: f64 = 1e-4;

/// How much the search grows every obstacle, metres (see the module's doc).
pub const MARGIN_M: f64 = crate::sim::collision::motion::MOTION_RESOLUTION_M / 2.0;

/// Iterations of one inverse-kinematics attempt.
const IK_ITERATIONS: usize = 200;

/// Statistics of one search (the `"rrt_connect"` object of a plan's output).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RrtStats {
    /// A path was found.
    pub solved: bool,
    /// Extensions of the search (one per random sample).
    pub iterations: u32,
    /// Nodes of both trees at the end (the start and the goals included).
    pub tree_nodes: u32,
    /// Shortcuts taken (waypoints dropped by a free straight edge).
    pub shortcuts: u32,
    /// Inverse-kinematics attempts, and the collision-free goals they gave.
    pub ik_attempts: u32,
    pub goals: u32,
    /// Waypoints of the path after shortcutting (0 unsolved).
    pub waypoints: u32,
    /// The seed of the search.
    pub seed: u64,
}

/// The planner's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RrtConnect {
    pub seed: u64,
    /// Wall-time budget of one search (goals, trees and shortcuts), seconds.
    pub budget_s: f64,
    /// Most extensions of one search.
    pub max_iterations: u32,
    /// Longest tree edge, radians (Euclidean in joint space).
    pub step_rad: f64,
    /// Most inverse-kinematics attempts, and most goals kept.
    pub ik_attempts: u32,
    pub goals: u32,
    /// Shortcut attempts.
    pub shortcuts: u32,
    /// How much [`RrtConnect::plan_timed`] grows the obstacles, metres (at least [`MARGIN_M`],
    /// the default).
    pub margin_m: f64,
}

/// Default `--planner-budget-s`.
pub const DEFAULT_BUDGET_S: f64 = 1.0;
/// Default `--planner-iterations`.
pub const DEFAULT_ITERATIONS: u32 = 10_000;

impl Default for RrtConnect {
    fn default() -> Self {
        RrtConnect {
            seed: 0,
            budget_s: DEFAULT_BUDGET_S,
            max_iterations: DEFAULT_ITERATIONS,
            step_rad: 0.5,
            ik_attempts: 1000,
            goals: 3,
            shortcuts: 300,
            margin_m: MARGIN_M,
        }
    }
}

/// A tree: nodes stored flat (`dof` values each) with their parents (the roots' are
/// `u32::MAX`).
struct Tree {
    dof: usize,
    q: Vec<f64>,
    parent: Vec<u32>,
}

impl Tree {
    fn new(dof: usize) -> Tree {
        Tree { dof, q: Vec::new(), parent: Vec::new() }
    }
    fn len(&self) -> usize {
        self.parent.len()
    }
    fn node(&self, i: usize) -> &[f64] {
        &self.q[i * self.dof..(i + 1) * self.dof]
    }
    fn push(&mut self, q: &[f64], parent: u32) -> usize {
        self.q.extend_from_slice(q);
        self.parent.push(parent);
        self.len() - 1
    }
    fn nearest(&self, q: &[f64]) -> usize {
        let mut best = (f64::INFINITY, 0);
        for i in 0..self.len() {
            let d = dist2(self.node(i), q);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }
    /// Node `i` and its ancestors up to a root, `i` first.
    fn branch(&self, mut i: usize) -> Vec<Vec<f64>> {
        let mut out = vec![self.node(i).to_vec()];
        while self.parent[i] != u32::MAX {
            i = self.parent[i] as usize;
            out.push(self.node(i).to_vec());
        }
        out
    }
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Whether an extension reached its sample, advanced towards it, or was blocked.
#[derive(PartialEq)]
enum Extend {
    Reached(usize),
    Advanced(usize),
    Trapped,
}

/// One search's state: the arm, its checker, the random stream, the clock.
struct Search<'a> {
    cfg: &'a RrtConnect,
    chain: &'a Chain,
    collider: &'a mut ArmCollider,
    rng: Rng,
    lo: Vec<f64>,
    hi: Vec<f64>,
    clock: Instant,
    stats: RrtStats,
}

impl Search<'_> {
    fn out_of_time(&self) -> bool {
        self.clock.elapsed().as_secs_f64() > self.cfg.budget_s
    }

    fn sample(&mut self) -> Vec<f64> {
        let rng = &mut self.rng;
        self.lo.iter().zip(&self.hi).map(|(&l, &h)| rng.uniform_range(l, h)).collect()
    }

    /// Damped-least-squares IK for `target` from `q` (in place); whether it converged.
    fn ik(&self, q: &mut [f64], target: &Vector3<f64>, jac: &mut [f64]) -> bool {
        let n = q.len();
        for _ in 0..IK_ITERATIONS {
            let pose = self.chain.jacobian(q, jac);
            let e = target - pose.position;
            if e.norm() < IK_TOLERANCE_M {
                return true;
            }
            let jp = |r: usize, c: usize| jac[r * n + c];
            let mut jjt = Matrix3::<f64>::identity() * 1e-4;
            for r in 0..3 {
                for s in 0..3 {
                    jjt[(r, s)] += (0..n).map(|c| jp(r, c) * jp(s, c)).sum::<f64>();
                }
            }
            let Some(y) = jjt.try_inverse().map(|m| m * e) else { return false };
            let dq: Vec<f64> = (0..n).map(|c| (0..3).map(|r| jp(r, c) * y[r]).sum()).collect();
            let norm = dq.iter().map(|v| v * v).sum::<f64>().sqrt();
            let scale = if norm > 0.5 { 0.5 / norm } else { 1.0 };
            for (i, v) in q.iter_mut().enumerate() {
                *v = (*v + scale * dq[i]).clamp(self.lo[i], self.hi[i]);
            }
        }
        false
    }

    /// Collision-free IK solutions for `target`: from `start`, then from random configurations.
    fn goals(&mut self, start: &[f64], target: &Vector3<f64>) -> Vec<Vec<f64>> {
        let mut jac = vec![0.0; 6 * start.len()];
        let mut goals: Vec<Vec<f64>> = Vec::new();
        while self.stats.ik_attempts < self.cfg.ik_attempts && goals.len() < self.cfg.goals as usize {
            if self.out_of_time() {
                break;
            }
            let mut q = if self.stats.ik_attempts == 0 { start.to_vec() } else { self.sample() };
            self.stats.ik_attempts += 1;
            let distinct = |q: &[f64]| goals.iter().all(|g| dist2(g, q) > 1e-4);
            if self.ik(&mut q, target, &mut jac)
                && distinct(&q)
                && self.collider.check(self.chain, &q).is_none()
            {
                goals.push(q);
            }
        }
        goals
    }

    /// Extend `tree` from its node nearest to `to` by at most one step towards it.
    fn extend(&mut self, tree: &mut Tree, to: &[f64]) -> Extend {
        let near = tree.nearest(to);
        let from = tree.node(near).to_vec();
        let d = dist2(&from, to).sqrt();
        let (q, reached) = if d <= self.cfg.step_rad {
            (to.to_vec(), true)
        } else {
            let t = self.cfg.step_rad / d;
            (from.iter().zip(to).map(|(a, b)| a + t * (b - a)).collect(), false)
        };
        if self.collider.check_motion(self.chain, &from, &q).is_some() {
            return Extend::Trapped;
        }
        let i = tree.push(&q, near as u32);
        if reached {
            Extend::Reached(i)
        } else {
            Extend::Advanced(i)
        }
    }

    /// Extend `tree` towards `to` until it gets there or is blocked.
    fn connect(&mut self, tree: &mut Tree, to: &[f64]) -> Extend {
        loop {
            match self.extend(tree, to) {
                Extend::Advanced(_) if !self.out_of_time() => continue,
                Extend::Advanced(_) => return Extend::Trapped,
                other => return other,
            }
        }
    }

    /// Drop waypoints that a free straight edge makes unnecessary.
    fn shortcut(&mut self, path: &mut Vec<Vec<f64>>) {
        for _ in 0..self.cfg.shortcuts {
            if path.len() <= 2 || self.out_of_time() {
                break;
            }
            let n = path.len() as u64;
            let (a, b) = (self.rng.below(n) as usize, self.rng.below(n) as usize);
            let (i, j) = (a.min(b), a.max(b));
            if j < i + 2 {
                continue;
            }
            if self.collider.check_motion(self.chain, &path[i], &path[j]).is_none() {
                path.drain(i + 1..j);
                self.stats.shortcuts += 1;
            }
        }
    }

    /// The bidirectional search from `start` to the goals: the joined path, or why not.
    fn search(&mut self, start: &[f64], goals: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, String> {
        let n = start.len();
        for g in goals {
            if self.collider.check_motion(self.chain, start, g).is_none() {
                self.stats.tree_nodes = 1 + goals.len() as u32;
                return Ok(vec![start.to_vec(), g.clone()]);
            }
        }
        let (mut a, mut b) = (Tree::new(n), Tree::new(n));
        a.push(start, u32::MAX);
        for g in goals {
            b.push(g, u32::MAX);
        }
        // `a` holds the start tree when `a_is_start`.
        let mut a_is_start = true;
        let result = loop {
            if self.stats.iterations >= self.cfg.max_iterations {
                break Err(format!("the iteration budget ({}) was spent", self.cfg.max_iterations));
            }
            if self.out_of_time() {
                break Err(format!("the time budget ({} s) was spent", self.cfg.budget_s));
            }
            self.stats.iterations += 1;
            let sample = self.sample();
            let new = match self.extend(&mut a, &sample) {
                Extend::Trapped => None,
                Extend::Reached(i) | Extend::Advanced(i) => Some(i),
            };
            if let Some(i) = new {
                let q = a.node(i).to_vec();
                if let Extend::Reached(j) = self.connect(&mut b, &q) {
                    let (from_a, from_b) = (a.branch(i), b.branch(j));
                    let (mut s, g) = if a_is_start { (from_a, from_b) } else { (from_b, from_a) };
                    s.reverse();
                    s.extend(g.into_iter().skip(1));
                    break Ok(s);
                }
            }
            std::mem::swap(&mut a, &mut b);
            a_is_start = !a_is_start;
        };
        self.stats.tree_nodes = (a.len() + b.len()) as u32;
        result
    }
}

impl RrtConnect {
    /// Search a collision-free path (waypoints in joint space, `start` first) from `start` to a
    /// configuration whose tip is at `target` (metres), among the obstacles and checks of
    /// `collider`. The statistics, and the path or the reason there is none.
    pub fn solve(
        &self,
        chain: &Chain,
        collider: &mut ArmCollider,
        start: &[f64],
        target: &Vector3<f64>,
    ) -> (RrtStats, Result<Vec<Vec<f64>>, String>) {
        let (lo, hi): (Vec<f64>, Vec<f64>) = chain
            .lower_limits()
            .iter()
            .zip(chain.upper_limits())
            .zip(start)
            .map(|((&l, &h), &s)| (l.max(s - std::f64::consts::PI), h.min(s + std::f64::consts::PI)))
            .unzip();
        let mut s = Search {
            cfg: self,
            chain,
            collider,
            rng: Rng::new(self.seed),
            lo,
            hi,
            clock: Instant::now(),
            stats: RrtStats { seed: self.seed, ..RrtStats::default() },
        };
        let goals = s.goals(start, target);
        s.stats.goals = goals.len() as u32;
        if goals.is_empty() {
            let why = format!(
                "no collision-free inverse-kinematics solution for the target in {} attempt(s) \
                 (the arm cannot reach it without a contact, or the time budget ended first)",
                s.stats.ik_attempts
            );
            return (s.stats, Err(why));
        }
        let result = s.search(start, &goals).map(|mut path| {
            s.shortcut(&mut path);
            path
        });
        s.stats.solved = result.is_ok();
        s.stats.waypoints = result.as_ref().map_or(0, |p| p.len() as u32);
        (s.stats, result)
    }
}

impl RrtConnect {
    /// The timed path from `start` to `target` among `obstacles`, one row of joint positions per
    /// control step of `dt_s` seconds (the first the start), within the joints' speed limits: the
    /// search ([`RrtConnect::solve`]) among the obstacles grown by [`RrtConnect::margin_m`] (at least
    /// [`MARGIN_M`]; half the distance from the start pose to the nearest obstacle where that is
    /// less than twice the margin), then [`time_parameterise`]. The collider's obstacles are left
    /// grown.
    pub fn plan_timed(
        &self,
        chain: &Chain,
        collider: &mut ArmCollider,
        obstacles: &[Obstacle],
        start: &[f64],
        target: &Vector3<f64>,
        dt_s: f64,
    ) -> (RrtStats, Result<Vec<Vec<f64>>, String>) {
        collider.set_obstacles(obstacles);
        let near = collider.motion_clearance_m(chain, start, start).unwrap_or(f64::INFINITY);
        let margin = self.margin_m.max(MARGIN_M).min(0.5 * near.max(0.0));
        let grown: Vec<Obstacle> = obstacles.iter().map(|o| o.grown(margin)).collect();
        collider.set_obstacles(&grown);
        let (stats, path) = self.solve(chain, collider, start, target);
        (stats, path.map(|p| time_parameterise(&p, chain.velocity_limits(), dt_s)))
    }
}

/// The waypoints of `path` at every control step of period `dt_s`: each straight segment in
/// `ceil(max_i |dq_i| / (v_i dt))` equal steps (at least 1), so no joint exceeds its speed
/// limit `v_i`; the first row is `path[0]`.
pub fn time_parameterise(path: &[Vec<f64>], vmax: &[f64], dt_s: f64) -> Vec<Vec<f64>> {
    let mut out = vec![path[0].clone()];
    for w in path.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let need =
            a.iter().zip(b).zip(vmax).map(|((x, y), v)| (y - x).abs() / (v * dt_s)).fold(0.0, f64::max);
        let steps = ((need - 1e-9).ceil() as usize).max(1);
        for k in 1..=steps {
            let t = k as f64 / steps as f64;
            out.push(a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_parameterisation_respects_the_speed_limits() {
        let path = vec![vec![0.0, 0.0], vec![1.0, -0.1], vec![1.0, 0.5]];
        let rows = time_parameterise(&path, &[2.0, 1.0], 0.05);
        // 1 rad at 0.1 rad per step: 10 steps; 0.6 rad at 0.05: 12 steps.
        assert_eq!(rows.len(), 1 + 10 + 12);
        assert_eq!(rows[10], path[1]);
        assert_eq!(rows.last(), path.last());
        for w in rows.windows(2) {
            assert!((w[1][0] - w[0][0]).abs() <= 0.1 + 1e-12 && (w[1][1] - w[0][1]).abs() <= 0.05 + 1e-12);
        }
    }
}
