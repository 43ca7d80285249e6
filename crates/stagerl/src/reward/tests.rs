//! Tests of `reward`.

use super::*;
use approx::assert_relative_eq;

const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

fn terms(
    function: RewardFunction,
    ee: [f64; 3],
    quat: [f64; 4],
    target: [f64; 3],
    vel: &[f64],
) -> RewardTerms {
    let cfg = RewardConfig { function, ..RewardConfig::default() };
    let input = RewardInput {
        ee_pos: Vector3::from(ee),
        ee_quat: quat,
        target: Vector3::from(target),
        joint_vel: vel,
        prev_ee_pos: None,
    };
    input.validate().unwrap();
    RewardTerms::compute(&cfg, 0.05, &input)
}

/// Quaternion of a rotation by `angle` about unit `axis`, as [x, y, z, w].
fn axis_angle(axis: [f64; 3], angle: f64) -> [f64; 4] {
    let (s, c) = (angle / 2.0).sin_cos();
    [axis[0] * s, axis[1] * s, axis[2] * s, c]
}

#[test]
fn position_eqs_1_2_at_and_around_beta() {
    let zero = [0.0; 6];
    // Exactly at beta = 0.01 m: not reached (J_reach needs D_PT < beta).
    let t = terms(RewardFunction::Posture, [0.0; 3], IDENTITY, [0.01, 0.0, 0.0], &zero);
    assert_eq!(t.distance, 0.01);
    assert!(!t.reached);
    assert_eq!(t.position, -0.01);
    assert_eq!(t.bonus, 0.0);
    // Just inside: J_reach = 1, position = 1 - D.
    let t = terms(RewardFunction::Posture, [0.0; 3], IDENTITY, [0.0, 0.0, 0.009], &zero);
    assert!(t.reached);
    assert_relative_eq!(t.position, 1.0 - 0.009, epsilon = 1e-15);
    assert_eq!(t.bonus, 20.0);
    assert_relative_eq!(t.total, t.reward + 20.0, epsilon = 1e-15);
    // 3-4-5 triangle: D = 0.5 exactly.
    let t = terms(RewardFunction::Stride, [0.1, 0.1, 0.1], IDENTITY, [0.4, 0.5, 0.1], &zero);
    assert_relative_eq!(t.distance, 0.5, epsilon = 1e-15);
    assert_relative_eq!(t.position, -0.5, epsilon = 1e-15);
}

#[test]
fn direction_eqs_3_6_hand_computed() {
    let zero = [0.0; 6];
    // Rotation about +x, target along +x: phi = 0, direction 0.
    let q = axis_angle([1.0, 0.0, 0.0], 0.7);
    let t = terms(RewardFunction::Posture, [0.0; 3], q, [0.3, 0.0, 0.0], &zero);
    assert_relative_eq!(t.phi, 0.0, epsilon = 1e-12);
    assert_relative_eq!(t.direction, 0.0, epsilon = 1e-12);
    // Axis +z, target along +x: phi = pi/2 -> fold gives pi - pi/2 = pi/2 -> 1/4.
    let q = axis_angle([0.0, 0.0, 1.0], 1.0);
    let t = terms(RewardFunction::Posture, [0.0; 3], q, [0.3, 0.0, 0.0], &zero);
    assert_relative_eq!(t.phi, FRAC_PI_2, epsilon = 1e-12);
    assert_relative_eq!(t.direction, 0.25, epsilon = 1e-12);
    // Axis at 60 degrees from the target direction: phi = pi/3 -> (pi/3)/(2 pi) = 1/6.
    let axis = [0.5, (3.0f64).sqrt() / 2.0, 0.0];
    let q = axis_angle(axis, 0.4);
    let t = terms(RewardFunction::Posture, [1.0, 1.0, 1.0], q, [1.2, 1.0, 1.0], &zero);
    assert_relative_eq!(t.phi, PI / 3.0, epsilon = 1e-12);
    assert_relative_eq!(t.direction, 1.0 / 6.0, epsilon = 1e-12);
    // Opposite axis (120 degrees): fold gives pi - 2pi/3 = pi/3 -> the same 1/6.
    let q = axis_angle([-axis[0], -axis[1], 0.0], 0.4);
    let t = terms(RewardFunction::Posture, [1.0, 1.0, 1.0], q, [1.2, 1.0, 1.0], &zero);
    assert_relative_eq!(t.phi, 2.0 * PI / 3.0, epsilon = 1e-12);
    assert_relative_eq!(t.direction, 1.0 / 6.0, epsilon = 1e-12);
    // Posture = position - direction (eq. 7).
    assert_relative_eq!(t.posture, -0.2 - 1.0 / 6.0, epsilon = 1e-12);
}

#[test]
fn direction_ignores_quaternion_sign() {
    let q = axis_angle([0.3, -0.5, 0.8f64].map(|x| x / (0.98f64).sqrt()), 2.0);
    let neg = q.map(|x| -x);
    let a = terms(RewardFunction::Posture, [0.1, 0.2, 0.3], q, [0.4, -0.1, 0.5], &[0.0; 6]);
    let b = terms(RewardFunction::Posture, [0.1, 0.2, 0.3], neg, [0.4, -0.1, 0.5], &[0.0; 6]);
    assert_relative_eq!(a.direction, b.direction, epsilon = 1e-12);
    assert_relative_eq!(a.phi + b.phi, PI, epsilon = 1e-12);
}

#[test]
fn identity_quaternion_and_zero_distance_give_phi_zero() {
    let t = terms(RewardFunction::Posture, [0.0; 3], IDENTITY, [0.3, 0.2, 0.1], &[0.0; 6]);
    assert_eq!(t.phi, 0.0);
    assert_eq!(t.direction, 0.0);
    // Target exactly at the end-effector: V_PT = 0.
    let q = axis_angle([0.0, 0.0, 1.0], 1.0);
    let t = terms(RewardFunction::Posture, [0.2; 3], q, [0.2; 3], &[0.0; 6]);
    assert_eq!(t.phi, 0.0);
    assert!(t.reached);
    assert!(t.posture.is_finite());
}

#[test]
fn movement_and_stride_eqs_9_10() {
    // Zero velocity: no movement penalty, stride = position.
    let t = terms(RewardFunction::Stride, [0.0; 3], IDENTITY, [0.2, 0.0, 0.0], &[0.0; 6]);
    assert_eq!(t.movement, 0.0);
    assert_eq!(t.stride, t.position);
    // V = [1, 2, 0, 0, 0, 1]: V.V = 6, dt 0.05, N 6 -> 0.05.
    let t =
        terms(RewardFunction::Stride, [0.0; 3], IDENTITY, [0.2, 0.0, 0.0], &[1.0, 2.0, 0.0, 0.0, 0.0, 1.0]);
    assert_relative_eq!(t.movement, 0.05, epsilon = 1e-15);
    assert_relative_eq!(t.stride, -0.2 - 0.05, epsilon = 1e-15);
    assert_eq!(t.reward, t.stride);
    // N is the velocity vector's length: 3 joints, V.V = 3 -> 0.05 * 3 / 3.
    let t = terms(RewardFunction::Stride, [0.0; 3], IDENTITY, [0.2, 0.0, 0.0], &[1.0, 1.0, 1.0]);
    assert_relative_eq!(t.movement, 0.05, epsilon = 1e-15);
}

#[test]
fn har_switches_at_half_a_metre_eqs_11_12() {
    let q = axis_angle([0.0, 0.0, 1.0], 1.0); // direction 1/4 for targets along x
    let vel = [1.0; 6]; // movement 0.05
    let far = terms(RewardFunction::Har, [0.0; 3], q, [0.5 + 1e-9, 0.0, 0.0], &vel);
    assert_eq!(far.gamma_posture, 1.0);
    assert_eq!(far.reward, far.posture);
    assert_relative_eq!(far.reward, -0.5 - 0.25, epsilon = 1e-8);
    // Exactly 0.5 m is the slow adjustable area (posture only when D_PT > 0.5).
    let at = terms(RewardFunction::Har, [0.0; 3], q, [0.5, 0.0, 0.0], &vel);
    assert_eq!(at.gamma_posture, 0.0);
    assert_eq!(at.reward, at.stride);
    assert_relative_eq!(at.reward, -0.5 - 0.05, epsilon = 1e-12);
    let near = terms(RewardFunction::Har, [0.0; 3], q, [0.3, 0.0, 0.0], &vel);
    assert_eq!(near.reward, near.stride);
}

#[test]
fn sar_blend_eqs_13_15() {
    let q = axis_angle([0.0, 0.0, 1.0], 1.0); // direction 1/4 along x
    let vel = [1.0; 6]; // movement 0.05
                        // D = 0.3: alpha1 0.7, alpha2 0.3; stride -0.35, posture -0.55.
    let t = terms(RewardFunction::Sar, [0.0; 3], q, [0.3, 0.0, 0.0], &vel);
    assert_relative_eq!(t.alpha1, 0.7, epsilon = 1e-12);
    assert_relative_eq!(t.alpha2, 0.3, epsilon = 1e-12);
    assert_relative_eq!(t.reward, 0.7 * -0.35 + 0.3 * -0.55, epsilon = 1e-12);
    // D = 1 and beyond: clamp to 1 -> pure posture.
    for d in [1.0, 1.7] {
        let t = terms(RewardFunction::Sar, [0.0; 3], q, [d, 0.0, 0.0], &vel);
        assert_eq!(t.alpha1, 0.0);
        assert_eq!(t.alpha2, 1.0);
        assert_relative_eq!(t.reward, t.posture, epsilon = 1e-12);
    }
    // D = 0: pure stride.
    let t = terms(RewardFunction::Sar, [0.0; 3], q, [0.0; 3], &vel);
    assert_eq!((t.alpha1, t.alpha2), (1.0, 0.0));
    assert_relative_eq!(t.reward, t.stride, epsilon = 1e-12);
}

#[test]
fn sar_sigmas_and_scale_are_used() {
    let cfg = RewardConfig { sar_sigma1: 2.0, sar_sigma2: 0.5, sar_scale_m: 0.5, ..RewardConfig::default() };
    let (a1, a2) = sar_weights(0.2, &cfg); // c = 0.4
    assert_relative_eq!(a1, 1.0 - 0.16, epsilon = 1e-12);
    assert_relative_eq!(a2, 0.4f64.sqrt(), epsilon = 1e-12);
}

#[test]
fn basic_eq_18_and_bonus() {
    let t = terms(RewardFunction::Basic, [0.0; 3], IDENTITY, [0.3, 0.0, 0.0], &[2.0; 6]);
    assert_eq!((t.reward, t.bonus, t.total), (0.0, 0.0, 0.0));
    let t = terms(RewardFunction::Basic, [0.0; 3], IDENTITY, [0.005, 0.0, 0.0], &[2.0; 6]);
    assert_eq!((t.reward, t.bonus, t.total), (1.0, 20.0, 21.0));
}

#[test]
fn displacement_direction_source() {
    let cfg = RewardConfig {
        function: RewardFunction::Posture,
        direction: DirectionSource::Displacement,
        direction_fold: false,
        ..RewardConfig::default()
    };
    let vel = [0.0; 6];
    let mk = |ee: [f64; 3]| RewardInput {
        ee_pos: Vector3::from(ee),
        ee_quat: IDENTITY,
        target: Vector3::new(1.0, 0.0, 0.0),
        joint_vel: &vel,
        prev_ee_pos: Some(Vector3::zeros()),
    };
    // Straight towards the target: phi 0.
    let t = RewardTerms::compute(&cfg, 0.05, &mk([0.1, 0.0, 0.0]));
    assert_relative_eq!(t.phi, 0.0, epsilon = 1e-12);
    // Straight away without the fold: phi = pi, direction 1/2.
    let t = RewardTerms::compute(&cfg, 0.05, &mk([-0.1, 0.0, 0.0]));
    assert_relative_eq!(t.direction, 0.5, epsilon = 1e-12);
    // Sideways: pi/2 -> 1/4.
    let t = RewardTerms::compute(&cfg, 0.05, &mk([0.0, 0.1, 0.0]));
    assert_relative_eq!(t.direction, 0.25, epsilon = 1e-12);
}

#[test]
fn input_validation_names_the_problem() {
    let vel = [0.0; 6];
    let mut input = RewardInput {
        ee_pos: Vector3::zeros(),
        ee_quat: [0.0, 0.0, 0.0, 1.1],
        target: Vector3::zeros(),
        joint_vel: &vel,
        prev_ee_pos: None,
    };
    let e = input.validate().unwrap_err().to_string();
    assert!(e.contains("ee_quat") && e.contains("norm"), "{e}");
    input.ee_quat = IDENTITY;
    input.target = Vector3::new(0.0, f64::NAN, 0.0);
    let e = input.validate().unwrap_err().to_string();
    assert!(e.contains("target[1]"), "{e}");
    input.target = Vector3::zeros();
    input.joint_vel = &[];
    assert!(input.validate().unwrap_err().to_string().contains("joint_vel"));
}

#[test]
fn config_validation_names_field_value_and_range() {
    let bad = [
        RewardConfig { beta_m: 0.0, ..Default::default() },
        RewardConfig { beta_m: -0.01, ..Default::default() },
        RewardConfig { sar_sigma1: -1.0, ..Default::default() },
        RewardConfig { sar_sigma2: f64::NAN, ..Default::default() },
        RewardConfig { har_boundary_m: -0.5, ..Default::default() },
        RewardConfig { sar_scale_m: 0.0, ..Default::default() },
        RewardConfig { success_bonus: f64::INFINITY, ..Default::default() },
    ];
    let fields = [
        "reward.beta_m",
        "reward.beta_m",
        "reward.sar_sigma1",
        "reward.sar_sigma2",
        "reward.har_boundary_m",
        "reward.sar_scale_m",
        "reward.success_bonus",
    ];
    for (cfg, field) in bad.iter().zip(fields) {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains(field), "{e} should name {field}");
    }
    RewardConfig::default().validate().unwrap();
    assert!("sar".parse::<RewardFunction>().is_ok());
    let e = "SAR2".parse::<RewardFunction>().unwrap_err().to_string();
    assert!(e.contains("SAR2") && e.contains("basic, posture"), "{e}");
}
