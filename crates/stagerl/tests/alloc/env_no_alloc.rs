//! `ReachEnv::step` and `VecEnv::step` allocate nothing: counted with a global allocator.

use crate::common;

use common::allocs;

#[test]
fn stepping_and_resetting_allocate_nothing() {
    no_allocation_in(stagerl::config::Config::default());
}

/// With random obstacles, observed (absolute, nearest, per link), and contacts ending episodes,
/// too; with the clearance term.
#[test]
fn random_obstacles_allocate_nothing() {
    let mut cfg = stagerl::config::Config::default();
    cfg.task.random_obstacles = Some(stagerl::sim::scene::RandomObstacles::default());
    cfg.task.observe_obstacles = true;
    cfg.task.on_collision = stagerl::env::OnCollision::Terminate;
    no_allocation_in(cfg.clone());
    cfg.task.obstacle_observation = stagerl::env::ObstacleObservation::Nearest;
    no_allocation_in(cfg.clone());
    // One slot per collision shape with its nearest obstacle, and the clearance term.
    cfg.task.obstacle_observation = stagerl::env::ObstacleObservation::PerLink;
    no_allocation_in(cfg.clone());
    cfg.reward.clearance = Some(stagerl::reward::ClearanceConfig::default());
    no_allocation_in(cfg);
}

/// With the safety shield filtering every command among random obstacles.
#[test]
fn the_shielded_step_allocates_nothing() {
    let mut cfg = stagerl::config::Config::default();
    cfg.task.random_obstacles = Some(stagerl::sim::scene::RandomObstacles::default());
    cfg.task.shield = Some(stagerl::sim::shield::ShieldConfig { enabled: true, ..Default::default() });
    no_allocation_in(cfg);
}

/// A vector env split over a pool of two threads: nothing allocates on the caller or the worker.
#[test]
fn a_vector_env_on_two_threads_allocates_nothing() {
    let _alone = common::POOL_TESTS.lock().unwrap_or_else(|p| p.into_inner());
    let mut cfg = stagerl::config::Config::default();
    cfg.task.random_obstacles = Some(stagerl::sim::scene::RandomObstacles::default());
    cfg.task.observe_obstacles = true;
    let n = 4 * stagerl::env::PAR_MIN_ENVS;
    let mut venv = stagerl::env::VecEnv::from_config(n, &cfg, 1).unwrap();
    let actions: Vec<f32> = (0..n * 6).map(|i| ((i * 7919) % 200) as f32 / 100.0 - 1.0).collect();
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    let split = stagerl::base::par::split_jobs();
    stagerl::base::par::install(Some(&pool), || {
        venv.step(&actions).unwrap();
        let (before, workers) = (allocs(), common::worker_allocs());
        for _ in 0..2000 {
            venv.step(&actions).unwrap();
        }
        assert_eq!(allocs() - before, 0, "allocations on the calling thread during 2000 steps");
        assert_eq!(common::worker_allocs() - workers, 0, "allocations on the worker during 2000 steps");
    });
    assert!(stagerl::base::par::split_jobs() > split, "work went to the worker");
}

fn no_allocation_in(cfg: stagerl::config::Config) {
    let mut env = stagerl::env::ReachEnv::from_config(&cfg, 1).unwrap();
    let mut venv = stagerl::env::VecEnv::from_config(4, &cfg, 1).unwrap();
    let actions: Vec<f32> = (0..4 * 6).map(|i| ((i * 7919) % 200) as f32 / 100.0 - 1.0).collect();
    env.reset();
    let before = allocs();
    let mut episodes = 0;
    for k in 0..10_000 {
        let a = &actions[(k % 4) * 6..(k % 4 + 1) * 6];
        if env.step(a).unwrap().done() {
            env.reset();
            episodes += 1;
        }
        venv.step(&actions).unwrap();
    }
    let after = allocs();
    assert!(episodes > 100, "resets were exercised: {episodes}");
    assert_eq!(after - before, 0, "allocations during 10 000 steps");
}

/// The eq. 16 rollout with the scripted controller and an observer allocates nothing either,
/// and its episode reward is the sum of the step rewards it observed.
#[test]
fn rollouts_allocate_nothing() {
    use stagerl::env::{rollout, Flow, Observed, Outcome, Scratch, Transition};
    let cfg = stagerl::config::Config::default();
    let mut env = stagerl::env::ReachEnv::from_config(&cfg, 2).unwrap();
    let mut ctl = stagerl::plan::controller::JacobianController::new(env.chain());
    let mut scratch = Scratch::new(&env);
    let (mut reached, mut observed, mut total) = (0, 0.0f64, 0.0f64);
    env.reset();
    let before = allocs();
    for _ in 0..200 {
        env.reset();
        let (mut sum, mut steps) = (0.0, 0u32);
        let observe = |t: &Transition<'_>| {
            sum += t.step.total();
            steps += 1;
            assert_eq!(t.env.steps(), steps);
            Ok(Flow::Continue)
        };
        let Outcome::Finished { reward, last } =
            rollout(&mut env, &mut scratch, &mut Observed(ctl.policy(), observe)).unwrap()
        else {
            panic!("nothing stops these rollouts")
        };
        assert!(last.done());
        reached += usize::from(last.reached());
        (observed, total) = (observed + sum, total + reward);
    }
    let after = allocs();
    assert_eq!(after - before, 0, "allocations during 200 rollouts");
    drop(std::hint::black_box(vec![1u8; 8]));
    assert!(allocs() > after, "the counter counts this thread's allocations");
    assert_eq!(observed, total, "the episode reward is the sum of the observed step rewards");
    assert!(reached > 190, "the controller reaches: {reached} of 200");
}

/// A driver's stop leaves the episode under way; the next rollout continues it.
#[test]
fn a_stopped_rollout_continues_where_it_stopped() {
    use stagerl::env::{rollout, Flow, Observed, Outcome, Scratch};
    let cfg = stagerl::config::Config::default();
    let mut env = stagerl::env::ReachEnv::from_config(&cfg, 3).unwrap();
    let mut scratch = Scratch::new(&env);
    env.reset();
    let zero = |_: &stagerl::env::ReachEnv, a: &mut [f32]| {
        a.fill(0.0);
        Ok(())
    };
    let stop_at_3 =
        |t: &stagerl::env::Transition<'_>| Ok(if t.env.steps() == 3 { Flow::Stop } else { Flow::Continue });
    let first = rollout(&mut env, &mut scratch, &mut Observed(zero, stop_at_3)).unwrap();
    assert_eq!((first, env.steps()), (Outcome::Stopped, 3));
    let rest = rollout(&mut env, &mut scratch, &mut stagerl::env::Policy(zero)).unwrap();
    assert!(matches!(rest, Outcome::Finished { last, .. } if last.truncated));
    assert_eq!(env.steps(), cfg.task.max_steps);
}
