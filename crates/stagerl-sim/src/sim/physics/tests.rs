//! Tests of `sim::physics`.

use super::*;
use crate::robot::{PANDA_URDF, UR5_URDF};
use crate::sim::collision::{ArmCollider, Checks};
use std::f64::consts::{FRAC_PI_2, PI};

const DT: f64 = 0.05;
const HOME: [f64; 6] = [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0];

fn ur5(obstacles: &[Obstacle], floor: bool) -> DynamicArm {
    DynamicArm::new(UR5_URDF, &Chain::ur5(), DT, obstacles, floor).unwrap()
}

/// `steps` steps of `cmd` from `q0` at rest: the joint positions after each.
fn run(arm: &mut DynamicArm, q0: &[f64], cmd: &[f64], steps: usize) -> Vec<Vec<f64>> {
    arm.set_state(q0, &vec![0.0; q0.len()]).unwrap();
    (0..steps)
        .map(|_| {
            arm.step(cmd);
            let mut q = vec![0.0; q0.len()];
            arm.joint_positions(&mut q);
            q
        })
        .collect()
}

/// The largest |q - q0| over a trajectory, rad.
fn drift(traj: &[Vec<f64>], q0: &[f64]) -> f64 {
    traj.iter().flat_map(|q| q.iter().zip(q0).map(|(a, b)| (a - b).abs())).fold(0.0, f64::max)
}

#[test]
fn joint_values_follow_the_chain_convention() {
    let chain = Chain::ur5();
    let mut arm = ur5(&[], false);
    let q = [0.3, -1.1, 1.4, -0.7, 2.0, -0.5];
    arm.set_state(&q, &[0.0; 6]).unwrap();
    let mut frames = vec![[0.0; 12]; 6];
    chain.segment_frames(&q, &mut frames);
    for (k, f) in frames.iter().enumerate() {
        // UR5 joint axes are their link's z.
        let (p, a) = arm.link_frame(k, [0.0, 0.0, 1.0]);
        for r in 0..3 {
            assert!((p[r] - f[4 * r + 3]).abs() < 1e-5, "joint {k} origin {p:?} vs {f:?}");
            assert!((a[r] - f[4 * r + 2]).abs() < 1e-5, "joint {k} axis {a:?} vs {f:?}");
        }
    }
    // State in, state out (as f32).
    let mut out = [0.0; 6];
    arm.joint_positions(&mut out);
    for k in 0..6 {
        assert_eq!(out[k], q[k] as f32 as f64);
    }
}

#[test]
fn zero_command_holds_the_ur5_home_pose() {
    let mut arm = ur5(&[], true);
    let traj = run(&mut arm, &HOME, &[0.0; 6], 100);
    let d = drift(&traj, &HOME);
    eprintln!("UR5 hold drift over 5 s: {d:.5} rad");
    assert!(d <= 0.02, "drift {d} rad");
    assert!(!arm.in_contact());
}

#[test]
fn zero_command_holds_the_panda() {
    let chain = Chain::load("panda", None).unwrap();
    let mut arm = DynamicArm::new(PANDA_URDF, &chain, DT, &[], true).unwrap();
    let q0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let traj = run(&mut arm, &q0, &[0.0; 7], 100);
    let d = drift(&traj, &q0);
    eprintln!("Panda hold drift over 5 s: {d:.5} rad");
    assert!(d <= 0.02, "drift {d} rad");
}

/// Mean achieved velocity of joint `j` over steps 2..=20, rad/s.
fn tracked(arm: &mut DynamicArm, q0: &[f64], j: usize, v: f64) -> f64 {
    let mut cmd = vec![0.0; q0.len()];
    cmd[j] = v;
    let traj = run(arm, q0, &cmd, 20);
    (traj[19][j] - traj[0][j]) / (19.0 * DT)
}

#[test]
fn one_rad_per_second_is_tracked() {
    let mut arm = ur5(&[], true);
    for (j, v) in [(0, 1.0), (2, 1.0), (2, -1.0), (4, 1.0)] {
        let got = tracked(&mut arm, &HOME, j, v);
        eprintln!("joint {j} at {v} rad/s: {got:.5} rad/s ({:.3} %)", 100.0 * (got - v).abs() / v.abs());
        assert!((got - v).abs() <= 0.05 * v.abs(), "joint {j}: {got} rad/s for {v}");
    }
}

/// The UR5 with its arm stretched out horizontally (upper arm, forearm and wrist along -x),
/// lifting it: shoulder_lift towards -pi/2 at its speed limit. Returns the achieved velocity
/// after the first step and the mean over steps 2..=20.
fn lift(urdf: &str) -> (f64, f64) {
    let chain = Chain::from_urdf_str(urdf, Some("tool0")).unwrap();
    let mut arm = DynamicArm::new(urdf, &chain, DT, &[], true).unwrap();
    let q0 = [0.0, 0.0, 0.0, -FRAC_PI_2, 0.0, 0.0];
    let cmd = [0.0, -PI, 0.0, 0.0, 0.0, 0.0];
    let traj = run(&mut arm, &q0, &cmd, 20);
    ((traj[0][1] - q0[1]) / DT, (traj[19][1] - traj[0][1]) / (19.0 * DT))
}

#[test]
fn shoulder_torque_saturates_lifting_the_arm() {
    let (first, mean) = lift(UR5_URDF);
    // The same arm with unlimited shoulder torque.
    let strong = UR5_URDF.replacen(r#"effort="150""#, r#"effort="0""#, 2);
    let (first_strong, mean_strong) = lift(&strong);
    eprintln!(
        "shoulder lift at -pi rad/s: first step {first:.4}, mean 2..20 {mean:.4} rad/s; \
         unlimited torque: {first_strong:.4}, {mean_strong:.4}"
    );
    assert!((first_strong + PI).abs() < 0.05 * PI, "{first_strong}");
    // 150 N m against about 54 N m of gravity and 3 kg m^2: well short in the first step.
    assert!(first > -0.8 * PI, "first step {first} rad/s");
}

#[test]
fn position_limits_hold() {
    // The Panda's joint 4 lives in [-3.0718, -0.0698] rad: driven up into its upper limit.
    let chain = Chain::load("panda", None).unwrap();
    let mut arm = DynamicArm::new(PANDA_URDF, &chain, DT, &[], true).unwrap();
    let q0 = [0.0, -0.785, 0.0, -0.5, 0.0, 1.571, 0.785];
    let traj = run(&mut arm, &q0, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], 30);
    let top = traj.iter().map(|q| q[3]).fold(f64::MIN, f64::max);
    eprintln!("Panda joint 4 at +1 rad/s into its limit -0.0698: at most {top:.5} rad");
    assert!(top <= -0.0698 + 0.005 && top > -0.0698 - 0.01, "{top}");
}

#[test]
fn a_link_without_inertial_is_refused() {
    let start = UR5_URDF.find("<link name=\"forearm_link\">").unwrap();
    let a = start + UR5_URDF[start..].find("<inertial>").unwrap();
    let b = start + UR5_URDF[start..].find("</inertial>").unwrap() + "</inertial>".len();
    let xml = format!("{}{}", &UR5_URDF[..a], &UR5_URDF[b..]);
    let chain = Chain::from_urdf_str(&xml, Some("tool0")).unwrap();
    let e = DynamicArm::new(&xml, &chain, DT, &[], false).err().unwrap();
    assert!(matches!(e, Error::Urdf(_)), "{e}");
    assert!(e.to_string().contains("link `forearm_link`") && e.to_string().contains("<inertial>"), "{e}");
    // A negative mass too.
    let xml = UR5_URDF.replacen(r#"<mass value="2.33"/>"#, r#"<mass value="-2.33"/>"#, 1);
    let e = DynamicArm::new(&xml, &Chain::ur5(), DT, &[], false).err().unwrap();
    assert!(e.to_string().contains("link `forearm_link`"), "{e}");
    // And a chain from another document.
    let e = DynamicArm::new(PANDA_URDF, &Chain::ur5(), DT, &[], false).err().unwrap();
    assert!(matches!(e, Error::Urdf(_)), "{e}");
}

/// A box the UR5's wrist meets when the base turns from HOME by about `angle` rad.
fn box_in_the_way(angle: f64) -> Obstacle {
    let p = Chain::ur5().fk(&HOME).position;
    let (s, c) = angle.sin_cos();
    Obstacle::cuboid([0.05, 0.05, 0.05], [c * p.x - s * p.y, s * p.x + c * p.y, p.z], None)
}

/// The commands of the contact trajectory: base towards the box, shoulder down to the floor.
fn pushing(t: usize) -> [f64; 6] {
    if t < 30 {
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    } else {
        [1.0, 0.5, 0.6, 0.0, 0.5, 0.0]
    }
}

#[test]
fn a_box_stops_the_arm() {
    let obstacle = box_in_the_way(0.8);
    let mut arm = ur5(std::slice::from_ref(&obstacle), true);
    let traj = run(&mut arm, &HOME, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], 40);
    assert!(arm.in_contact());
    let pen = arm.penetration_m();
    assert!(pen < 0.005, "{pen} m");
    // Where the kinematic check first finds the arm in the box, turning the base.
    let chain = Chain::ur5();
    let mut col = ArmCollider::new(&chain, Checks { floor: false, self_collision: false });
    col.set_obstacles(std::slice::from_ref(&obstacle));
    let mut q = HOME;
    while col.check(&chain, &q).is_none() {
        q[0] += 1e-4;
    }
    let last = traj[39][0];
    eprintln!(
        "base stopped at {last:.4} rad, penetration {pen:.5} m; capsules first touch the box at {:.4}",
        q[0]
    );
    // The capsules are a little larger than the cylinders: stopping near, not past, there.
    assert!(last < q[0] + 0.01 && last > q[0] - 0.1, "{last} vs {}", q[0]);
}

#[test]
fn same_inputs_same_bits() {
    let obstacles = [box_in_the_way(0.8)];
    let mut a = ur5(&obstacles, true);
    let mut b = ur5(&obstacles, true);
    let ta: Vec<Vec<f64>> = (0..60).map(|t| run_one(&mut a, t)).collect();
    let tb: Vec<Vec<f64>> = (0..60).map(|t| run_one(&mut b, t)).collect();
    assert_eq!(bits(&ta), bits(&tb));
}

/// One step of the contact trajectory from HOME (set at t = 0): q then qdot.
fn run_one(arm: &mut DynamicArm, t: usize) -> Vec<f64> {
    if t == 0 {
        arm.set_state(&HOME, &[0.0; 6]).unwrap();
    }
    arm.step(&pushing(t));
    state(arm)
}

/// A UR5's joint positions then velocities.
fn state(arm: &DynamicArm) -> Vec<f64> {
    let mut out = vec![0.0; 12];
    arm.joint_positions(&mut out[..6]);
    arm.joint_velocities(&mut out[6..]);
    out
}

fn bits(t: &[Vec<f64>]) -> Vec<Vec<u64>> {
    t.iter().map(|v| v.iter().map(|x| x.to_bits()).collect()).collect()
}

/// Steps `from..to` of the contact trajectory on a new arm set to `state` (q then qdot).
fn resumed(state: &[f64], from: usize, to: usize, obstacles: &[Obstacle]) -> Vec<Vec<f64>> {
    let mut arm = ur5(obstacles, true);
    arm.set_state(&state[..6], &state[6..]).unwrap();
    (from..to).map(|t| run_one(&mut arm, t.max(1))).collect()
}

#[test]
fn set_state_then_step_continues_bit_for_bit() {
    let obstacles = [box_in_the_way(0.8)];
    let mut arm = ur5(&obstacles, true);
    let mut contacts = 0;
    let full: Vec<Vec<f64>> = (0..80)
        .map(|t| {
            let s = run_one(&mut arm, t);
            contacts += arm.in_contact() as usize;
            s
        })
        .collect();
    eprintln!("{contacts} of 80 steps in contact");
    assert!(contacts >= 20, "the trajectory should press into the box and the floor");
    for k in [5, 31, 40, 55, 70] {
        let again = resumed(&full[k - 1], k, 80, &obstacles);
        assert_eq!(bits(&again), bits(&full[k..]), "resumed at step {k}");
    }
    // The same arm, its state set back to where it was: the same too.
    arm.set_state(&full[49][..6], &full[49][6..]).unwrap();
    let again: Vec<Vec<f64>> = (50..80).map(|t| run_one(&mut arm, t)).collect();
    assert_eq!(bits(&again), bits(&full[50..]));
}

/// The contact trajectory, then one that stays near HOME (q then qdot after each step).
fn both_trajectories(arm: &mut DynamicArm) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = (0..80).map(|t| run_one(arm, t)).collect();
    arm.set_state(&HOME, &[0.0; 6]).unwrap();
    for t in 0..200 {
        arm.step(&swaying(t, 6));
        out.push(state(arm));
    }
    out
}

#[test]
fn exact_resume_equals_a_fresh_world_every_step() {
    let obstacles = four_boxes();
    let mut a = ur5(&obstacles, true);
    let mut b = ur5(&obstacles, true);
    b.rebuild_every_step = true;
    assert_eq!(bits(&both_trajectories(&mut a)), bits(&both_trajectories(&mut b)));
    // New obstacles: `a` copies its new snapshot from then on, `b` still builds every step.
    a.set_obstacles(&obstacles[1..]);
    b.set_obstacles(&obstacles[1..]);
    assert_eq!(bits(&both_trajectories(&mut a)), bits(&both_trajectories(&mut b)));
    // A clone starts from a copy of the snapshot: the same bits again.
    let mut c = a.clone();
    assert_eq!(bits(&both_trajectories(&mut c)), bits(&both_trajectories(&mut a)));
}

/// Positions and velocities of `steps` steps from the UR5's home pose under commands of
/// 1.5 rad/s that press the arm into the floor and itself most of the time; the steps in
/// contact.
fn rough(arm: &mut DynamicArm, steps: usize) -> (Vec<Vec<f64>>, usize) {
    arm.set_state(&HOME, &[0.0; 6]).unwrap();
    let (mut out, mut contacts) = (Vec::new(), 0);
    for t in 0..steps {
        let cmd: Vec<f64> =
            (0..6).map(|j| 1.5 * ((t as f64) * 0.03 * (1.0 + j as f64 * 0.37)).sin()).collect();
        arm.step(&cmd);
        contacts += arm.in_contact() as usize;
        out.push(state(arm));
    }
    (out, contacts)
}

#[test]
fn far_pair_filter_changes_no_bit() {
    let obstacles = four_boxes();
    let mut a = ur5(&obstacles, true);
    let mut b = ur5(&obstacles, true);
    b.filter_far_pairs = false;
    assert_eq!(bits(&both_trajectories(&mut a)), bits(&both_trajectories(&mut b)));
    let ((ta, ca), (tb, cb)) = (rough(&mut a, 600), rough(&mut b, 600));
    assert!(ca > 100, "the rough motion makes contact ({ca} steps)");
    assert_eq!((bits(&ta), ca), (bits(&tb), cb));
    // It is not idle: at the home pose it drops most pairs of the arm's 14 colliders, the
    // floor and the boxes (rapier hands it those whose boxes overlap).
    a.set_state(&HOME, &[0.0; 6]).unwrap();
    a.step(&[0.0; 6]);
    let w = &a.world;
    let handles: Vec<ColliderHandle> = w.colliders.iter().map(|(h, _)| h).collect();
    let (mut dropped, mut pairs) = (0, 0);
    for (i, &collider1) in handles.iter().enumerate() {
        for &collider2 in &handles[i + 1..] {
            let context = PairFilterContext {
                bodies: &w.bodies,
                colliders: &w.colliders,
                collider1,
                collider2,
                rigid_body1: None,
                rigid_body2: None,
            };
            pairs += 1;
            dropped += a.far_pairs.filter_contact_pair(&context).is_none() as usize;
        }
    }
    assert!(dropped * 10 > pairs * 8, "{dropped} of {pairs} pairs dropped");
    assert!(dropped < pairs);
}

#[test]
fn gaps_between_bounds() {
    let cap = |a: [f64; 3], b: [f64; 3], radius: f64| Placed::Capsule { a, b, radius };
    let floor = Placed::HalfSpace { normal: [0.0, 0.0, 1.0], offset: 0.0 };
    // Parallel segments 1 m apart, radii 0.1 and 0.2.
    let g = gap_m(cap([0.0; 3], [1.0, 0.0, 0.0], 0.1), cap([0.0, 1.0, 0.0], [1.0, 1.0, 0.0], 0.2));
    assert!((g.unwrap() - 0.7).abs() < 1e-12);
    // A tilted capsule above the floor: its lower end, less the radius.
    let c = cap([0.0, 0.0, 0.5], [0.3, 0.0, 0.2], 0.05);
    assert!((gap_m(c, floor).unwrap() - 0.15).abs() < 1e-12);
    assert!((gap_m(floor, c).unwrap() - 0.15).abs() < 1e-12);
    // A floor raised to z = 0.3 (offset along its normal) is in the capsule: negative.
    let raised = Placed::HalfSpace { normal: [0.0, 0.0, 1.0], offset: 0.3 };
    assert!((gap_m(c, raised).unwrap() + 0.15).abs() < 1e-12);
    assert_eq!(gap_m(floor, raised), None);
}

/// A command swaying every joint around where it starts (at most 0.4 rad away), rad/s.
fn swaying(t: usize, n: usize) -> Vec<f64> {
    (0..n)
        .map(|j| {
            let w = 2.0 + 0.7 * j as f64;
            0.4 * w * (w * t as f64 * DT).cos()
        })
        .collect()
}

/// Four boxes around the UR5 (one in the way of the `timing` motion).
fn four_boxes() -> Vec<Obstacle> {
    vec![
        box_in_the_way(0.8),
        Obstacle::cuboid([0.1, 0.1, 0.2], [0.0, 0.6, 0.2], None),
        Obstacle::cuboid([0.2, 0.05, 0.1], [-0.5, -0.3, 0.1], Some([0.0, 0.0, 0.3826834, 0.9238795])),
        Obstacle::cuboid([0.05, 0.3, 0.05], [0.4, 0.0, 0.9], None),
    ]
}

/// Microseconds a step over `steps` steps: swaying around `q0`, or (`rough`) sweeping
/// commands of 1.5 rad/s that press the arm into the floor and itself most of the time.
fn time_steps(arm: &mut DynamicArm, q0: &[f64], steps: usize, rough: bool) -> (f64, usize) {
    let n = q0.len();
    arm.set_state(q0, &vec![0.0; n]).unwrap();
    let mut cmd = vec![0.0; n];
    let mut contacts = 0;
    let t0 = thread_cpu_s();
    for t in 0..steps {
        if rough {
            for (j, c) in cmd.iter_mut().enumerate() {
                *c = 1.5 * ((t as f64) * 0.03 * (1.0 + j as f64 * 0.37)).sin();
            }
        } else {
            cmd = swaying(t, n);
        }
        arm.step(&cmd);
        contacts += arm.in_contact() as usize;
    }
    ((thread_cpu_s() - t0) * 1e6 / steps as f64, contacts)
}

/// This thread's CPU time, s (the machine is shared: wall time would count other processes).
fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write into.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// `cargo test --release -p stagerl --lib physics::tests::timing -- --ignored --nocapture`
#[test]
#[ignore]
fn timing() {
    let panda = Chain::load("panda", None).unwrap();
    let q_panda = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let steps = 4000;
    for (mode, exact, every) in
        [("exact", true, false), ("persistent", false, false), ("rebuild", true, true)]
    {
        for rough in [false, true] {
            for (name, obstacles) in [("UR5, floor", vec![]), ("UR5, floor + 4 boxes", four_boxes())] {
                let mut arm = ur5(&obstacles, true);
                arm.set_exact_resume(exact);
                arm.rebuild_every_step = every;
                time_steps(&mut arm, &HOME, 200, rough);
                let (us, contacts) = time_steps(&mut arm, &HOME, steps, rough);
                eprintln!(
                    "{mode}, rough {rough}: {name}: {us:.2} us/step ({contacts} of {steps} in contact)"
                );
            }
            let mut arm = DynamicArm::new(PANDA_URDF, &panda, DT, &[], true).unwrap();
            arm.set_exact_resume(exact);
            arm.rebuild_every_step = every;
            time_steps(&mut arm, &q_panda, 200, rough);
            let (us, contacts) = time_steps(&mut arm, &q_panda, steps, rough);
            eprintln!(
                "{mode}, rough {rough}: Panda, floor: {us:.2} us/step ({contacts} of {steps} in contact)"
            );
        }
    }
    let arm = ur5(&four_boxes(), true);
    let t0 = thread_cpu_s();
    for _ in 0..1000 {
        std::hint::black_box(arm.template.build());
    }
    eprintln!("building the world: {:.2} us (thread CPU time)", (thread_cpu_s() - t0) * 1e3);
}

/// A mesh link is a convex collider of its link: swung down at 1 rad/s onto the floor, the 0.1 m
/// cube of `swing_arm` stops where its lowest corner meets the floor (the angle t* of
/// `0.3 - 0.3 sin t - 0.05 (cos t + sin t) = 0`, about 0.871 rad); without the floor it swings on.
#[test]
fn a_mesh_link_is_stopped_by_the_floor() {
    let chain = crate::sim::collision::tests::swing_arm("dynamic");
    let t_star = {
        let f = |t: f64| 0.3 - 0.3 * t.sin() - 0.05 * (t.cos() + t.sin());
        let (mut lo, mut hi) = (0.0, 1.5);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > 0.0 {
                lo = mid
            } else {
                hi = mid
            }
        }
        lo
    };
    assert!((t_star - 0.871).abs() < 0.002, "{t_star}");
    for floor in [true, false] {
        let mut arm = DynamicArm::new(chain.urdf_source(), &chain, 0.01, &[], floor).unwrap();
        let convex =
            arm.world.colliders.iter().filter(|(_, c)| c.shape().as_convex_polyhedron().is_some()).count();
        assert_eq!(convex, 1);
        let traj = run(&mut arm, &[0.0], &[1.0], 150);
        let end = traj.last().unwrap()[0];
        if floor {
            assert!((end - t_star).abs() < 0.02, "stopped at {end}, the floor is met at {t_star}");
            assert!(arm.in_contact());
        } else {
            assert!(end > 1.4, "{end}");
        }
    }
}
