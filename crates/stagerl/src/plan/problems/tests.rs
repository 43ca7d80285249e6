//! The benchmark's problem sets: seeded, each of its kind, refusals counted.

use super::*;

fn set(s: ProblemSet, n: usize, seed: u64) -> Vec<Problem> {
    draw_problems(&Config::default(), s, n, seed, &mut |_| true).unwrap().0
}

#[test]
fn the_same_seed_draws_the_same_problems_and_another_seed_others() {
    for s in ProblemSet::ALL {
        assert_eq!(set(s, 6, 3), set(s, 6, 3), "{s:?}");
        assert_ne!(set(s, 6, 3), set(s, 6, 4), "{s:?}");
        // A set's first problems do not depend on how many are drawn.
        assert_eq!(set(s, 3, 3)[..], set(s, 6, 3)[..3], "{s:?}");
    }
}

#[test]
fn each_set_has_its_kind_of_scene() {
    let env = ReachEnv::from_config(&Config::default(), 0).unwrap();
    let chain = env.chain().clone();
    let mut c = ArmCollider::new(&chain, env.task().collision);
    for s in ProblemSet::ALL {
        for p in set(s, 20, 1) {
            let want = match s {
                ProblemSet::Free => 0,
                ProblemSet::InTheWay => 1,
                ProblemSet::Random3 => 3,
                ProblemSet::Random6 => 6,
                ProblemSet::NarrowGap => 2,
            };
            assert_eq!(p.obstacles.len(), want, "{s:?} {}", p.id);
            assert_eq!(p.start_rad, env.task().home_pose);
            c.set_obstacles(&p.obstacles);
            assert!(c.check(&chain, &p.start_rad).is_none(), "{s:?} {}: the start pose touches", p.id);
            for o in &p.obstacles {
                assert!(
                    o.distance_to_point_m(p.target_m) >= 0.05 - 1e-12,
                    "{s:?} {}: target too close",
                    p.id
                );
            }
            let from = chain.fk(&p.start_rad).position;
            let to = Vector3::from(p.target_m);
            if s == ProblemSet::InTheWay {
                assert!(crosses_segment(&p.obstacles[0], from, to), "{}: not in the way", p.id);
            }
            if s == ProblemSet::NarrowGap {
                // The line passes through the gap: the middle of the line is GAP_M / 2 from each box.
                let mid = (from + to) / 2.0;
                for o in &p.obstacles {
                    let d = o.distance_to_point_m(mid.into());
                    assert!((d - GAP_M / 2.0).abs() < 1e-9, "{}: {d}", p.id);
                }
            }
        }
    }
}

#[test]
fn refused_candidates_are_counted_and_an_impossible_set_is_an_error() {
    let mut k = 0;
    let (p, refused) = draw_problems(&Config::default(), ProblemSet::Free, 5, 0, &mut |_| {
        k += 1;
        k % 2 == 0
    })
    .unwrap();
    assert_eq!((p.len(), refused), (5, 5));
    assert!(p.iter().enumerate().all(|(i, p)| p.id == i));
    let e =
        draw_problems(&Config::default(), ProblemSet::Random3, 2, 0, &mut |_| false).unwrap_err().to_string();
    assert!(e.contains("`random-3`") && e.contains("only 0 of 2") && e.contains("not solvable"), "{e}");
}

/// A run's config with the per-link observation and the clearance term, or the bundled
/// obstacle preset (its curriculum too), draws the problems of the default config: neither what
/// a policy observes, nor its reward, nor its training schedule changes them.
#[test]
fn the_problems_do_not_depend_on_the_observation_the_clearance_term_or_the_curriculum() {
    let mut cfg = Config::default();
    cfg.task.random_obstacles = Some(crate::sim::scene::RandomObstacles::default());
    cfg.task.observe_obstacles = true;
    cfg.task.obstacle_observation = crate::env::ObstacleObservation::PerLink;
    cfg.reward.clearance = Some(crate::reward::ClearanceConfig::default());
    let preset = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/obstacles.toml");
    let preset = Config::load(&preset).unwrap();
    assert!(preset.train.curriculum.is_some(), "the preset trains with a curriculum");
    for cfg in [cfg, preset] {
        for set in [ProblemSet::Free, ProblemSet::InTheWay] {
            let mine = draw_problems(&cfg, set, 4, 3, &mut |_| true).unwrap().0;
            let plain = draw_problems(&Config::default(), set, 4, 3, &mut |_| true).unwrap().0;
            assert_eq!(format!("{mine:?}"), format!("{plain:?}"), "{set:?}");
        }
    }
}
