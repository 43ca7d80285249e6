//! Tests of `sim::shield`: the guarantee (thousands of random commands near random obstacles
//! never end in contact, checked with the exact contact test at fine sub-steps), a safe command
//! left alone, determinism, the dampers' gradients.

use super::*;
use crate::base::rng::Rng;
use crate::sim::collision::Checks;
use crate::sim::scene::Obstacle;

use std::f64::consts::FRAC_PI_2;

/// The UR5 home pose.
const HOME: [f64; 6] = [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0];

fn panda() -> Chain {
    Chain::load("panda", None).unwrap()
}

/// A random pose within the limits (and within +-pi) clear of the floor and of itself.
fn random_pose(chain: &Chain, rng: &mut Rng, bare: &mut ArmCollider) -> Vec<f64> {
    let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
    loop {
        let q: Vec<f64> = (0..chain.dof())
            .map(|i| rng.uniform_range(lo[i].max(-std::f64::consts::PI), hi[i].min(std::f64::consts::PI)))
            .collect();
        if bare.check(chain, &q).is_none() {
            return q;
        }
    }
}

/// A random obstacle 0-10 cm from a random point of the arm's skeleton at `q`, clear of the arm.
fn obstacle_near(chain: &Chain, q: &[f64], rng: &mut Rng, collider: &mut ArmCollider) -> Option<Obstacle> {
    let points = chain.joint_origins(q).unwrap();
    for _ in 0..50 {
        let k = rng.below(points.len() as u64 - 1) as usize;
        let s = rng.uniform();
        let mut c = [0, 1, 2].map(|r| points[k][r] + s * (points[k + 1][r] - points[k][r]));
        let dir = [rng.normal(), rng.normal(), rng.normal()];
        let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        let offset = rng.uniform_range(0.05, 0.2);
        for r in 0..3 {
            c[r] += offset * dir[r] / len;
        }
        let size = rng.uniform_range(0.02, 0.08);
        let o = if rng.uniform() < 0.5 {
            Obstacle::sphere(size, c)
        } else {
            let (x, y, z, w) = (rng.normal(), rng.normal(), rng.normal(), rng.normal());
            let n = (x * x + y * y + z * z + w * w).sqrt();
            let h = [size, rng.uniform_range(0.02, 0.08), rng.uniform_range(0.02, 0.08)];
            Obstacle::cuboid(h, c, Some([x / n, y / n, z / n, w / n]))
        };
        if !collider.touches(chain, q, &o) {
            return Some(o);
        }
    }
    None
}

/// A random action: each joint uniform in [-1, 1], or at its limit.
fn random_command(chain: &Chain, rng: &mut Rng, out: &mut [f64]) {
    for (i, c) in out.iter_mut().enumerate() {
        let a = match rng.below(4) {
            0 => 1.0,
            1 => -1.0,
            _ => rng.uniform_range(-1.0, 1.0),
        };
        *c = a * chain.velocity_limits()[i];
    }
}

/// The smallest exact signed distance over every checked pair at `q`.
fn exact_clearance(chain: &Chain, collider: &mut ArmCollider, q: &[f64]) -> f64 {
    let mut pairs = Vec::new();
    collider.checked_pairs(&mut pairs);
    collider.place_at(chain, q);
    pairs.iter().map(|&p| collider.closest(p).unwrap().distance_m).fold(f64::INFINITY, f64::min)
}

/// What [`guarantee`] saw.
#[derive(Debug, Default)]
struct Seen {
    shield: ShieldStats,
    /// Sub-steps where the contact test reported a contact the exact distance denies.
    false_contacts: usize,
}

/// Run `scenes` random scenes of `steps` random commands each through the shield; every step
/// checked at 40 sub-steps with the contact test (and a reported contact with the exact
/// distances). Returns the shield's counts.
fn guarantee(chain: &Chain, seed: u64, scenes: usize, steps: usize) -> Seen {
    let mut stats = Seen::default();
    let dt = 0.05;
    let mut rng = Rng::new(seed);
    let mut bare = ArmCollider::new(chain, Checks::default());
    let mut collider = ArmCollider::new(chain, Checks::default());
    let mut shield = Shield::new(chain, &mut collider, ShieldConfig { enabled: true, ..Default::default() });
    let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
    let n = chain.dof();
    let (mut command, mut sub) = (vec![0.0; n], vec![0.0; n]);
    let mut done = 0;
    while done < scenes {
        let mut q = random_pose(chain, &mut rng, &mut bare);
        let Some(o) = obstacle_near(chain, &q, &mut rng, &mut bare) else { continue };
        collider.set_obstacles(std::slice::from_ref(&o));
        assert_eq!(collider.check(chain, &q), None);
        for step in 0..steps {
            random_command(chain, &mut rng, &mut command);
            shield.filter(chain, &mut collider, &q, &mut command, dt);
            let q_new: Vec<f64> = (0..n).map(|i| (q[i] + command[i] * dt).clamp(lo[i], hi[i])).collect();
            for s in 1..=40 {
                let t = s as f64 / 40.0;
                for i in 0..n {
                    sub[i] = q[i] + t * (q_new[i] - q[i]);
                }
                if let Some(c) = collider.check(chain, &sub) {
                    // A reported contact must be a false one (parry's capsule-box test reported
                    // contacts millimetres away before the check's closed form; docs/physics.md).
                    let d = exact_clearance(chain, &mut collider, &sub);
                    assert!(
                        d > 0.0,
                        "scene {done} step {step} t {t}: {} at {d} m (q {q:?}, command {command:?}, obstacle {o:?})",
                        c.describe(chain)
                    );
                    stats.false_contacts += 1;
                }
            }
            q = q_new;
        }
        done += 1;
    }
    stats.shield = *shield.stats();
    stats
}

#[test]
fn random_commands_near_random_obstacles_never_touch_anything_ur5() {
    let seen = guarantee(&Chain::ur5(), 1, 1000, 4);
    let stats = seen.shield;
    assert_eq!(stats.steps, 4000);
    // The scenes are close enough that the shield has work to do.
    assert!(stats.interventions > 400, "{seen:?}");
    // The arm's capsules against spheres and boxes are checked exactly: not even a false contact.
    assert_eq!(seen.false_contacts, 0, "{seen:?}");
    eprintln!("UR5: {seen:?}");
}

#[test]
fn random_commands_near_random_obstacles_never_touch_anything_panda() {
    let seen = guarantee(&panda(), 2, 1000, 4);
    assert!(seen.shield.interventions > 400, "{seen:?}");
    assert_eq!(seen.false_contacts, 0, "{seen:?}");
    eprintln!("Panda: {seen:?}");
}

#[test]
fn without_the_shield_the_same_commands_do_touch() {
    // The scenes of the guarantee test are not trivially safe: unshielded, some end in contact.
    let chain = Chain::ur5();
    let mut rng = Rng::new(1);
    let mut bare = ArmCollider::new(&chain, Checks::default());
    let (mut hits, mut command) = (0, vec![0.0; 6]);
    for _ in 0..300 {
        let q = random_pose(&chain, &mut rng, &mut bare);
        let Some(o) = obstacle_near(&chain, &q, &mut rng, &mut bare) else { continue };
        random_command(&chain, &mut rng, &mut command);
        let q_new: Vec<f64> = (0..6).map(|i| q[i] + 2.0 * command[i] * 0.05).collect();
        bare.set_obstacles(std::slice::from_ref(&o));
        hits += usize::from(bare.check(&chain, &q_new).is_some());
        bare.set_obstacles(&[]);
    }
    assert!(hits > 20, "{hits}");
}

#[test]
fn a_safe_command_far_from_everything_is_left_exactly_as_it_was() {
    let chain = Chain::ur5();
    let mut collider = ArmCollider::new(&chain, Checks::default());
    collider.set_obstacles(&[Obstacle::sphere(0.05, [1.5, 1.5, 1.0])]);
    let mut shield = Shield::new(&chain, &mut collider, ShieldConfig { enabled: true, ..Default::default() });
    let home = HOME;
    let wanted = [0.1, -0.05, 0.2, 0.3, -0.3, 0.7];
    let mut command = wanted;
    assert_eq!(shield.filter(&chain, &mut collider, &home, &mut command, 0.05), Verdict::Kept);
    assert_eq!(command.map(f64::to_bits), wanted.map(f64::to_bits));
    assert_eq!(shield.stats().interventions, 0);
    assert_eq!(shield.stats().steps, 1);
}

#[test]
fn a_command_into_an_obstacle_is_changed_and_the_arm_keeps_its_margin() {
    let chain = Chain::ur5();
    let home = HOME;
    let mut collider = ArmCollider::new(&chain, Checks::default());
    // Turning the base carries the arm into a sphere beside it.
    let mut q = home.to_vec();
    let tip = chain.fk(&q).position;
    let beside = nalgebra::Vector3::new(0.0, 0.0, 1.0).cross(&tip).normalize() * 0.12 + tip;
    collider.set_obstacles(&[Obstacle::sphere(0.04, [beside.x, beside.y, beside.z])]);
    assert_eq!(collider.check(&chain, &q), None);
    let mut shield = Shield::new(&chain, &mut collider, ShieldConfig { enabled: true, ..Default::default() });
    let mut out = Vec::new();
    for _ in 0..40 {
        let mut command = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        shield.filter(&chain, &mut collider, &q, &mut command, 0.05);
        for i in 0..6 {
            q[i] += command[i] * 0.05;
        }
        let clearance = collider.contacts(&chain, &q, &mut out).unwrap();
        assert!(out.is_empty() && clearance > 0.0, "{out:?} {clearance}");
    }
    let s = shield.stats();
    assert!(s.interventions > 0 && s.max_change_rad_per_s > 0.5, "{s:?}");
}

#[test]
fn the_shield_is_deterministic() {
    let chain = Chain::ur5();
    let a = guarantee(&chain, 9, 60, 4);
    let b = guarantee(&chain, 9, 60, 4);
    assert_eq!(a.shield.interventions, b.shield.interventions);
    assert_eq!(a.shield.change_sum_rad_per_s.to_bits(), b.shield.change_sum_rad_per_s.to_bits());
}

#[test]
fn each_damper_row_is_the_distance_gradient() {
    // n^T (J_A - J_B) e_i = d d / d q_i, by central differences, for pairs of every kind.
    for (chain, seed) in [(Chain::ur5(), 3), (panda(), 4)] {
        let mut rng = Rng::new(seed);
        let mut bare = ArmCollider::new(&chain, Checks::default());
        let mut collider = ArmCollider::new(&chain, Checks::default());
        let config = ShieldConfig { enabled: true, influence_m: 10.0, ..Default::default() };
        let mut shield = Shield::new(&chain, &mut collider, config);
        let mut checked = 0;
        while checked < 200 {
            let q = random_pose(&chain, &mut rng, &mut bare);
            let Some(o) = obstacle_near(&chain, &q, &mut rng, &mut bare) else { continue };
            collider.set_obstacles(&[o]);
            collider.checked_pairs(&mut shield.pairs);
            let pair = shield.pairs[rng.below(shield.pairs.len() as u64) as usize];
            collider.place_at(&chain, &q);
            let Some(cl) = collider.closest(pair).filter(|c| c.distance_m > 1e-3) else { continue };
            shield.jacobian_row(&collider, pair, &cl);
            let row = shield.row.clone();
            let h = 1e-4;
            for i in 0..chain.dof() {
                let mut at = |dx: f64| {
                    let mut qq = q.clone();
                    qq[i] += dx;
                    collider.place_at(&chain, &qq);
                    collider.closest(pair).unwrap().distance_m
                };
                let fd = (at(h) - at(-h)) / (2.0 * h);
                let tol = 1e-4;
                assert!(
                    (fd - row[i]).abs() < tol * (1.0 + row[i].abs()),
                    "{pair:?} joint {i}: {fd} vs {}",
                    row[i]
                );
            }
            checked += 1;
        }
    }
}

#[test]
fn bad_values_are_refused_naming_the_field() {
    let ok = ShieldConfig { enabled: true, ..Default::default() };
    assert!(ok.validate().is_ok());
    for (c, field) in [
        (ShieldConfig { margin_m: -0.1, ..ok }, "task.shield.margin_m"),
        (ShieldConfig { margin_m: f64::NAN, ..ok }, "task.shield.margin_m"),
        (ShieldConfig { self_margin_m: 0.5, ..ok }, "task.shield.self_margin_m"),
        (ShieldConfig { influence_m: 0.01, ..ok }, "task.shield.influence_m"),
        (ShieldConfig { gain: 0.0, ..ok }, "task.shield.gain"),
        (ShieldConfig { gain: 1.5, ..ok }, "task.shield.gain"),
    ] {
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains(field), "{e}");
    }
}

/// Step 4's bound: over `q + t dq`, `t in [0, 1]`, no point of an arm shape's bounding sphere
/// moves farther than `D_k = sum_i rho_ki |dq_i|`, and `rho_ki` is never above the pose-free
/// lever. Checked on the UR5 and the Panda, at random poses and motions up to 0.6 rad a joint.
#[test]
fn the_pose_dependent_motion_bound_covers_the_motion_and_is_tighter_than_the_levers() {
    for chain in [Chain::ur5(), panda()] {
        let n = chain.dof();
        let mut collider = ArmCollider::new(&chain, Checks::default());
        let mut shield =
            Shield::new(&chain, &mut collider, ShieldConfig { enabled: true, ..Default::default() });
        let mut rng = Rng::new(17);
        let (mut tighter, mut total) = (0usize, 0usize);
        for _ in 0..300 {
            let q: Vec<f64> = (0..n).map(|_| rng.uniform_range(-3.0, 3.0)).collect();
            for i in 0..n {
                shield.dq[i] = if rng.below(4) == 0 { 0.0 } else { rng.uniform_range(-0.6, 0.6) };
            }
            collider.place_at(&chain, &q);
            // Points of each shape's bounding sphere (its centre, and 6 random ones inside),
            // in its segment's frame: they move rigidly with it.
            let mut points = Vec::new();
            for k in 0..collider.len() {
                let Some(seg) = collider.segment_of(k) else { continue };
                let (c, r) = collider.bounding_sphere(k);
                let f = collider.placed_frames()[seg];
                for j in 0..7 {
                    let u = [rng.normal(), rng.normal(), rng.normal()];
                    let len = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                    let s = if j == 0 { 0.0 } else { r * rng.uniform().cbrt() / len };
                    let p = [0, 1, 2].map(|a| c[a] + s * u[a]);
                    let d = [p[0] - f[3], p[1] - f[7], p[2] - f[11]];
                    // The inverse of a rigid frame: the transposed rotation.
                    let local = [0, 1, 2].map(|col| f[col] * d[0] + f[4 + col] * d[1] + f[8 + col] * d[2]);
                    points.push((k, seg, p, local));
                }
            }
            shield.reach_bounds(&collider);
            let bound: Vec<f64> =
                (0..collider.len()).map(|k| shield.reach[k * n..(k + 1) * n].iter().sum()).collect();
            for k in 0..collider.len() {
                let pose_free: f64 = (0..n).map(|i| shield.levers[k * n + i] * shield.dq[i].abs()).sum();
                assert!(bound[k] <= pose_free + 1e-12, "shape {k}: {} > {pose_free}", bound[k]);
                total += 1;
                tighter += usize::from(bound[k] < 0.9 * pose_free);
            }
            for s in 1..=64 {
                let t = f64::from(s) / 64.0;
                let q_t: Vec<f64> = (0..n).map(|i| q[i] + t * shield.dq[i]).collect();
                collider.place_at(&chain, &q_t);
                for &(k, seg, p0, l) in &points {
                    let f = collider.placed_frames()[seg];
                    let p = [0, 1, 2]
                        .map(|a| f[4 * a] * l[0] + f[4 * a + 1] * l[1] + f[4 * a + 2] * l[2] + f[4 * a + 3]);
                    let moved =
                        ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2) + (p[2] - p0[2]).powi(2)).sqrt();
                    assert!(
                        moved <= bound[k] + 1e-9,
                        "a point of shape {k} moved {moved} > bound {}",
                        bound[k]
                    );
                }
            }
        }
        // The pose-dependent bound is what makes it worth having: well below the levers often.
        assert!(tighter * 4 > total, "{tighter} of {total} shapes' bounds under 0.9 x the levers");
    }
}
