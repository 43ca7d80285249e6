//! Property tests (proptest): the reward terms, the forward kinematics, the Jacobian and the
//! environment hold their invariants for every input of their domain, not only hand-picked ones.
//!
//! The generator is seeded (`PROPTEST_RNG_SEED` overrides the seed, `PROPTEST_CASES` the number of
//! cases), so a CI failure reproduces; the failing input is printed, shrunk.

use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;
use proptest::test_runner::{Config as PtConfig, RngSeed, TestCaseError, TestRunner};
use stagerl::config::Config;
use stagerl::env::ReachEnv;
use stagerl::reward::{sar_weights, DirectionSource, RewardConfig, RewardFunction, RewardInput, RewardTerms};
use stagerl::robot::{Chain, JointKind, UR5_URDF};

const TEST_ARM: &str = include_str!("../robot_test_arm.urdf");

/// A runner with `cases` cases and a fixed seed, unless the environment asks otherwise.
fn runner(cases: u32) -> TestRunner {
    let mut c = PtConfig::default();
    if std::env::var_os("PROPTEST_CASES").is_none() {
        c.cases = cases;
    }
    if std::env::var_os("PROPTEST_RNG_SEED").is_none() {
        c.rng_seed = RngSeed::Fixed(0x57A6_E2E1);
    }
    c.failure_persistence = None;
    TestRunner::new(c)
}

/// Run a property; a failure panics with the (shrunk) input.
fn check<S: Strategy>(cases: u32, strategy: S, test: impl Fn(S::Value) -> Result<(), TestCaseError>)
where
    S::Value: std::fmt::Debug,
{
    if let Err(e) = runner(cases).run(&strategy, test) {
        panic!("{e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Strategies.

/// A point in the cube [-10, 10]^3 m.
fn point() -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(-10.0f64..10.0).prop_map(Vector3::from)
}

/// A unit quaternion `[x, y, z, w]`: random directions and the special ones (identity, its
/// negation, half turns with w = 0).
fn unit_quat() -> impl Strategy<Value = [f64; 4]> {
    prop_oneof![
        1 => Just([0.0, 0.0, 0.0, 1.0]),
        1 => Just([0.0, 0.0, 0.0, -1.0]),
        1 => Just([1.0, 0.0, 0.0, 0.0]),
        1 => prop::array::uniform3(-1.0f64..1.0)
            .prop_filter("nonzero axis", |v| v.iter().map(|x| x * x).sum::<f64>() > 1e-6)
            .prop_map(|v| {
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                [v[0] / n, v[1] / n, v[2] / n, 0.0]
            }),
        8 => prop::array::uniform4(-1.0f64..1.0)
            .prop_filter("nonzero quaternion", |q| q.iter().map(|x| x * x).sum::<f64>() > 1e-6)
            .prop_map(|q| {
                let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
                q.map(|x| x / n)
            }),
    ]
}

/// Joint velocities: 1 to 12 joints, each finite with |v| <= 1e3.
fn joint_vel() -> impl Strategy<Value = Vec<f64>> {
    let v = prop_oneof![8 => -1e3f64..1e3, 1 => Just(0.0), 1 => Just(1e3), 1 => Just(-1e3)];
    prop::collection::vec(v, 1..=12)
}

/// A positive finite number over the whole range validation accepts, edges included.
fn positive_any() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => 1e-6f64..10.0,
        4 => (-300.0f64..300.0).prop_map(|e| 10f64.powf(e)),
        1 => Just(f64::MIN_POSITIVE),
        1 => Just(5e-324),
        1 => Just(f64::MAX),
    ]
}

/// A non-negative finite number, zero included.
fn non_negative_any() -> impl Strategy<Value = f64> {
    prop_oneof![1 => Just(0.0), 6 => positive_any()]
}

fn reward_function() -> impl Strategy<Value = RewardFunction> {
    prop::sample::select(RewardFunction::ALL.to_vec())
}

fn direction_source() -> impl Strategy<Value = DirectionSource> {
    prop_oneof![Just(DirectionSource::Quaternion), Just(DirectionSource::Displacement)]
}

/// Any reward configuration that validates.
fn reward_config() -> impl Strategy<Value = RewardConfig> {
    (
        reward_function(),
        positive_any(),
        prop_oneof![3 => -1e6f64..1e6, 1 => Just(f64::MAX), 1 => Just(-f64::MAX), 1 => Just(0.0)],
        non_negative_any(),
        non_negative_any(),
        non_negative_any(),
        positive_any(),
        direction_source(),
        any::<bool>(),
    )
        .prop_map(
            |(function, beta_m, success_bonus, har_boundary_m, s1, s2, sar_scale_m, direction, fold)| {
                RewardConfig {
                    function,
                    beta_m,
                    success_bonus,
                    har_boundary_m,
                    sar_sigma1: s1,
                    sar_sigma2: s2,
                    sar_scale_m,
                    direction,
                    direction_fold: fold,
                    collision_penalty: None,
                    clearance: None,
                    shield_penalty: None,
                }
            },
        )
}

/// End-effector, target and previous end-effector positions; sometimes the target sits exactly
/// on the end-effector, or the end-effector did not move (degenerate directions).
fn positions() -> impl Strategy<Value = (Vector3<f64>, Vector3<f64>, Option<Vector3<f64>>)> {
    (point(), point(), prop::option::of(point()), 0..6u8).prop_map(|(ee, target, prev, kind)| match kind {
        0 => (ee, ee, prev),
        1 => (ee, target, Some(ee)),
        2 => (ee, target, Some(target)),
        _ => (ee, target, prev),
    })
}

#[derive(Debug, Clone)]
struct RewardCase {
    ee: Vector3<f64>,
    quat: [f64; 4],
    target: Vector3<f64>,
    prev: Option<Vector3<f64>>,
    vel: Vec<f64>,
    dt: f64,
}

fn reward_case() -> impl Strategy<Value = RewardCase> {
    (positions(), unit_quat(), joint_vel(), prop_oneof![Just(0.05), 1e-4f64..1.0])
        .prop_map(|((ee, target, prev), quat, vel, dt)| RewardCase { ee, quat, target, prev, vel, dt })
}

fn compute(cfg: &RewardConfig, c: &RewardCase) -> Result<RewardTerms, TestCaseError> {
    let input = RewardInput {
        ee_pos: c.ee,
        ee_quat: c.quat,
        target: c.target,
        joint_vel: &c.vel,
        prev_ee_pos: c.prev,
    };
    prop_assert!(input.validate().is_ok(), "generated input rejected: {:?}", input.validate());
    Ok(RewardTerms::compute(cfg, c.dt, &input))
}

fn all_terms(t: &RewardTerms) -> [(&'static str, f64); 16] {
    [
        ("distance", t.distance),
        ("position", t.position),
        ("phi", t.phi),
        ("direction", t.direction),
        ("posture", t.posture),
        ("movement", t.movement),
        ("stride", t.stride),
        ("gamma_posture", t.gamma_posture),
        ("har", t.har),
        ("alpha1", t.alpha1),
        ("alpha2", t.alpha2),
        ("sar", t.sar),
        ("basic", t.basic),
        ("reward", t.reward),
        ("bonus", t.bonus),
        ("total", t.total),
    ]
}

// ---------------------------------------------------------------------------------------------
// Rewards.

#[test]
fn every_reward_term_is_finite_and_the_equations_hold() {
    check(256, (reward_config(), reward_case()), |(cfg, c)| {
        prop_assert!(cfg.validate().is_ok(), "generated config rejected: {:?}", cfg.validate());
        let t = compute(&cfg, &c)?;
        for (name, v) in all_terms(&t) {
            prop_assert!(v.is_finite(), "{name} = {v} for {cfg:?} {c:?}");
        }
        prop_assert!(t.distance >= 0.0);
        prop_assert!((0.0..=std::f64::consts::PI).contains(&t.phi), "phi = {}", t.phi);
        prop_assert!(t.movement >= 0.0);
        prop_assert!((0.0..=1.0).contains(&t.alpha1) && (0.0..=1.0).contains(&t.alpha2));
        prop_assert!(t.gamma_posture == 0.0 || t.gamma_posture == 1.0);
        prop_assert_eq!(t.reached, t.distance < cfg.beta_m);
        prop_assert_eq!(t.posture, t.position - t.direction); // eq. 7
        prop_assert_eq!(t.stride, t.position - t.movement); // eq. 10
        prop_assert_eq!(t.total, t.reward + t.bonus);
        let expect = match cfg.function {
            RewardFunction::Basic => t.basic,
            RewardFunction::Posture => t.posture,
            RewardFunction::Stride => t.stride,
            RewardFunction::Har => t.har,
            RewardFunction::Sar => t.sar,
        };
        prop_assert_eq!(t.reward, expect);
        Ok(())
    });
}

#[test]
fn direction_reward_lies_in_zero_to_a_quarter_with_the_fold() {
    let cfg_and_case = (direction_source(), reward_case());
    check(256, cfg_and_case, |(direction, c)| {
        let cfg = RewardConfig { direction, ..RewardConfig::default() };
        assert!(cfg.direction_fold, "the default folds");
        let t = compute(&cfg, &c)?;
        prop_assert!((0.0..=0.25).contains(&t.direction), "direction = {} (phi {})", t.direction, t.phi);
        // Without the fold the range is [0, 1/2] and the folded value is min(d, 1/2 - d).
        let unfolded = compute(&RewardConfig { direction_fold: false, ..cfg }, &c)?;
        prop_assert!((0.0..=0.5).contains(&unfolded.direction));
        let folded = unfolded.direction.min(0.5 - unfolded.direction);
        prop_assert!((t.direction - folded).abs() <= 1e-15, "{} vs {folded}", t.direction);
        Ok(())
    });
}

#[test]
fn sar_weights_sum_to_one_with_the_default_sigmas() {
    let distance = prop_oneof![
        1 => Just(0.0),
        1 => Just(1.0),
        4 => 0.0f64..1.5,
        2 => (-300.0f64..300.0).prop_map(|e| 10f64.powf(e)),
        1 => Just(f64::MAX),
    ];
    let scale = prop_oneof![3 => Just(1.0), 1 => positive_any()];
    check(256, (distance, scale), |(d, scale)| {
        let cfg = RewardConfig { sar_scale_m: scale, ..RewardConfig::default() };
        assert_eq!((cfg.sar_sigma1, cfg.sar_sigma2), (1.0, 1.0));
        let (a1, a2) = sar_weights(d, &cfg);
        prop_assert!((0.0..=1.0).contains(&a1) && (0.0..=1.0).contains(&a2), "{a1} {a2}");
        prop_assert!((a1 + a2 - 1.0).abs() <= 1e-15, "alpha1 + alpha2 = {}", a1 + a2);
        // Far beyond the scale: pure posture; at the target: pure stride.
        if d >= scale {
            prop_assert_eq!((a1, a2), (0.0, 1.0));
        }
        if d == 0.0 {
            prop_assert_eq!((a1, a2), (1.0, 0.0));
        }
        Ok(())
    });
}

// ---------------------------------------------------------------------------------------------
// Kinematics.

/// The UR5 with three probe links fixed 1 m along tool0's x, y and z axes: the probes' positions
/// minus tool0's are the columns of the rotation FK computed, read without the quaternion.
fn ur5_with_probes() -> [Chain; 4] {
    let probes = r#"
  <link name="probe_x"/><link name="probe_y"/><link name="probe_z"/>
  <joint name="px" type="fixed"><parent link="tool0"/><child link="probe_x"/><origin xyz="1 0 0"/></joint>
  <joint name="py" type="fixed"><parent link="tool0"/><child link="probe_y"/><origin xyz="0 1 0"/></joint>
  <joint name="pz" type="fixed"><parent link="tool0"/><child link="probe_z"/><origin xyz="0 0 1"/></joint>
</robot>"#;
    let xml = UR5_URDF.replace("</robot>", probes);
    ["tool0", "probe_x", "probe_y", "probe_z"]
        .map(|tip| Chain::from_urdf_str(&xml, Some(tip)).expect("UR5 with probe links"))
}

/// Joint values far beyond the limits too: FK is defined everywhere.
fn wide_joint_values(n: usize) -> impl Strategy<Value = Vec<f64>> {
    let v = prop_oneof![
        6 => -7.0f64..7.0,
        3 => -1e3f64..1e3,
        1 => -1e6f64..1e6,
        1 => prop::sample::select(vec![0.0, -0.0, std::f64::consts::PI, -std::f64::consts::FRAC_PI_2, 1e5, 1.0000001e5]),
    ];
    prop::collection::vec(v, n)
}

#[test]
fn fk_rotation_is_orthonormal_and_quaternion_unit_canonical() {
    let chains = ur5_with_probes();
    let ur5 = Chain::ur5();
    check(256, wide_joint_values(6), |q| {
        let pose = chains[0].fk(&q);
        prop_assert_eq!(pose, ur5.fk(&q), "probe links change nothing up to tool0");
        let p0 = pose.position;
        let cols: Vec<Vector3<f64>> = chains[1..].iter().map(|c| c.fk(&q).position - p0).collect();
        let r = Matrix3::from_columns(&cols);
        let rtr = r.transpose() * r;
        prop_assert!(
            (rtr - Matrix3::identity()).amax() <= 1e-12,
            "R^T R - I = {}",
            rtr - Matrix3::identity()
        );
        prop_assert!((r.determinant() - 1.0).abs() <= 1e-12, "det R = {}", r.determinant());

        let [x, y, z, w] = pose.quaternion_xyzw();
        let norm = (x * x + y * y + z * z + w * w).sqrt();
        prop_assert!((norm - 1.0).abs() <= 1e-12, "|q| = {norm}");
        prop_assert!(w >= 0.0, "w = {w}");
        // The quaternion is the rotation FK computed.
        let rq = pose.orientation.to_rotation_matrix();
        prop_assert!((rq.matrix() - r).amax() <= 1e-12, "quaternion {:?} vs R {}", [x, y, z, w], r);
        // tool0's z axis is the last joint's axis, which the Jacobian reports independently.
        let mut jac = [0.0; 36];
        chains[0].jacobian(&q, &mut jac);
        let z6 = Vector3::new(jac[3 * 6 + 5], jac[4 * 6 + 5], jac[5 * 6 + 5]);
        prop_assert!((z6 - cols[2]).amax() <= 1e-12, "z6 {z6} vs R e_z {}", cols[2]);
        Ok(())
    });
}

/// The Jacobian's linear rows against central differences of the FK position.
fn jacobian_matches_finite_differences(chain: &Chain) {
    let n = chain.dof();
    check(128, wide_joint_values(n), |mut q| {
        // A prismatic joint 1e6 m out puts the tip 1e6 m away, where differences of positions
        // lose the digits a finite-difference check needs: keep those within +-10 m.
        for (qi, j) in q.iter_mut().zip(chain.joints()) {
            if j.kind == JointKind::Prismatic {
                *qi %= 10.0;
            }
        }
        let mut jac = vec![0.0; 6 * n];
        let pose = chain.jacobian(&q, &mut jac);
        prop_assert_eq!(pose, chain.fk(&q));
        let h = 1e-6;
        for i in 0..n {
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[i] += h;
            qm[i] -= h;
            // The step as represented: at |q| ~ 1e6 the spacing of f64 is ~1e-10.
            let fd = (chain.fk(&qp).position - chain.fk(&qm).position) / (qp[i] - qm[i]);
            for r in 0..3 {
                let (a, b) = (jac[r * n + i], fd[r]);
                prop_assert!(
                    (a - b).abs() <= 1e-7 * (1.0 + b.abs()),
                    "J[{r}][{i}] = {a}, finite differences {b}"
                );
            }
        }
        Ok(())
    });
}

#[test]
fn ur5_jacobian_linear_part_matches_finite_differences() {
    jacobian_matches_finite_differences(&Chain::ur5());
}

#[test]
fn test_arm_jacobian_linear_part_matches_finite_differences() {
    // Skewed axes, a prismatic joint, a continuous joint, folded fixed joints.
    jacobian_matches_finite_differences(&Chain::from_urdf_str(TEST_ARM, Some("tool")).unwrap());
}

// ---------------------------------------------------------------------------------------------
// Environment.

/// One action value: mostly ordinary, often extreme (the environment clips, it must not break).
fn action_value() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => -1.0f32..1.0,
        6 => prop::sample::select(vec![
            1.0f32, -1.0, 1e30, -1e30, f32::MAX, f32::MIN, f32::MIN_POSITIVE, -f32::MIN_POSITIVE,
            -0.0, 0.0, 1e-45, -1e-45, f32::EPSILON, 1.0 + f32::EPSILON,
        ]),
        2 => prop::num::f32::NORMAL | prop::num::f32::SUBNORMAL | prop::num::f32::ZERO
            | prop::num::f32::POSITIVE | prop::num::f32::NEGATIVE,
    ]
}

/// A whole config: any reward settings, any control period and observation scale that validate.
fn env_config() -> impl Strategy<Value = Config> {
    (
        reward_config(),
        prop_oneof![3 => Just(0.05), 1 => (-4.0f64..1.0).prop_map(|e| 10f64.powf(e))],
        prop_oneof![3 => Just(10.0), 2 => (-3.0f64..6.0).prop_map(|e| 10f64.powf(e)),
                    1 => (6.0f64..300.0).prop_map(|e| 10f64.powf(e))],
        1..=60u32,
    )
        .prop_map(|(reward, dt_s, obs_delta_scale, max_steps)| {
            let mut cfg = Config { reward, ..Config::default() };
            cfg.task.dt_s = dt_s;
            cfg.task.obs_delta_scale = obs_delta_scale;
            cfg.task.max_steps = max_steps;
            cfg
        })
}

/// Run two whole episodes of `actions` (cycled), checking every observation and reward.
fn episodes_stay_finite(env: &mut ReachEnv, actions: &[f32], max_steps: u32) -> Result<(), TestCaseError> {
    let n = env.act_dim();
    let (lo, hi) = (env.chain().lower_limits().to_vec(), env.chain().upper_limits().to_vec());
    let mut k = 0;
    for episode in 0..2 {
        let obs = env.reset();
        prop_assert!(obs.iter().all(|x| x.is_finite()), "reset observation {obs:?}");
        for step in 1..=max_steps {
            let a: Vec<f32> = (0..n).map(|j| actions[(k + j) % actions.len()]).collect();
            k += n;
            let s = env.step(&a).map_err(|e| TestCaseError::fail(format!("step {step}: {e}")))?;
            let obs = env.observation();
            prop_assert!(
                obs.iter().all(|x| x.is_finite()),
                "episode {episode} step {step}: action {a:?} gave observation {obs:?}"
            );
            for (name, v) in all_terms(&s.terms) {
                prop_assert!(v.is_finite(), "episode {episode} step {step}: action {a:?} gave {name} = {v}");
            }
            let q = env.joint_positions();
            prop_assert!((0..n).all(|i| q[i] >= lo[i] && q[i] <= hi[i]), "q {q:?} outside the limits");
            prop_assert!(env.joint_velocities().iter().all(|v| v.is_finite()));
            prop_assert_eq!(s.truncated, !s.terminated && step == max_steps);
            if s.done() {
                break;
            }
        }
        prop_assert!(env.is_done(), "the episode ends by max_steps");
    }
    Ok(())
}

#[test]
fn ur5_environment_stays_finite_under_any_finite_actions() {
    let actions = prop::collection::vec(action_value(), 6..=400);
    check(256, (env_config(), actions, any::<u64>()), |(cfg, actions, seed)| {
        if let Err(e) = cfg.validate() {
            // Out of the config's domain: refused with the field named, never a broken run.
            prop_assert!(e.to_string().contains("task.obs_delta_scale"), "{e}");
            return Ok(());
        }
        let mut env = ReachEnv::from_config(&cfg, seed).map_err(|e| TestCaseError::fail(e.to_string()))?;
        episodes_stay_finite(&mut env, &actions, cfg.task.max_steps)
    });
}

#[test]
fn test_arm_environment_stays_finite_under_any_finite_actions() {
    // Continuous (unbounded) and prismatic joints.
    let dir = std::env::temp_dir().join(format!("stagerl-props-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = dir.join("test_arm.urdf");
    std::fs::write(&urdf, TEST_ARM).unwrap();
    let mut cfg = Config::default();
    cfg.robot.urdf = urdf.to_string_lossy().into_owned();
    cfg.robot.tip = Some("tool".into());
    cfg.task.home_pose_rad = Some(vec![0.0; 4]);
    cfg.task.target_joint_range_rad = Some(vec![1.0, 0.3, 2.0, 1.0]);
    cfg.task.target_min_z_m = -10.0;
    let base = ReachEnv::from_config(&cfg, 0).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let actions = prop::collection::vec(action_value(), 4..=400);
    check(128, (actions, any::<u64>(), reward_function()), |(actions, seed, function)| {
        let reward = RewardConfig { function, ..base.reward_config().clone() };
        let mut env = ReachEnv::new(base.chain().clone(), base.task().clone(), reward, seed)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        env.reset_with_seed(seed);
        episodes_stay_finite(&mut env, &actions, 50)
    });
}
