//! The NaN guard of `train()`: when a loss, a gradient or a parameter becomes non-finite, training
//! stops with an error naming the episode, the step and the quantity, and the last checkpoint
//! written before the fault is left intact and loadable.
//!
//! The fault is forced, deterministically (seeded), by absurd learning rates: the first Adam
//! step moves every weight by about the learning rate, so the next forward pass overflows f32
//! (or, past f32::MAX, the weights themselves become infinite).

use stagerl::agent::Algo;
use stagerl::config::Config;
use stagerl::env::ReachEnv;
use stagerl::io::checkpoint::Checkpoint;
use stagerl::run::dir::RunDir;
use stagerl::train::{load_agent, train};

/// A small seeded run with absurd learning rates `lr`; learning starts after `learning_starts`
/// environment steps (episodes are 50 steps: random actions never reach the target here).
fn exploding(algo: Algo, lr: f64, learning_starts: u64) -> Config {
    let mut cfg = Config::default();
    cfg.agent.algo = algo;
    cfg.agent.hidden = vec![8, 8];
    cfg.agent.batch_size = 8;
    cfg.agent.buffer_size = 1000;
    cfg.agent.learning_starts = learning_starts;
    cfg.agent.actor_lr = Some(lr);
    cfg.agent.critic_lr = Some(lr);
    // CrossQ's critics as small as the actor (their default is 1024 wide).
    cfg.agent.crossq = (algo == Algo::Crossq)
        .then(|| stagerl::agent::CrossqConfig { critic_hidden: vec![8, 8], ..Default::default() });
    cfg.train.seed = 7;
    cfg.train.episodes = 20;
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 1;
    cfg
}

/// A forced fault and where the guard must see it.
struct Fault {
    algo: Algo,
    lr: f64,
    learning_starts: u64,
    /// The message names this quantity...
    quantity: &'static str,
    /// ...and this place.
    at: &'static str,
}

#[rustfmt::skip]
const FAULTS: &[Fault] = &[
    // Learning starts at step 10 of episode 2, after the checkpoint of episode 1. Weights of
    // about 1e30 overflow the next forward pass: the loss check after the update sees it.
    Fault { algo: Algo::Ddpg, lr: 1e30, learning_starts: 60, quantity: "actor loss = inf", at: "at episode 2, step 10 (update 1)" },
    Fault { algo: Algo::Td3, lr: 1e30, learning_starts: 60, quantity: "critic loss = inf", at: "at episode 2, step 11 (update 2)" },
    // SAC's overflowing actor loss is NaN since the products are chains of fused multiply-adds
    // (nn::matmul; it was inf with gemm's rounding): the guard names whichever it is.
    Fault { algo: Algo::Sac, lr: 1e30, learning_starts: 60, quantity: "actor loss = NaN", at: "at episode 2, step 10 (update 1)" },
    // 1e39 is infinite in f32: TD3's first update (critics only) has a finite loss and leaves
    // infinite critic weights. It is the last step of episode 2, so the parameter check at the
    // episode's end is the one that sees it.
    // CrossQ: its critics' first step (the actor waits for the 3rd update) leaves weights of
    // about 1e30, which the second update's joint pass overflows.
    Fault { algo: Algo::Crossq, lr: 1e30, learning_starts: 60, quantity: "critic loss = NaN", at: "at episode 2, step 11 (update 2)" },
    Fault { algo: Algo::Td3, lr: 1e39, learning_starts: 100, quantity: "q1 parameter layer0.weight", at: "at episode 2, step 50" },
];

/// Train `cfg`; expect the guard to stop it with `quantity` and `at` named, and the checkpoint
/// of the last finished episode intact and loadable.
fn assert_fault(cfg: &Config, quantity: &str, at: &str) {
    let algo = cfg.agent.algo;
    let dir = std::env::temp_dir()
        .join(format!("stagerl-nan-{}-{algo}-{at}", std::process::id()).replace([' ', ','], "_"));
    std::fs::remove_dir_all(&dir).ok();
    let run = RunDir::new(&dir);
    // The bytes of `latest` after each finished episode, as the callback saw them.
    let mut seen: Vec<(u64, Vec<u8>)> = Vec::new();
    let result = train(cfg, &dir, |p| {
        seen.push((p.record.episode, std::fs::read(run.latest()).expect("latest checkpoint")))
    });
    let e = match result {
        Ok(s) => panic!(
            "{algo}: no fault in {} updates with learning rates of {:?}",
            s.updates, cfg.agent.actor_lr
        ),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("numerical fault"), "{algo}: {e}");
    assert!(e.contains(quantity), "{algo}: {e:?} should name {quantity:?}");
    assert!(e.contains(at), "{algo}: {e:?} should say {at:?}");
    let episode = seen.len() as u64 + 1;
    assert!(e.contains(&format!("at episode {episode}, step ")), "{algo}: {e}");
    assert!(e.contains("last good checkpoint"), "{algo}: {e}");

    // The checkpoint of the last finished episode is on disk as it was written, and loads.
    let (last, bytes) = seen.last().unwrap_or_else(|| panic!("{algo}: the fault came before any checkpoint"));
    assert_eq!(*last, episode - 1);
    assert_eq!(&std::fs::read(run.latest()).unwrap(), bytes, "{algo}: latest checkpoint changed");
    assert!(!run.final_checkpoint().exists(), "{algo}: a failed run wrote a final checkpoint");
    let ck = Checkpoint::load(&run.latest()).unwrap();
    assert_eq!(ck.json::<u64>("episode").unwrap(), *last);
    assert_eq!(ck.meta("algorithm").unwrap(), algo.name());
    for name in ck.tensor_names() {
        let (_, data) = ck.tensor(name).unwrap();
        assert!(data.iter().all(|x| x.is_finite()), "{algo}: tensor {name} of the kept checkpoint");
    }
    let env = ReachEnv::from_config(cfg, 0).unwrap();
    let mut agent = load_agent(cfg, &env, &run.latest()).unwrap();
    let mut action = vec![0.0f32; env.act_dim()];
    agent.predict(env.observation(), &mut action);
    assert!(action.iter().all(|a| a.is_finite() && a.abs() <= 1.0), "{algo}: {action:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_numerical_fault_stops_training_naming_episode_step_and_quantity() {
    for f in FAULTS {
        assert_fault(&exploding(f.algo, f.lr, f.learning_starts), f.quantity, f.at);
    }
}

/// Known gap in `train()`, reported: with learning rates of 1e10 the first update leaves DDPG's
/// and SAC's actor with finite weights whose forward pass overflows to NaN, and the loss of that
/// update was finite. The next `agent.act` returns a NaN action and `env.step` rejects it, so
/// training stops with "invalid input: action[0] = NaN is not finite": no "numerical fault", no
/// episode, step or quantity, before any guard runs. Enable when the loop checks the action (or
/// the parameters) after every update.
#[test]

fn a_nan_action_is_reported_as_a_numerical_fault() {
    for algo in [Algo::Ddpg, Algo::Sac] {
        assert_fault(&exploding(algo, 1e10, 60), "actor", "at episode 2, step 1");
    }
}

#[test]
fn the_same_seed_faults_at_the_same_place() {
    let run = |tag: &str| {
        let dir = std::env::temp_dir().join(format!("stagerl-nan-det-{}-{tag}", std::process::id()));
        let e = train(&exploding(Algo::Sac, 1e30, 60), &dir, |_| {}).unwrap_err().to_string();
        std::fs::remove_dir_all(&dir).ok();
        e.replace(&dir.display().to_string(), "")
    };
    assert_eq!(run("a"), run("b"));
}

#[test]
fn ordinary_learning_rates_do_not_trip_the_guard() {
    // The control: the same run with the default learning rates finishes.
    let mut cfg = exploding(Algo::Sac, 1e-3, 60);
    cfg.agent.actor_lr = None;
    cfg.agent.critic_lr = None;
    cfg.train.episodes = 4;
    let dir = std::env::temp_dir().join(format!("stagerl-nan-ok-{}", std::process::id()));
    let s = train(&cfg, &dir, |_| {}).unwrap();
    assert!(s.updates > 100, "{}", s.updates);
    std::fs::remove_dir_all(&dir).ok();
}
