//! Tests of `sim::collision`.

use super::*;
use crate::base::rng::Rng;

fn panda() -> Chain {
    Chain::from_urdf_file(
        std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/robots/panda.urdf")),
        None,
    )
    .unwrap()
}

const PANDA_HOME: [f64; 7] = {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
    [0.0, -FRAC_PI_4, 0.0, -3.0 * FRAC_PI_4, 0.0, FRAC_PI_2, FRAC_PI_4]
};

/// The closest distance between segments p0-p1 and q0-q1 (clamped parameters, by a fine
/// search: an independent check of parry's capsule test).
fn segment_distance(p: [[f64; 3]; 2], q: [[f64; 3]; 2]) -> f64 {
    let at = |s: [[f64; 3]; 2], t: f64| [0, 1, 2].map(|i| s[0][i] + t * (s[1][i] - s[0][i]));
    let mut best = f64::INFINITY;
    for i in 0..=200 {
        let a = at(p, i as f64 / 200.0);
        for j in 0..=200 {
            let b = at(q, j as f64 / 200.0);
            best = best.min(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt());
        }
    }
    best
}

fn capsule_ends(chain: &Chain, frames: &[[f64; 12]], k: usize) -> ([[f64; 3]; 2], f64) {
    let s = &chain.collision_shapes()[k];
    let m = match s.segment {
        None => s.pose,
        Some(i) => crate::robot::mul_tf(&frames[i], &s.pose),
    };
    let Shape::Capsule { radius_m, half_length_m: h } = s.shape else { panic!("not a capsule") };
    let end = |sign: f64| [m[3] + sign * h * m[2], m[7] + sign * h * m[6], m[11] + sign * h * m[10]];
    ([end(-1.0), end(1.0)], radius_m)
}

#[test]
fn the_home_pose_is_clear_and_a_low_pose_hits_the_floor() {
    let chain = panda();
    let mut c = ArmCollider::new(&chain, Checks { floor: true, self_collision: true });
    assert!(c.len() >= 8);
    assert_eq!(c.check(&chain, &PANDA_HOME), None);
    // Poses that put the flange below the floor are floor contacts (with the floor test
    // only), and the floor test off reports none.
    let mut floor_only = ArmCollider::new(&chain, Checks { floor: true, self_collision: false });
    let mut none = ArmCollider::new(&chain, Checks { floor: false, self_collision: false });
    let mut below = 0;
    for i in 0..=20 {
        for k in 0..=20 {
            let mut q = PANDA_HOME;
            q[1] = -1.7 + 3.4 * i as f64 / 20.0;
            q[3] = -3.0 + 2.9 * k as f64 / 20.0;
            if chain.fk(&q).position.z < -0.02 {
                below += 1;
                let hit = floor_only.check(&chain, &q);
                assert!(matches!(hit, Some(Contact::Floor { .. })), "{q:?}: {hit:?}");
                assert_eq!(none.check(&chain, &q), None);
            }
        }
    }
    assert!(below >= 10, "{below} poses below the floor");
}

#[test]
fn an_obstacle_at_the_tool_is_hit_and_one_far_away_is_not() {
    let chain = panda();
    let mut c = ArmCollider::new(&chain, Checks { floor: true, self_collision: true });
    let tool = chain.fk(&PANDA_HOME).position;
    let near = Obstacle::sphere(0.05, [tool.x, tool.y, tool.z - 0.02]);
    let far = Obstacle::sphere(0.05, [2.0, 2.0, 0.5]);
    let cube = Obstacle::cuboid(
        [0.05, 0.3, 0.02],
        [tool.x, tool.y, tool.z + 0.2],
        Some([0.0, 0.0, 0.382_683_4, 0.923_879_5]),
    );
    c.set_obstacles(std::slice::from_ref(&far));
    assert_eq!(c.check(&chain, &PANDA_HOME), None);
    c.set_obstacles(&[far, near]);
    assert!(matches!(c.check(&chain, &PANDA_HOME), Some(Contact::Obstacle { obstacle: 1, .. })));
    c.set_obstacles(&[cube]);
    assert!(matches!(c.check(&chain, &PANDA_HOME), Some(Contact::Obstacle { obstacle: 0, .. })));
}

/// Over random poses, the collider reports a self-collision exactly when an independent
/// computation (distances between the capsules' segments by a fine search) finds two
/// shapes of links no joint connects overlapping. Poses with a pair within 3 mm of touching
/// are skipped (parry is f32, the search discrete).
#[test]
fn self_collision_agrees_with_segment_distances() {
    let chain = panda();
    let mut c = ArmCollider::new(&chain, Checks { floor: false, self_collision: true });
    let mut rng = Rng::new(7);
    let mut frames = vec![[0.0; 12]; chain.dof()];
    let shapes = chain.collision_shapes();
    assert!(shapes.iter().all(|s| matches!(s.shape, Shape::Capsule { .. })));
    let seg = |s: Option<usize>| s.map_or(-1, |i| i as i64);
    let (mut colliding, mut clear) = (0, 0);
    for _ in 0..150 {
        let q: Vec<f64> =
            (0..7).map(|i| rng.uniform_range(chain.lower_limits()[i], chain.upper_limits()[i])).collect();
        chain.segment_frames(&q, &mut frames);
        let mut gaps = Vec::new();
        for a in 0..shapes.len() {
            for b in a + 1..shapes.len() {
                if (seg(shapes[a].segment) - seg(shapes[b].segment)).abs() >= 2 {
                    let ((pa, ra), (pb, rb)) =
                        (capsule_ends(&chain, &frames, a), capsule_ends(&chain, &frames, b));
                    gaps.push(segment_distance(pa, pb) - ra - rb);
                }
            }
        }
        if gaps.iter().any(|g| g.abs() < 3e-3) {
            continue;
        }
        let expected = gaps.iter().any(|&g| g < 0.0);
        let got = c.check(&chain, &q);
        assert_eq!(got.is_some(), expected, "{q:?}: {got:?}, gaps {gaps:?}");
        if expected {
            assert!(matches!(got, Some(Contact::SelfCollision { .. })));
            colliding += 1;
        } else {
            clear += 1;
        }
    }
    assert!(colliding >= 10 && clear >= 10, "{colliding} colliding poses, {clear} clear");
}

/// The closed-form segment distance against the fine search, on random, parallel,
/// collinear and point-like segments.
#[test]
fn segment_distance_closed_form_matches_the_search() {
    let mut rng = Rng::new(12);
    let mut p = || [0, 1, 2].map(|_| rng.uniform_range(-1.0, 1.0));
    for case in 0..400 {
        let (a, b, c) = (p(), p(), p());
        let d = match case % 4 {
            0 => p(),
            // Parallel to a-b.
            1 => [c[0] + (b[0] - a[0]) * 0.7, c[1] + (b[1] - a[1]) * 0.7, c[2] + (b[2] - a[2]) * 0.7],
            // Collinear with a-b.
            2 => {
                let c2 = [a[0] + (b[0] - a[0]) * 1.3, a[1] + (b[1] - a[1]) * 1.3, a[2] + (b[2] - a[2]) * 1.3];
                let d2 = [a[0] + (b[0] - a[0]) * 2.0, a[1] + (b[1] - a[1]) * 2.0, a[2] + (b[2] - a[2]) * 2.0];
                let want = segment_distance([a, b], [c2, d2]);
                let got = segment_segment_distance2(a, b, c2, d2).sqrt();
                assert!((got - want).abs() < 1e-2, "collinear: {got} vs {want}");
                continue;
            }
            // A point.
            _ => c,
        };
        let want = segment_distance([a, b], [c, d]);
        let got = segment_segment_distance2(a, b, c, d).sqrt();
        assert!(got <= want + 1e-12 && want - got < 1.5e-2, "case {case}: {got} vs {want}");
    }
}
