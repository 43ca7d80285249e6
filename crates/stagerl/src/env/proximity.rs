//! What an environment senses of the obstacles around the whole arm, not only its end
//! effector: each collision shape's nearest obstacle, measured with the signed distances of
//! [`crate::sim::collision::distance`] (the safety shield's), for the per-link observation
//! ([`ObstacleObservation::PerLink`]) and the clearance term of the reward (`[reward.clearance]`,
//! eqs. 19-21 of [`crate::reward`]).
//!
//! After every reset and step, when either is on:
//! 1. the arm is placed at its joint positions and, for each collision shape `k`, its nearest
//!    obstacle found among those nearer than the cutoff `max(R, m)` (R the per-link radius, m
//!    the clearance margin, each when on): `(d_k, n_k)`, the signed distance (m, negative
//!    inside) and the unit direction from the obstacle to the shape;
//! 2. the arm's clearance `d = min_k d_k` (`f64::INFINITY` when no obstacle is within the
//!    cutoff) goes to the reward ([`super::Step::outcome`]);
//! 3. per-link slot `k` (4 values): `-n_k (1 - max(d_k, 0) / R)` and `max(d_k, -R) / R` when
//!    `d_k < R`, else `0, 0, 0, 1`: every value in [-1, 1].

use std::ops::Range;

use super::task::PER_LINK_OBS_LEN;
use super::{ObstacleObservation, ReachEnv, ResolvedTask};
use crate::reward::RewardConfig;

/// The distance below which the environment measures each shape's nearest obstacle (step 1),
/// metres; `None` when neither the per-link observation nor the clearance term is on.
pub(super) fn proximity_cutoff(task: &ResolvedTask, reward: &RewardConfig) -> Option<f64> {
    let per_link = task.observe_obstacles && task.obstacle_observation == ObstacleObservation::PerLink;
    let radius = per_link.then(|| task.per_link_range_m());
    let margin = reward.clearance.map(|c| c.margin_m);
    match (radius, margin) {
        (None, None) => None,
        (r, m) => Some(r.unwrap_or(0.0).max(m.unwrap_or(0.0))),
    }
}

impl ReachEnv {
    /// Steps 1-2 at the current joint positions, into `self.proximity`: the arm's clearance
    /// from the obstacles, `None` when nothing is measured (neither user is on, or the arm has
    /// no collision shape). No allocation.
    pub(super) fn measure_proximity(&mut self) -> Option<f64> {
        let cutoff = self.proximity_cutoff?;
        let collider = self.arm.collider_mut()?;
        if self.obstacles.is_empty() {
            self.proximity.fill(None);
            return Some(f64::INFINITY);
        }
        collider.place_at(&self.chain, &self.q);
        Some(collider.nearest_obstacles(cutoff, &mut self.proximity))
    }

    /// Step 3: the per-link slots, into `self.obs[slots]`, from the last measurement.
    pub(super) fn write_obstacles_per_link(&mut self, slots: Range<usize>) {
        let r = self.task.per_link_range_m();
        for (p, slot) in self.proximity.iter().zip(self.obs[slots].chunks_exact_mut(PER_LINK_OBS_LEN)) {
            match p {
                Some((_, c)) if c.distance_m < r => {
                    let d = c.distance_m;
                    let w = 1.0 - d.max(0.0) / r;
                    for k in 0..3 {
                        // parry's normals (f32) can be a hair longer than 1.
                        slot[k] = (-c.normal[k] * w).clamp(-1.0, 1.0) as f32;
                    }
                    slot[3] = (d.max(-r) / r) as f32;
                }
                _ => {
                    slot[..3].fill(0.0);
                    slot[3] = 1.0;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
