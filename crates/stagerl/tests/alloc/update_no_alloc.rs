//! A warmed-up SAC, TD3, DDPG or CrossQ update allocates nothing (the matrix products included: their
//! packing buffers are on the stack): counted with a global allocator.

use crate::common;

use common::allocs;
use stagerl::agent::replay::Batch;
use stagerl::agent::{build_off_policy, AgentConfig, Algo, CrossqConfig, SacConfig};
use stagerl::base::rng::Rng;

/// As `stagerl bench update`: observations 16, actions 6, a random batch of 256.
fn no_allocation_in(algo: Algo, hidden: usize, updates: usize) {
    no_allocation_with(AgentConfig { algo, hidden: vec![hidden, hidden], ..AgentConfig::default() }, updates);
}

fn no_allocation_with(cfg: AgentConfig, updates: usize) {
    let (od, ad, b) = (16, 6, 256);
    let (algo, hidden) = (cfg.algo, cfg.hidden[0]);
    let cfg = AgentConfig { batch_size: b, ..cfg };
    let mut agent = build_off_policy(&cfg, od, ad, 0).unwrap();
    let mut rng = Rng::new(1);
    let mut batch = Batch::new(b, od, ad);
    for x in batch.obs.iter_mut().chain(batch.next_obs.iter_mut()).chain(batch.act.iter_mut()) {
        *x = rng.uniform_range(-1.0, 1.0) as f32;
    }
    for (i, r) in batch.reward.iter_mut().enumerate() {
        *r = rng.normal() as f32;
        batch.terminal[i] = f32::from(u8::from(i % 7 == 0));
    }
    // Warm-up: buffers grow to the batch; TD3's delayed actor update runs at least once.
    for _ in 0..4 {
        agent.update(&batch);
    }
    let before = allocs();
    let workers = common::worker_allocs();
    let mut loss = 0.0;
    for _ in 0..updates {
        loss += agent.update(&batch).critic_loss;
    }
    let after = allocs();
    // Only the test with a pool has workers (tests run at once: others' warm-ups would count).
    if stagerl::base::par::current_threads() > 1 {
        let on_workers = common::worker_allocs() - workers;
        assert_eq!(on_workers, 0, "allocations on pool workers during {updates} {algo:?} updates");
    }
    assert!(loss.is_finite());
    assert_eq!(after - before, 0, "allocations during {updates} {algo:?} updates at hidden {hidden}");
    drop(std::hint::black_box(vec![1u8; 8]));
    assert!(allocs() > after, "the counter counts this thread's allocations");
}

#[test]
fn sac_updates_allocate_nothing() {
    no_allocation_in(Algo::Sac, 64, 20);
    no_allocation_in(Algo::Sac, 256, 3);
}

/// REDQ: ten critics, two drawn per target, the actor on their mean; DroQ: dropout and layer
/// normalisation in the critics.
#[test]
fn redq_and_droq_updates_allocate_nothing() {
    let sac = SacConfig { n_critics: 10, critic_subset: Some(2), ..SacConfig::default() };
    no_allocation_with(AgentConfig { sac: Some(sac), hidden: vec![64, 64], ..AgentConfig::default() }, 20);
    let sac = SacConfig { critic_dropout: 0.01, critic_layer_norm: true, ..SacConfig::default() };
    no_allocation_with(AgentConfig { sac: Some(sac), hidden: vec![64, 64], ..AgentConfig::default() }, 20);
}

/// With observation normalisation (`agent.norm_obs`): each update normalises its batch into
/// buffers allocated once.
#[test]
fn normalised_updates_allocate_nothing() {
    let norm_obs = Some(stagerl::agent::obs_norm::ObsNormConfig::default());
    for algo in [Algo::Sac, Algo::Td3, Algo::Ddpg] {
        no_allocation_with(
            AgentConfig { algo, norm_obs, hidden: vec![64, 64], ..AgentConfig::default() },
            20,
        );
    }
}

/// CrossQ: batch-renormalised critics (their joint pass of 2 x 256 rows) and actor, the critics
/// folded for the actor's step (its delayed step runs at the 3rd warm-up update and in the
/// counted ones); with observation normalisation too.
fn crossq(critic: usize, norm: bool) -> AgentConfig {
    let crossq = CrossqConfig { critic_hidden: vec![critic, critic], ..CrossqConfig::default() };
    let norm_obs = norm.then(stagerl::agent::obs_norm::ObsNormConfig::default);
    AgentConfig {
        algo: Algo::Crossq,
        crossq: Some(crossq),
        norm_obs,
        hidden: vec![64, 64],
        ..AgentConfig::default()
    }
}

#[test]
fn crossq_updates_allocate_nothing() {
    no_allocation_with(crossq(256, false), 10);
    no_allocation_with(crossq(64, true), 20);
}

#[test]
fn td3_updates_allocate_nothing() {
    no_allocation_in(Algo::Td3, 64, 20);
}

#[test]
fn ddpg_updates_allocate_nothing() {
    no_allocation_in(Algo::Ddpg, 64, 20);
}

/// On two threads (twin critics at once, wide products split): after the warm-up (whose buffers
/// may grow on either thread) nothing allocates on the caller or on the pool's worker.
#[test]
fn updates_on_two_threads_allocate_nothing() {
    let _alone = common::POOL_TESTS.lock().unwrap_or_else(|p| p.into_inner());
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    let split = stagerl::base::par::split_jobs();
    stagerl::base::par::install(Some(&pool), || {
        for algo in [Algo::Sac, Algo::Td3, Algo::Ddpg] {
            no_allocation_in(algo, 64, 10);
        }
        no_allocation_in(Algo::Sac, 256, 2);
        let sac = SacConfig { n_critics: 10, critic_subset: Some(2), ..SacConfig::default() };
        no_allocation_with(
            AgentConfig { sac: Some(sac), hidden: vec![64, 64], ..AgentConfig::default() },
            10,
        );
        let sac = SacConfig { critic_dropout: 0.01, critic_layer_norm: true, ..SacConfig::default() };
        no_allocation_with(
            AgentConfig { sac: Some(sac), hidden: vec![64, 64], ..AgentConfig::default() },
            10,
        );
        no_allocation_with(crossq(256, false), 6);
    });
    assert!(stagerl::base::par::split_jobs() > split, "work went to the worker");
}
