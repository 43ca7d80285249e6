//! stagerl's forward kinematics against the `k` crate on 10 000 seeded random configurations per
//! robot: the bundled UR5 and `robot_test_arm.urdf` (prismatic, continuous, fixed joints in the
//! middle, non-trivial rpy origins, skew axes, an off-chain floating branch).

use std::f64::consts::PI;
use std::path::Path;

use stagerl::base::rng::Rng;
use stagerl::robot::{Chain, UR5_URDF};

use crate::k_oracle::{k_chain, random_q};

const TEST_ARM_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/robot_test_arm.urdf");
const CONFIGS: usize = 10_000;

/// Rotation angle of `a^-1 b` for quaternions `[x, y, z, w]`, either sign (atan2: exact near 0).
fn angle_between(a: [f64; 4], b: [f64; 4]) -> f64 {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    // conj(a) * b
    let w = aw * bw + ax * bx + ay * by + az * bz;
    let x = aw * bx - ax * bw - ay * bz + az * by;
    let y = aw * by + ax * bz - ay * bw - az * bx;
    let z = aw * bz - ax * by + ay * bx - az * bw;
    2.0 * (x * x + y * y + z * z).sqrt().atan2(w.abs())
}

/// Worst position error (m) and orientation error (rad) over `CONFIGS` random configurations.
fn compare_with_k(ours: &Chain, theirs: &k::SerialChain<f64>, seed: u64) -> (f64, f64) {
    assert_eq!(ours.dof(), theirs.dof());
    let mut rng = Rng::new(seed);
    let (mut worst_p, mut worst_r) = (0.0f64, 0.0f64);
    for _ in 0..CONFIGS {
        let q = random_q(ours, &mut rng);
        theirs.set_joint_positions_unchecked(&q);
        let t = theirs.end_transform();
        let pose = ours.fk(&q);
        let kq = t.rotation.quaternion();
        let ep = (0..3).map(|i| (pose.position[i] - t.translation.vector[i]).abs()).fold(0.0, f64::max);
        let er = angle_between(pose.quaternion_xyzw(), [kq.i, kq.j, kq.k, kq.w]);
        assert!(ep <= 1e-12, "position differs by {ep} m at q = {q:?}");
        assert!(er <= 1e-12, "orientation differs by {er} rad at q = {q:?}");
        worst_p = worst_p.max(ep);
        worst_r = worst_r.max(er);
    }
    (worst_p, worst_r)
}

#[test]
fn ur5_fk_matches_k_on_10000_configurations() {
    let ours = Chain::ur5();
    let theirs = k_chain(UR5_URDF, "tool0");
    let (p, r) = compare_with_k(&ours, &theirs, 2024);
    println!("UR5 vs k: worst position {p:e} m, orientation {r:e} rad");
}

#[test]
fn test_arm_fk_matches_k_on_10000_configurations() {
    let ours = Chain::from_urdf_file(Path::new(TEST_ARM_PATH), Some("tool")).unwrap();
    assert_eq!(ours.dof(), 4);
    let xml = std::fs::read_to_string(TEST_ARM_PATH).unwrap();
    let theirs = k_chain(&xml, "tool");
    let (p, r) = compare_with_k(&ours, &theirs, 7);
    println!("test arm vs k: worst position {p:e} m, orientation {r:e} rad");
}

#[test]
fn test_arm_intermediate_tip_matches_k() {
    // A tip in the middle of the chain, right after the fixed joints (tip l2b: 2 dof).
    let ours = Chain::from_urdf_file(Path::new(TEST_ARM_PATH), Some("l2b")).unwrap();
    assert_eq!(ours.dof(), 2);
    let xml = std::fs::read_to_string(TEST_ARM_PATH).unwrap();
    let theirs = k_chain(&xml, "l2b");
    compare_with_k(&ours, &theirs, 8);
}

/// An 11-joint chain (longer than the 8-joint chunks of the hot loops), seeded: revolute,
/// prismatic and continuous joints on both sides of the chunk boundary, fixed joints between,
/// random origins and axes.
fn long_chain_urdf(seed: u64) -> String {
    let mut rng = Rng::new(seed);
    let mut r = |lo: f64, hi: f64| rng.uniform_range(lo, hi);
    let mut links = vec!["l0".to_string()];
    let mut joints = String::new();
    for i in 0..11 {
        let kind = match i {
            2 | 9 => "prismatic",
            5 | 8 => "continuous",
            _ => "revolute",
        };
        let limit = match kind {
            "prismatic" => r#"<limit lower="-0.2" upper="0.3" effort="1" velocity="0.5"/>"#,
            "continuous" => r#"<limit effort="1" velocity="2"/>"#,
            _ => r#"<limit lower="-2.9" upper="2.9" effort="1" velocity="2"/>"#,
        };
        let (parent, child) = (links.last().unwrap().clone(), format!("l{}", links.len()));
        joints += &format!(
            "<joint name=\"j{i}\" type=\"{kind}\"><parent link=\"{parent}\"/>\
             <child link=\"{child}\"/><origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>\
             <axis xyz=\"{} {} {}\"/>{limit}</joint>\n",
            r(-0.3, 0.3),
            r(-0.3, 0.3),
            r(-0.3, 0.3),
            r(-PI, PI),
            r(-PI, PI),
            r(-PI, PI),
            r(-1.0, 1.0),
            r(-1.0, 1.0),
            r(-1.0, 1.0),
        );
        links.push(child);
        if i % 3 == 1 {
            let (parent, child) = (links.last().unwrap().clone(), format!("l{}", links.len()));
            joints += &format!(
                "<joint name=\"f{i}\" type=\"fixed\"><parent link=\"{parent}\"/>\
                 <child link=\"{child}\"/><origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/></joint>\n",
                r(-0.3, 0.3),
                r(-0.3, 0.3),
                r(-0.3, 0.3),
                r(-PI, PI),
                r(-PI, PI),
                r(-PI, PI),
            );
            links.push(child);
        }
    }
    let links: String = links.iter().map(|l| format!("<link name=\"{l}\"/>\n")).collect();
    format!("<robot name=\"long\">\n{links}{joints}</robot>\n")
}

#[test]
fn long_chain_fk_matches_k() {
    let xml = long_chain_urdf(99);
    let ours = Chain::from_urdf_str(&xml, None).unwrap();
    assert_eq!(ours.dof(), 11);
    let tip = ours.tip_link().to_string();
    compare_with_k(&ours, &k_chain(&xml, &tip), 100);
}

/// Rotation vector of `a * b^-1` for quaternions `[x, y, z, w]` (atan2: exact for small angles).
fn rotation_vector(a: [f64; 4], b: [f64; 4]) -> [f64; 3] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = [-b[0], -b[1], -b[2], b[3]];
    let mut w = aw * bw - ax * bx - ay * by - az * bz;
    let mut v = [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ];
    if w < 0.0 {
        w = -w;
        v = v.map(|x| -x);
    }
    let s = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if s == 0.0 {
        return [0.0; 3];
    }
    let k = 2.0 * s.atan2(w) / s;
    v.map(|x| x * k)
}

#[test]
fn long_chain_jacobian_matches_finite_differences() {
    let ours = Chain::from_urdf_str(&long_chain_urdf(99), None).unwrap();
    let n = ours.dof();
    let mut rng = Rng::new(101);
    let mut jac = vec![0.0; 6 * n];
    let h = 1e-6;
    for _ in 0..200 {
        let q = random_q(&ours, &mut rng);
        assert_eq!(ours.jacobian(&q, &mut jac), ours.fk(&q));
        for i in 0..n {
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[i] += h;
            qm[i] -= h;
            let (pp, pm) = (ours.fk(&qp), ours.fk(&qm));
            let w = rotation_vector(pp.quaternion_xyzw(), pm.quaternion_xyzw());
            for r in 0..3 {
                let dv = (pp.position[r] - pm.position[r]) / (2.0 * h);
                let dw = w[r] / (2.0 * h);
                assert!((jac[r * n + i] - dv).abs() < 1e-7, "v{r} col {i}");
                assert!((jac[(r + 3) * n + i] - dw).abs() < 1e-7, "w{r} col {i}");
            }
        }
    }
}
