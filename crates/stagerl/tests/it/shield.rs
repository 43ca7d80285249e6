//! The safety shield through the environment and the planner: refusals, no contact among
//! obstacles in the way, counts, and the unshielded environment untouched by the option.

use stagerl::config::Config;
use stagerl::env::{ReachEnv, Sim};
use stagerl::plan::Planner;
use stagerl::sim::scene::RandomObstacles;
use stagerl::sim::shield::ShieldConfig;

fn on() -> Option<ShieldConfig> {
    Some(ShieldConfig { enabled: true, ..Default::default() })
}

#[test]
fn the_dynamic_simulation_and_bad_values_are_refused_naming_the_field() {
    let mut cfg = Config::default();
    cfg.task.sim = Sim::Dynamic;
    cfg.task.shield = on();
    let e = cfg.resolve().unwrap_err().to_string();
    assert!(e.contains("task.shield.enabled") && e.contains("dynamic"), "{e}");
    let mut cfg = Config::default();
    cfg.task.shield = Some(ShieldConfig { enabled: true, influence_m: 0.001, ..Default::default() });
    let e = cfg.resolve().unwrap_err().to_string();
    assert!(e.contains("task.shield.influence_m"), "{e}");
    // Turned on later, on a dynamic environment: refused too.
    let mut cfg = Config::default();
    cfg.task.sim = Sim::Dynamic;
    let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
    let e = env.set_shield(true).unwrap_err().to_string();
    assert!(e.contains("task.shield.enabled"), "{e}");
}

/// Random obstacles, the first always in the way; the shielded Jacobian controller never
/// touches one, the unshielded one does.
#[test]
fn shielded_plans_among_obstacles_in_the_way_have_no_contact() {
    let mut cfg = Config::default();
    cfg.task.random_obstacles = Some(RandomObstacles::default());
    let mut plain = Planner::jacobian(&cfg, None).unwrap();
    let mut shielded = Planner::jacobian(&cfg, None).unwrap();
    shielded.set_shield(true).unwrap();
    let (mut contacts_plain, mut contacts_shielded, mut interventions) = (0, 0, 0);
    let mut rng = stagerl::base::rng::Rng::new(3);
    for _ in 0..60 {
        let target = [rng.uniform_range(0.2, 0.5), rng.uniform_range(-0.4, 0.4), rng.uniform_range(0.2, 0.6)];
        let a = plain.plan(&target, None).unwrap();
        let b = shielded.plan(&target, None).unwrap();
        contacts_plain += a.summary.collision_steps;
        contacts_shielded += b.summary.collision_steps;
        assert!(a.summary.shield.is_none());
        let s = b.summary.shield.unwrap();
        assert_eq!(s.shield_steps, u64::from(b.summary.steps));
        interventions += s.shield_interventions;
    }
    assert_eq!(contacts_shielded, 0);
    assert!(contacts_plain > 0 || interventions > 0, "the scenes test something");
}

#[test]
fn the_shield_off_changes_nothing_and_far_from_everything_on_changes_nothing_either() {
    let cfg = Config::default();
    let mut a = ReachEnv::from_config(&cfg, 5).unwrap();
    let mut b = ReachEnv::from_config(&cfg, 5).unwrap();
    b.set_shield(true).unwrap();
    b.set_shield(false).unwrap();
    let mut c = ReachEnv::from_config(&cfg, 5).unwrap();
    c.set_shield(true).unwrap();
    let actions: Vec<[f32; 6]> =
        (0..40).map(|k| [0.1, -0.1, 0.05 * (k % 3) as f32, 0.2, -0.2, 0.3]).collect();
    for env in [&mut a, &mut b, &mut c] {
        env.reset();
    }
    for act in &actions {
        let (sa, sb, sc) = (a.step(act).unwrap(), b.step(act).unwrap(), c.step(act).unwrap());
        assert_eq!(sa, sb);
        assert_eq!(a.joint_positions(), b.joint_positions());
        if c.shield_stats().unwrap().interventions == 0 {
            // The same step, but that the shielded one says what the shield changed: nothing.
            assert_eq!((sa.shield_change_rad_per_s, sc.shield_change_rad_per_s), (None, Some(0.0)));
            assert_eq!(sa, stagerl::env::Step { shield_change_rad_per_s: None, ..sc });
            assert_eq!(a.joint_positions(), c.joint_positions());
        }
        if sa.done() {
            break;
        }
    }
    assert!(a.shield_stats().is_none() && b.shield_stats().is_none());
}
