//! The per-link observation and the clearance term against an independent computation: the
//! UR5's capsules placed by the chain's frames, and their distance to a sphere found by
//! sampling points along each capsule's axis.

use std::sync::Arc;

use super::super::{ObservationLayout, ObstacleObservation, ReachEnv, TaskConfig, PER_LINK_OBS_LEN};
use crate::base::rng::Rng;
use crate::reward::{ClearanceConfig, RewardConfig};
use crate::robot::{Chain, Shape};
use crate::sim::scene::{Obstacle, RandomObstacles};

/// The axis (ends, world frame) and radius of collision shape `k` of `chain` at `q`.
fn capsule(chain: &Chain, q: &[f64], k: usize) -> ([f64; 3], [f64; 3], f64) {
    let mut frames = vec![[0.0; 12]; chain.dof()];
    chain.segment_frames(q, &mut frames);
    let s = &chain.collision_shapes()[k];
    let m = s.segment.map_or(s.pose, |i| crate::robot::mul_tf(&frames[i], &s.pose));
    let Shape::Capsule { radius_m, half_length_m: h } = s.shape else {
        panic!("the UR5's shapes are capsules")
    };
    let (c, z) = ([m[3], m[7], m[11]], [m[2], m[6], m[10]]);
    ([0, 1, 2].map(|i| c[i] - h * z[i]), [0, 1, 2].map(|i| c[i] + h * z[i]), radius_m)
}

/// By brute force: the signed distance from a capsule (axis `a`-`b`, radius `r`) to a sphere
/// (`centre`, `radius`) and the unit direction from the capsule's axis to the sphere's centre,
/// from `n + 1` points along the axis.
fn sampled(a: [f64; 3], b: [f64; 3], r: f64, centre: [f64; 3], radius: f64, n: usize) -> (f64, [f64; 3]) {
    let (mut best, mut at) = (f64::INFINITY, a);
    for i in 0..=n {
        let s = i as f64 / n as f64;
        let p = [0, 1, 2].map(|j| a[j] + s * (b[j] - a[j]));
        let d = (0..3).map(|j| (centre[j] - p[j]).powi(2)).sum::<f64>().sqrt();
        if d < best {
            (best, at) = (d, p);
        }
    }
    (best - r - radius, [0, 1, 2].map(|j| (centre[j] - at[j]) / best))
}

fn per_link_env(task: TaskConfig, reward: RewardConfig, seed: u64) -> ReachEnv {
    let chain = Arc::new(Chain::ur5());
    let task =
        TaskConfig { observe_obstacles: true, obstacle_observation: ObstacleObservation::PerLink, ..task };
    ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), reward, seed).unwrap()
}

/// Every per-link slot equals the encoding of the sampled distance and direction: far slots
/// `0, 0, 0, 1`, near ones the direction weighted by proximity and `max(d, -R) / R`, an
/// overlapping one negative; at the home pose and along random episodes.
#[test]
fn per_link_slots_match_a_brute_force_distance_to_a_sphere() {
    let chain = Chain::ur5();
    let home = crate::env::UR5_HOME_POSE_RAD;
    // A sphere that overlaps shape 4 at home: 3 cm from its axis's middle, across the axis.
    let (a, b, _) = capsule(&chain, &home, 4);
    let mid = [0, 1, 2].map(|i| 0.5 * (a[i] + b[i]));
    let u = [0, 1, 2].map(|i| b[i] - a[i]);
    let e = if u[0].abs() < 0.5 * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt() {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let across = [u[1] * e[2] - u[2] * e[1], u[2] * e[0] - u[0] * e[2], u[0] * e[1] - u[1] * e[0]];
    let len = across.iter().map(|v| v * v).sum::<f64>().sqrt();
    let (radius, r) = (0.05, 0.25);
    let centre = [0, 1, 2].map(|i| mid[i] + 0.03 * across[i] / len);
    let task = TaskConfig {
        obstacles: vec![Obstacle::sphere(radius, centre)],
        obstacle_range_m: Some(r),
        ..TaskConfig::default()
    };
    let mut env = per_link_env(task, RewardConfig::default(), 4);
    let slots = ObservationLayout::of(env.task()).obstacles();
    assert_eq!(slots.len(), PER_LINK_OBS_LEN * chain.collision_shapes().len());
    let (mut rng, mut action) = (Rng::new(2), [0.0f32; 6]);
    let (mut near, mut far, mut inside) = (0, 0, 0);
    env.reset();
    for step in 0..60 {
        let q = env.joint_positions().to_vec();
        let obs = &env.observation()[slots.clone()];
        for (k, slot) in obs.chunks_exact(PER_LINK_OBS_LEN).enumerate() {
            let (a, b, rc) = capsule(&chain, &q, k);
            let (d, dir) = sampled(a, b, rc, centre, radius, 100_000);
            let expected = if d < r {
                let w = 1.0 - d.max(0.0) / r;
                [dir[0] * w, dir[1] * w, dir[2] * w, d.max(-r) / r]
            } else {
                [0.0, 0.0, 0.0, 1.0]
            };
            for i in 0..4 {
                let tol = if i == 3 { 1e-6 } else { 1e-4 };
                assert!(
                    (f64::from(slot[i]) - expected[i]).abs() < tol,
                    "step {step} shape {k} value {i}: {} against {} (d = {d})",
                    slot[i],
                    expected[i]
                );
            }
            near += usize::from(d < r);
            far += usize::from(d >= r);
            inside += usize::from(d < 0.0);
        }
        if step == 0 {
            assert!(obs[4 * 4 + 3] < 0.0, "shape 4 overlaps the sphere at home: {:?}", &obs[16..20]);
        }
        if env.is_done() {
            env.reset();
        }
        action.iter_mut().for_each(|x| *x = rng.uniform_range(-0.5, 0.5) as f32);
        env.step(&action).unwrap();
    }
    assert!(near > 60 && far > 60 && inside > 0, "both cases seen: {near} near, {far} far, {inside} inside");
}

/// Among random spheres and boxes, some in the way: every per-link value in [-1, 1] (the
/// layout's bounds), each direction at most a unit vector, near slots seen; two environments
/// of one seed observe the same bits.
#[test]
fn per_link_values_are_bounded_and_deterministic() {
    let random = RandomObstacles { count: [1, 3], size_m: [0.05, 0.15], ..Default::default() };
    let task = TaskConfig { random_obstacles: Some(random), ..TaskConfig::default() };
    let mut envs = [0, 1].map(|_| per_link_env(task.clone(), RewardConfig::default(), 11));
    for e in &mut envs {
        e.set_obstacles_in_path(0.7).unwrap();
    }
    let layout = ObservationLayout::of(envs[0].task());
    let (lo, hi) = layout.bounds(envs[0].task(), envs[0].chain());
    assert!(layout.obstacles().all(|i| lo[i] == -1.0 && hi[i] == 1.0));
    let (mut rng, mut action, mut near) = (Rng::new(5), [0.0f32; 6], 0);
    for _ in 0..40 {
        let first = envs[0].reset().to_vec();
        assert_eq!(first, envs[1].reset());
        while !envs[0].is_done() {
            let obs = envs[0].observation();
            for (i, x) in obs.iter().enumerate() {
                assert!(lo[i] <= *x && *x <= hi[i], "value {i} = {x}");
            }
            for slot in obs[layout.obstacles()].chunks_exact(PER_LINK_OBS_LEN) {
                let norm = slot[..3].iter().map(|v| v * v).sum::<f32>().sqrt();
                assert!(norm <= 1.0 + 1e-6 && (-1.0..=1.0).contains(&slot[3]), "{slot:?}");
                near += usize::from(slot[3] < 1.0);
            }
            action.iter_mut().for_each(|x| *x = rng.uniform_range(-1.0, 1.0) as f32);
            let (s0, s1) = (envs[0].step(&action).unwrap(), envs[1].step(&action).unwrap());
            assert_eq!(s0, s1);
            assert_eq!(envs[0].observation(), envs[1].observation());
        }
    }
    assert!(near > 100, "near slots were exercised: {near}");
}

/// Eqs. 19-20 at known points, and the checks of `[reward.clearance]`.
#[test]
fn the_clearance_penalty_by_hand_and_its_checks() {
    let c = ClearanceConfig { weight: 2.0, margin_m: 0.1 };
    for (d, p) in [
        (f64::INFINITY, 0.0),
        (0.3, 0.0),
        (0.1, 0.0),
        (0.05, 0.5),
        (0.0, 2.0),
        (-0.05, 4.5),
        (-0.1, 8.0),
        (-3.0, 8.0),
    ] {
        assert!((c.penalty(d) - p).abs() < 1e-12, "d = {d}: {} against {p}", c.penalty(d));
    }
    let bad = |c: ClearanceConfig, field: &str| {
        let e = RewardConfig { clearance: Some(c), ..RewardConfig::default() }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{field} in {e}");
    };
    bad(ClearanceConfig { weight: -1.0, ..c }, "reward.clearance.weight");
    bad(ClearanceConfig { weight: f64::NAN, ..c }, "reward.clearance.weight");
    bad(ClearanceConfig { margin_m: 0.0, ..c }, "reward.clearance.margin_m");
    bad(ClearanceConfig { margin_m: f64::INFINITY, ..c }, "reward.clearance.margin_m");
    // Nothing to keep clear of: refused, naming the field.
    let chain = Arc::new(Chain::ur5());
    let reward = RewardConfig { clearance: Some(c), ..RewardConfig::default() };
    let task = TaskConfig::default().resolve(&chain).unwrap();
    let e = ReachEnv::new(chain, task, reward, 1).unwrap_err().to_string();
    assert!(e.contains("reward.clearance") && e.contains("without obstacles"), "{e}");
    let e = c.refused_by("stagerl reward").to_string();
    assert!(e.contains("reward.clearance") && e.contains("stagerl reward"), "{e}");
}

/// Every step's clearance penalty is eq. 20 of the sampled smallest distance between the arm's
/// capsules and a sphere, the total is the reward and bonus less it, and the same episode
/// without `[reward.clearance]` takes the same steps with the paper's totals.
#[test]
fn the_clearance_term_matches_a_brute_force_clearance() {
    let chain = Arc::new(Chain::ur5());
    let tool = chain.fk(&crate::env::UR5_HOME_POSE_RAD).position;
    let (radius, centre) = (0.08, [tool.x + 0.15, tool.y, tool.z - 0.05]);
    let task = TaskConfig { obstacles: vec![Obstacle::sphere(radius, centre)], ..TaskConfig::default() };
    let task = task.resolve(&chain).unwrap();
    let c = ClearanceConfig { weight: 2.0, margin_m: 0.15 };
    let with = RewardConfig { clearance: Some(c), ..RewardConfig::default() };
    let mut env = ReachEnv::new(chain.clone(), task.clone(), with, 6).unwrap();
    let mut plain = ReachEnv::new(chain.clone(), task, RewardConfig::default(), 6).unwrap();
    let (mut rng, mut action, mut charged) = (Rng::new(8), [0.0f32; 6], 0);
    for _ in 0..6 {
        env.reset();
        plain.reset();
        while !env.is_done() {
            action.iter_mut().for_each(|x| *x = rng.uniform_range(-0.6, 0.6) as f32);
            let (s, p) = (env.step(&action).unwrap(), plain.step(&action).unwrap());
            let q = env.joint_positions();
            let d = (0..chain.collision_shapes().len())
                .map(|k| {
                    let (a, b, r) = capsule(&chain, q, k);
                    sampled(a, b, r, centre, radius, 20_000).0
                })
                .fold(f64::INFINITY, f64::min);
            let expected = if d < 0.15 { 2.0 * (1.0 - d.max(-0.15) / 0.15).powi(2) } else { 0.0 };
            assert!(
                (s.terms.clearance - expected).abs() < 1e-6,
                "{} against {expected} (d = {d})",
                s.terms.clearance
            );
            assert_eq!(s.total(), s.terms.reward + s.terms.bonus - s.terms.clearance);
            assert_eq!((p.terms.clearance, p.total()), (0.0, p.terms.reward + p.terms.bonus));
            assert_eq!((s.terms.reward, s.terminated), (p.terms.reward, p.terminated));
            charged += usize::from(s.terms.clearance > 0.0);
        }
    }
    assert!(charged > 10, "the penalty was exercised: {charged} steps");
}
