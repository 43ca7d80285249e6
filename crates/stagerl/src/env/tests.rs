//! Tests of `env`.

use super::*;
use crate::reward::RewardFunction;

/// The default task on the UR5 with `reward`.
pub(crate) fn ur5_env(reward: RewardConfig, seed: u64) -> ReachEnv {
    let chain = Arc::new(Chain::ur5());
    let task = TaskConfig::default().resolve(&chain).unwrap();
    ReachEnv::new(chain, task, reward, seed).unwrap()
}

fn env(seed: u64) -> ReachEnv {
    ur5_env(RewardConfig::default(), seed)
}

#[test]
fn reset_starts_at_home_with_a_target_above_the_floor() {
    let mut e = env(1);
    let mut dists = Vec::new();
    for _ in 0..300 {
        e.reset();
        assert_eq!(e.joint_positions(), &task::UR5_HOME_POSE_RAD);
        assert!(e.target().z > 0.05);
        dists.push(e.distance());
    }
    let mean = dists.iter().sum::<f64>() / dists.len() as f64;
    // Design notes: the mean start distance is about 0.44 m, so both HAR stages occur.
    assert!((0.35..0.55).contains(&mean), "mean start distance {mean}");
    assert!(dists.iter().any(|&d| d > 0.5) && dists.iter().any(|&d| d < 0.5));
}

#[test]
fn observation_layout() {
    let mut e = env(2);
    e.reset();
    let o = e.observation().to_vec();
    assert_eq!(o.len(), 16);
    let (p, t) = (e.ee_pose().position, e.target());
    for k in 0..6 {
        assert_eq!(o[k], (e.joint_positions()[k] / PI) as f32);
    }
    for k in 0..3 {
        assert_eq!(o[6 + k], p[k] as f32);
        assert_eq!(o[9 + k], t[k] as f32);
        assert_eq!(o[12 + k], ((t[k] - p[k]) * 10.0) as f32);
    }
    assert_eq!(o[15], (e.distance() * 10.0) as f32);
}

/// For every observation option (no obstacles; fixed or random ones observed absolute,
/// nearest, with and without a range, or per link; a 7-joint arm), the layout's entries tile the
/// observation from 0 without gap, their sizes sum to its length, and every value of a few
/// random episodes stays within the layout's bounds.
#[test]
fn the_layout_describes_every_value_of_every_observation_option() {
    let chain = Arc::new(Chain::ur5());
    let random = || Some(crate::sim::scene::RandomObstacles { count: [1, 3], ..Default::default() });
    let fixed = vec![crate::sim::scene::Obstacle::sphere(0.05, [0.0, 0.6, 0.3])];
    let nearest = ObstacleObservation::Nearest;
    let options = [
        TaskConfig::default(),
        TaskConfig { obstacles: fixed.clone(), ..TaskConfig::default() },
        TaskConfig { obstacles: fixed.clone(), observe_obstacles: true, ..TaskConfig::default() },
        TaskConfig { random_obstacles: random(), observe_obstacles: true, ..TaskConfig::default() },
        TaskConfig {
            obstacles: fixed,
            random_obstacles: random(),
            observe_obstacles: true,
            obstacle_observation: nearest,
            ..TaskConfig::default()
        },
        TaskConfig {
            random_obstacles: random(),
            observe_obstacles: true,
            obstacle_observation: nearest,
            obstacle_range_m: Some(0.15),
            ..TaskConfig::default()
        },
        TaskConfig {
            random_obstacles: random(),
            observe_obstacles: true,
            obstacle_observation: ObstacleObservation::PerLink,
            ..TaskConfig::default()
        },
    ];
    let mut envs: Vec<ReachEnv> = options
        .into_iter()
        .map(|t| {
            ReachEnv::new(chain.clone(), t.resolve(&chain).unwrap(), RewardConfig::default(), 3).unwrap()
        })
        .collect();
    envs.push(panda_env(Vec::new(), None));
    let mut slots_seen = Vec::new();
    for env in &mut envs {
        let layout = ObservationLayout::of(env.task());
        let entries = layout.entries(env.task(), env.chain());
        let mut next = 0;
        for e in &entries {
            assert_eq!(e.start, next, "{} starts where the one before ends", e.name);
            assert!(e.size > 0 && !e.value.is_empty());
            next += e.size;
        }
        assert_eq!(next, env.obs_dim());
        assert_eq!(layout.dim(), env.obs_dim());
        assert_eq!(entries.len(), 5 + layout.obstacle_slots());
        slots_seen.push(layout.obstacle_slots());
        let (lo, hi) = layout.bounds(env.task(), env.chain());
        let mut rng = Rng::new(9);
        let mut action = vec![0.0f32; env.act_dim()];
        for _ in 0..5 {
            env.reset();
            while !env.is_done() {
                for (i, x) in env.observation().iter().enumerate() {
                    assert!(lo[i] <= *x && *x <= hi[i], "value {i} = {x} within [{}, {}]", lo[i], hi[i]);
                }
                action.iter_mut().for_each(|a| *a = rng.uniform_range(-1.0, 1.0) as f32);
                env.step(&action).unwrap();
            }
        }
    }
    // The per-link encoding: one slot per collision shape of the UR5 (14), whatever the count.
    assert_eq!(slots_seen, [0, 0, 1, 3, 4, 3, 14, 0]);
}

#[test]
fn action_is_clipped_scaled_and_applied_velocity_is_reported() {
    let mut e = env(3);
    e.reset();
    let q0 = e.joint_positions().to_vec();
    let s = e.step(&[5.0, -5.0, 0.5, 0.0, 0.0, -0.25]).unwrap();
    let q1 = e.joint_positions();
    let dt = 0.05;
    let expect = [PI, -PI, 0.5 * PI, 0.0, 0.0, -0.25 * PI];
    for i in 0..6 {
        assert!((q1[i] - (q0[i] + expect[i] * dt)).abs() < 1e-12, "joint {i}");
        assert!((e.joint_velocities()[i] - expect[i]).abs() < 1e-9, "joint {i}");
    }
    // The movement term sees the applied velocity (eq. 9).
    let vv: f64 = expect.iter().map(|v| v * v).sum();
    assert!((s.terms.movement - dt * vv / 6.0).abs() < 1e-9);
}

#[test]
fn joint_limits_clamp_and_the_reported_velocity_follows() {
    let mut e = env(4);
    e.reset();
    // The elbow starts at pi/2 with limit pi: 20 full-speed steps would go to 3.5 pi/2.
    for _ in 0..20 {
        if e.step(&[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).unwrap().done() {
            break;
        }
    }
    assert!(e.joint_positions()[2] <= PI);
    assert!((e.joint_positions()[2] - PI).abs() < 1e-12);
    // Once clamped, the applied velocity is zero.
    assert!(e.joint_velocities()[2].abs() < 1e-9);
}

#[test]
fn truncates_at_max_steps_and_refuses_to_step_after() {
    let mut e = env(5);
    e.reset();
    let mut last = None;
    for k in 1..=50 {
        let s = e.step(&[0.0; 6]).unwrap();
        assert!(!s.terminated);
        assert_eq!(s.truncated, k == 50);
        last = Some(s);
    }
    assert!(last.unwrap().truncated);
    let err = e.step(&[0.0; 6]).unwrap_err().to_string();
    assert!(err.contains("reset"), "{err}");
}

#[test]
fn bad_actions_are_errors_not_clamps() {
    let mut e = env(6);
    e.reset();
    assert!(e.step(&[0.0; 5]).unwrap_err().to_string().contains("6 joints"));
    let err = e.step(&[0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0]).unwrap_err().to_string();
    assert!(err.contains("action[1]"), "{err}");
    let err = e.step(&[0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0]).unwrap_err().to_string();
    assert!(err.contains("action[3]"), "{err}");
    // The failed calls did not advance the episode.
    assert_eq!(e.steps(), 0);
}

#[test]
fn success_terminates_with_the_bonus() {
    let mut e = env(7);
    e.reset();
    // Put the target where one known action will take the end-effector.
    let mut probe = e.clone();
    probe.step(&[0.3, -0.2, 0.1, 0.0, 0.4, 0.0]).unwrap();
    let reached_at = probe.ee_pose().position + Vector3::new(0.004, 0.0, 0.0);
    e.reset_to_target(reached_at).unwrap();
    let s = e.step(&[0.3, -0.2, 0.1, 0.0, 0.4, 0.0]).unwrap();
    assert!(s.terminated && !s.truncated);
    assert!((s.terms.distance - 0.004).abs() < 1e-12);
    assert_eq!(s.terms.bonus, 20.0);
    assert_eq!(s.total(), s.terms.reward + 20.0);
    assert!(e.is_done());
}

#[test]
fn same_seed_same_episodes() {
    let run = |seed| {
        let mut e = env(seed);
        let mut rng = Rng::new(99);
        let mut out = Vec::new();
        for _ in 0..5 {
            e.reset();
            out.push(e.target());
            loop {
                let a: Vec<f32> = (0..6).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
                let s = e.step(&a).unwrap();
                out.push(Vector3::new(s.total(), s.terms.distance, 0.0));
                if s.done() {
                    break;
                }
            }
        }
        out
    };
    assert_eq!(run(11), run(11));
    assert_ne!(run(11), run(12));
}

#[test]
fn state_restore_continues_identically() {
    let mut a = env(31);
    a.reset();
    a.step(&[0.2, -0.1, 0.3, 0.0, 0.5, -0.4]).unwrap();
    let saved = a.state();
    let mut b = env(999);
    b.restore(&saved).unwrap();
    assert_eq!(a.observation(), b.observation());
    for _ in 0..3 {
        let sa = a.step(&[0.1; 6]).unwrap();
        let sb = b.step(&[0.1; 6]).unwrap();
        assert_eq!(sa, sb);
    }
    a.reset();
    b.reset();
    assert_eq!(a.target(), b.target());
    let bad = EnvState { q: vec![0.0; 5], ..saved };
    assert!(b.restore(&bad).is_err());
}

#[test]
fn reward_function_selects_the_reward() {
    for f in RewardFunction::ALL {
        let mut e = ur5_env(RewardConfig { function: f, ..RewardConfig::default() }, 8);
        e.reset();
        let s = e.step(&[0.1; 6]).unwrap();
        let t = s.terms;
        let expect = match f {
            RewardFunction::Basic => t.basic,
            RewardFunction::Posture => t.posture,
            RewardFunction::Stride => t.stride,
            RewardFunction::Har => t.har,
            RewardFunction::Sar => t.sar,
        };
        assert_eq!(t.reward, expect, "{f}");
    }
}

fn panda_env(
    obstacles: Vec<crate::sim::scene::Obstacle>,
    checks: Option<crate::sim::collision::Checks>,
) -> ReachEnv {
    panda_env_with(obstacles, checks, OnCollision::Record, None)
}

fn panda_env_with(
    obstacles: Vec<crate::sim::scene::Obstacle>,
    checks: Option<crate::sim::collision::Checks>,
    on_collision: OnCollision,
    collision_penalty: Option<f64>,
) -> ReachEnv {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/robots/panda.urdf");
    let chain = Arc::new(Chain::from_urdf_file(std::path::Path::new(path), None).unwrap());
    let task = TaskConfig {
        home_pose_rad: Some(PANDA_HOME.to_vec()),
        target_joint_range_rad: Some(vec![0.8, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0]),
        obstacles,
        collision: checks,
        on_collision,
        ..TaskConfig::default()
    };
    let task = task.resolve(&chain).unwrap();
    ReachEnv::new(chain, task, RewardConfig { collision_penalty, ..RewardConfig::default() }, 3).unwrap()
}

const PANDA_HOME: [f64; 7] = {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
    [0.0, -FRAC_PI_4, 0.0, -3.0 * FRAC_PI_4, 0.0, FRAC_PI_2, FRAC_PI_4]
};

/// Contacts are found at reset and after each step, named, and recorded in the step; they
/// change nothing else: with the checks off, the same steps give the same bits.
#[test]
fn collisions_are_recorded_and_change_nothing_else() {
    use crate::sim::collision::{Checks, CollisionKind, Contact};
    use crate::sim::scene::Obstacle;
    let mut env = panda_env(Vec::new(), None);
    env.reset();
    assert_eq!(env.contact(), None, "the home pose is clear");
    // A pose with the flange below the floor (shoulder forward, elbow open).
    let low = [0.0, 1.7, 0.0, -0.5, 0.0, 1.57, 0.0];
    let target = Vector3::new(0.5, 0.0, 0.3);
    env.reset_to(&low, target).unwrap();
    let c = env.contact().expect("a contact below the floor");
    assert_eq!(c.kind(), CollisionKind::Floor);
    assert!(c.describe(env.chain()).contains("with the floor"), "{}", c.describe(env.chain()));
    let step = env.step(&[0.0; 7]).unwrap();
    assert_eq!(step.collision, Some(CollisionKind::Floor));
    // An obstacle at the tool of the home pose.
    let tool = env.chain().fk(&PANDA_HOME).position;
    let ball = Obstacle::sphere(0.05, [tool.x, tool.y, tool.z]);
    let mut env = panda_env(vec![ball], None);
    env.reset();
    assert!(matches!(env.contact(), Some(Contact::Obstacle { obstacle: 0, .. })));
    // Recording changes nothing: the same random steps with all checks off.
    let mut on = panda_env(Vec::new(), None);
    let mut off = panda_env(Vec::new(), Some(Checks { floor: false, self_collision: false }));
    let (mut rng, mut seen) = (Rng::new(9), 0);
    for _ in 0..20 {
        assert_eq!(on.reset(), off.reset());
        while !on.is_done() {
            let a: Vec<f32> = (0..7).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
            let (x, y) = (on.step(&a).unwrap(), off.step(&a).unwrap());
            assert_eq!(x.terms, y.terms);
            assert_eq!((x.terminated, x.truncated), (y.terminated, y.truncated));
            assert_eq!(on.observation(), off.observation());
            assert_eq!(y.collision, None);
            seen += usize::from(x.collision.is_some());
        }
    }
    assert!(seen > 0, "random motion touched something at least once");
}

/// `task.on_collision = "terminate"`: the first step that ends in contact ends the episode,
/// not as a success, with the penalty taken off what the agent receives; the count of
/// contact steps is kept per episode. With `"record"` the same steps go on.
#[test]
fn terminate_on_collision_ends_the_episode_with_the_penalty() {
    let low = [0.0, 1.7, 0.0, -0.5, 0.0, 1.57, 0.0];
    let target = Vector3::new(0.5, 0.0, 0.3);
    let mut rec = panda_env(Vec::new(), None);
    let mut term = panda_env_with(Vec::new(), None, OnCollision::Terminate, Some(5.0));
    rec.reset_to(&low, target).unwrap();
    term.reset_to(&low, target).unwrap();
    let (a, b) = (rec.step(&[0.0; 7]).unwrap(), term.step(&[0.0; 7]).unwrap());
    assert_eq!(a.collision, Some(CollisionKind::Floor));
    assert!(!a.done() && rec.collision_steps() == 1);
    assert!(b.terminated && !b.truncated && !b.reached() && term.is_done());
    assert_eq!(b.terms.reward, a.terms.reward);
    assert_eq!(b.total(), a.total() - 5.0);
    assert_eq!(term.collision_steps(), 1);
    // The count goes on in record mode and starts again with each episode.
    rec.step(&[0.0; 7]).unwrap();
    assert_eq!(rec.collision_steps(), 2);
    assert_eq!(rec.state().collision_steps, 2);
    rec.reset();
    assert_eq!(rec.collision_steps(), 0);
    // Without a penalty, the episode still ends and loses nothing.
    let mut free = panda_env_with(Vec::new(), None, OnCollision::Terminate, None);
    free.reset_to(&low, target).unwrap();
    let c = free.step(&[0.0; 7]).unwrap();
    assert!(c.terminated && c.total() == a.total());
    // Clear of everything, terminate mode runs the same episodes as record mode.
    let mut x = panda_env(Vec::new(), None);
    let mut y = panda_env_with(Vec::new(), None, OnCollision::Terminate, Some(5.0));
    for _ in 0..5 {
        assert_eq!(x.reset(), y.reset());
        while !x.is_done() && x.contact().is_none() {
            let (p, q) = (x.step(&[0.1; 7]).unwrap(), y.step(&[0.1; 7]).unwrap());
            if p.collision.is_none() {
                assert_eq!(p, q);
            }
        }
    }
}

/// The penalty without "terminate", or "terminate" on an arm without collision shapes, is a
/// config error naming the field.
#[test]
fn collision_settings_that_cannot_work_are_errors() {
    let reward = RewardConfig { collision_penalty: Some(1.0), ..RewardConfig::default() };
    let e = check_collision_settings(OnCollision::Record, &reward).unwrap_err().to_string();
    assert!(e.contains("reward.collision_penalty") && e.contains("terminate"), "{e}");
    assert!(check_collision_settings(OnCollision::Terminate, &reward).is_ok());
    let bad = RewardConfig { collision_penalty: Some(-1.0), ..RewardConfig::default() };
    assert!(bad.validate().unwrap_err().to_string().contains("reward.collision_penalty"));
    let xml = r#"<robot name="bare"><link name="a"/><link name="b"/>
        <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
        <origin xyz="0 0 0.3"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>"#;
    let chain = Arc::new(Chain::from_urdf_str(xml, None).unwrap());
    let task = TaskConfig {
        home_pose_rad: Some(vec![0.0]),
        target_joint_range_rad: Some(vec![1.0]),
        target_min_z_m: 0.0,
        on_collision: OnCollision::Terminate,
        ..TaskConfig::default()
    };
    let task = task.resolve(&chain).unwrap();
    let e = ReachEnv::new(chain, task, RewardConfig::default(), 1).unwrap_err().to_string();
    assert!(e.contains("task.on_collision") && e.contains("collision shape"), "{e}");
}

fn random_obstacles_env(seed: u64, observe: bool) -> ReachEnv {
    let chain = Arc::new(Chain::ur5());
    let task = TaskConfig {
        obstacles: vec![crate::sim::scene::Obstacle::sphere(0.05, [0.0, 0.6, 0.3])],
        random_obstacles: Some(crate::sim::scene::RandomObstacles { count: [2, 5], ..Default::default() }),
        observe_obstacles: observe,
        ..TaskConfig::default()
    };
    ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), RewardConfig::default(), seed).unwrap()
}

/// `set_obstacles_in_path`: with 1, the first random obstacle stands across the straight
/// line from the start end effector to the target in most episodes (with 0, in few), still
/// clear of the start pose and of the target; 0 spends no random number (the same episodes
/// as an environment never set); bad fractions are refused by name.
#[test]
fn obstacles_in_path_stand_in_the_way() {
    let chain = Arc::new(Chain::ur5());
    let task = TaskConfig {
        random_obstacles: Some(crate::sim::scene::RandomObstacles { count: [1, 1], ..Default::default() }),
        ..TaskConfig::default()
    };
    let env = |seed| {
        ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), RewardConfig::default(), seed).unwrap()
    };
    let mut checker =
        crate::sim::collision::ArmCollider::new(&chain, crate::sim::collision::Checks::default());
    let mut blocked_share = |fraction: f64| {
        let mut e = env(11);
        e.set_obstacles_in_path(fraction).unwrap();
        let mut blocked = 0;
        for _ in 0..400 {
            e.reset();
            let (o, from, to) = (&e.obstacles()[0], e.ee_pose().position, e.target());
            assert!(o.distance_to_point_m(to.into()) >= 0.05);
            assert!(!checker.touches(&chain, e.joint_positions(), o));
            let region = [(-0.6, 0.6), (-0.6, 0.6), (0.0, 0.7)];
            assert!(o.position_m.iter().zip(region).all(|(p, (lo, hi))| (lo..=hi).contains(p)));
            let on_line = |u: f64| o.distance_to_point_m((from + u * (to - from)).into());
            blocked += usize::from((0..=100).any(|i| on_line(f64::from(i) / 100.0) <= 0.01));
        }
        blocked as f64 / 400.0
    };
    let (never, half, always) = (blocked_share(0.0), blocked_share(0.5), blocked_share(1.0));
    assert!(
        never < 0.2 && always > 0.6 && half > never + 0.15 && half < always - 0.15,
        "{never} {half} {always}"
    );

    let (mut a, mut b) = (env(5), env(5));
    b.set_obstacles_in_path(0.0).unwrap();
    for _ in 0..50 {
        a.reset();
        b.reset();
        assert_eq!((a.obstacles(), a.target()), (b.obstacles(), b.target()));
    }
    // Placed in the way from a side stream: the same targets and the same later obstacles.
    let two = TaskConfig {
        random_obstacles: Some(crate::sim::scene::RandomObstacles { count: [2, 2], ..Default::default() }),
        ..TaskConfig::default()
    };
    let env2 =
        || ReachEnv::new(chain.clone(), two.resolve(&chain).unwrap(), RewardConfig::default(), 8).unwrap();
    let (mut plain, mut biased) = (env2(), env2());
    biased.set_obstacles_in_path(1.0).unwrap();
    let mut moved = 0;
    for _ in 0..50 {
        plain.reset();
        biased.reset();
        assert_eq!((plain.target(), &plain.obstacles()[1..]), (biased.target(), &biased.obstacles()[1..]));
        moved += usize::from(plain.obstacles()[0] != biased.obstacles()[0]);
    }
    assert!(moved > 40, "{moved} of 50 first obstacles placed in the way");
    for bad in [-0.1, 1.5, f64::NAN] {
        let e = a.set_obstacles_in_path(bad).unwrap_err().to_string();
        assert!(e.contains("train.obstacles_in_path") && e.contains("[0, 1]"), "{e}");
    }
    let plain_task = TaskConfig::default().resolve(&chain).unwrap();
    let mut plain = ReachEnv::new(chain.clone(), plain_task, RewardConfig::default(), 1).unwrap();
    let e = plain.set_obstacles_in_path(0.5).unwrap_err().to_string();
    assert!(e.contains("train.obstacles_in_path") && e.contains("task.random_obstacles"), "{e}");
    plain.set_obstacles_in_path(0.0).unwrap();
}

/// Random obstacles: a count in range each episode, each clear of the start pose and of the
/// target, drawn from the seed; observed in their slots; restored with the state.
#[test]
fn random_obstacles_are_placed_clear_of_the_start_and_the_target() {
    let mut env = random_obstacles_env(4, true);
    assert_eq!(env.obs_dim(), 16 + 7 * (1 + 5));
    let mut checker =
        crate::sim::collision::ArmCollider::new(env.chain(), crate::sim::collision::Checks::default());
    let (mut counts, mut hit) = (std::collections::BTreeSet::new(), 0);
    for _ in 0..200 {
        env.reset();
        let (obstacles, n) = (env.obstacles().to_vec(), env.obstacles().len() - 1);
        assert!((2..=5).contains(&n), "{n} random obstacles");
        counts.insert(n);
        assert_eq!(obstacles[0].position_m, [0.0, 0.6, 0.3], "the fixed one first");
        for o in &obstacles[1..] {
            assert!(o.distance_to_point_m(env.target().into()) >= 0.05);
            assert!(!checker.touches(env.chain(), env.joint_positions(), o));
            assert!(o.position_m.iter().zip([0.6, 0.6, 0.7]).all(|(p, m)| p.abs() <= m));
        }
        let obs = env.observation();
        for (i, o) in obstacles.iter().enumerate() {
            let slot = &obs[16 + 7 * i..16 + 7 * (i + 1)];
            assert_eq!(slot[..3], o.position_m.map(|x| x as f32));
            assert_eq!(slot[3..6], o.half_size_m().map(|x| x as f32));
            assert_eq!(slot[6], if o.radius_m.is_some() { 1.0 } else { 0.0 });
        }
        assert!(obs[16 + 7 * obstacles.len()..].iter().all(|&x| x == 0.0), "empty slots are zeros");
        while !env.is_done() {
            hit += usize::from(env.step(&[0.4, 0.3, -0.3, 0.0, 0.0, 0.0]).unwrap().collision.is_some());
        }
    }
    assert_eq!(counts.len(), 4, "every count of 2..=5 occurs: {counts:?}");
    assert!(hit > 0, "the arm runs into some of them");
    // The same seed draws the same obstacles; another seed others.
    let (mut a, mut b, mut c) =
        (random_obstacles_env(9, false), random_obstacles_env(9, false), random_obstacles_env(10, false));
    assert_eq!(a.obs_dim(), 16);
    a.reset();
    b.reset();
    c.reset();
    assert_eq!(a.obstacles(), b.obstacles());
    assert_ne!(a.obstacles(), c.obstacles());
    // A state mid-episode restores the episode's obstacles.
    a.step(&[0.1; 6]).unwrap();
    let saved = a.state();
    assert_eq!(saved.random_obstacles, a.obstacles()[1..].to_vec());
    let mut d = random_obstacles_env(77, false);
    d.reset();
    d.restore(&saved).unwrap();
    assert_eq!(d.obstacles(), a.obstacles());
    for _ in 0..10 {
        assert_eq!(
            a.step(&[0.5, 0.2, 0.1, 0.0, 0.0, 0.0]).unwrap(),
            d.step(&[0.5, 0.2, 0.1, 0.0, 0.0, 0.0]).unwrap()
        );
        if a.is_done() {
            break;
        }
    }
    let too_many = EnvState { random_obstacles: vec![a.obstacles()[1].clone(); 6], ..saved };
    assert!(d.restore(&too_many).unwrap_err().to_string().contains("6 random obstacles"));
}

/// `task.obstacle_observation = "nearest"`: slots nearest first, relative to the end effector
/// and scaled; empty slots read as far away; every value within the bounds the Python
/// observation space uses; the same episodes as the absolute encoding (only the
/// observation differs).
#[test]
fn nearest_obstacle_observation_orders_and_scales_the_slots() {
    let chain = Arc::new(Chain::ur5());
    let make = |encoding| {
        let task = TaskConfig {
            obstacles: vec![crate::sim::scene::Obstacle::sphere(0.05, [0.0, 0.6, 0.3])],
            random_obstacles: Some(crate::sim::scene::RandomObstacles {
                count: [1, 3],
                ..Default::default()
            }),
            observe_obstacles: true,
            obstacle_observation: encoding,
            ..TaskConfig::default()
        };
        ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), RewardConfig::default(), 3).unwrap()
    };
    let (mut near, mut abs) = (make(ObstacleObservation::Nearest), make(ObstacleObservation::Absolute));
    let bounds = near.task().obstacle_obs_bounds(chain.reach_bound_m());
    let k = near.task().obs_delta_scale;
    let far = bounds[6].1 as f32;
    assert!(far > 10.0 && bounds[6].0 < 0.0, "{bounds:?}");
    let mut empty_seen = false;
    for episode in 0..50 {
        near.reset();
        abs.reset();
        assert_eq!(near.obstacles(), abs.obstacles(), "episode {episode}");
        for step in 0.. {
            let obs = near.observation().to_vec();
            let ee = near.ee_pose().position;
            let slots: Vec<&[f32]> = obs[16..].chunks_exact(7).collect();
            let used = near.obstacles().len();
            let mut last = f32::NEG_INFINITY;
            for slot in &slots[..used] {
                // The slot's obstacle: the one whose scaled offset it holds.
                let o = near
                    .obstacles()
                    .iter()
                    .find(|o| (0..3).all(|c| slot[c] == (k * (o.position_m[c] - ee[c])) as f32))
                    .expect("a slot per obstacle");
                assert_eq!(slot[3..6], o.half_size_m().map(|h| (k * h) as f32));
                assert_eq!(slot[6], (k * o.distance_to_point_m(ee.into())) as f32);
                assert!(slot[6] >= last, "nearest first: {slot:?} after {last}");
                last = slot[6];
            }
            for slot in &slots[used..] {
                assert_eq!(slot, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, far]);
                empty_seen = true;
            }
            for (i, x) in obs[16..].iter().enumerate() {
                let (lo, hi) = bounds[i % 7];
                assert!((lo as f32..=hi as f32).contains(x), "value {i} = {x} outside [{lo}, {hi}]");
            }
            assert_eq!(obs[..16], abs.observation()[..16]);
            if near.is_done() || step == 20 {
                break;
            }
            let a = [0.6, -0.3, 0.4, 0.2, 0.0, 0.0];
            assert_eq!(near.step(&a).unwrap(), abs.step(&a).unwrap());
        }
    }
    assert!(empty_seen, "some episode has fewer obstacles than slots");
    let e = TaskConfig { obstacle_observation: ObstacleObservation::Nearest, ..TaskConfig::default() }
        .validate()
        .unwrap_err()
        .to_string();
    assert!(e.contains("task.obstacle_observation") && e.contains("observe_obstacles"), "{e}");
}

/// `task.obstacle_range_m`: the nearest encoding without the obstacles beyond the range,
/// whose slots read as empty; the same slots as without it otherwise; checked settings.
#[test]
fn obstacle_range_leaves_far_obstacles_out() {
    let chain = Arc::new(Chain::ur5());
    let make = |range| {
        let task = TaskConfig {
            random_obstacles: Some(crate::sim::scene::RandomObstacles {
                count: [1, 3],
                ..Default::default()
            }),
            observe_obstacles: true,
            obstacle_observation: ObstacleObservation::Nearest,
            obstacle_range_m: range,
            ..TaskConfig::default()
        };
        ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), RewardConfig::default(), 5).unwrap()
    };
    let range = 0.3;
    let (mut gated, mut all) = (make(Some(range)), make(None));
    let far = gated.task().obstacle_obs_bounds(chain.reach_bound_m())[6].1 as f32;
    let (mut kept, mut dropped) = (0, 0);
    for _ in 0..40 {
        gated.reset();
        all.reset();
        for step in 0..15 {
            let k = gated.task().obs_delta_scale;
            let (g, a) = (gated.observation().to_vec(), all.observation().to_vec());
            assert_eq!(g[..16], a[..16]);
            for (gs, as_) in g[16..].chunks_exact(7).zip(a[16..].chunks_exact(7)) {
                if as_[6] <= (k * range) as f32 {
                    assert_eq!(gs, as_);
                    kept += usize::from(as_[6] < far);
                } else {
                    assert_eq!(gs, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, far]);
                    dropped += usize::from(as_[6] < far);
                }
            }
            let act = [0.6, -0.3, 0.4, 0.2, 0.0, 0.0];
            assert_eq!(gated.step(&act).unwrap(), all.step(&act).unwrap());
            if gated.is_done() || step == 14 {
                break;
            }
        }
    }
    assert!(kept > 0 && dropped > 0, "{kept} obstacle slots kept, {dropped} dropped");
    let check = |t: TaskConfig| t.validate().unwrap_err().to_string();
    let near = || TaskConfig {
        random_obstacles: Some(crate::sim::scene::RandomObstacles::default()),
        observe_obstacles: true,
        obstacle_observation: ObstacleObservation::Nearest,
        ..TaskConfig::default()
    };
    for bad in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        let e = check(TaskConfig { obstacle_range_m: Some(bad), ..near() });
        assert!(e.contains("task.obstacle_range_m") && e.contains("> 0"), "{e}");
    }
    let e = check(TaskConfig {
        obstacle_observation: ObstacleObservation::Absolute,
        obstacle_range_m: Some(0.2),
        ..near()
    });
    assert!(e.contains("task.obstacle_range_m") && e.contains("nearest"), "{e}");
}

#[test]
fn random_obstacle_settings_are_checked() {
    let bad = |r: crate::sim::scene::RandomObstacles, field: &str| {
        let t = TaskConfig { random_obstacles: Some(r), ..TaskConfig::default() };
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains(field), "{e}");
    };
    let d = crate::sim::scene::RandomObstacles::default;
    bad(crate::sim::scene::RandomObstacles { count: [3, 2], ..d() }, "task.random_obstacles.count");
    bad(crate::sim::scene::RandomObstacles { count: [0, 33], ..d() }, "task.random_obstacles.count");
    bad(crate::sim::scene::RandomObstacles { shapes: Vec::new(), ..d() }, "task.random_obstacles.shapes");
    bad(crate::sim::scene::RandomObstacles { size_m: [0.0, 0.1], ..d() }, "task.random_obstacles.size_m");
    bad(crate::sim::scene::RandomObstacles { size_m: [0.2, 0.1], ..d() }, "task.random_obstacles.size_m");
    bad(crate::sim::scene::RandomObstacles { region_min_m: [1.0, 0.0, 0.0], ..d() }, "region_min_m");
    bad(crate::sim::scene::RandomObstacles { target_clearance_m: f64::NAN, ..d() }, "target_clearance_m");
    let e = TaskConfig { observe_obstacles: true, ..TaskConfig::default() }.validate().unwrap_err();
    assert!(e.to_string().contains("task.observe_obstacles"), "{e}");
}

fn dynamic_env(seed: u64, obstacles: Vec<crate::sim::scene::Obstacle>) -> ReachEnv {
    let chain = Arc::new(Chain::ur5());
    let task = TaskConfig { sim: Sim::Dynamic, obstacles, ..TaskConfig::default() };
    ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), RewardConfig::default(), seed).unwrap()
}

/// `task.sim = "dynamic"`: the arm holds still on a zero command, tracks a moderate one, and
/// the reward sees the velocity achieved; the same seed gives the same episodes.
#[test]
fn the_dynamic_arm_tracks_commands_and_the_reward_sees_what_it_achieved() {
    let mut env = dynamic_env(1, Vec::new());
    env.reset();
    let home = env.joint_positions().to_vec();
    for _ in 0..20 {
        env.step(&[0.0; 6]).unwrap();
    }
    let drift = env.joint_positions().iter().zip(&home).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(drift < 0.02, "zero command: drift {drift} rad in 1 s");
    env.reset();
    // 0.3 of the speed limit (pi rad/s) on the base and the elbow.
    let a = [0.3, 0.0, 0.3, 0.0, 0.0, 0.0];
    let mut s = env.step(&a).unwrap();
    for _ in 0..3 {
        s = env.step(&a).unwrap();
    }
    let v = env.joint_velocities();
    for i in [0, 2] {
        assert!((v[i] - 0.3 * PI).abs() < 0.05 * 0.3 * PI, "joint {i}: {} rad/s", v[i]);
    }
    let vv: f64 = v.iter().map(|x| x * x).sum();
    assert_eq!(s.terms.movement, 0.05 * vv / 6.0, "eq. 9 on the achieved velocity");
    // The kinematic arm applies the command exactly; the dynamic one does not, quite.
    let mut k = ur5_env(RewardConfig::default(), 1);
    k.reset();
    k.step(&a).unwrap();
    assert_ne!(k.joint_velocities(), env.joint_velocities());
    let run = |seed| {
        let mut e = dynamic_env(seed, Vec::new());
        let mut out = Vec::new();
        for _ in 0..2 {
            e.reset();
            for k in 0..10 {
                let s = e.step(&[0.5, -0.4, 0.3, 0.2 * (k as f32 % 3.0 - 1.0), 0.1, 0.0]).unwrap();
                out.push((s.total(), e.joint_positions().to_vec()));
            }
        }
        out
    };
    assert_eq!(run(5), run(5));
}

/// A dynamic episode restored from its state mid-way (also into a fresh environment, as a
/// resumed run does) continues bit for bit, through contacts with an obstacle and the floor.
#[test]
fn a_dynamic_state_restores_exactly_through_contacts() {
    let chain = Chain::ur5();
    let home = chain.fk(&task::UR5_HOME_POSE_RAD).position;
    // A box in the way of the base's turn.
    let wall = crate::sim::scene::Obstacle::cuboid([0.05, 0.3, 0.3], [home.x, home.y + 0.25, home.z], None);
    let mut a = dynamic_env(3, vec![wall.clone()]);
    a.reset();
    let push = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let actions: Vec<[f32; 6]> = (0..30)
        .map(|k| if k < 15 { [-0.6, 0.2, 0.0, 0.0, 0.0, 0.0] } else { [-0.2, 0.6, -0.4, 0.1, 0.0, 0.0] })
        .collect();
    let mut saved = Vec::new();
    let mut steps = Vec::new();
    for act in &actions {
        saved.push(a.state());
        let st = a.step(act).unwrap();
        steps.push((st, a.joint_positions().to_vec()));
        if st.done() {
            break;
        }
    }
    let contacts = steps.iter().filter(|(s, _)| s.collision.is_some()).count();
    assert!(contacts >= 3, "the arm pressed into something for a few steps: {contacts}");
    for from in [1, 8, steps.len() / 2, steps.len() - 2] {
        let mut b = dynamic_env(99, vec![wall.clone()]);
        b.reset();
        b.step(&push).unwrap();
        b.restore(&saved[from]).unwrap();
        for (k, act) in actions.iter().enumerate().take(steps.len()).skip(from) {
            let st = b.step(act).unwrap();
            assert_eq!((st, b.joint_positions().to_vec()), steps[k], "resumed at {from}, step {k}");
        }
    }
}

/// A link without inertial data cannot be simulated: the error names it.
#[test]
fn the_dynamic_simulation_needs_every_moving_link_s_inertia() {
    let xml = r#"<robot name="bare"><link name="a"/><link name="b">
        <collision><geometry><sphere radius="0.05"/></geometry></collision></link>
        <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
        <origin xyz="0 0 0.3"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>"#;
    let chain = Arc::new(Chain::from_urdf_str(xml, None).unwrap());
    let task = TaskConfig {
        home_pose_rad: Some(vec![0.0]),
        target_joint_range_rad: Some(vec![1.0]),
        target_min_z_m: 0.0,
        sim: Sim::Dynamic,
        ..TaskConfig::default()
    };
    let e = ReachEnv::new(chain.clone(), task.resolve(&chain).unwrap(), RewardConfig::default(), 1);
    let e = e.unwrap_err().to_string();
    assert!(e.contains("link `b`") && e.contains("inertial"), "{e}");
}

/// An arm that is not six-jointed without a home pose or a target range: one message naming
/// both fields (and where suggested values come from); with one of them set, the other.
#[test]
fn a_seven_joint_arm_without_its_per_joint_settings_names_all_of_them_at_once() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/robots/panda.urdf");
    let chain = Chain::from_urdf_file(std::path::Path::new(path), None).unwrap();
    let e = TaskConfig::default().resolve(&chain).unwrap_err().to_string();
    assert!(
        e.contains("task.home_pose_rad and task.target_joint_range_rad")
            && e.contains("this one has 7 joints")
            && e.contains("stagerl robot URDF"),
        "{e}"
    );
    let home = TaskConfig { home_pose_rad: Some(PANDA_HOME.to_vec()), ..TaskConfig::default() };
    let e = home.resolve(&chain).unwrap_err().to_string();
    assert!(e.contains("`task.target_joint_range_rad`") && !e.contains("home_pose_rad"), "{e}");
    let range = TaskConfig { target_joint_range_rad: Some(vec![0.1; 7]), ..TaskConfig::default() };
    let e = range.resolve(&chain).unwrap_err().to_string();
    assert!(e.contains("`task.home_pose_rad`") && !e.contains("target_joint_range"), "{e}");
}

/// A state saved while a request's scene is set (more obstacles than the task's random ones
/// allow) restores that scene: the episode goes on among the same obstacles, and the next
/// episodes keep the request's scene, as in the environment it was saved from; a state
/// without one goes back to the task's random obstacles; a request's scene that is too large
/// is refused by name.
#[test]
fn a_state_with_a_request_scene_restores_it_for_this_episode_and_the_next() {
    use crate::sim::scene::{Obstacle, MAX_OBSTACLES};
    let mut a = random_obstacles_env(3, true);
    let scene: Vec<Obstacle> =
        (0..7).map(|i| Obstacle::sphere(0.03, [0.5, -0.6 + 0.2 * f64::from(i), 0.9])).collect();
    a.set_request_obstacles(Some(&scene));
    a.reset();
    assert_eq!(
        a.obstacles().len(),
        1 + 7,
        "the fixed obstacle and the request's 7 (the task allows 5 random)"
    );
    a.step(&[0.2; 6]).unwrap();
    let saved = a.state();
    assert_eq!(saved.request_obstacles.as_deref(), Some(&scene[..]));
    let mut b = random_obstacles_env(44, true);
    b.reset();
    b.restore(&saved).unwrap();
    assert_eq!(b.obstacles(), a.obstacles());
    assert_eq!(b.observation(), a.observation());
    for _ in 0..3 {
        while !a.is_done() {
            assert_eq!(
                a.step(&[0.3, -0.2, 0.1, 0.0, 0.1, 0.0]).unwrap(),
                b.step(&[0.3, -0.2, 0.1, 0.0, 0.1, 0.0]).unwrap()
            );
        }
        a.reset();
        b.reset();
        assert_eq!(b.obstacles(), a.obstacles(), "the next episode keeps the request's scene");
        assert_eq!(b.obstacles()[1..], scene[..]);
    }
    // Saved without a request: the next episode draws random obstacles again.
    let mut c = random_obstacles_env(3, true);
    c.reset();
    b.restore(&c.state()).unwrap();
    b.reset();
    assert!((2..=5).contains(&(b.obstacles().len() - 1)), "{} obstacles", b.obstacles().len());
    // Through the checkpoint's serialisation, and refusals.
    let json = serde_json::to_string(&saved).unwrap();
    assert!(json.contains("request_obstacles"));
    let back: EnvState = serde_json::from_str(&json).unwrap();
    b.restore(&back).unwrap();
    assert_eq!(b.obstacles(), a.obstacles().iter().take(1).chain(&scene).cloned().collect::<Vec<_>>());
    assert!(!serde_json::to_string(&c.state()).unwrap().contains("request_obstacles"), "absent when none");
    let huge =
        EnvState { request_obstacles: Some(vec![scene[0].clone(); MAX_OBSTACLES + 1]), ..saved.clone() };
    let e = b.restore(&huge).unwrap_err().to_string();
    assert!(
        e.contains("EnvState.request_obstacles") && e.contains(&format!("at most {MAX_OBSTACLES}")),
        "{e}"
    );
    let too_many = EnvState { random_obstacles: vec![scene[0].clone(); 8], ..saved };
    let e = b.restore(&too_many).unwrap_err().to_string();
    assert!(e.contains("8 random obstacles") && e.contains("request's scene 7"), "{e}");
}

/// The shield's counts of the episode in progress are part of the state: an environment
/// restored mid-episode ends it with the counts of the one it was saved from (a resumed run
/// logs what an uninterrupted one does); without the shield the state holds none.
#[test]
fn the_shields_episode_counts_survive_a_restore() {
    let make = |seed| {
        let mut e = random_obstacles_env(seed, true);
        e.set_shield(true).unwrap();
        e.set_obstacles_in_path(1.0).unwrap();
        e
    };
    let (mut a, mut b) = (make(21), make(5));
    a.reset();
    b.reset();
    let action = [0.6, 0.5, -0.4, 0.2, 0.0, 0.0];
    for _ in 0..8 {
        a.step(&action).unwrap();
    }
    let saved = a.state();
    assert_eq!(saved.shield_episode, a.episode_shield_stats());
    assert_eq!(saved.shield_episode.unwrap().steps, 8);
    b.restore(&saved).unwrap();
    while !a.is_done() {
        assert_eq!(a.step(&action).unwrap(), b.step(&action).unwrap());
    }
    let (ea, eb) = (a.episode_shield_stats().unwrap(), b.episode_shield_stats().unwrap());
    assert_eq!(ea, eb);
    assert_eq!(ea.steps, u64::from(a.steps()));
    let plain = random_obstacles_env(21, true);
    assert!(plain.state().shield_episode.is_none());
}

/// `set_max_random_obstacles` (the curriculum's stages): counts drawn from `count[0]` to the
/// cap, every count of that range drawn; the task's largest count draws the same episodes as an
/// environment never set; caps outside `count` and tasks without random obstacles are refused.
#[test]
fn the_largest_random_obstacle_count_can_be_capped() {
    // count = [2, 5] and one fixed obstacle.
    let counts = |cap: Option<u32>| {
        let mut e = random_obstacles_env(3, true);
        if let Some(c) = cap {
            e.set_max_random_obstacles(c).unwrap();
        }
        (0..300)
            .map(|_| {
                e.reset();
                e.obstacles().len() - 1
            })
            .collect::<Vec<usize>>()
    };
    for cap in [2u32, 3, 4] {
        let seen: std::collections::BTreeSet<usize> = counts(Some(cap)).into_iter().collect();
        // (A random obstacle with no free place in 100 tries is left out: at most one fewer.)
        assert!(seen.iter().all(|&n| n <= cap as usize), "cap {cap}: {seen:?}");
        assert!((2..=cap as usize).all(|n| seen.contains(&n)), "cap {cap}: {seen:?}");
    }
    let (mut a, mut b) = (random_obstacles_env(4, true), random_obstacles_env(4, true));
    b.set_max_random_obstacles(5).unwrap();
    for _ in 0..50 {
        a.reset();
        b.reset();
        assert_eq!(
            (a.obstacles(), a.target(), a.observation()),
            (b.obstacles(), b.target(), b.observation())
        );
    }
    // Back from a cap to the task's count.
    b.set_max_random_obstacles(2).unwrap();
    b.set_max_random_obstacles(5).unwrap();
    let mut c = random_obstacles_env(4, true);
    for _ in 0..50 {
        c.reset();
    }
    b.reset();
    c.reset();
    assert_eq!(b.obstacles(), c.obstacles());
    for bad in [1, 6] {
        let e = random_obstacles_env(3, true).set_max_random_obstacles(bad).unwrap_err().to_string();
        assert!(e.contains("train.curriculum.max_obstacles") && e.contains("[2, 5]"), "{e}");
    }
    assert!(env(1).set_max_random_obstacles(1).is_err());
}

/// The UR5's default task with a sphere beside the tool at the home pose and the shield on, and
/// `reward` (the sphere's centre: the shield then changes some of the random commands).
fn shielded_ur5(reward: RewardConfig, seed: u64) -> ReachEnv {
    use crate::sim::scene::Obstacle;
    use crate::sim::shield::ShieldConfig;
    let chain = Arc::new(Chain::ur5());
    let tool = chain.fk(&task::UR5_HOME_POSE_RAD).position;
    let task = TaskConfig {
        obstacles: vec![Obstacle::sphere(0.08, [tool.x + 0.15, tool.y, tool.z - 0.05])],
        shield: Some(ShieldConfig { enabled: true, ..ShieldConfig::default() }),
        ..TaskConfig::default()
    };
    let task = task.resolve(&chain).unwrap();
    ReachEnv::new(chain, task, reward, seed).unwrap()
}

/// Eq. 22 against an independent computation: every step's shield term is `w |x - c'|`, with `x`
/// the command asked for (the action times the speed limits, clamped so that the joints stay
/// within their limits, as the shield's step 1 clamps it) and `c'` the joint velocities the arm
/// moved with; the total is the reward and bonus less it; the same episodes without the penalty
/// take the same steps; and the terms of an episode add up to the shield's own count of changes.
#[test]
fn the_shield_penalty_charges_the_change_the_shield_made() {
    let w = 2.0;
    let mut env = shielded_ur5(RewardConfig { shield_penalty: Some(w), ..RewardConfig::default() }, 6);
    let mut plain = shielded_ur5(RewardConfig::default(), 6);
    let chain = env.chain().clone();
    let (lo, hi, vmax) = (chain.lower_limits(), chain.upper_limits(), chain.velocity_limits());
    let dt = env.task().dt_s;
    let (mut rng, mut action, mut charged) = (Rng::new(8), [0.0f32; 6], 0);
    for _ in 0..6 {
        env.reset();
        plain.reset();
        let mut sum = 0.0;
        while !env.is_done() {
            action.iter_mut().for_each(|x| *x = rng.uniform_range(-1.0, 1.0) as f32);
            let q = env.joint_positions().to_vec();
            let (s, p) = (env.step(&action).unwrap(), plain.step(&action).unwrap());
            let change = (0..6)
                .map(|i| {
                    let x = (f64::from(action[i]) * vmax[i]).clamp(
                        (-vmax[i]).max((lo[i] - q[i]) / dt).min(0.0),
                        vmax[i].min((hi[i] - q[i]) / dt).max(0.0),
                    );
                    (x - env.joint_velocities()[i]).powi(2)
                })
                .sum::<f64>()
                .sqrt();
            let expected = if change > 1e-9 { w * change } else { 0.0 };
            assert!((s.terms.shield - expected).abs() < 1e-9, "{} against {expected}", s.terms.shield);
            assert_eq!(s.total(), s.terms.reward + s.terms.bonus - s.terms.shield);
            assert_eq!(s.shield_change_rad_per_s.map(|c| w * c), Some(s.terms.shield));
            assert_eq!((p.terms.shield, p.total()), (0.0, p.terms.reward + p.terms.bonus));
            assert_eq!(
                (s.terms.reward, s.terminated, env.joint_positions()),
                (p.terms.reward, p.terminated, plain.joint_positions())
            );
            sum += s.terms.shield / w;
            charged += usize::from(s.terms.shield > 0.0);
        }
        let counted = env.episode_shield_stats().unwrap().change_sum_rad_per_s;
        assert!((sum - counted).abs() < 1e-9 * (1.0 + counted), "{sum} against {counted}");
    }
    assert!(charged > 10, "the penalty was exercised: {charged} steps");
}

/// `reward.shield_penalty` needs the shield: refused without it and when negative or not finite,
/// and by the tools that see the end effector only, each naming the field; with the shield
/// turned off afterwards (`eval --no-shield`) nothing is charged.
#[test]
fn the_shield_penalty_is_checked_and_charges_nothing_without_the_shield() {
    let with = |w: f64| RewardConfig { shield_penalty: Some(w), ..RewardConfig::default() };
    let chain = Arc::new(Chain::ur5());
    let task = TaskConfig::default().resolve(&chain).unwrap();
    let e = ReachEnv::new(chain, task, with(1.0), 1).unwrap_err().to_string();
    assert!(e.contains("reward.shield_penalty") && e.contains("[task.shield] has enabled = true"), "{e}");
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let e = with(bad).validate().unwrap_err().to_string();
        assert!(e.contains("reward.shield_penalty") && e.contains("a finite number >= 0"), "{e}");
    }
    let e = with(1.0).pose_only("stagerl reward").unwrap_err().to_string();
    assert!(e.contains("reward.shield_penalty") && e.contains("unset for stagerl reward"), "{e}");
    assert!(RewardConfig::default().pose_only("stagerl reward").is_ok());
    let mut e = shielded_ur5(with(1.0), 3);
    e.set_shield(false).unwrap();
    e.reset();
    while !e.is_done() {
        let s = e.step(&[1.0, -1.0, 1.0, -1.0, 1.0, -1.0]).unwrap();
        assert_eq!((s.shield_change_rad_per_s, s.terms.shield), (None, 0.0));
    }
}
