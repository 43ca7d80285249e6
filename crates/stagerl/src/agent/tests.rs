//! Agent-level tests: every algorithm runs, is deterministic, saves and loads exactly.

use super::*;
use crate::rng::Rng;

fn small_cfg(algo: Algo) -> AgentConfig {
    AgentConfig { algo, hidden: vec![32, 32], batch_size: 16, ..AgentConfig::default() }
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
    for algo in Algo::ALL {
        let run = || {
            let mut agent = build(&small_cfg(algo), 16, 6, 7).unwrap();
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
    for algo in Algo::ALL {
        let cfg = AgentConfig { gamma: 0.0, critic_lr: Some(1e-3), ..small_cfg(algo) };
        let mut agent = build(&cfg, 16, 6, 1).unwrap();
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
    for algo in Algo::ALL {
        let cfg = small_cfg(algo);
        let mut rng = Rng::new(9);
        let batch = random_batch(&mut rng, 16, 16, 6);
        let mut a = build(&cfg, 16, 6, 11).unwrap();
        for _ in 0..5 {
            a.update(&batch);
        }
        let mut ck = Checkpoint::new();
        a.save(&mut ck);
        let bytes = ck.to_bytes().unwrap();
        let ck = Checkpoint::from_bytes(&bytes, std::path::Path::new("mem")).unwrap();
        let mut b = build(&cfg, 16, 6, 999).unwrap();
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
        let mut c = build(&other, 16, 6, 1).unwrap();
        let e = c.load(&ck).unwrap_err().to_string();
        assert!(e.contains("shape"), "{algo}: {e}");
    }
}
