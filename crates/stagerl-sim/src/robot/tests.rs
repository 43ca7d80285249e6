//! Unit tests of the robot module: UR5 against standard DH, a hand-checked pose, the Jacobian
//! against finite differences, numerical properties and one test per URDF error.
//! (The comparison with the `k` crate is in `tests/it/robot_k_oracle.rs`.)

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix3, Matrix4, Rotation3, UnitQuaternion, Vector3};

use super::kin;
use super::*;
use crate::base::rng::Rng;
use crate::Error;

/// The test arm of `crates/stagerl/tests/robot_test_arm.urdf` (tip `tool`).
const TEST_ARM: &str = include_str!("../../../stagerl/tests/robot_test_arm.urdf");

fn test_arm() -> Chain {
    Chain::from_urdf_str(TEST_ARM, Some("tool")).unwrap()
}

/// A random configuration within the limits (continuous joints: within +-2 pi).
fn random_q(chain: &Chain, rng: &mut Rng) -> Vec<f64> {
    chain
        .lower_limits()
        .iter()
        .zip(chain.upper_limits())
        .map(|(&lo, &hi)| {
            let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (-2.0 * PI, 2.0 * PI) };
            rng.uniform_range(lo, hi)
        })
        .collect()
}

/// The URDF error message, or a panic naming what came instead.
fn urdf_message<T: std::fmt::Debug>(r: Result<T>) -> String {
    match r {
        Err(Error::Urdf(m)) => m,
        other => panic!("expected a URDF error, got {other:?}"),
    }
}

fn rot_of(m: &[f64; 12]) -> Matrix3<f64> {
    Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10])
}

// ---------------------------------------------------------------------------------------------
// UR5

/// Standard DH forward kinematics of the UR5, written independently of the URDF.
fn ur5_dh(q: &[f64]) -> Matrix4<f64> {
    let d = [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823];
    let a = [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0];
    let alpha = [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];
    let mut t = Matrix4::identity();
    for i in 0..6 {
        let (st, ct) = q[i].sin_cos();
        let (sa, ca) = alpha[i].sin_cos();
        // Rz(theta) Tz(d) Tx(a) Rx(alpha)
        let ti = Matrix4::new(
            ct,
            -st * ca,
            st * sa,
            a[i] * ct,
            st,
            ct * ca,
            -ct * sa,
            a[i] * st,
            0.0,
            sa,
            ca,
            d[i],
            0.0,
            0.0,
            0.0,
            1.0,
        );
        t *= ti;
    }
    t
}

#[test]
fn ur5_structure_and_limits() {
    let c = Chain::ur5();
    assert_eq!(c.dof(), 6);
    assert_eq!(c.base_link(), "base_link");
    assert_eq!(c.tip_link(), "tool0");
    let names: Vec<&str> = c.joints().iter().map(|j| j.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint"
        ]
    );
    assert!(c.joints().iter().all(|j| j.kind == JointKind::Revolute));
    let two_pi = 2.0 * PI;
    assert_eq!(c.lower_limits(), [-two_pi, -two_pi, -PI, -two_pi, -two_pi, -two_pi]);
    assert_eq!(c.upper_limits(), [two_pi, two_pi, PI, two_pi, two_pi, two_pi]);
    assert_eq!(c.velocity_limits(), [PI; 6]);
    for (j, (&lo, (&hi, &v))) in
        c.joints().iter().zip(c.lower_limits().iter().zip(c.upper_limits().iter().zip(c.velocity_limits())))
    {
        assert_eq!((j.lower, j.upper, j.velocity), (lo, hi, v));
    }
}

/// Hand check at q = 0 (see the derivation): the upper arm and forearm lie along base -x
/// (a2 + a3 = -0.81725), d4 and d6 point along base -y (-0.10915 - 0.0823 = -0.19145), d5 along
/// base -z (0.089159 - 0.09465 = -0.005491); the orientation is Rx(pi/2) (alphas pi/2 + pi/2 - pi/2).
#[test]
fn ur5_zero_configuration_hand_checked() {
    let p = Chain::ur5().fk(&[0.0; 6]);
    let expected = Vector3::new(-0.81725, -0.19145, -0.005491);
    assert!((p.position - expected).amax() < 1e-12, "{:?}", p.position);
    let s = (PI / 4.0).sin();
    let q = p.quaternion_xyzw();
    let e = [s, 0.0, 0.0, s];
    for k in 0..4 {
        assert!((q[k] - e[k]).abs() < 1e-12, "{q:?}");
    }
    // And the DH reference agrees with the hand values.
    let t = ur5_dh(&[0.0; 6]);
    assert!((t.fixed_view::<3, 1>(0, 3) - expected).amax() < 1e-12);
}

#[test]
fn ur5_matches_standard_dh() {
    let c = Chain::ur5();
    let mut rng = Rng::new(11);
    for _ in 0..2000 {
        let q = random_q(&c, &mut rng);
        let t = ur5_dh(&q);
        let m = c.fk_matrix(&q);
        let pose = c.fk(&q);
        for r in 0..3 {
            assert!((m[4 * r + 3] - t[(r, 3)]).abs() < 1e-12, "q = {q:?}");
            assert!((pose.position[r] - t[(r, 3)]).abs() < 1e-12, "q = {q:?}");
            for k in 0..3 {
                assert!((m[4 * r + k] - t[(r, k)]).abs() < 1e-12, "q = {q:?}");
            }
        }
        let r_dh = Rotation3::from_matrix_unchecked(t.fixed_view::<3, 3>(0, 0).into_owned());
        let q_dh = UnitQuaternion::from_rotation_matrix(&r_dh);
        assert!(rotation_vector(&pose.orientation, &q_dh).norm() < 1e-12, "q = {q:?}");
    }
}

#[test]
fn ur5_tip_choice() {
    let tool = Chain::load("ur5", None).unwrap();
    assert_eq!(tool.tip_link(), "tool0");
    let wrist = Chain::load("ur5", Some("wrist_3_link")).unwrap();
    assert_eq!(wrist.tip_link(), "wrist_3_link");
    assert_eq!(wrist.dof(), 6);
    let mut rng = Rng::new(5);
    for _ in 0..100 {
        let q = random_q(&tool, &mut rng);
        let a = tool.fk(&q);
        let b = wrist.fk(&q);
        // tool0 is 0.0823 m along wrist_3_link's z, same orientation.
        let expected = b.position + b.orientation * Vector3::new(0.0, 0.0, 0.0823);
        assert!((a.position - expected).amax() < 1e-12);
        assert!(rotation_vector(&a.orientation, &b.orientation).norm() < 1e-12);
    }
}

// ---------------------------------------------------------------------------------------------
// Numerical properties

#[test]
fn quaternion_unit_canonical_and_rotation_orthonormal() {
    let mut rng = Rng::new(3);
    for chain in [Chain::ur5(), test_arm()] {
        for _ in 0..2000 {
            let q = random_q(&chain, &mut rng);
            let pose = chain.fk(&q);
            let [x, y, z, w] = pose.quaternion_xyzw();
            assert!(w >= 0.0);
            assert!(((x * x + y * y + z * z + w * w).sqrt() - 1.0).abs() < 1e-14);
            let r = rot_of(&chain.fk_matrix(&q));
            assert!((r * r.transpose() - Matrix3::identity()).amax() < 1e-13);
            assert!((r.determinant() - 1.0).abs() < 1e-13);
            let from_q = pose.orientation.to_rotation_matrix().into_inner();
            assert!((from_q - r).amax() < 1e-14, "{q:?}");
        }
    }
}

#[test]
fn shepperd_is_robust_near_half_turns() {
    let mut rng = Rng::new(9);
    for i in 0..4000 {
        let axis = Vector3::new(
            rng.uniform_range(-1.0, 1.0),
            rng.uniform_range(-1.0, 1.0),
            rng.uniform_range(-1.0, 1.0),
        )
        .normalize();
        // Angles near pi (the hard case for the trace formula), near 0 and anywhere.
        let angle = match i % 3 {
            0 => PI - rng.uniform_range(0.0, 1e-6),
            1 => rng.uniform_range(0.0, 1e-6),
            _ => rng.uniform_range(0.0, PI),
        };
        let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
        let m = r.matrix();
        let tf = [
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            0.0,
            m[(1, 0)],
            m[(1, 1)],
            m[(1, 2)],
            0.0,
            m[(2, 0)],
            m[(2, 1)],
            m[(2, 2)],
            0.0,
        ];
        let pose = kin::pose_of(&tf);
        assert!(pose.orientation.w >= 0.0);
        let back = pose.orientation.to_rotation_matrix().into_inner();
        assert!((back - m).amax() < 1e-14, "axis {axis:?} angle {angle}");
    }
    // Exact half turns about the coordinate axes.
    for tf in [
        [1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
    ] {
        let back = kin::pose_of(&tf).orientation.to_rotation_matrix().into_inner();
        assert!((back - rot_of(&tf)).amax() < 1e-15);
    }
}

#[test]
fn axis_basis_is_a_rotation_taking_z_to_the_axis() {
    let mut rng = Rng::new(21);
    let mut axes = vec![[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
    for _ in 0..1000 {
        let v = Vector3::new(
            rng.uniform_range(-1.0, 1.0),
            rng.uniform_range(-1.0, 1.0),
            rng.uniform_range(-1.0, 1.0),
        )
        .normalize();
        axes.push([v.x, v.y, v.z]);
    }
    for n in axes {
        let a = kin::basis_for_axis(n);
        let r = rot_of(&a);
        assert!((r * r.transpose() - Matrix3::identity()).amax() < 1e-14, "{n:?}");
        assert!((r.determinant() - 1.0).abs() < 1e-14, "{n:?}");
        assert!((r * Vector3::z() - Vector3::from(n)).amax() < 1e-15, "{n:?}");
    }
    // Exact for +z (the UR5 case): no rounding introduced.
    assert_eq!(kin::basis_for_axis([0.0, 0.0, 1.0]), kin::IDENTITY);
}

#[test]
fn fast_sin_cos_matches_std() {
    let mut rng = Rng::new(33);
    let mut xs: Vec<f64> = vec![0.0, -0.0, 1e-300, -1e-300, 5e-324, PI, -PI, 1e5, -1e5, 1.5e5];
    for _ in 0..200_000 {
        xs.push(rng.uniform_range(-2.0 * PI, 2.0 * PI));
        xs.push(rng.uniform_range(-1e5, 1e5));
        // Near multiples of pi/4 (quadrant and kernel boundaries).
        let k = rng.uniform_range(-4000.0, 4000.0).round();
        xs.push(k * PI / 4.0 + rng.uniform_range(-1e-9, 1e-9));
    }
    let mut worst = 0.0f64;
    for &x in &xs {
        let (s, c) = kin::sin_cos(x);
        let (s0, c0) = x.sin_cos();
        worst = worst.max((s - s0).abs()).max((c - c0).abs());
        assert!((s - s0).abs() <= 2.3e-16 && (c - c0).abs() <= 2.3e-16, "x = {x:e}");
        assert!(s.abs() <= 1.0 && c.abs() <= 1.0, "x = {x:e}");
    }
    assert!(worst <= 2.3e-16, "{worst:e}");
    // Tiny arguments are returned exactly; large and non-finite ones go to the standard library.
    assert_eq!(kin::sin_cos(1e-300), (1e-300, 1.0));
    assert_eq!(kin::sin_cos(1e12), 1e12f64.sin_cos());
    assert!(kin::sin_cos(f64::NAN).0.is_nan() && kin::sin_cos(f64::INFINITY).1.is_nan());
}

// ---------------------------------------------------------------------------------------------
// Jacobian

/// The rotation vector of `a * b^-1` (exact for small angles, unlike an acos-based angle).
fn rotation_vector(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> Vector3<f64> {
    let rel = a * b.inverse();
    let (w, v) = (rel.w, rel.imag());
    let (w, v) = if w < 0.0 { (-w, -v) } else { (w, v) };
    let s = v.norm();
    if s == 0.0 {
        return Vector3::zeros();
    }
    v * (2.0 * s.atan2(w) / s)
}

fn check_jacobian_against_finite_differences(chain: &Chain, seed: u64) {
    let n = chain.dof();
    let mut rng = Rng::new(seed);
    let mut jac = vec![0.0; 6 * n];
    let h = 1e-6;
    for _ in 0..300 {
        let q = random_q(chain, &mut rng);
        let pose = chain.jacobian(&q, &mut jac);
        assert_eq!(pose, chain.fk(&q));
        for i in 0..n {
            let mut qp = q.clone();
            let mut qm = q.clone();
            qp[i] += h;
            qm[i] -= h;
            let (pp, pm) = (chain.fk(&qp), chain.fk(&qm));
            let dv = (pp.position - pm.position) / (2.0 * h);
            let dw = rotation_vector(&pp.orientation, &pm.orientation) / (2.0 * h);
            for r in 0..3 {
                let (jv, jw) = (jac[r * n + i], jac[(r + 3) * n + i]);
                assert!((jv - dv[r]).abs() < 1e-7, "v row {r} col {i}: {jv} vs {}", dv[r]);
                assert!((jw - dw[r]).abs() < 1e-7, "w row {r} col {i}: {jw} vs {}", dw[r]);
            }
        }
    }
}

#[test]
fn ur5_jacobian_matches_finite_differences() {
    check_jacobian_against_finite_differences(&Chain::ur5(), 17);
}

#[test]
fn test_arm_jacobian_matches_finite_differences() {
    let c = test_arm();
    assert_eq!(
        c.joints().iter().map(|j| j.kind).collect::<Vec<_>>(),
        [JointKind::Revolute, JointKind::Prismatic, JointKind::Revolute, JointKind::Revolute]
    );
    check_jacobian_against_finite_differences(&c, 18);
}

#[test]
fn prismatic_column_is_the_unit_axis() {
    // j2 translates along (1, 1, 0)/sqrt 2 in l1: its linear column has unit norm, angular zero.
    let c = test_arm();
    let mut jac = vec![0.0; 6 * c.dof()];
    c.jacobian(&[0.3, 0.1, -1.0, 0.5], &mut jac);
    let n = c.dof();
    let v = Vector3::new(jac[1], jac[n + 1], jac[2 * n + 1]);
    assert!((v.norm() - 1.0).abs() < 1e-14);
    for r in 3..6 {
        assert_eq!(jac[r * n + 1], 0.0);
    }
}

// ---------------------------------------------------------------------------------------------
// Checked FK and loading

#[test]
fn try_fk_checks_length_and_finiteness() {
    let c = Chain::ur5();
    let q = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6];
    assert_eq!(c.try_fk(&q).unwrap(), c.fk(&q));
    match c.try_fk(&q[..5]) {
        Err(Error::InvalidInput(m)) => assert!(m.contains("expected length 6"), "{m}"),
        other => panic!("{other:?}"),
    }
    match c.try_fk(&[0.0; 7]) {
        Err(Error::InvalidInput(m)) => assert!(m.contains("7 values"), "{m}"),
        other => panic!("{other:?}"),
    }
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut q = q;
        q[2] = bad;
        match c.try_fk(&q) {
            Err(Error::InvalidInput(m)) => {
                assert!(m.contains("q[2]") && m.contains("elbow_joint"), "{m}")
            }
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn load_reads_files_and_reports_io_errors() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../stagerl/tests/robot_test_arm.urdf");
    let c = Chain::load(path, Some("tool")).unwrap();
    assert_eq!(c.dof(), 4);
    assert_eq!(c.base_link(), "world");
    let q = [0.2, -0.1, 3.0, 1.0];
    assert_eq!(c.fk(&q), test_arm().fk(&q));
    match Chain::load("/nonexistent/dir/robot.urdf", None) {
        Err(Error::Io { path, .. }) => assert!(path.ends_with("robot.urdf")),
        other => panic!("{other:?}"),
    }
    // URDF errors from a file name the file.
    let m = urdf_message(Chain::load(path, None));
    assert!(m.contains("robot_test_arm.urdf") && m.contains("`tool`"), "{m}");
}

#[test]
fn test_arm_limits() {
    let c = test_arm();
    assert_eq!(c.lower_limits(), [-2.5, -0.3, f64::NEG_INFINITY, -1.5]);
    assert_eq!(c.upper_limits(), [2.8, 0.4, f64::INFINITY, 1.7]);
    assert_eq!(c.velocity_limits(), [2.0, 0.5, 3.0, 1.5]);
}

// ---------------------------------------------------------------------------------------------
// URDF errors: one per case, each naming the joint or link at fault.

const LIMIT: &str = r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#;

/// A robot from link names and joint XML snippets.
fn robot(links: &[&str], joints: &[String]) -> String {
    let mut s = String::from("<robot name=\"r\">\n");
    for l in links {
        s += &format!("  <link name=\"{l}\"/>\n");
    }
    for j in joints {
        s += j;
        s += "\n";
    }
    s + "</robot>\n"
}

/// A joint snippet; `extra` goes inside the element (origin, axis, limit, ...).
fn joint(name: &str, kind: &str, parent: &str, child: &str, extra: &str) -> String {
    format!(
        "  <joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/>\
         <child link=\"{child}\"/>{extra}</joint>"
    )
}

fn rev(name: &str, parent: &str, child: &str) -> String {
    joint(name, "revolute", parent, child, &format!("<axis xyz=\"0 0 1\"/>{LIMIT}"))
}

#[test]
fn error_unparseable_document() {
    let m = urdf_message(Chain::from_urdf_str("<robot name=\"r\"><link", None));
    assert!(m.contains("parse"), "{m}");
}

#[test]
fn error_unknown_tip_link() {
    let xml = robot(&["a", "b"], &[rev("j", "a", "b")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, Some("hand")));
    assert!(m.contains("unknown tip link `hand`"), "{m}");
}

#[test]
fn error_several_leaves_without_tip() {
    let xml = robot(&["a", "b", "c"], &[rev("j1", "a", "b"), rev("j2", "a", "c")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("`b`") && m.contains("`c`") && m.contains("pass the tip"), "{m}");
    // With a tip it compiles.
    assert_eq!(Chain::from_urdf_str(&xml, Some("c")).unwrap().dof(), 1);
}

#[test]
fn error_link_with_no_path_to_root() {
    // b and c are each other's parent: a cycle detached from the root a.
    let xml = robot(&["a", "x", "b", "c"], &[rev("j0", "a", "x"), rev("jb", "c", "b"), rev("jc", "b", "c")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, Some("c")));
    assert!(m.contains("link `c` has no path to the root link `a`"), "{m}");
    assert!(m.contains("`jb`") && m.contains("`jc`"), "{m}");
}

#[test]
fn error_joint_with_missing_parent_or_child_link() {
    let xml = robot(&["a", "b"], &[rev("j", "a", "b"), rev("k", "ghost", "b")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("joint `k`") && m.contains("parent link `ghost`"), "{m}");
    let xml = robot(&["a", "b"], &[rev("j", "a", "b"), rev("k", "b", "phantom")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("joint `k`") && m.contains("child link `phantom`"), "{m}");
}

#[test]
fn error_more_than_one_root() {
    let xml = robot(&["a", "b", "c", "d"], &[rev("j1", "a", "b"), rev("j2", "c", "d")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, Some("b")));
    assert!(m.contains("more than one root") && m.contains("`a`") && m.contains("`c`"), "{m}");
}

#[test]
fn error_link_with_two_parent_joints() {
    let xml = robot(&["a", "b", "c"], &[rev("j1", "a", "b"), rev("j2", "c", "b")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, Some("b")));
    assert!(m.contains("link `b`") && m.contains("`j1`") && m.contains("`j2`"), "{m}");
}

#[test]
fn error_unsupported_joint_types_on_chain() {
    for kind in ["floating", "planar", "spherical"] {
        let xml = robot(&["a", "b", "c"], &[rev("j1", "a", "b"), joint("odd", kind, "b", "c", "")]);
        let m = urdf_message(Chain::from_urdf_str(&xml, None));
        assert!(m.contains("joint `odd`") && m.contains("unsupported type"), "{kind}: {m}");
    }
}

#[test]
fn error_mimic_joint_on_chain() {
    let mimic = format!("<axis xyz=\"0 0 1\"/>{LIMIT}<mimic joint=\"j1\"/>");
    let xml = robot(&["a", "b", "c"], &[rev("j1", "a", "b"), joint("m", "revolute", "b", "c", &mimic)]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("joint `m`") && m.contains("mimic"), "{m}");
}

#[test]
fn error_revolute_or_prismatic_without_usable_limits() {
    let cases = [
        ("revolute", String::new()),
        ("revolute", r#"<limit lower="1" upper="1" effort="1" velocity="1"/>"#.to_string()),
        ("prismatic", r#"<limit lower="0.5" upper="-0.5" effort="1" velocity="1"/>"#.to_string()),
        ("prismatic", r#"<limit lower="-1" upper="1" effort="1" velocity="0"/>"#.to_string()),
        ("revolute", r#"<limit lower="-1" upper="inf" effort="1" velocity="1"/>"#.to_string()),
        ("revolute", r#"<limit lower="nan" upper="1" effort="1" velocity="1"/>"#.to_string()),
    ];
    for (kind, limit) in cases {
        let extra = format!("<axis xyz=\"0 0 1\"/>{limit}");
        let xml = robot(&["a", "b"], &[joint("lim", kind, "a", "b", &extra)]);
        let m = urdf_message(Chain::from_urdf_str(&xml, None));
        assert!(m.contains("joint `lim`") && m.contains("no usable <limit>"), "{limit}: {m}");
    }
}

#[test]
fn error_continuous_without_velocity_limit() {
    let xml = robot(&["a", "b"], &[joint("spin", "continuous", "a", "b", "<axis xyz=\"0 0 1\"/>")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("joint `spin`") && m.contains("velocity"), "{m}");
    // With one it compiles, unbounded.
    let xml = robot(
        &["a", "b"],
        &[joint("spin", "continuous", "a", "b", "<axis xyz=\"0 0 1\"/><limit effort=\"1\" velocity=\"2\"/>")],
    );
    let c = Chain::from_urdf_str(&xml, None).unwrap();
    assert_eq!(c.lower_limits(), [f64::NEG_INFINITY]);
    assert_eq!(c.upper_limits(), [f64::INFINITY]);
    assert_eq!(c.velocity_limits(), [2.0]);
}

#[test]
fn error_non_finite_origin_or_axis() {
    for origin in [r#"<origin xyz="0 nan 0" rpy="0 0 0"/>"#, r#"<origin xyz="0 0 0" rpy="0 inf 0"/>"#] {
        // On a fixed joint in the middle of the chain as well as on an actuated one.
        let xml = robot(&["a", "b", "c"], &[rev("j1", "a", "b"), joint("bad", "fixed", "b", "c", origin)]);
        let m = urdf_message(Chain::from_urdf_str(&xml, None));
        assert!(m.contains("joint `bad`") && m.contains("non-finite origin"), "{m}");
        let extra = format!("{origin}<axis xyz=\"0 0 1\"/>{LIMIT}");
        let xml = robot(&["a", "b"], &[joint("bad", "revolute", "a", "b", &extra)]);
        let m = urdf_message(Chain::from_urdf_str(&xml, None));
        assert!(m.contains("joint `bad`") && m.contains("non-finite origin"), "{m}");
    }
    let extra = format!("<axis xyz=\"0 NaN 1\"/>{LIMIT}");
    let xml = robot(&["a", "b"], &[joint("bad", "prismatic", "a", "b", &extra)]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("joint `bad`") && m.contains("non-finite axis"), "{m}");
}

#[test]
fn error_zero_axis() {
    let extra = format!("<axis xyz=\"0 0 0\"/>{LIMIT}");
    let xml = robot(&["a", "b"], &[joint("flat", "revolute", "a", "b", &extra)]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("joint `flat`") && m.contains("zero axis"), "{m}");
}

#[test]
fn error_chain_without_actuated_joint() {
    let xml = robot(&["a", "b"], &[joint("weld", "fixed", "a", "b", "")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, None));
    assert!(m.contains("no actuated joint") && m.contains("`a`") && m.contains("`b`"), "{m}");
    // The root as tip: an empty chain.
    let xml = robot(&["a", "b"], &[rev("j", "a", "b")]);
    let m = urdf_message(Chain::from_urdf_str(&xml, Some("a")));
    assert!(m.contains("no actuated joint"), "{m}");
}

#[test]
fn joints_off_the_chain_are_ignored() {
    // A floating joint, a limitless revolute joint and a NaN origin on a side branch.
    let xml = robot(
        &["a", "b", "c", "s1", "s2", "s3"],
        &[
            rev("j1", "a", "b"),
            rev("j2", "b", "c"),
            joint("float", "floating", "a", "s1", ""),
            joint("nolim", "revolute", "b", "s2", "<axis xyz=\"0 0 1\"/>"),
            joint("nan", "fixed", "c", "s3", r#"<origin xyz="nan 0 0" rpy="0 0 0"/>"#),
        ],
    );
    let c = Chain::from_urdf_str(&xml, Some("c")).unwrap();
    assert_eq!(c.dof(), 2);
    assert_eq!(c.joints()[1].name, "j2");
}

#[test]
fn axes_are_normalised() {
    // An unnormalised axis gives the same kinematics as the unit one.
    let mk = |axis: &str| {
        let extra = format!("<origin xyz=\"0.1 0.2 0.3\" rpy=\"0.3 0.2 0.1\"/><axis xyz=\"{axis}\"/>{LIMIT}");
        let xml = robot(
            &["a", "b", "c"],
            &[joint("j", "revolute", "a", "b", &extra), joint("p", "prismatic", "b", "c", &extra)],
        );
        Chain::from_urdf_str(&xml, None).unwrap()
    };
    let (big, unit) = (mk("0 3 4"), mk("0 0.6 0.8"));
    let q = [0.7, 0.4];
    let (a, b) = (big.fk(&q), unit.fk(&q));
    assert!((a.position - b.position).amax() < 1e-15);
    assert!(rotation_vector(&a.orientation, &b.orientation).norm() < 1e-15);
}

#[test]
fn sin_cos_chunk_matches_scalar() {
    let mut rng = Rng::new(44);
    for len in 0..=kin::CHUNK {
        let mut q: Vec<f64> = (0..len).map(|_| rng.uniform_range(-10.0, 10.0)).collect();
        if len == 5 {
            q[2] = 3e7; // one value past the fast range: the whole chunk takes the scalar path
        }
        let sc = kin::sin_cos_chunk(&q);
        for (i, &(s, c)) in sc.iter().enumerate() {
            let expected = q.get(i).map_or((0.0, 1.0), |&v| kin::sin_cos(v));
            assert_eq!((s.to_bits(), c.to_bits()), (expected.0.to_bits(), expected.1.to_bits()));
        }
    }
}

#[test]
fn reach_bound_holds_and_is_tight_enough() {
    let mut rng = Rng::new(17);
    for chain in [Chain::ur5(), test_arm()] {
        let bound = chain.reach_bound_m();
        assert!(bound.is_finite() && bound > 0.0);
        let mut farthest: f64 = 0.0;
        for _ in 0..20_000 {
            let q = random_q(&chain, &mut rng);
            let r = chain.fk(&q).position.norm();
            assert!(r <= bound + 1e-12, "{} > bound {bound}", r);
            farthest = farthest.max(r);
        }
        // A bound, not a guess: within a factor 2 of the farthest sampled tip.
        assert!(bound < 2.0 * farthest, "bound {bound}, farthest {farthest}");
    }
}

#[test]
fn joint_origins_are_the_skeleton_of_the_arm() {
    let mut rng = Rng::new(11);
    for chain in [Chain::ur5(), test_arm()] {
        for _ in 0..50 {
            let q = random_q(&chain, &mut rng);
            let points = chain.joint_origins(&q).unwrap();
            assert_eq!(points.len(), chain.dof() + 1);
            let first = Vector3::from(points[0]);
            assert!((first - chain.first_joint_origin()).norm() < 1e-12);
            let tip = Vector3::from(points[chain.dof()]);
            assert!((tip - chain.fk(&q).position).norm() < 1e-12);
            // The jacobian's joint origins: column i's linear part is z_i x (tip - p_i).
            let mut jac = vec![0.0; 6 * chain.dof()];
            chain.jacobian(&q, &mut jac);
            let n = chain.dof();
            for (i, j) in chain.joints().iter().enumerate() {
                if j.kind == JointKind::Revolute {
                    let z = Vector3::new(jac[3 * n + i], jac[4 * n + i], jac[5 * n + i]);
                    let lin = Vector3::new(jac[i], jac[n + i], jac[2 * n + i]);
                    let want = z.cross(&(tip - Vector3::from(points[i])));
                    assert!((lin - want).norm() < 1e-12, "joint {i}");
                }
            }
        }
    }
    // UR5 (revolute only): consecutive origins are the constant link lengths apart.
    let ur5 = Chain::ur5();
    let points = ur5.joint_origins(&random_q(&ur5, &mut rng)).unwrap();
    for (w, len) in points.windows(2).zip(ur5.kin.link_lengths()) {
        let d = (Vector3::from(w[1]) - Vector3::from(w[0])).norm();
        assert!((d - len).abs() < 1e-12, "{d} vs {len}");
    }
    assert!(ur5.joint_origins(&[0.0; 5]).unwrap_err().to_string().contains("expected length 6"));
}

/// A two-joint arm with collision shapes: joint 1 about z, joint 2 about y (not z, so the
/// axis-alignment basis matters), shapes on the base, on each link and on a link fixed to link 2.
const SHAPED_ARM: &str = r#"<robot name="shaped">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0.2 0 0" rpy="0 1.5707963267948966 0"/><geometry><cylinder radius="0.05" length="0.4"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.1 0 0"/><geometry><sphere radius="0.03"/></geometry></collision>
    <collision><geometry><mesh filename="package://x/l2.stl"/></geometry></collision></link>
  <link name="tool"><collision><origin xyz="0 0 0.02"/><geometry><sphere radius="0.01"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.4 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="fix" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0.2 0 0"/></joint>
</robot>"#;

/// World position of shape `k` and the world direction of its local z axis.
fn shape_world(chain: &Chain, q: &[f64], k: usize) -> ([f64; 3], [f64; 3]) {
    let mut frames = vec![[0.0; 12]; chain.dof()];
    chain.segment_frames(q, &mut frames);
    let s = &chain.collision_shapes()[k];
    let m = match s.segment {
        None => s.pose,
        Some(i) => kin::mul(&frames[i], &s.pose),
    };
    ([m[3], m[7], m[11]], [m[2], m[6], m[10]])
}

#[test]
fn collision_shapes_are_placed_where_the_urdf_puts_them() {
    let chain = Chain::from_urdf_str(SHAPED_ARM, None).unwrap();
    let shapes = chain.collision_shapes();
    let links: Vec<&str> = shapes.iter().map(|s| s.link.as_str()).collect();
    assert_eq!(links, ["base", "l1", "l2", "tool"]);
    assert_eq!(chain.mesh_collision_links(), ["l2"]);
    assert_eq!(shapes[0].shape, Shape::Cuboid { half_extents_m: [0.1, 0.1, 0.05] });
    assert_eq!(shapes[1].shape, Shape::Capsule { radius_m: 0.05, half_length_m: 0.2 });
    assert_eq!((shapes[0].segment, shapes[1].segment, shapes[3].segment), (None, Some(0), Some(1)));
    let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12);
    for (q1, q2) in [(0.0, 0.0), (FRAC_PI_2, 0.0), (FRAC_PI_2, FRAC_PI_2), (-0.7, 1.1)] {
        let q = [q1, q2];
        let (c1, s1) = (q1.cos(), q1.sin());
        // The base box does not move.
        assert!(close(shape_world(&chain, &q, 0).0, [0.0, 0.0, 0.05]));
        // l1's capsule: centred 0.2 m along l1's x, its axis along l1's x.
        let (p, z) = shape_world(&chain, &q, 1);
        assert!(close(p, [0.2 * c1, 0.2 * s1, 0.1]), "{p:?}");
        assert!(close(z, [c1, s1, 0.0]), "{z:?}");
        // l2's sphere: 0.1 m along l2's x; l2 turns about l1's y by q2 (x -> x cos q2 - z sin q2).
        let elbow = [0.4 * c1, 0.4 * s1, 0.1];
        let (c2, s2) = (q2.cos(), q2.sin());
        let local = |d: f64| [d * c2 * c1, d * c2 * s1, 0.1 - d * s2];
        let p = shape_world(&chain, &q, 2).0;
        let want = local(0.1);
        assert!(close(p, [want[0] + elbow[0] - 0.0, want[1] + elbow[1], want[2]]), "{p:?} vs {want:?}");
        // The tool's sphere: 0.2 m along l2's x (the fixed joint), then 0.02 m along its z.
        let p = shape_world(&chain, &q, 3).0;
        let z_dir = [s2 * c1, s2 * s1, c2];
        let want = local(0.2);
        let want = [
            want[0] + elbow[0] + 0.02 * z_dir[0],
            want[1] + elbow[1] + 0.02 * z_dir[1],
            want[2] + 0.02 * z_dir[2],
        ];
        assert!(close(p, want), "{p:?} vs {want:?}");
        // The tool's frame is the chain's tip: segment frame 1 times the folded constant.
        let tip = chain.fk(&q).position;
        let t = shape_world(&chain, &q, 3).0;
        assert!(
            ((t[0] - 0.02 * z_dir[0] - tip.x).powi(2) + (t[2] - 0.02 * z_dir[2] - tip.z).powi(2)).sqrt()
                < 1e-12
        );
    }
}

#[test]
fn segment_frames_agree_with_the_skeleton_and_the_tip() {
    let chain = Chain::ur5();
    let mut rng = Rng::new(4);
    let mut frames = vec![[0.0; 12]; 6];
    for _ in 0..50 {
        let q = random_q(&chain, &mut rng);
        chain.segment_frames(&q, &mut frames);
        let origins = chain.joint_origins(&q).unwrap();
        for i in 0..6 {
            let f = frames[i];
            assert!((0..3).all(|r| (f[4 * r + 3] - origins[i][r]).abs() < 1e-12), "joint {i}");
        }
    }
}

#[test]
fn bad_collision_geometry_is_an_error_naming_the_link() {
    let bad = SHAPED_ARM.replace(r#"<sphere radius="0.03"/>"#, r#"<sphere radius="-1"/>"#);
    let e = Chain::from_urdf_str(&bad, None).unwrap_err().to_string();
    assert!(e.contains("`l2`") && e.contains("radius"), "{e}");
    let bad = SHAPED_ARM.replace(
        r#"<origin xyz="0.1 0 0"/><geometry><sphere"#,
        r#"<origin xyz="1e9 0 0"/><geometry><sphere"#,
    );
    let e = Chain::from_urdf_str(&bad, None).unwrap_err().to_string();
    assert!(e.contains("`l2`") && e.contains("collision origin"), "{e}");
}

#[test]
fn effort_limits() {
    // The bundled arms' efforts, N m.
    let efforts = |c: &Chain| c.joints().iter().map(|j| j.effort).collect::<Vec<_>>();
    assert_eq!(efforts(&Chain::ur5()), [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]);
    let panda = Chain::load("panda", None).unwrap();
    assert_eq!(efforts(&panda), [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]);
    // None or 0: unlimited.
    for limit in [
        r#"<limit lower="-1" upper="1" velocity="1"/>"#,
        r#"<limit lower="-1" upper="1" effort="0" velocity="1"/>"#,
    ] {
        let xml = robot(&["a", "b"], &[joint("j", "revolute", "a", "b", limit)]);
        assert_eq!(efforts(&Chain::from_urdf_str(&xml, None).unwrap()), [f64::INFINITY]);
    }
    // Negative or NaN: refused, naming the joint.
    for effort in ["-1", "nan"] {
        let limit = format!(r#"<limit lower="-1" upper="1" effort="{effort}" velocity="1"/>"#);
        let xml = robot(&["a", "b"], &[joint("bad", "revolute", "a", "b", &limit)]);
        let m = urdf_message(Chain::from_urdf_str(&xml, None));
        assert!(m.contains("joint `bad`") && m.contains("effort"), "{m}");
    }
}

/// The tip's pose from the segment frames is `fk`'s to the bit (the environment's step takes
/// it from the collision check's frames), on the UR5, the Panda and the test arm with its
/// prismatic joint, joint values past 1e5 rad included (the standard library's sine there).
#[test]
fn the_tip_from_the_segment_frames_is_fk_to_the_bit() {
    let mut rng = Rng::new(21);
    for chain in [Chain::ur5(), Chain::load("panda", None).unwrap(), test_arm()] {
        let mut frames = vec![[0.0; 12]; chain.dof()];
        for k in 0..2000 {
            let mut q = random_q(&chain, &mut rng);
            if k % 100 == 0 {
                q[0] += 2.0e5;
            }
            chain.segment_frames(&q, &mut frames);
            let (a, b) = (chain.tip_pose_from_frames(&frames).unwrap(), chain.fk(&q));
            let bits = |p: &Pose| {
                let (v, w) = (p.position, p.quaternion_xyzw());
                [v.x, v.y, v.z, w[0], w[1], w[2], w[3]].map(f64::to_bits)
            };
            assert_eq!(bits(&a), bits(&b), "{q:?}");
        }
        assert!(chain.tip_pose_from_frames(&frames[..chain.dof() - 1]).is_none());
    }
}
