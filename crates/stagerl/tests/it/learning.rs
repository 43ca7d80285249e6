//! Learning in CI: short seeded runs (SAC + SAR, SAC + HER on the sparse reward, PPO + SAR,
//! CrossQ + SAR)
//! must reach the target far more often than an untrained policy does. The thresholds come from measured runs of this exact configuration
//! (see the numbers beside them); an untrained or broken agent scores 0 % success and a median
//! final distance of decimetres.

use stagerl::agent::Agent;
use stagerl::config::Config;
use stagerl::env::{Policy, ReachEnv};
use stagerl::run::dir::RunDir;
use stagerl::train::eval::{deterministic, evaluate, EvalOptions, EvalSummary};
use stagerl::train::{load_agent, train};

/// The deterministic policy of `agent` on the 200 targets of seed 77.
fn evaluate_200(agent: &mut dyn Agent, env: &mut ReachEnv) -> EvalSummary {
    evaluate(env, &mut Policy(deterministic(agent)), &EvalOptions::new(200, 77)).unwrap().0
}

fn short_run_config(seed: u64) -> Config {
    let mut cfg = Config::default();
    cfg.train.seed = seed;
    cfg.train.episodes = 800;
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 0;
    cfg
}

#[test]
fn untrained_policy_fails_the_task() {
    let cfg = short_run_config(0);
    let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
    let mut agent = stagerl::train::build_agent(&cfg, &env).unwrap();
    let s = evaluate_200(agent.as_mut(), &mut env);
    assert!(s.success_rate < 0.02, "untrained success {}", s.success_rate);
    assert!(s.median_final_distance_m > 0.1, "untrained median distance {}", s.median_final_distance_m);
}

/// Train `cfg` and evaluate its final checkpoint on 200 targets: (success rate, median final
/// distance in metres, episodes logged).
fn train_and_evaluate(cfg: &Config, tag: &str) -> (f64, f64, usize) {
    let dir = std::env::temp_dir().join(format!("stagerl-learning-{tag}-{}", std::process::id()));
    let summary = train(cfg, &dir, |_| {}).unwrap();
    let mut env = ReachEnv::from_config(cfg, 0).unwrap();
    let mut agent = load_agent(cfg, &env, &summary.final_checkpoint).unwrap();
    let s = evaluate_200(agent.as_mut(), &mut env);
    let rows = stagerl::io::csv::read_episodes(&RunDir::new(&dir).episodes()).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    eprintln!(
        "{tag}: success {:.3}, median final distance {:.4} m",
        s.success_rate, s.median_final_distance_m
    );
    (s.success_rate, s.median_final_distance_m, rows.len())
}

/// Hindsight relabelling makes the sparse reward (eq. 18) learnable: SAC + HER (`future`,
/// k = 4) on the basic reward, 800 episodes.
#[test]
fn sac_her_learns_the_sparse_reward_in_a_short_run() {
    let mut cfg = short_run_config(1);
    cfg.reward.function = stagerl::reward::RewardFunction::Basic;
    cfg.agent.her = Some(stagerl::agent::HerConfig::default());
    let (success, median, rows) = train_and_evaluate(&cfg, "sac-her");
    assert_eq!(rows, 800);
    // Measured for this seed and budget: 93.0 % success over 200 other targets, median final
    // distance 7.7 mm. Without HER, SAC on this reward stays near 0 % this early.
    assert!(success >= 0.5, "success {success}");
    assert!(median < 0.02, "median final distance {median}");
}

/// PPO + SAR (the defaults of `[agent.ppo]`, CleanRL's), 8000 episodes (about 0.3 M
/// environment steps; PPO's updates are cheap: seconds of CPU).
#[test]
fn ppo_sar_learns_to_reach_in_a_short_run() {
    let mut cfg = short_run_config(1);
    cfg.agent.algo = stagerl::agent::Algo::Ppo;
    cfg.train.episodes = 8000;
    let (success, median, rows) = train_and_evaluate(&cfg, "ppo");
    assert_eq!(rows, 8000);
    // Measured for this seed and budget: 86.0 % success over 200 other targets, median final
    // distance 8.9 mm.
    assert!(success >= 0.5, "success {success}");
    assert!(median < 0.02, "median final distance {median}");
}

#[test]
fn sac_sar_learns_to_reach_in_a_short_run() {
    let cfg = short_run_config(1);
    let dir = std::env::temp_dir().join(format!("stagerl-learning-{}", std::process::id()));
    let summary = train(&cfg, &dir, |_| {}).unwrap();
    let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
    let mut agent = load_agent(&cfg, &env, &summary.final_checkpoint).unwrap();
    let s = evaluate_200(agent.as_mut(), &mut env);
    let rows = stagerl::io::csv::read_episodes(&RunDir::new(&dir).episodes()).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(rows.len(), 800);
    eprintln!(
        "short run: success {:.3}, median final distance {:.4} m, mean steps {:?}",
        s.success_rate, s.median_final_distance_m, s.mean_steps
    );
    // Measured for this seed and budget (800 episodes, about 25 000 env steps): 75.5 % success,
    // median final distance 8.7 mm, 7.3 steps. The untrained policy: under 2 %, over 0.1 m.
    assert!(s.success_rate >= 0.4, "success {}", s.success_rate);
    assert!(s.median_final_distance_m < 0.02, "median final distance {}", s.median_final_distance_m);
}

/// CrossQ + SAR on a tiny budget (6000 environment steps, 5001 updates; critics 64 x 64, its
/// default 1024 being for real runs): the final policy ends far closer to the targets, and
/// collects far more reward, than the same agent untrained on the same 200 targets.
#[test]
fn crossq_sar_learns_to_approach_in_a_tiny_run() {
    let mut cfg = short_run_config(1);
    cfg.agent.algo = stagerl::agent::Algo::Crossq;
    let own = stagerl::agent::CrossqConfig { critic_hidden: vec![64, 64], ..Default::default() };
    cfg.agent.crossq = Some(own);
    cfg.train.env_steps = Some(6000);
    let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
    let mut untrained = stagerl::train::build_agent(&cfg, &env).unwrap();
    let before = evaluate_200(untrained.as_mut(), &mut env);
    let dir = std::env::temp_dir().join(format!("stagerl-learning-crossq-{}", std::process::id()));
    let summary = train(&cfg, &dir, |_| {}).unwrap();
    let mut agent = load_agent(&cfg, &env, &summary.final_checkpoint).unwrap();
    let after = evaluate_200(agent.as_mut(), &mut env);
    std::fs::remove_dir_all(&dir).ok();
    eprintln!(
        "crossq: untrained median {:.4} m, reward {:.2}; trained median {:.4} m, reward {:.2}, success {:.3}",
        before.median_final_distance_m,
        before.mean_reward,
        after.median_final_distance_m,
        after.mean_reward,
        after.success_rate
    );
    assert_eq!(summary.updates, 5001);
    // Measured for this seed and budget (about 4 s): untrained median final distance 0.843 m,
    // mean reward -31.4; trained 0.095 m, -6.9 (1 % success: the last centimetre takes longer,
    // as for SAC, 5 % at 8000 steps).
    assert!(before.median_final_distance_m > 0.3, "untrained median {}", before.median_final_distance_m);
    assert!(after.median_final_distance_m < 0.15, "trained median {}", after.median_final_distance_m);
    assert!(
        after.mean_reward > before.mean_reward + 10.0,
        "reward {} -> {}",
        before.mean_reward,
        after.mean_reward
    );
}
