use super::*;
use crate::agent::{build, AgentConfig, Algo};
use crate::env::Policy;
use std::f64::consts::PI;

fn jacobian() -> Planner {
    Planner::jacobian(&Config::default(), None).unwrap()
}

/// An untrained SAC agent at hidden 32 on the default task.
fn agent_planner(max_steps: Option<u32>) -> Planner {
    let mut cfg = Config::default();
    if let Some(n) = max_steps {
        cfg.task.max_steps = n;
    }
    let env = ReachEnv::from_config(&cfg, 0).unwrap();
    let acfg = AgentConfig { algo: Algo::Sac, hidden: vec![32, 32], ..AgentConfig::default() };
    let agent = build(&acfg, env.obs_dim(), env.act_dim(), 5).unwrap();
    Planner::new(env, PlanPolicy::Agent(agent))
}

/// Targets of the task's distribution.
fn targets(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let chain = Chain::ur5();
    let task = crate::env::TaskConfig::default().resolve(&chain).unwrap();
    let mut rng = Rng::new(seed);
    let mut q = vec![0.0; 6];
    (0..n).map(|_| task.sample_target(&chain, &mut rng, &mut q).into()).collect()
}

/// The invariants every plan keeps.
fn check_plan(p: &Plan, planner: &Planner, target: &[f64; 3]) {
    let chain = planner.env().chain();
    let (lo, hi, dt) = (chain.lower_limits(), chain.upper_limits(), p.dt_s);
    let beta = planner.env().reward_config().beta_m;
    let rows = p.rows();
    assert_eq!(rows, p.summary.steps as usize + 1);
    assert!(p.row(0).joint_vel.iter().all(|&v| v == 0.0));
    assert_eq!(p.row(0).reward, 0.0);
    let (mut path, mut travel, mut reward) = (0.0, 0.0, 0.0);
    for k in 0..rows {
        let r = p.row(k);
        assert_eq!(r.t_s, k as f64 * dt);
        let pose = chain.fk(r.q);
        for i in 0..3 {
            assert!((pose.position[i] - r.ee_pos[i]).abs() <= 1e-9, "row {k}");
        }
        let d = (Vector3::from(*target) - pose.position).norm();
        assert!((d - r.distance).abs() <= 1e-12, "row {k}");
        reward += r.reward;
        if k > 0 {
            let prev = p.row(k - 1);
            for i in 0..p.dof {
                let free = r.q[i] > lo[i] && r.q[i] < hi[i];
                if free {
                    let expect = prev.q[i] + r.joint_vel[i] * dt;
                    assert!((r.q[i] - expect).abs() <= 1e-12, "row {k} joint {i}");
                }
                travel += (r.q[i] - prev.q[i]).abs();
            }
            path += (Vector3::from(r.ee_pos) - Vector3::from(prev.ee_pos)).norm();
        }
    }
    let s = &p.summary;
    assert_eq!(s.reached, s.final_distance < beta, "{s:?}");
    assert_eq!(s.final_distance, p.distance[rows - 1]);
    assert!((s.path_length_m - path).abs() <= 1e-12);
    assert!((s.joint_travel_rad - travel).abs() <= 1e-12);
    assert!((s.episode_reward - reward).abs() <= 1e-9);
    assert!(s.reached || s.steps == planner.env().task().max_steps);
}

#[test]
fn jacobian_plans_keep_the_invariants_and_reach() {
    let mut planner = jacobian();
    let mut reached = 0;
    for t in targets(100, 1) {
        let p = planner.plan(&t, None).unwrap();
        assert_eq!(p.row(0).q, &crate::env::UR5_HOME_POSE_RAD);
        assert!(p.warning.is_none());
        check_plan(&p, &planner, &t);
        reached += usize::from(p.summary.reached);
    }
    assert_eq!(reached, 100);
}

#[test]
fn agent_plans_follow_the_evaluation_rollout_and_start_anywhere() {
    let mut planner = agent_planner(Some(20));
    let mut cfg = Config::default();
    cfg.task.max_steps = 20;
    let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
    let acfg = AgentConfig { algo: Algo::Sac, hidden: vec![32, 32], ..AgentConfig::default() };
    let mut agent = build(&acfg, env.obs_dim(), env.act_dim(), 5).unwrap();
    let start = [0.3, -1.2, 1.0, -1.0, -1.5, 0.2];
    for (k, t) in targets(20, 2).into_iter().enumerate() {
        let s = (k % 2 == 1).then_some(&start[..]);
        let p = planner.plan(&t, s).unwrap();
        check_plan(&p, &planner, &t);
        assert_eq!(p.row(0).q, s.unwrap_or(&crate::env::UR5_HOME_POSE_RAD));
        // The same rollout as evaluation's, from the same state.
        env.reset_to(s.unwrap_or(&env.task().home_pose.clone()), Vector3::from(t)).unwrap();
        let mut scratch = Scratch::new(&env);
        let policy = crate::train::eval::deterministic(agent.as_mut());
        let Outcome::Finished { reward, .. } = rollout(&mut env, &mut scratch, &mut Policy(policy)).unwrap()
        else {
            panic!("stopped")
        };
        assert_eq!(reward.to_bits(), p.summary.episode_reward.to_bits());
        assert_eq!(env.joint_positions(), p.row(p.rows() - 1).q);
    }
}

#[test]
fn bad_targets_and_starts_are_errors_naming_them() {
    let mut planner = jacobian();
    let reach = planner.env().chain().reach_m();
    let e = planner.plan(&[0.3, 0.2], None).unwrap_err().to_string();
    assert!(e.contains("2 values") && e.contains("expected 3"), "{e}");
    let e = planner.plan(&[0.3, 0.2, -0.1], None).unwrap_err().to_string();
    assert!(
        e.contains("[0.3, 0.2, -0.1]") && e.contains("below the floor") && e.contains("reaches at most"),
        "{e}"
    );
    let e = planner.plan(&[3.0, 0.0, 0.5], None).unwrap_err().to_string();
    assert!(e.contains("[3, 0, 0.5]") && e.contains(&format!("{reach:.4} m")), "{e}");
    let e = planner.plan(&[f64::NAN, 0.0, 0.5], None).unwrap_err().to_string();
    assert!(e.contains("not finite"), "{e}");
    let t = targets(1, 3)[0];
    let e = planner.plan(&t, Some(&[0.0; 5])).unwrap_err().to_string();
    assert!(e.contains("5 values") && e.contains("expected 6"), "{e}");
    let e = planner.plan(&t, Some(&[0.0, 0.0, 4.0, 0.0, 0.0, 0.0])).unwrap_err().to_string();
    assert!(e.contains("elbow_joint") && e.contains("= 4") && e.contains("[-3.14159"), "{e}");
    // The planner still works after refusals.
    assert!(planner.plan(&t, None).unwrap().summary.reached);
}

#[test]
fn reach_bounds_every_pose() {
    let chain = Chain::ur5();
    let (o, reach) = (chain.first_joint_origin(), chain.reach_m());
    assert_eq!(o, Vector3::zeros());
    let mut rng = Rng::new(9);
    let mut far: f64 = 0.0;
    for _ in 0..20_000 {
        let q: Vec<f64> = (0..6).map(|_| rng.uniform_range(-PI, PI)).collect();
        far = far.max((chain.fk(&q).position - o).norm());
    }
    assert!(far <= reach && far > 0.8 * reach, "farthest {far}, reach {reach}");
}

#[test]
fn a_target_outside_the_training_distribution_warns_and_still_plans() {
    let mut planner = agent_planner(None);
    let o = planner.env().chain().first_joint_origin();
    for t in targets(200, 4) {
        assert!(planner.plan(&t, None).unwrap().warning.is_none(), "{t:?}");
    }
    // Behind the arm: the training targets' mirror image through the first joint's axis.
    let t = targets(1, 5)[0];
    let behind = [2.0 * o.x - t[0], 2.0 * o.y - t[1], t[2]];
    let p = planner.plan(&behind, None).unwrap();
    let w = p.warning.clone().unwrap_or_else(|| panic!("no warning for {behind:?}"));
    assert!(
        w.contains("outside the training target distribution") && w.contains(&format!("{:?}", behind[0])),
        "{w}"
    );
    check_plan(&p, &planner, &behind);
}

#[test]
fn csv_and_rows_carry_the_same_numbers() {
    let mut planner = jacobian();
    let t = targets(1, 6)[0];
    let p = planner.plan(&t, None).unwrap();
    let csv = p.to_csv();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), Plan::csv_header(6));
    for (k, line) in lines.enumerate() {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let r = p.row(k);
        let mut expect = vec![k as f64, r.t_s];
        expect.extend(r.q.iter().chain(r.joint_vel).chain(&r.ee_pos).chain(&r.ee_quat));
        expect.extend([r.distance, r.reward]);
        assert_eq!(v.len(), expect.len());
        assert!(v.iter().zip(&expect).all(|(a, b)| a.to_bits() == b.to_bits()), "row {k}");
    }
}

fn ball(r: f64, p: [f64; 3]) -> Obstacle {
    Obstacle::sphere(r, p)
}

#[test]
fn request_lines_carry_obstacles_and_bad_ones_are_refused_by_field() {
    let line = r#"{"target":[0.4,0.2,0.3],"obstacles":[{"shape":"sphere","radius_m":0.05,"position_m":[0.3,-0.3,0.4]},{"shape":"cuboid","half_extents_m":[0.1,0.02,0.05],"position_m":[-0.3,0.3,0.2],"rotation_xyzw":[0,0,0.7071067811865476,0.7071067811865476]}]}"#;
    let r: PlanRequest = serde_json::from_str(line).unwrap();
    let o = r.obstacles.as_ref().unwrap();
    assert_eq!(o.len(), 2);
    assert_eq!(o[1].half_extents_m, Some([0.1, 0.02, 0.05]));
    let unknown =
        r#"{"target":[0.4,0.2,0.3],"obstacles":[{"shape":"sphere","radius":0.05,"position_m":[0,0,1]}]}"#;
    assert!(serde_json::from_str::<PlanRequest>(unknown).is_err());
    let mut p = jacobian();
    let t = [0.4, 0.2, 0.3];
    let refused = |p: &mut Planner, o: Obstacle| {
        p.plan_among(&t, None, Some(&[ball(0.05, [0.3, -0.3, 0.9]), o])).unwrap_err().to_string()
    };
    let e = refused(&mut p, ball(-0.1, [0.3, 0.3, 0.3]));
    assert!(e.contains("`obstacles[1].radius_m` = -0.1") && e.contains("(0, 100]"), "{e}");
    let e = refused(&mut p, ball(0.0, [0.3, 0.3, 0.3]));
    assert!(e.contains("`obstacles[1].radius_m` = 0"), "{e}");
    let e = refused(&mut p, ball(0.1, [f64::NAN, 0.3, 0.3]));
    assert!(e.contains("`obstacles[1].position_m`"), "{e}");
    let e = refused(&mut p, Obstacle::cuboid([0.1, 0.1, 0.1], [0.3, 0.3, 0.6], Some([0.0, 0.0, 0.5, 0.5])));
    assert!(e.contains("`obstacles[1].rotation_xyzw`") && e.contains("unit quaternion"), "{e}");
    let e = refused(&mut p, Obstacle::cuboid([0.1, -0.1, 0.1], [0.3, 0.3, 0.6], None));
    assert!(e.contains("`obstacles[1].half_extents_m`"), "{e}");
    let e = refused(&mut p, ball(0.02, [0.41, 0.2, 0.3]));
    assert!(e.contains("`obstacles[1]`") && e.contains("encloses the target"), "{e}");
    let tool = p.env().chain().fk(&p.env().task().home_pose).position;
    let e = refused(&mut p, ball(0.02, [tool.x, tool.y, tool.z]));
    assert!(e.contains("`obstacles[1]`") && e.contains("start pose"), "{e}");
    // A start pose in contact with the floor.
    let low = [0.0, 0.3, 1.5, 0.0, 0.0, 0.0];
    assert!(p.env().chain().fk(&low).position.z < 0.0);
    let e = p.plan_among(&t, Some(&low), Some(&[])).unwrap_err().to_string();
    assert!(e.contains("already in contact") && e.contains("floor"), "{e}");
    // The scene's errors name it.
    let e = p
        .set_scene(vec![ball(f64::INFINITY, [0.0; 3])], "--scene s.toml: obstacles")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`--scene s.toml: obstacles[0].radius_m` = inf"), "{e}");
    let e = crate::env::request::parse_scene("[[obstacles]]\nshape = \"ball\"\n", "s.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("scene file s.toml") && e.contains("ball"), "{e}");
    let s = crate::env::request::parse_scene(
        "[[obstacles]]\nshape = \"sphere\"\nradius_m = 0.05\nposition_m = [0.3, -0.3, 0.9]\n",
        "s.toml",
    )
    .unwrap();
    assert_eq!(s, [ball(0.05, [0.3, -0.3, 0.9])]);
}

#[test]
fn a_line_adds_to_the_scene_and_the_report_sees_contacts_along_the_path() {
    let mut p = jacobian();
    let t = [0.4, 0.2, 0.3];
    let free = p.plan(&t, None).unwrap();
    assert!(!free.summary.collision && free.summary.min_clearance_m.is_none());
    assert!(free.summary.plan_time_s > 0.0);
    // A ball across the straight way, where the Jacobian controller goes through it.
    let mid = free.ee_pos[free.rows() / 3];
    let blocking = ball(0.04, mid);
    let far = ball(0.05, [-0.4, -0.4, 0.6]);
    p.set_scene(vec![far.clone()], "scene").unwrap();
    let hit = p.plan_among(&t, None, Some(std::slice::from_ref(&blocking))).unwrap();
    assert_eq!(p.env().obstacles(), [far.clone(), blocking.clone()]);
    assert!(hit.summary.collision && hit.summary.min_clearance_m.unwrap() < 0.0, "{:?}", hit.summary);
    let again = p.plan_among(&t, None, Some(std::slice::from_ref(&blocking))).unwrap();
    assert_eq!(again.q, hit.q);
    assert_eq!(
        (again.summary.collision, again.summary.min_clearance_m),
        (hit.summary.collision, hit.summary.min_clearance_m)
    );
    // Without a line's obstacles: the scene alone, clear of the path.
    let clear = p.plan(&t, None).unwrap();
    assert_eq!(p.env().obstacles(), [far]);
    assert_eq!(clear.q, free.q);
    let m = clear.summary.min_clearance_m.unwrap();
    assert!(!clear.summary.collision && m > 0.05, "{m}");
}

#[test]
fn a_policy_that_observes_obstacles_sees_the_nearest_of_a_larger_scene() {
    let mut cfg = Config::default();
    cfg.task.observe_obstacles = true;
    cfg.task.random_obstacles =
        Some(crate::sim::scene::RandomObstacles { count: [1, 1], ..Default::default() });
    let env = ReachEnv::from_config(&cfg, 0).unwrap();
    let acfg = AgentConfig { algo: Algo::Sac, hidden: vec![16, 16], ..AgentConfig::default() };
    let agent = build(&acfg, env.obs_dim(), env.act_dim(), 5).unwrap();
    let mut p = Planner::new(env, PlanPolicy::Agent(agent));
    let scene = [ball(0.05, [0.5, -0.5, 0.6]), ball(0.05, [-0.5, 0.5, 0.6]), ball(0.05, [0.0, 0.6, 0.1])];
    let plan = p.plan_among(&[0.4, 0.2, 0.3], None, Some(&scene)).unwrap();
    let w = plan.warning.unwrap_or_default();
    assert!(w.contains("observes 1 obstacle(s) and the scene has 3"), "{w}");
    let env = p.env();
    let ee: [f64; 3] = env.ee_pose().position.into();
    let nearest =
        scene.iter().min_by(|a, b| a.distance_to_point_m(ee).total_cmp(&b.distance_to_point_m(ee))).unwrap();
    let slot = &env.observation()[crate::env::ObservationLayout::of(env.task()).obstacles()];
    assert_eq!(&slot[..3], nearest.position_m.map(|v| v as f32));
    // Planning without a scene again: the task's random obstacle, and no warning.
    let plan = p.plan(&[0.4, 0.2, 0.3], None).unwrap();
    let w = plan.warning.unwrap_or_default();
    assert!(!w.contains("observes") && p.env().obstacles().len() == 1, "{w}");
}

/// RRT-Connect ([`crate::sim::rrt_connect`]) through the planner.
mod rrt_connect {
    use crate::config::Config;
    use crate::plan::{problems, Planner};
    use crate::sim::rrt_connect::{RrtConnect, RrtStats};
    use crate::sim::scene::Obstacle;

    fn planner(seed: u64) -> Planner {
        Planner::rrt_connect(&Config::default(), None, RrtConnect { seed, ..RrtConnect::default() }).unwrap()
    }

    #[test]
    fn obstacles_across_the_straight_line_are_gone_round_without_contact() {
        let cfg = Config::default();
        let set = problems::obstacle_in_path(&cfg, 30, 11).unwrap();
        let mut jac = Planner::jacobian(&cfg, None).unwrap();
        let mut p = planner(3);
        let (mut solved, mut blocked) = (0, 0);
        for pr in &set {
            let straight = jac.plan_among(&pr.target, None, Some(&pr.obstacles)).unwrap();
            blocked += usize::from(straight.summary.collision);
            let plan = p.plan_among(&pr.target, None, Some(&pr.obstacles)).unwrap();
            let stats = plan.summary.rrt_connect.unwrap();
            assert!(!plan.summary.collision, "{:?}", plan.summary);
            assert!(plan.summary.min_clearance_m.unwrap() > 0.0);
            if plan.summary.reached {
                solved += 1;
                assert!(stats.solved && stats.ik_attempts >= 1 && stats.goals >= 1);
                // Within the speed limits: every action in [-1, 1].
                let v = p.env().chain().velocity_limits();
                for (k, row) in plan.joint_vel.chunks_exact(plan.dof).enumerate() {
                    assert!(row.iter().zip(v).all(|(q, v)| q.abs() <= v * (1.0 + 1e-6)), "row {k}");
                }
            }
        }
        assert!(blocked >= 5, "the straight way is blocked in {blocked} of 30");
        assert!(solved >= 29, "solved {solved} of 30");
    }

    #[test]
    fn a_caged_target_is_reported_unsolved_within_the_budget() {
        let t = [0.45, 0.15, 0.3];
        // Six walls 6 cm from the target, 1 cm thick: no arm pose puts the tip inside.
        let wall = |axis: usize, sign: f64| {
            let mut h = [0.07; 3];
            h[axis] = 0.005;
            let mut c = t;
            c[axis] += sign * 0.065;
            Obstacle::cuboid(h, c, None)
        };
        let cage: Vec<Obstacle> = (0..3).flat_map(|a| [wall(a, 1.0), wall(a, -1.0)]).collect();
        // No time budget in play (an hour): the attempts' bound ends the search, on any machine.
        let rrt = RrtConnect { seed: 1, budget_s: 3600.0, ..RrtConnect::default() };
        let mut p = Planner::rrt_connect(&Config::default(), None, rrt.clone()).unwrap();
        let plan = p.plan_among(&t, None, Some(&cage)).unwrap();
        assert!(!plan.summary.reached && plan.summary.steps == 0 && !plan.summary.collision);
        let why = plan.summary.reason.clone().unwrap();
        assert!(why.contains("no collision-free inverse-kinematics solution"), "{why}");
        let stats = plan.summary.rrt_connect.unwrap();
        assert!(!stats.solved && stats.goals == 0);
        assert_eq!(stats.ik_attempts, rrt.ik_attempts, "every attempt made, then given up");
        // A budget spent before the first attempt: given up at once, whatever the machine.
        let instant = RrtConnect { budget_s: 1e-9, ..rrt };
        let mut p = Planner::rrt_connect(&Config::default(), None, instant).unwrap();
        let stats = p.plan_among(&t, None, Some(&cage)).unwrap().summary.rrt_connect.unwrap();
        assert_eq!((stats.ik_attempts, stats.solved), (0, false));
        let line = serde_json::to_value(plan.batch_record()).unwrap();
        assert_eq!(line["reached"], false);
        assert!(line["reason"].as_str().unwrap().contains("RRT-Connect found no path"));
        // A budget of one iteration on a blocked problem: unsolved, the iteration budget named.
        let set = problems::obstacle_in_path(&Config::default(), 40, 11).unwrap();
        let mut tight = Planner::rrt_connect(
            &Config::default(),
            None,
            RrtConnect { max_iterations: 1, ..RrtConnect::default() },
        )
        .unwrap();
        let reasons: Vec<String> = set
            .iter()
            .filter_map(|pr| tight.plan_among(&pr.target, None, Some(&pr.obstacles)).unwrap().summary.reason)
            .collect();
        assert!(reasons.iter().any(|r| r.contains("iteration budget (1)")), "{reasons:?}");
    }

    #[test]
    fn a_seed_gives_the_same_paths() {
        let set = problems::obstacle_in_path(&Config::default(), 8, 5).unwrap();
        let run = |seed: u64| -> Vec<(Vec<f64>, RrtStats)> {
            let mut p = planner(seed);
            set.iter()
                .map(|pr| {
                    let plan = p.plan_among(&pr.target, None, Some(&pr.obstacles)).unwrap();
                    (plan.q, plan.summary.rrt_connect.unwrap())
                })
                .collect()
        };
        let (a, b) = (run(9), run(9));
        assert_eq!(a, b);
        assert!(a.iter().all(|(_, s)| s.seed == 9));
        // Another seed: the same problems, other searches (some of them).
        let c = run(10);
        assert!(a.iter().zip(&c).any(|(x, y)| x.1 != y.1));
    }
}
