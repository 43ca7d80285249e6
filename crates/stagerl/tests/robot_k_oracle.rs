//! stagerl's forward kinematics against the `k` crate on 10 000 seeded random configurations per
//! robot: the bundled UR5 and `robot_test_arm.urdf` (prismatic, continuous, fixed joints in the
//! middle, non-trivial rpy origins, skew axes, an off-chain floating branch).

use std::f64::consts::PI;
use std::path::Path;

use stagerl::rng::Rng;
use stagerl::robot::{Chain, UR5_URDF};

const TEST_ARM_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/robot_test_arm.urdf");
const CONFIGS: usize = 10_000;

/// `k`'s serial chain from the root to the joint whose child is `tip`.
fn k_chain(xml: &str, tip: &str) -> k::SerialChain<f64> {
    let robot = urdf_rs::read_from_string(xml).expect("URDF parses");
    let chain = k::Chain::<f64>::from(&robot);
    let end = chain.find_link(tip).expect("tip link in k's chain");
    k::SerialChain::from_end(end)
}

/// A random configuration within the limits (continuous joints: within +-2 pi).
fn random_q(chain: &Chain, rng: &mut Rng) -> Vec<f64> {
    chain
        .lower_limits()
        .iter()
        .zip(chain.upper_limits())
        .map(|(&lo, &hi)| {
            if lo.is_finite() {
                rng.uniform_range(lo, hi)
            } else {
                rng.uniform_range(-2.0 * PI, 2.0 * PI)
            }
        })
        .collect()
}

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
        let ep = (0..3)
            .map(|i| (pose.position[i] - t.translation.vector[i]).abs())
            .fold(0.0, f64::max);
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

/// `cargo test -p stagerl --test robot_k_oracle bench -- --ignored --nocapture`
#[test]
#[ignore = "timing, run by hand"]
fn bench_fk_and_jacobian_vs_k() {
    use std::hint::black_box;
    use std::time::Instant;
    let ours = Chain::ur5();
    let theirs = k_chain(UR5_URDF, "tool0");
    let mut rng = Rng::new(1);
    let qs: Vec<Vec<f64>> = (0..1024).map(|_| random_q(&ours, &mut rng)).collect();
    let n = 2_000_000;
    let mut acc = 0.0;
    for round in 0..3 {
        let t = Instant::now();
        for i in 0..n {
            let p = ours.fk(black_box(&qs[i & 1023]));
            acc += p.position.x + p.orientation.w;
        }
        let fk_ns = t.elapsed().as_nanos() as f64 / n as f64;
        let mut jac = [0.0; 36];
        let t = Instant::now();
        for i in 0..n {
            let p = ours.jacobian(black_box(&qs[i & 1023]), black_box(&mut jac));
            acc += p.position.x + jac[7];
        }
        let jac_ns = t.elapsed().as_nanos() as f64 / n as f64;
        let t = Instant::now();
        for i in 0..n / 10 {
            theirs.set_joint_positions_unchecked(black_box(&qs[i & 1023]));
            acc += theirs.end_transform().translation.vector.x;
        }
        let k_ns = t.elapsed().as_nanos() as f64 / (n / 10) as f64;
        let t = Instant::now();
        for i in 0..n {
            for &v in black_box(&qs[i & 1023]) {
                let (s, c) = v.sin_cos();
                acc += s + c;
            }
        }
        let sc_ns = t.elapsed().as_nanos() as f64 / n as f64;
        println!(
            "round {round}: UR5 fk {fk_ns:.1} ns/call, jacobian {jac_ns:.1} ns/call, \
             k fk {k_ns:.1} ns/call, 6 x f64::sin_cos {sc_ns:.1} ns"
        );
    }
    black_box(acc);
}
