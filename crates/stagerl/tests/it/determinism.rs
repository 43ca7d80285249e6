//! The same config and seed give the same run: identical episodes.csv (every column but wall
//! time) and identical final networks, for every algorithm.

use stagerl::agent::obs_norm::ObsNormConfig;
use stagerl::agent::{ActorLogStd, ActorQ, Algo, CrossqConfig, PpoConfig, SacConfig};
use stagerl::agent::{HerConfig, HerStrategy};
use stagerl::config::Config;
use stagerl::io::checkpoint::Checkpoint;
use stagerl::reward::RewardFunction;
use stagerl::run::dir::RunDir;
use stagerl::train::train;

fn run(algo: Algo, seed: u64, tag: &str) -> (Vec<String>, Checkpoint) {
    run_with(algo, seed, tag, None, RewardFunction::Sar)
}

fn run_with(
    algo: Algo,
    seed: u64,
    tag: &str,
    her: Option<HerConfig>,
    reward: RewardFunction,
) -> (Vec<String>, Checkpoint) {
    run_cfg(algo, seed, tag, |cfg| {
        cfg.agent.her = her;
        cfg.reward.function = reward;
    })
}

fn run_cfg(algo: Algo, seed: u64, tag: &str, tweak: impl Fn(&mut Config)) -> (Vec<String>, Checkpoint) {
    run_sized(algo, seed, tag, |cfg| {
        tweak(cfg);
        cfg.agent.hidden = vec![32, 32];
        cfg.agent.batch_size = 64;
    })
}

/// `run_cfg` with the network and batch sizes left to `tweak`.
fn run_sized(algo: Algo, seed: u64, tag: &str, tweak: impl Fn(&mut Config)) -> (Vec<String>, Checkpoint) {
    let mut cfg = Config::default();
    cfg.agent.algo = algo;
    // PPO: rollouts small enough for many updates in 40 episodes.
    cfg.agent.ppo =
        (algo == Algo::Ppo).then(|| PpoConfig { num_envs: 4, num_steps: 32, ..PpoConfig::default() });
    tweak(&mut cfg);
    if algo == Algo::Crossq && cfg.agent.crossq.is_none() {
        // CrossQ's critics as wide as the actor (its default, 1024, is for training runs).
        cfg.agent.crossq =
            Some(CrossqConfig { critic_hidden: cfg.agent.hidden.clone(), ..CrossqConfig::default() });
    }
    cfg.agent.learning_starts = 300;
    cfg.train.seed = seed;
    cfg.train.episodes = 40;
    cfg.train.eval_every_episodes = 20;
    cfg.train.eval_trials = 5;
    cfg.train.checkpoint_every_episodes = 10;
    let dir = std::env::temp_dir().join(format!("stagerl-det-{}-{algo}-{seed}-{tag}", std::process::id(),));
    let summary = train(&cfg, &dir, |_| {}).unwrap();
    let least = if algo == Algo::Ppo { 50 } else { 500 };
    assert!(summary.updates > least, "updates happened: {}", summary.updates);
    let text = std::fs::read_to_string(RunDir::new(&dir).episodes()).unwrap();
    let rows = text.lines().map(|l| l.rsplit_once(',').unwrap().0.to_string()).collect();
    let ck = Checkpoint::load(&summary.final_checkpoint).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    (rows, ck)
}

#[test]
fn same_seed_same_run_different_seed_different_run() {
    for algo in Algo::ALL {
        let (a, ca) = run(algo, 5, "a");
        let (b, cb) = run(algo, 5, "b");
        assert_eq!(a.len(), 41);
        assert_eq!(a, b, "{algo}: episodes.csv differs between identical runs");
        let names: Vec<&str> = ca.tensor_names().collect();
        assert!(names.iter().any(|n| n.starts_with("actor.")));
        for n in names {
            assert_eq!(ca.tensor(n).unwrap(), cb.tensor(n).unwrap(), "{algo}: tensor {n}");
        }
        let (c, _) = run(algo, 6, "c");
        assert_ne!(a, c, "{algo}: another seed gives another run");
    }
}

/// With hindsight relabelling (the sparse reward, each strategy) too; and relabelling changes
/// the run (the relabelled transitions are learned from).
#[test]
fn her_runs_are_deterministic_and_differ_from_plain_runs() {
    for (algo, strategy) in [
        (Algo::Sac, HerStrategy::Future),
        (Algo::Ddpg, HerStrategy::Final),
        (Algo::Td3, HerStrategy::Episode),
    ] {
        let her = Some(HerConfig { strategy, k: 4 });
        let basic = RewardFunction::Basic;
        let (a, ca) = run_with(algo, 5, "her-a", her, basic);
        let (b, cb) = run_with(algo, 5, "her-b", her, basic);
        assert_eq!(a, b, "{algo} + HER: episodes.csv differs between identical runs");
        for n in ca.tensor_names() {
            assert_eq!(ca.tensor(n).unwrap(), cb.tensor(n).unwrap(), "{algo} + HER: tensor {n}");
        }
        let (_, plain) = run_with(algo, 5, "her-plain", None, basic);
        assert!(
            ca.tensor_names().any(|n| ca.tensor(n).ok() != plain.tensor(n).ok()),
            "{algo}: relabelling changed nothing"
        );
    }
}

/// PPO with observation normalisation: deterministic, the statistics saved with the networks
/// (and they moved from their start), and a run other than the plain one.
#[test]
fn ppo_with_observation_normalisation_is_deterministic_and_differs_from_plain_ppo() {
    let norm = |cfg: &mut Config| {
        let p = cfg.agent.ppo.as_mut().unwrap();
        p.norm_obs = Some(ObsNormConfig::default());
    };
    let (a, ca) = run_cfg(Algo::Ppo, 5, "norm-a", norm);
    let (b, cb) = run_cfg(Algo::Ppo, 5, "norm-b", norm);
    assert_eq!(a, b, "PPO + norm_obs: episodes.csv differs between identical runs");
    for n in ca.tensor_names() {
        assert_eq!(ca.tensor(n).unwrap(), cb.tensor(n).unwrap(), "PPO + norm_obs: tensor {n}");
    }
    let stats: serde_json::Value = ca.json("obs_norm").unwrap();
    assert!(stats["count"].as_f64().unwrap() > 1000.0, "statistics merged: {stats}");
    let (_, std) = ca.tensor("obs_norm.std").unwrap();
    assert!(std.iter().all(|&s| s.is_finite() && s > 0.0) && std.iter().any(|&s| s < 0.9), "{std:?}");
    let (plain, _) = run(Algo::Ppo, 5, "norm-plain");
    assert_ne!(a, plain, "normalisation changed nothing");
}

/// The off-policy agents with observation normalisation (`agent.norm_obs`; SAC with HER too):
/// the same run for the same seed on 1 and 2 threads, the statistics saved with the networks
/// (merged from every step collected, and moved from their start), and a run other than the
/// plain one.
#[test]
fn off_policy_observation_normalisation_is_deterministic_on_any_thread_count_and_changes_the_run() {
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    let her = Some(HerConfig { strategy: HerStrategy::Future, k: 4 });
    for (algo, her) in [(Algo::Sac, None), (Algo::Td3, None), (Algo::Ddpg, None), (Algo::Sac, her)] {
        let norm = |cfg: &mut Config| {
            cfg.agent.norm_obs = Some(ObsNormConfig::default());
            cfg.agent.her = her;
            cfg.agent.hidden = vec![128, 128];
            cfg.agent.batch_size = 256;
        };
        let (a, ca) = run_sized(algo, 5, "onorm-a", norm);
        let split = stagerl::base::par::split_jobs();
        let (b, cb) = stagerl::base::par::install(Some(&pool), || run_sized(algo, 5, "onorm-b", norm));
        assert!(stagerl::base::par::split_jobs() > split + 100, "{algo}: the updates were split");
        assert_eq!(a, b, "{algo} + norm_obs: episodes.csv differs between 1 and 2 threads");
        for n in ca.tensor_names() {
            assert_eq!(ca.tensor(n).unwrap(), cb.tensor(n).unwrap(), "{algo} + norm_obs: tensor {n}");
        }
        let stats: serde_json::Value = ca.json("obs_norm").unwrap();
        let steps = stats["count"].as_f64().unwrap();
        let collected: f64 =
            a.iter().skip(1).map(|r| r.split(',').nth(2).unwrap().parse::<f64>().unwrap()).sum();
        assert_eq!(steps.round(), collected, "one merge per step collected: {stats}");
        let (_, std) = ca.tensor("obs_norm.std").unwrap();
        assert!(std.iter().all(|&s| s.is_finite() && s > 0.0) && std.iter().any(|&s| s < 0.9), "{std:?}");
        let plain = |cfg: &mut Config| {
            norm(cfg);
            cfg.agent.norm_obs = None;
        };
        let (p, cp) = run_sized(algo, 5, "onorm-plain", plain);
        assert_ne!(a, p, "{algo}: normalisation changed nothing");
        assert!(cp.json::<serde_json::Value>("obs_norm").is_err(), "{algo}: no statistics when off");
    }
}

/// Splitting an update over worker threads (`stagerl::base::par`) changes no bit: the same
/// episodes.csv and networks on 1 and 2 threads, for every algorithm, with networks and batches
/// large enough that the products are split (hidden 128, batch 256), and twin critics at once.
#[test]
fn threads_do_not_change_the_run() {
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    for algo in Algo::ALL {
        let big = |cfg: &mut Config| {
            cfg.agent.hidden = vec![128, 128];
            cfg.agent.batch_size = 256;
            // PPO: minibatches of 256 rows.
            if let Some(ppo) = &mut cfg.agent.ppo {
                (ppo.num_envs, ppo.num_steps, ppo.num_minibatches) = (4, 64, 1);
            }
        };
        let one = run_sized(algo, 7, "t1", big);
        let split = stagerl::base::par::split_jobs();
        let two = stagerl::base::par::install(Some(&pool), || run_sized(algo, 7, "t2", big));
        assert!(stagerl::base::par::split_jobs() > split + 100, "{algo}: the updates were split");
        assert_eq!(one.0, two.0, "{algo}: episodes.csv differs between 1 and 2 threads");
        for n in one.1.tensor_names() {
            assert_eq!(one.1.tensor(n).unwrap(), two.1.tensor(n).unwrap(), "{algo}: tensor {n}");
        }
    }
}

/// REDQ (SAC with ten critics, each target the minimum of two drawn per update, the actor on
/// their mean) and DroQ (dropout and layer normalisation in two critics, the actor on their
/// mean), at 4 updates per step: the same run for the same seed on 1 and 2 threads (the critics
/// at once), the ensemble's parts in the checkpoint, another run than SAC's, and another run for
/// another seed.
#[test]
fn redq_and_droq_runs_are_deterministic_on_any_thread_count_and_differ_from_sac() {
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    let redq = SacConfig { n_critics: 10, critic_subset: Some(2), ..SacConfig::default() };
    let droq = SacConfig {
        critic_dropout: 0.01,
        critic_layer_norm: true,
        actor_q: Some(ActorQ::Mean),
        ..SacConfig::default()
    };
    // sbx's DroQ recipe: its actor's log-std clip and the actor stepped once every 3 updates
    // (policy delay, counted across environment steps).
    let droq_sbx = SacConfig { actor_log_std: ActorLogStd::Clip, policy_delay: 3, ..droq };
    let (_, sac) = run(Algo::Sac, 5, "ens-sac");
    let (sac_rows, _) = run(Algo::Sac, 5, "ens-sac");
    for (name, own, parts) in [
        ("redq", redq, vec!["q10.layer0.weight", "q10_target.layer2.bias"]),
        ("droq", droq, vec!["q2.ln1.scale", "q2_target.ln0.bias", "q1_dropout_rng", "q2_target_dropout_rng"]),
        ("droq-sbx", droq_sbx, vec!["q2.ln1.scale", "q1_dropout_rng", "agent_updates"]),
    ] {
        let tweak = |cfg: &mut Config| {
            cfg.agent.sac = Some(own);
            cfg.agent.updates_per_step = 4;
        };
        let (a, ca) = run_cfg(Algo::Sac, 5, &format!("{name}-a"), tweak);
        let (b, cb) =
            stagerl::base::par::install(Some(&pool), || run_cfg(Algo::Sac, 5, &format!("{name}-b"), tweak));
        assert_eq!(a, b, "{name}: episodes.csv differs between 1 and 2 threads");
        let names: Vec<&str> = ca.tensor_names().collect();
        for part in parts {
            let there = names.contains(&part) || ca.json::<serde_json::Value>(part).is_ok();
            assert!(there, "{name}: {part} in {names:?}");
        }
        assert!(!names.iter().any(|n| n.starts_with("q11")), "{names:?}");
        for n in names {
            assert_eq!(ca.tensor(n).unwrap(), cb.tensor(n).unwrap(), "{name}: tensor {n}");
        }
        let (c, _) = run_cfg(Algo::Sac, 6, &format!("{name}-c"), tweak);
        assert_ne!(a, c, "{name}: another seed gives another run");
        assert_ne!(a, sac_rows, "{name} is not SAC");
    }
    // Plain SAC saves no dropout stream and no update count.
    assert!(sac.json::<serde_json::Value>("q1_dropout_rng").is_err());
    assert!(sac.json::<serde_json::Value>("agent_updates").is_err());
}

/// The loop's collector is chosen from the agent: the off-policy one saves its replay buffer and
/// random streams, PPO's its environments and rollout and no replay buffer.
#[test]
fn each_collector_saves_its_own_state_and_ppo_keeps_no_replay_buffer() {
    for algo in [Algo::Sac, Algo::Ppo] {
        let mut cfg = Config::default();
        cfg.agent.algo = algo;
        cfg.agent.hidden = vec![16, 16];
        cfg.agent.ppo =
            (algo == Algo::Ppo).then(|| PpoConfig { num_envs: 2, num_steps: 16, ..PpoConfig::default() });
        cfg.agent.learning_starts = 50;
        cfg.train.episodes = 4;
        cfg.train.eval_every_episodes = 0;
        let dir = std::env::temp_dir().join(format!("stagerl-collector-{}-{algo}", std::process::id()));
        train(&cfg, &dir, |_| {}).unwrap();
        let ck = Checkpoint::load(&RunDir::new(&dir).latest()).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let replay: Vec<&str> = ck.tensor_names().filter(|n| n.starts_with("replay.")).collect();
        let state: serde_json::Value = ck.json("train_state").unwrap();
        let has = |key: &str| state.get(key).is_some();
        if algo == Algo::Ppo {
            assert!(replay.is_empty(), "PPO saved {replay:?}");
            assert!(has("on_policy") && !has("replay_rng") && !has("replay_len"), "{state}");
        } else {
            assert_eq!(replay.len(), 5, "{replay:?}");
            assert_eq!(state["replay_len"].as_u64(), state["env_steps"].as_u64(), "every step stored");
            assert!(has("replay_rng") && has("warmup_rng") && !has("on_policy"), "{state}");
        }
        assert_eq!(state["episode"].as_u64(), Some(4));
    }
}

/// CrossQ (batch-renormalised critics and actor, no targets), past its renormalisation's
/// warm-up, at 2 updates per step, with observation normalisation: the same run for the same
/// seed on 1 and 2 threads (the critics at once, their products split), every network's running
/// statistics in the checkpoint and moved from their start, another run than SAC's, and another
/// run for another seed.
#[test]
fn crossq_runs_are_deterministic_on_any_thread_count_and_differ_from_sac() {
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    let tweak = |cfg: &mut Config| {
        let own = CrossqConfig {
            critic_hidden: vec![128, 128],
            renorm_warmup_steps: 300,
            ..CrossqConfig::default()
        };
        cfg.agent.crossq = Some(own);
        cfg.agent.updates_per_step = 2;
        cfg.agent.norm_obs = Some(ObsNormConfig::default());
        cfg.agent.hidden = vec![32, 32];
        cfg.agent.batch_size = 128;
    };
    let (a, ca) = run_sized(Algo::Crossq, 5, "crossq-a", tweak);
    let split = stagerl::base::par::split_jobs();
    let (b, cb) = stagerl::base::par::install(Some(&pool), || run_sized(Algo::Crossq, 5, "crossq-b", tweak));
    assert!(stagerl::base::par::split_jobs() > split + 100, "the updates were split");
    assert_eq!(a, b, "CrossQ: episodes.csv differs between 1 and 2 threads");
    let names: Vec<&str> = ca.tensor_names().collect();
    for part in ["actor.layer2.weight", "actor_bn.bn0.scale", "q1.bn2.bias", "q2.layer2.weight"] {
        assert!(names.contains(&part), "{part} in {names:?}");
    }
    assert!(!names.iter().any(|n| n.contains("target")), "no target networks: {names:?}");
    for n in &names {
        assert_eq!(ca.tensor(n).unwrap(), cb.tensor(n).unwrap(), "CrossQ: tensor {n}");
    }
    for net in ["actor_bn", "q1", "q2"] {
        let key = format!("{net}.bn_stats");
        let (x, y): (serde_json::Value, serde_json::Value) = (ca.json(&key).unwrap(), cb.json(&key).unwrap());
        assert_eq!(x, y, "{key}");
        let steps = x[0]["steps"].as_u64().unwrap();
        assert!(steps > 300, "{key}: past the warm-up: {steps}");
        let var0 = x[1]["var"][0].as_f64().unwrap();
        assert!(var0 != 1.0 && var0.is_finite(), "{key}: the running statistics moved: {var0}");
    }
    let (c, _) = run_sized(Algo::Crossq, 6, "crossq-c", tweak);
    assert_ne!(a, c, "another seed gives another run");
    let (sac, _) = run(Algo::Sac, 5, "crossq-sac");
    assert_ne!(a, sac, "CrossQ is not SAC");
}
