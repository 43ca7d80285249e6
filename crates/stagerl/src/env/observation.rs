//! The observation vector's layout, written here and nowhere else: its entries in order, with
//! their names, offsets, sizes, what they hold and bounds every episode's values stay within.
//!
//! The environment writes its observations by it, hindsight relabelling rewrites the target
//! entries by it ([`ObservationLayout::write_target_entries`]), the portable policy description and the ONNX
//! metadata serialise its entries ([`ObservationLayout::entries`]), the Python binding reads its
//! bounds ([`ObservationLayout::bounds`]) and the memory estimate its size
//! ([`ObservationLayout::dim`]).
//!
//! The standard observation of an arm with `n` joints (`k = task.obs_delta_scale`):
//! 1. `q_over_pi` (`n`): the joint positions (radians) divided by pi;
//! 2. `ee_pos` (3): the end-effector position, metres, base frame;
//! 3. `target` (3): the target, metres, base frame;
//! 4. `scaled_delta` (3): `k (target - ee_pos)`;
//! 5. `scaled_distance` (1): `k |target - ee_pos|`;
//! 6. with `task.observe_obstacles`, `obstacle_<i>` for each obstacle slot `i`, in the encoding
//!    of `task.obstacle_observation` ([`ObstacleObservation`]): 7 values per obstacle slot
//!    (`"absolute"`, `"nearest"`), or 4 per collision shape of the arm (`"per_link"`, each
//!    value in [-1, 1]).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::ops::Range;

use super::task::{ObservationKind, ObstacleObservation, ResolvedTask, OBSTACLE_OBS_LEN, PER_LINK_OBS_LEN};
use crate::robot::Chain;

/// One block of the observation, as the portable policy description writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsEntry {
    /// `q_over_pi`, `ee_pos`, `target`, `scaled_delta`, `scaled_distance` or `obstacle_<i>`.
    pub name: String,
    /// Index of its first value.
    pub start: usize,
    pub size: usize,
    /// What it holds, in words.
    pub value: String,
}

/// Where each entry of the observation is, for an arm's joint count and a number of observed
/// obstacle slots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObservationLayout {
    kind: ObservationKind,
    dof: usize,
    obstacle_slots: usize,
    /// Values per obstacle slot.
    slot_len: usize,
}

impl ObservationLayout {
    /// The layout of `kind` for `dof` joints and `obstacle_slots` observed obstacles of
    /// [`OBSTACLE_OBS_LEN`] values each (the `"absolute"` and `"nearest"` encodings).
    pub const fn new(kind: ObservationKind, dof: usize, obstacle_slots: usize) -> ObservationLayout {
        ObservationLayout { kind, dof, obstacle_slots, slot_len: OBSTACLE_OBS_LEN }
    }

    /// The layout of `kind` for `dof` joints with `encoding`'s slots: `slots` of them
    /// (obstacles, or the arm's collision shapes for `"per_link"`).
    pub const fn with_encoding(
        kind: ObservationKind,
        dof: usize,
        encoding: ObstacleObservation,
        slots: usize,
    ) -> ObservationLayout {
        let slot_len = match encoding {
            ObstacleObservation::PerLink => PER_LINK_OBS_LEN,
            _ => OBSTACLE_OBS_LEN,
        };
        ObservationLayout { kind, dof, obstacle_slots: slots, slot_len }
    }

    /// The layout of a resolved task.
    pub fn of(task: &ResolvedTask) -> ObservationLayout {
        ObservationLayout::with_encoding(
            task.observation,
            task.home_pose.len(),
            task.obstacle_observation,
            task.obstacle_slots(),
        )
    }

    /// `q / pi`, one per joint.
    #[inline]
    pub fn q_over_pi(&self) -> Range<usize> {
        match self.kind {
            ObservationKind::Standard => 0..self.dof,
        }
    }

    /// The end-effector position (3).
    #[inline]
    pub fn ee_pos(&self) -> Range<usize> {
        let s = self.q_over_pi().end;
        s..s + 3
    }

    /// The target (3).
    #[inline]
    pub fn target(&self) -> Range<usize> {
        let s = self.ee_pos().end;
        s..s + 3
    }

    /// `k (target - ee)` (3).
    #[inline]
    pub fn scaled_delta(&self) -> Range<usize> {
        let s = self.target().end;
        s..s + 3
    }

    /// `k |target - ee|` (1).
    #[inline]
    pub fn scaled_distance(&self) -> usize {
        self.scaled_delta().end
    }

    /// Every obstacle slot's values, [`ObservationLayout::slot_len`] per slot (empty without
    /// observed obstacles).
    #[inline]
    pub fn obstacles(&self) -> Range<usize> {
        let s = self.scaled_distance() + 1;
        s..s + self.slot_len * self.obstacle_slots
    }

    /// Values per obstacle slot: [`OBSTACLE_OBS_LEN`], or [`PER_LINK_OBS_LEN`] for the
    /// per-link encoding.
    pub fn slot_len(&self) -> usize {
        self.slot_len
    }

    /// Observed obstacle slots.
    pub fn obstacle_slots(&self) -> usize {
        self.obstacle_slots
    }

    /// Write the entries that depend on the target (metres, base frame) for an end effector at
    /// `ee` (metres): the target, `k (target - ee)` and its norm, with `k = task.obs_delta_scale`.
    /// The environment writes its own observations with it, and hindsight relabelling
    /// ([`crate::train::her`]) those of a substituted goal, so both are the same bits.
    #[inline]
    pub fn write_target_entries(&self, obs: &mut [f32], k: f64, ee: Vector3<f64>, target: Vector3<f64>) {
        let d = (target - ee) * k;
        let (t, s) = (self.target().start, self.scaled_delta().start);
        for i in 0..3 {
            obs[t + i] = target[i] as f32;
            obs[s + i] = d[i] as f32;
        }
        obs[self.scaled_distance()] = d.norm() as f32;
    }

    /// Number of values.
    #[inline]
    pub fn dim(&self) -> usize {
        self.obstacles().end
    }

    /// The entries in order, with what each holds in words for `task` on `chain` (whose layout
    /// this is).
    pub fn entries(&self, task: &ResolvedTask, chain: &Chain) -> Vec<ObsEntry> {
        let k = task.obs_delta_scale;
        let entry = |name: &str, r: Range<usize>, value: String| ObsEntry {
            name: name.into(),
            start: r.start,
            size: r.len(),
            value,
        };
        let d = self.scaled_distance();
        let mut out = vec![
            entry("q_over_pi", self.q_over_pi(), "joint positions (radians) divided by pi".into()),
            entry("ee_pos", self.ee_pos(), "end-effector position x, y, z, metres, base frame".into()),
            entry("target", self.target(), "target position x, y, z, metres, base frame".into()),
            entry("scaled_delta", self.scaled_delta(), format!("{k} * (target - ee_pos), per axis")),
            entry("scaled_distance", d..d + 1, format!("{k} * |target - ee_pos| (Euclidean norm)")),
        ];
        let (start, len) = (self.obstacles().start, self.slot_len);
        for i in 0..self.obstacle_slots {
            let r = start + i * len..start + (i + 1) * len;
            out.push(entry(&format!("obstacle_{i}"), r, slot_words(task, chain, i)));
        }
        out
    }

    /// Bounds `(low, high)` per value that hold for every observation an episode of `task` on
    /// `chain` can produce (f32, as the observation is): joints within their limits and within
    /// `max_steps` full-speed steps of the home pose (continuous joints have no limits),
    /// positions within the arm's reach, deltas within twice it, obstacle slots within
    /// [`ResolvedTask::obstacle_obs_bounds`] (per-link slots: [-1, 1]); widened a little so that
    /// rounding to f32 never puts a value outside.
    pub fn bounds(&self, task: &ResolvedTask, chain: &Chain) -> (Vec<f32>, Vec<f32>) {
        let (mut lo, mut hi) = (vec![0.0f32; self.dim()], vec![0.0f32; self.dim()]);
        let travel = f64::from(task.max_steps) * task.dt_s;
        for (j, i) in self.q_over_pi().enumerate() {
            let (home, v) = (task.home_pose[j], chain.velocity_limits()[j]);
            lo[i] = (chain.lower_limits()[j].max(home - travel * v) / PI) as f32;
            hi[i] = (chain.upper_limits()[j].min(home + travel * v) / PI) as f32;
        }
        let reach = chain.reach_bound_m() * 1.001 + 1e-6;
        let delta = 2.0 * reach * task.obs_delta_scale;
        let mut set = |r: Range<usize>, l: f64, h: f64| {
            for i in r {
                (lo[i], hi[i]) = (l as f32, h as f32);
            }
        };
        set(self.ee_pos().start..self.target().end, -reach, reach);
        set(self.scaled_delta(), -delta, delta);
        set(self.scaled_distance()..self.scaled_distance() + 1, 0.0, delta);
        if task.obstacle_observation == ObstacleObservation::PerLink {
            // Each value is in [-1, 1] by construction, and so is its f32.
            set(self.obstacles(), -1.0, 1.0);
            return (lo, hi);
        }
        let slot = task.obstacle_obs_bounds(chain.reach_bound_m());
        for (i, v) in self.obstacles().enumerate() {
            let (l, h) = slot[i % OBSTACLE_OBS_LEN];
            lo[v] = (l - 1e-6 - l.abs() * 1e-6) as f32;
            hi[v] = (h + 1e-6 + h.abs() * 1e-6) as f32;
        }
        (lo, hi)
    }
}

/// What obstacle slot `i` of `task`'s observation holds, in words.
fn slot_words(task: &ResolvedTask, chain: &Chain, i: usize) -> String {
    let k = task.obs_delta_scale;
    match task.obstacle_observation {
        ObstacleObservation::Absolute => format!(
            "obstacle {i} of the episode (the fixed ones first, then the random ones; all zeros when \
             there is none): centre x, y, z (metres, base frame), half size along its axes x, y, z \
             (metres; a sphere's radius three times), then 1 for a sphere, 0 for a box"
        ),
        ObstacleObservation::Nearest => {
            let range = task
                .obstacle_range_m
                .map_or_else(String::new, |r| format!(" among those whose surface is within {r} m of it"));
            format!(
                "the obstacle {} nearest to the end effector by surface distance{range} (ties by \
                 obstacle order: fixed ones first, then random ones): {k} * (centre - ee_pos) x, y, \
                 z, {k} * half size along its axes x, y, z (metres; a sphere's radius three times), \
                 then {k} * the end effector's distance to its surface (metres, negative inside); \
                 without such an obstacle, zeros and the distance {}",
                ordinal(i + 1),
                empty_slot_distance(task, chain)
            )
        }
        ObstacleObservation::PerLink => {
            let r = task.per_link_range_m();
            let link = chain.collision_shapes().get(i).map_or("?", |s| s.link.as_str());
            format!(
                "collision shape {i} of the arm (on link `{link}`) and its nearest obstacle, with d \
                 its signed distance (metres, negative inside) and R = {r} m: when d < R, the unit \
                 direction x, y, z from the shape's closest point to the obstacle's times \
                 1 - max(d, 0) / R, then max(d, -R) / R; otherwise 0, 0, 0, 1 (every value in [-1, 1])"
            )
        }
    }
}

/// The distance entry of an empty "nearest" slot: the largest a slot can hold, so that it reads
/// as far away (f32, as written).
pub fn empty_slot_distance(task: &ResolvedTask, chain: &Chain) -> f32 {
    task.obstacle_obs_bounds(chain.reach_bound_m())[OBSTACLE_OBS_LEN - 1].1 as f32
}

fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}
