//! Tests of hindsight relabelling against the environment's own steps.

use super::*;
use crate::agent::MAX_HER_K;
use crate::env::{rollout, Observed, ReachEnv, Scratch};
use crate::reward::RewardFunction;
use std::sync::Arc;

/// One random-action episode of `steps` steps at most, logged, with the joint positions
/// before each step.
fn episode(env: &mut ReachEnv, seed: u64) -> (EpisodeLog, Vec<Vec<f64>>) {
    let mut log = EpisodeLog::default();
    let mut qs = Vec::new();
    let mut rng = Rng::new(seed);
    env.reset();
    log.begin(env.ee_pose().position);
    let mut scratch = Scratch::new(env);
    let mut driver = Observed(
        |e: &ReachEnv, a: &mut [f32]| {
            qs.push(e.joint_positions().to_vec());
            for x in a.iter_mut() {
                *x = rng.uniform_range(-0.6, 0.6) as f32;
            }
            Ok(())
        },
        |t: &Transition<'_>| {
            log.push(t);
            Ok(crate::env::Flow::Continue)
        },
    );
    rollout(env, &mut scratch, &mut driver).unwrap();
    (log, qs)
}

fn env(function: RewardFunction, seed: u64) -> ReachEnv {
    let chain = Arc::new(crate::robot::Chain::ur5());
    let task =
        crate::env::TaskConfig { obs_delta_scale: 10.0, ..Default::default() }.resolve(&chain).unwrap();
    let reward = RewardConfig { function, ..RewardConfig::default() };
    ReachEnv::new(chain, task, reward, seed).unwrap()
}

/// The acceptance test of relabelling: for every relabelled transition, a fresh environment
/// put at the step's joint positions with the substituted goal as its target, and given the
/// step's action, observes the relabelled observation, then takes a step whose reward (bonus
/// included), termination and next observation are the relabelled ones, bit for bit; for
/// every reward function and strategy.
#[test]
fn a_relabelled_transition_is_the_environments_own_for_the_new_goal() {
    for (i, function) in RewardFunction::ALL.into_iter().enumerate() {
        let mut e = env(function, 10 + i as u64);
        let mut fresh = e.clone();
        let (log, qs) = episode(&mut e, 7 + i as u64);
        assert_eq!(log.len(), 50, "random actions do not reach the target");
        for strategy in [HerStrategy::Future, HerStrategy::Final, HerStrategy::Episode] {
            let cfg = HerConfig { strategy, k: 3 };
            let (task, reward) = (e.task().clone(), e.reward_config().clone());
            let mut r = Relabeller::default();
            let (mut n, mut terminal, mut bonus) = (0, 0, 0.0);
            r.relabel(&cfg, &task, &reward, &log, &mut Rng::new(3), |x| {
                n += 1;
                let obs = fresh.reset_to(&qs[x.step], x.goal).unwrap().to_vec();
                assert_eq!(obs, x.obs, "{function:?} {strategy:?} step {}: observation", x.step);
                let s = fresh.step(x.action).unwrap();
                assert_eq!(s.total().to_bits(), x.terms.total.to_bits(), "{function:?} step {}", x.step);
                assert_eq!(s.terms, x.terms);
                assert_eq!(s.terminated, x.terminal);
                assert_eq!(fresh.observation(), x.next_obs, "{function:?} step {}: next observation", x.step);
                terminal += usize::from(x.terminal);
                bonus += x.terms.bonus;
                match strategy {
                    HerStrategy::Final => assert_eq!(x.goal, log.ee_after(49)),
                    HerStrategy::Future => {
                        assert!((x.step..50).any(|g| log.ee_after(g) == x.goal), "a later position")
                    }
                    HerStrategy::Episode => assert!((0..50).any(|g| log.ee_after(g) == x.goal)),
                }
            });
            assert_eq!(n, 50 * cfg.copies());
            // Goals reached by the step itself are successes, with the bonus.
            assert!(terminal >= 1, "{strategy:?}: the last step reaches the final goal");
            assert_eq!(bonus, terminal as f64 * reward.success_bonus);
        }
    }
}

/// With `task.on_collision = "terminate"`, the step that ends in contact is terminal for
/// every substituted goal and loses the penalty, as the environment's own step does.
#[test]
fn a_contact_that_ends_the_episode_is_terminal_for_every_goal() {
    use crate::sim::scene::Obstacle;
    let chain = Arc::new(crate::robot::Chain::ur5());
    let tool = chain.fk(&crate::env::UR5_HOME_POSE_RAD).position;
    let task = crate::env::TaskConfig {
        obstacles: vec![Obstacle::sphere(0.12, [tool.x + 0.2, tool.y, tool.z - 0.1])],
        on_collision: crate::env::OnCollision::Terminate,
        ..Default::default()
    };
    let task = task.resolve(&chain).unwrap();
    let reward = RewardConfig { collision_penalty: Some(7.5), ..RewardConfig::default() };
    let mut e = ReachEnv::new(chain, task.clone(), reward.clone(), 5).unwrap();
    let mut fresh = e.clone();
    // The first random episode that runs into the obstacle after a few steps.
    let (log, qs) = (0..300)
        .map(|seed| episode(&mut e, seed))
        .find(|(log, _)| log.len() >= 3 && log.contact_after(log.len() - 1))
        .expect("some random episode runs into the obstacle");
    let last = log.len() - 1;
    let cfg = HerConfig { strategy: HerStrategy::Future, k: 4 };
    let mut ended = 0;
    Relabeller::default().relabel(&cfg, &task, &reward, &log, &mut Rng::new(1), |x| {
        fresh.reset_to(&qs[x.step], x.goal).unwrap();
        let s = fresh.step(x.action).unwrap();
        assert_eq!(s.total().to_bits(), x.terms.total.to_bits(), "step {}", x.step);
        assert_eq!(s.terminated, x.terminal, "step {}", x.step);
        if x.step == last {
            assert!(x.terminal && s.collision.is_some());
            assert_eq!(x.terms.total, x.terms.reward + x.terms.bonus - 7.5);
            ended += 1;
        }
    });
    assert_eq!(ended, 4, "every copy of the last step");
}

#[test]
fn future_goals_cover_the_rest_of_the_episode_and_k_is_checked() {
    let mut e = env(RewardFunction::Basic, 1);
    let (log, _) = episode(&mut e, 2);
    let (task, reward) = (e.task().clone(), e.reward_config().clone());
    let mut r = Relabeller::default();
    let mut seen = vec![vec![false; 50]; 50];
    let cfg = HerConfig { strategy: HerStrategy::Future, k: 64 };
    r.relabel(&cfg, &task, &reward, &log, &mut Rng::new(4), |x| {
        let g = (0..50).find(|&g| log.ee_after(g) == x.goal).unwrap();
        assert!(g >= x.step);
        seen[x.step][g] = true;
    });
    // Step 45 has 5 possible goals, 64 draws: all of them seen; step 0 many different ones.
    assert!((45..50).all(|g| seen[45][g]));
    assert!(seen[0].iter().filter(|s| **s).count() > 30);
    for k in [0, MAX_HER_K + 1] {
        let e = HerConfig { k, ..HerConfig::default() }.validate().unwrap_err().to_string();
        assert!(e.contains("agent.her.k") && e.contains(&k.to_string()), "{e}");
    }
}

/// The UR5 with a sphere beside its tool at the home pose (and the shield on when `shield`), and
/// `reward`: random-action episodes of seeds `seeds` relabelled (`future`, k = 2), each relabelled
/// step checked bit for bit against a fresh environment's step for its goal, and its total against
/// the reward and bonus less `term` of its terms. Returns the steps relabelled and those with
/// `term` charged.
fn relabel_beside_a_sphere(
    reward: RewardConfig,
    shield: bool,
    seeds: std::ops::Range<u64>,
    term: fn(&crate::reward::RewardTerms) -> f64,
) -> (usize, usize) {
    use crate::sim::scene::Obstacle;
    use crate::sim::shield::ShieldConfig;
    let chain = Arc::new(crate::robot::Chain::ur5());
    let tool = chain.fk(&crate::env::UR5_HOME_POSE_RAD).position;
    let task = crate::env::TaskConfig {
        obstacles: vec![Obstacle::sphere(0.08, [tool.x + 0.15, tool.y, tool.z - 0.05])],
        shield: shield.then(|| ShieldConfig { enabled: true, ..ShieldConfig::default() }),
        ..Default::default()
    };
    let task = task.resolve(&chain).unwrap();
    let mut e = ReachEnv::new(chain, task.clone(), reward.clone(), 5).unwrap();
    let mut fresh = e.clone();
    let (mut n, mut charged) = (0, 0);
    for seed in seeds {
        let (log, qs) = episode(&mut e, seed);
        let cfg = HerConfig { strategy: HerStrategy::Future, k: 2 };
        Relabeller::default().relabel(&cfg, &task, &reward, &log, &mut Rng::new(2), |x| {
            fresh.reset_to(&qs[x.step], x.goal).unwrap();
            let s = fresh.step(x.action).unwrap();
            assert_eq!(s.terms, x.terms, "step {}", x.step);
            assert_eq!(x.terms.total, x.terms.reward + x.terms.bonus - term(&x.terms));
            n += 1;
            charged += usize::from(term(&x.terms) > 0.0);
        });
    }
    (n, charged)
}

/// With `[reward.clearance]`, every relabelled step is charged the clearance penalty the
/// environment charged for it (it depends on the arm, not on the goal), bit for bit as a fresh
/// environment's step for the new goal; some steps near the sphere are charged.
#[test]
fn a_relabelled_step_keeps_its_clearance_penalty() {
    let clearance = Some(crate::reward::ClearanceConfig { weight: 2.0, margin_m: 0.15 });
    let reward = RewardConfig { clearance, ..RewardConfig::default() };
    let (n, charged) = relabel_beside_a_sphere(reward, false, 3..4, |t| t.clearance);
    assert!(n > 0 && charged > 0, "{charged} of {n} relabelled steps charged");
}

/// With `reward.shield_penalty` and the shield on, every relabelled step is charged the shield's
/// penalty the environment charged for it (it depends on the command, not on the goal), bit for
/// bit as a fresh environment's step for the new goal; some steps are charged.
#[test]
fn a_relabelled_step_keeps_its_shield_penalty() {
    let reward = RewardConfig { shield_penalty: Some(2.0), ..RewardConfig::default() };
    let (n, charged) = relabel_beside_a_sphere(reward, true, 3..6, |t| t.shield);
    assert!(n > 0 && charged > 0, "{charged} of {n} relabelled steps charged");
}
