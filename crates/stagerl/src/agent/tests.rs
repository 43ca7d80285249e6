//! Agent-level tests: every algorithm runs, is deterministic, saves and loads exactly.

use super::parts::{Part, PartMut};
use super::*;
use crate::base::rng::Rng;

fn small_cfg(algo: Algo) -> AgentConfig {
    // CrossQ's critics 32 wide (its default, 1024, is for training runs).
    let crossq =
        (algo == Algo::Crossq).then(|| CrossqConfig { critic_hidden: vec![32, 32], ..Default::default() });
    AgentConfig { algo, hidden: vec![32, 32], batch_size: 16, crossq, ..AgentConfig::default() }
}

fn random_batch(rng: &mut Rng, b: usize, od: usize, ad: usize) -> Batch {
    let mut batch = Batch::new(b, od, ad);
    for x in batch.obs.iter_mut().chain(batch.next_obs.iter_mut()) {
        *x = rng.normal() as f32;
    }
    for x in batch.act.iter_mut() {
        *x = rng.uniform_range(-1.0, 1.0) as f32;
    }
    for i in 0..b {
        batch.reward[i] = rng.normal() as f32;
        batch.terminal[i] = f32::from(u8::from(rng.uniform() < 0.1));
    }
    batch
}

#[test]
fn every_algorithm_updates_acts_in_range_and_is_deterministic() {
    for algo in Algo::ALL.into_iter().filter(|a| a.is_off_policy()) {
        let run = || {
            let mut agent = build_off_policy(&small_cfg(algo), 16, 6, 7).unwrap();
            let mut rng = Rng::new(3);
            let batch = random_batch(&mut rng, 16, 16, 6);
            let mut stats = Vec::new();
            for _ in 0..20 {
                stats.push(agent.update(&batch));
            }
            let obs: Vec<f32> = (0..16).map(|i| i as f32 / 16.0).collect();
            let mut a = [0.0f32; 6];
            agent.act(&obs, &mut a);
            assert!(a.iter().all(|x| x.abs() <= 1.0), "{algo}: {a:?}");
            let mut p = [0.0f32; 6];
            agent.predict(&obs, &mut p);
            assert!(p.iter().all(|x| x.abs() <= 1.0), "{algo}: {p:?}");
            assert!(agent.first_non_finite().is_none());
            (stats.iter().map(|s| s.critic_loss).collect::<Vec<_>>(), a, p)
        };
        let (l1, a1, p1) = run();
        let (l2, a2, p2) = run();
        assert_eq!(l1, l2, "{algo}: same seed, same losses");
        assert_eq!((a1, p1), (a2, p2), "{algo}");
        assert!(l1.iter().all(|l| l.is_finite()));
    }
}

#[test]
fn critic_fits_a_fixed_target() {
    // With gamma 0 the critic target is the reward itself: the TD loss must fall.
    for algo in Algo::ALL.into_iter().filter(|a| a.is_off_policy()) {
        let cfg = AgentConfig { gamma: 0.0, critic_lr: Some(1e-3), ..small_cfg(algo) };
        let mut agent = build_off_policy(&cfg, 16, 6, 1).unwrap();
        let mut rng = Rng::new(5);
        let batch = random_batch(&mut rng, 16, 16, 6);
        let first = agent.update(&batch).critic_loss;
        let mut last = first;
        for _ in 0..300 {
            last = agent.update(&batch).critic_loss;
        }
        assert!(last < first * 0.05, "{algo}: critic loss {first} -> {last}");
    }
}

#[test]
fn save_load_round_trip_continues_identically() {
    for algo in Algo::ALL.into_iter().filter(|a| a.is_off_policy()) {
        let cfg = small_cfg(algo);
        let mut rng = Rng::new(9);
        let batch = random_batch(&mut rng, 16, 16, 6);
        let mut a = build_off_policy(&cfg, 16, 6, 11).unwrap();
        for _ in 0..5 {
            a.update(&batch);
        }
        let mut ck = Checkpoint::new();
        a.save(&mut ck);
        let bytes = ck.to_bytes().unwrap();
        let ck = Checkpoint::from_bytes(&bytes, std::path::Path::new("mem")).unwrap();
        let mut b = build_off_policy(&cfg, 16, 6, 999).unwrap();
        b.load(&ck).unwrap();
        for _ in 0..5 {
            assert_eq!(a.update(&batch), b.update(&batch), "{algo}");
        }
        let obs = [0.1f32; 16];
        let (mut x, mut y) = ([0.0f32; 6], [0.0f32; 6]);
        a.act(&obs, &mut x);
        b.act(&obs, &mut y);
        assert_eq!(x, y, "{algo}: exploration continues identically");
        // A different network shape is refused with the tensor's name.
        let other = AgentConfig { hidden: vec![16, 16], ..cfg.clone() };
        let mut c = build_off_policy(&other, 16, 6, 1).unwrap();
        let e = c.load(&ck).unwrap_err().to_string();
        assert!(e.contains("shape"), "{algo}: {e}");
    }
}

#[test]
fn ddpg_is_td3_with_one_critic_no_delay_and_no_smoothing() {
    let (od, ad) = (16, 6);
    let mut rng = Rng::new(2);
    let batch = random_batch(&mut rng, 16, od, ad);
    let mut ddpg = ddpg::new(&small_cfg(Algo::Ddpg), od, ad, 3);
    let mut td3 = Td3::new(&small_cfg(Algo::Td3), od, ad, 3);
    assert_eq!((ddpg.algo(), ddpg.num_critics()), (Algo::Ddpg, 1));
    assert_eq!((td3.algo(), td3.num_critics()), (Algo::Td3, 2));
    for i in 1..=6 {
        assert!(ddpg.update(&batch).actor_loss.is_some(), "DDPG updates its actor at update {i}");
        assert_eq!(td3.update(&batch).actor_loss.is_some(), i % 2 == 0, "TD3's policy delay 2, update {i}");
    }
    // No target smoothing: DDPG's updates draw no random numbers, so its exploration stream
    // after 6 updates is the one of a fresh agent.
    let obs = [0.3f32; 16];
    let mut fresh = ddpg::new(&small_cfg(Algo::Ddpg), od, ad, 3);
    let (mut a, mut b, mut pa, mut pb) = ([0.0f32; 6], [0.0f32; 6], [0.0f32; 6], [0.0f32; 6]);
    ddpg.predict(&obs, &mut pa);
    fresh.predict(&obs, &mut pb);
    ddpg.act(&obs, &mut a);
    fresh.act(&obs, &mut b);
    let noise = |x: &[f32; 6], p: &[f32; 6]| -> Vec<f32> { x.iter().zip(p).map(|(x, p)| x - p).collect() };
    assert_ne!(pa, pb, "the trained actor moved");
    for (na, nb) in noise(&a, &pa).iter().zip(noise(&b, &pb)) {
        // Equal noise draws, up to clipping at the action bounds.
        assert!((na - nb).abs() < 1e-6 || a.iter().chain(&b).any(|v| v.abs() == 1.0), "{a:?} {b:?}");
    }
}

/// The names of an agent's learned parts, by kind, in list order.
fn part_names(agent: &dyn Agent) -> (Vec<String>, Vec<String>) {
    let (mut nets, mut others) = (Vec::new(), Vec::new());
    agent.parts(&mut |name, part| match part {
        Part::Net(_) | Part::BnNet(_) => nets.push(name.to_string()),
        _ => others.push(name.to_string()),
    });
    (nets, others)
}

#[test]
fn one_list_of_parts_drives_save_load_and_the_guard() {
    // DDPG keeps its checkpoint names (`critic`, ...), TD3 and SAC theirs (`q1`, `q2`, ...).
    let expected: [(Algo, &[&str], &[&str]); 4] = [
        (
            Algo::Ddpg,
            &["actor", "critic", "actor_target", "critic_target"],
            &["actor_opt", "critic_opt", "agent_rng", "agent_noise", "agent_updates"],
        ),
        (
            Algo::Td3,
            &["actor", "q1", "q2", "actor_target", "q1_target", "q2_target"],
            &["actor_opt", "q1_opt", "q2_opt", "agent_rng", "agent_noise", "agent_updates"],
        ),
        (
            Algo::Sac,
            &["actor", "q1", "q2", "q1_target", "q2_target"],
            &["log_alpha", "actor_opt", "q1_opt", "q2_opt", "alpha_opt", "agent_rng"],
        ),
        (
            // CrossQ: no targets; the actor's inference and the batch-renormalised actor.
            Algo::Crossq,
            &["actor", "actor_bn", "q1", "q2"],
            &["log_alpha", "actor_opt", "q1_opt", "q2_opt", "alpha_opt", "agent_rng", "agent_updates"],
        ),
    ];
    for (algo, nets, rest) in expected {
        let mut agent = build_off_policy(&small_cfg(algo), 16, 6, 5).unwrap();
        let (names, others) = part_names(agent.as_ref());
        assert_eq!(names, nets, "{algo}");
        assert_eq!(others, rest, "{algo}");
        // Saving writes every part of the list, and nothing else.
        let mut ck = Checkpoint::new();
        agent.save(&mut ck);
        let mut written: Vec<String> = ck
            .tensor_names()
            .map(|t| t.split('.').next().unwrap().to_string())
            .chain(ck.metadata().keys().map(|k| k.split('.').next().unwrap().to_string()))
            .collect();
        written.sort();
        written.dedup();
        let mut listed: Vec<String> = names.iter().chain(&others).cloned().collect();
        listed.sort();
        assert_eq!(written, listed, "{algo}");
        // Loading reads every part: a checkpoint without one of them is refused, naming it.
        for missing in &listed {
            let mut partial = Checkpoint::new();
            for t in ck.tensor_names().filter(|t| t.split('.').next() != Some(missing)) {
                let (shape, data) = ck.tensor(t).unwrap();
                partial.put_tensor(t, shape, data);
            }
            for (k, v) in ck.metadata().iter().filter(|(k, _)| k.split('.').next() != Some(missing)) {
                partial.put_meta(k, v.clone());
            }
            let e = agent.load(&partial).expect_err(missing).to_string();
            assert!(e.contains(missing.as_str()), "{algo}: {e}");
        }
        // The guard checks every network of the list, naming it.
        for net in nets {
            agent.load(&ck).unwrap();
            assert_eq!(agent.first_non_finite(), None, "{algo}");
            agent.parts_mut(&mut |name, part| match (name == *net, part) {
                (true, PartMut::Net(m)) => m.params_mut()[3] = f32::NAN,
                (true, PartMut::BnNet(m)) => m.params_mut()[3] = f32::NAN,
                _ => {}
            });
            let fault = agent.first_non_finite().unwrap_or_else(|| panic!("{algo}: NaN in {net} unseen"));
            assert!(fault.starts_with(&format!("{net} parameter layer0.weight[3]")), "{algo}: {fault}");
        }
    }
}

/// SAC's `bc_weight`: on a batch whose half are demonstrations of one fixed action, the actor's
/// deterministic action moves to it (its distance falls to a fifth in 300 updates), and only
/// the demonstration rows pull (with `bc_weight = 0` it stays as far as it started); the
/// loss it reports includes the term.
#[test]
fn behaviour_cloning_pulls_the_actor_to_the_demonstrated_actions() {
    let (od, ad, b) = (3, 2, 8);
    let demo_act = [0.6f32, -0.4];
    let mut rng = Rng::new(11);
    let mut batch = random_batch(&mut rng, b, od, ad);
    for i in 0..b / 2 {
        batch.act[i * ad..(i + 1) * ad].copy_from_slice(&demo_act);
        batch.demo[i] = 1.0;
    }
    let distance = |agent: &mut sac::Sac| {
        let mut sum = 0.0f32;
        for i in 0..b / 2 {
            let mut a = [0.0f32; 2];
            agent.predict(&batch.obs[i * od..(i + 1) * od], &mut a);
            sum += a.iter().zip(&demo_act).map(|(x, y)| (x - y).powi(2)).sum::<f32>();
        }
        sum.sqrt()
    };
    let run = |w: f64| {
        let acfg = AgentConfig {
            hidden: vec![16, 16],
            batch_size: b,
            sac: Some(SacConfig { bc_weight: w, ..SacConfig::default() }),
            ..AgentConfig::new(Algo::Sac)
        };
        let mut agent = sac::Sac::new(&acfg, od, ad, 4);
        let start = distance(&mut agent);
        let mut loss = 0.0;
        for _ in 0..300 {
            loss = agent.update(&batch).actor_loss.unwrap();
        }
        (start, distance(&mut agent), loss)
    };
    let (start, cloned, loss_bc) = run(20.0);
    let (start0, plain, loss0) = run(0.0);
    assert_eq!(start, start0, "the same initial actor");
    assert!(cloned < 0.2 * start, "cloned: {start} -> {cloned}");
    assert!(plain > 0.5 * start, "without the term: {start} -> {plain}");
    assert!(loss_bc.is_finite() && loss_bc != loss0);
    let e = SacConfig { bc_weight: -1.0, ..SacConfig::default() }.validate().unwrap_err().to_string();
    assert!(e.contains("`agent.sac.bc_weight`") && e.contains("[0, 1e6]"), "{e}");
}
