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

/// A fresh temporary folder holding `cube.obj`, the axis-aligned cube of side `side` centred at
/// the origin; the folder's path.
pub(crate) fn cube_dir(name: &str, side: f64) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("stagerl-collision-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let h = side / 2.0;
    let mut obj = String::new();
    for i in 0..8 {
        let p = [0, 1, 2].map(|k| if i >> k & 1 == 1 { h } else { -h });
        obj.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for f in [[1, 2, 4, 3], [5, 7, 8, 6], [1, 5, 6, 2], [3, 4, 8, 7], [1, 3, 7, 5], [2, 6, 8, 4]] {
        obj.push_str(&format!("f {} {} {} {}\n", f[0], f[1], f[2], f[3]));
    }
    std::fs::write(d.join(format!("cube{side}.obj")), obj).unwrap();
    d
}

/// One revolute joint about y at height 0.3 m; its link is a 0.1 m cube mesh whose centre is
/// 0.3 m out along the link's x axis.
pub(crate) fn swing_arm(name: &str) -> Chain {
    let d = cube_dir(name, 0.1);
    let urdf = r#"<robot name="swing">
  <link name="base"/>
  <link name="arm">
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.3 0 0"/><geometry><mesh filename="cube0.1.obj"/></geometry></collision>
  </link>
  <joint name="swing" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" velocity="2" effort="50"/></joint>
</robot>"#;
    std::fs::write(d.join("swing.urdf"), urdf).unwrap();
    Chain::from_urdf_file(&d.join("swing.urdf"), None).unwrap()
}

/// A mesh cube swung about y: it touches the floor exactly when its lowest corner, in closed
/// form `0.3 - 0.3 sin(t) - 0.05 (|cos t| + |sin t|)`, is below z = 0; the clearance is that
/// height (outside a 1 mm band: parry is f32).
#[test]
fn a_mesh_link_meets_the_floor_where_its_lowest_corner_does() {
    let chain = swing_arm("floor");
    assert!(matches!(chain.collision_shapes()[0].shape, Shape::Convex(_)));
    let mut c = ArmCollider::new(&chain, Checks { floor: true, self_collision: true });
    let (mut hits, mut clear, mut all) = (0, 0, Vec::new());
    for i in 0..=600 {
        let t = -3.0 + 6.0 * i as f64 / 600.0;
        let lowest = 0.3 - 0.3 * t.sin() - 0.05 * (t.cos().abs() + t.sin().abs());
        let clearance = c.contacts(&chain, &[t], &mut all).unwrap();
        // The hull's vertices are f32.
        assert!((clearance - lowest).abs() < 1e-6, "t = {t}: {clearance} vs {lowest}");
        if lowest.abs() < 1e-3 {
            continue;
        }
        let got = c.check(&chain, &[t]);
        assert_eq!(got.is_some(), lowest < 0.0, "t = {t}: {got:?}, lowest corner at {lowest} m");
        assert_eq!(all.len(), usize::from(lowest < 0.0));
        if lowest < 0.0 {
            assert_eq!(got, Some(Contact::Floor { shape: 0 }));
            hits += 1;
        } else {
            clear += 1;
        }
    }
    assert!(hits > 50 && clear > 50, "{hits} {clear}");
    // Within microns of the floor, where the lowest vertex found by climbing does not settle
    // it and every vertex is scanned: `check` (placing the part partly, first) agrees with
    // `contacts` (every vertex) on both sides of each crossing.
    let lowest = |t: f64| 0.3 - 0.3 * t.sin() - 0.05 * (t.cos().abs() + t.sin().abs());
    let (mut fresh, mut every) =
        (ArmCollider::new(&chain, Checks::default()), ArmCollider::new(&chain, Checks::default()));
    let mut sides = [0; 2];
    for i in 0..600 {
        let (mut lo, mut hi) = (-3.0 + 6.0 * i as f64 / 600.0, -3.0 + 6.0 * (i + 1) as f64 / 600.0);
        if (lowest(lo) < 0.0) == (lowest(hi) < 0.0) {
            continue;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if (lowest(mid) < 0.0) == (lowest(lo) < 0.0) {
                lo = mid
            } else {
                hi = mid
            }
        }
        for k in -100..=100 {
            let t = lo + k as f64 * 2e-8;
            let got = fresh.check(&chain, &[t]).is_some();
            every.contacts(&chain, &[t], &mut all);
            assert_eq!(got, all.contains(&Contact::Floor { shape: 0 }), "t = {t}");
            sides[usize::from(got)] += 1;
        }
    }
    assert!(sides[0] > 50 && sides[1] > 50, "{sides:?}");
}

/// A 0.1 m mesh cube on a prismatic joint along z above a 0.2 m mesh cube at the base: the
/// links overlap exactly when the gap `0.35 + d` (d the joint's value) is negative, the floor
/// is touched when `0.45 + d` is; the clearance is `0.35 + d` (the penetration depth when
/// negative), whatever the turn of the first joint about z.
#[test]
fn mesh_links_collide_with_each_other_as_the_gap_between_them_says() {
    let d = cube_dir("self", 0.2);
    let small = cube_dir("self-small", 0.1);
    std::fs::copy(small.join("cube0.1.obj"), d.join("cube0.1.obj")).unwrap();
    let urdf = r#"<robot name="lift">
  <link name="base"><collision><geometry><mesh filename="cube0.2.obj"/></geometry></collision></link>
  <link name="turn"/>
  <link name="lift"><collision><geometry><mesh filename="package://parts/cube0.1.obj"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="turn"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1"/></joint>
  <joint name="j2" type="prismatic"><parent link="turn"/><child link="lift"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 0 1"/><limit lower="-0.6" upper="0.2" velocity="1"/></joint>
</robot>"#;
    std::fs::write(d.join("lift.urdf"), urdf).unwrap();
    // `package://parts/...` through robot.package_paths: a folder holding the folder `parts`.
    std::fs::create_dir_all(d.join("pkgs/parts")).unwrap();
    std::fs::copy(small.join("cube0.1.obj"), d.join("pkgs/parts/cube0.1.obj")).unwrap();
    let opts = crate::robot::MeshOptions { package_paths: vec![d.join("pkgs")], ..Default::default() };
    let chain = Chain::from_urdf_file_with(&d.join("lift.urdf"), None, &opts).unwrap();
    assert_eq!(chain.collision_shapes().len(), 2);
    let mut c = ArmCollider::new(&chain, Checks { floor: true, self_collision: true });
    let mut rng = Rng::new(3);
    let mut all = Vec::new();
    let (mut overlapping, mut apart) = (0, 0);
    for i in 0..=340 {
        let lift = -0.48 + 0.68 * i as f64 / 340.0;
        let q = [rng.uniform_range(-3.0, 3.0), lift];
        let gap = 0.35 + lift;
        let clearance = c.contacts(&chain, &q, &mut all).unwrap();
        assert!((clearance - gap).abs() < 2e-5, "{q:?}: clearance {clearance}, gap {gap}");
        if gap.abs() < 1e-3 || (0.45 + lift).abs() < 1e-3 {
            continue;
        }
        let expected_self = gap < 0.0;
        let on_floor = 0.45 + lift < 0.0;
        assert_eq!(
            all.contains(&Contact::SelfCollision { shape_a: 0, shape_b: 1 }),
            expected_self,
            "{q:?}: {all:?}"
        );
        assert_eq!(all.contains(&Contact::Floor { shape: 1 }), on_floor, "{q:?}: {all:?}");
        assert_eq!(all.len(), usize::from(expected_self) + usize::from(on_floor));
        let first = c.check(&chain, &q);
        match (on_floor, expected_self) {
            (true, _) => assert_eq!(first, Some(Contact::Floor { shape: 1 })),
            (false, true) => assert_eq!(first, Some(Contact::SelfCollision { shape_a: 0, shape_b: 1 })),
            (false, false) => assert_eq!(first, None),
        }
        if expected_self {
            overlapping += 1;
        } else {
            apart += 1;
        }
    }
    assert!(overlapping > 20 && apart > 20, "{overlapping} {apart}");
    // The root's shapes are not tested against the floor; with no checks there is no clearance.
    let mut none = ArmCollider::new(&chain, Checks { floor: false, self_collision: false });
    assert_eq!(none.contacts(&chain, &[0.0, 0.0], &mut all), None);
}

/// A three-joint arm whose four links are random elongated blobs (OBJ files of vertices, each
/// loaded as its hull; the same blobs for every `name`, written under a scratch folder of it).
fn blob_arm(name: &str) -> Chain {
    let d = std::env::temp_dir().join(format!("stagerl-collision-{}-blobs-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let mut rng = Rng::new(17);
    for (i, (len, width)) in [(0.12, 0.08), (0.35, 0.06), (0.3, 0.05), (0.2, 0.04)].iter().enumerate() {
        let mut obj = String::new();
        for _ in 0..200 {
            let p = [len * rng.uniform_range(-0.5, 0.5), width * rng.normal(), width * rng.normal()];
            obj.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
        }
        std::fs::write(d.join(format!("blob{i}.obj")), obj).unwrap();
    }
    let link = |name: &str, i: usize, at: &str, rpy: &str| {
        format!(
            r#"<link name="{name}"><collision><origin xyz="{at}" rpy="{rpy}"/><geometry><mesh filename="blob{i}.obj"/></geometry></collision></link>"#
        )
    };
    let joint = |name: &str, parent: &str, child: &str, at: &str, axis: &str| {
        format!(
            r#"<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/><origin xyz="{at}"/><axis xyz="{axis}"/><limit lower="-3.1" upper="3.1" velocity="1"/></joint>"#
        )
    };
    let urdf = format!(
        "<robot name=\"blobs\">{}{}{}{}{}{}{}</robot>",
        link("base", 0, "0 0 0.05", "0 1.5708 0"),
        link("l1", 1, "0 0 0.2", "0 1.5708 0"),
        link("l2", 2, "0.15 0 0", "0 0 0"),
        link("l3", 3, "0.1 0 0", "0 0 0"),
        joint("j1", "base", "l1", "0 0 0.1", "0 0 1"),
        joint("j2", "l1", "l2", "0 0 0.4", "0 1 0"),
        joint("j3", "l2", "l3", "0.3 0 0", "0 1 0"),
    );
    std::fs::write(d.join("blobs.urdf"), urdf).unwrap();
    let chain = Chain::from_urdf_file(&d.join("blobs.urdf"), None).unwrap();
    assert_eq!(chain.collision_shapes().len(), 4);
    chain
}

/// The obstacles the blob arm is checked among.
fn blob_obstacles() -> [Obstacle; 2] {
    [
        Obstacle::sphere(0.08, [0.3, 0.1, 0.3]),
        Obstacle::cuboid([0.1, 0.05, 0.2], [-0.25, 0.0, 0.35], Some([0.0, 0.0, 0.38268343, 0.92387953])),
    ]
}

/// Every contact parry's exact test finds on every pair at `c`'s last (whole) placement, into
/// `want` in the order of the checks; and how many pairs have capsules that meet where the hulls
/// do not.
fn parry_contacts(c: &ArmCollider, want: &mut Vec<Contact>) -> usize {
    want.clear();
    for (k, s) in c.shapes.iter().enumerate().filter(|(_, s)| s.segment >= 0) {
        if lowest_z(&s.shape, &c.world[k]) < 0.0 {
            want.push(Contact::Floor { shape: s.index });
        }
    }
    let exact = |a: usize, pose: &Pose3, s: &dyn ParryShape| {
        overlap(&pose3(&c.world[a]), c.shapes[a].parry.shape(), pose, s)
    };
    let mut near_misses = 0;
    for &(a, b) in &c.pairs {
        let (pb, sb) = (pose3(&c.world[b]), c.shapes[b].parry.shape());
        let hit = exact(a, &pb, sb);
        let (ga, gb) = (&c.geo[a], &c.geo[b]);
        let capsules_meet =
            segment_segment_distance2(ga.a, ga.b, gb.a, gb.b) < (ga.radius + gb.radius).powi(2);
        near_misses += usize::from(capsules_meet && !hit);
        if hit {
            want.push(Contact::SelfCollision { shape_a: c.shapes[a].index, shape_b: c.shapes[b].index });
        }
    }
    for (i, o) in c.obstacles.iter().enumerate() {
        for k in 0..c.shapes.len() {
            if exact(k, &o.pose, o.prim.shape()) {
                want.push(Contact::Obstacle { shape: c.shapes[k].index, obstacle: i });
            }
        }
    }
    near_misses
}

/// The capsules around mesh parts (the broad phase) never change a verdict: over 4000 random
/// poses of the blob arm among obstacles, every contact `contacts` reports, and `check`'s first,
/// are those of parry's exact test on every pair without the capsules.
#[test]
fn the_capsules_around_mesh_parts_never_change_a_verdict() {
    let chain = blob_arm("random");
    let mut rng = Rng::new(18);
    let mut c = ArmCollider::new(&chain, Checks { floor: true, self_collision: true });
    c.set_obstacles(&blob_obstacles());
    let (mut out, mut want) = (Vec::new(), Vec::new());
    let (mut contacts, mut near_misses) = (0, 0);
    for _ in 0..4000 {
        let q: Vec<f64> = (0..3).map(|_| rng.uniform_range(-3.1, 3.1)).collect();
        c.contacts(&chain, &q, &mut out);
        near_misses += parry_contacts(&c, &mut want);
        assert_eq!(out, want, "q = {q:?}");
        assert_eq!(c.check(&chain, &q), want.first().copied(), "q = {q:?}");
        contacts += usize::from(!want.is_empty());
    }
    // Both kinds of pose are common: contacts, and capsules that meet where the hulls do not
    // (the exact test decides those).
    assert!(contacts > 400 && near_misses > 200, "{contacts} {near_misses}");
}

/// Over 6000 steps of a random walk of the blob arm among obstacles (0.03 rad a joint at most,
/// as an episode takes them), most exact tests are answered by the axis that separated the pair
/// at the step before, and never wrongly: every contact and `check`'s first are parry's (a sign
/// error in the axis test fails this).
#[test]
fn the_last_separating_axis_never_changes_a_verdict() {
    let chain = blob_arm("walk");
    let mut rng = Rng::new(19);
    let obstacles = blob_obstacles();
    let (mut out, mut want) = (Vec::new(), Vec::new());
    // (No floor test: its contacts would come first.)
    let mut walk = ArmCollider::new(&chain, Checks { floor: false, self_collision: true });
    walk.set_obstacles(&obstacles);
    let mut q = vec![0.0; 3];
    let (mut walk_contacts, mut walk_near) = (0, 0);
    for _ in 0..6000 {
        for x in q.iter_mut() {
            *x = (*x + rng.uniform_range(-0.03, 0.03)).clamp(-3.1, 3.1);
        }
        let got = walk.check(&chain, &q);
        walk.contacts(&chain, &q, &mut out);
        walk_near += parry_contacts(&walk, &mut want);
        want.retain(|c| !matches!(c, Contact::Floor { .. }));
        assert_eq!(out, want, "walk at q = {q:?}");
        assert_eq!(got, want.first().copied(), "walk at q = {q:?}");
        walk_contacts += usize::from(got.is_some());
    }
    let skips = walk.axis_skips.0[0].load(std::sync::atomic::Ordering::Relaxed) as usize;
    assert!(walk_contacts > 100 && walk_near > 1000, "{walk_contacts} contacts, {walk_near} near misses");
    assert!(
        skips > walk_near / 2,
        "{skips} exact tests answered by the last axis of {walk_near} near misses"
    );
}

/// An arm of capsules, spheres, a box and a mesh part (written under a scratch folder).
fn mixed_arm(rng: &mut Rng) -> Chain {
    let d = std::env::temp_dir().join(format!("stagerl-collision-{}-mixed", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let mut obj = String::new();
    for _ in 0..120 {
        obj.push_str(&format!(
            "v {} {} {}\n",
            0.2 * rng.uniform_range(-0.5, 0.5),
            0.04 * rng.normal(),
            0.04 * rng.normal()
        ));
    }
    std::fs::write(d.join("part.obj"), obj).unwrap();
    let geometry = [
        "<cylinder radius=\"0.05\" length=\"0.3\"/>",
        "<sphere radius=\"0.07\"/>",
        "<box size=\"0.3 0.06 0.05\"/>",
        "<mesh filename=\"part.obj\"/>",
        "<cylinder radius=\"0.03\" length=\"0.2\"/>",
    ];
    let mut urdf = String::from("<robot name=\"mixed\">");
    for (i, g) in geometry.iter().enumerate() {
        urdf.push_str(&format!(
            r#"<link name="l{i}"><collision><origin xyz="0.1 0 0.05" rpy="0.3 1.2 0"/><geometry>{g}</geometry></collision><collision><origin xyz="0 0 0.12"/><geometry><sphere radius="0.03"/></geometry></collision></link>"#
        ));
        if i > 0 {
            urdf.push_str(&format!(
                r#"<joint name="j{i}" type="revolute"><parent link="l{}"/><child link="l{i}"/><origin xyz="0.2 0 0.15" rpy="0 0.4 0"/><axis xyz="{}"/><limit lower="-3.1" upper="3.1" velocity="1"/></joint>"#,
                i - 1,
                if i % 2 == 0 { "0 1 0" } else { "0 0 1" }
            ));
        }
    }
    urdf.push_str("</robot>");
    std::fs::write(d.join("mixed.urdf"), urdf).unwrap();
    Chain::from_urdf_file(&d.join("mixed.urdf"), None).unwrap()
}

/// `check` places capsules and spheres only as far as its tests need (their axis and centre);
/// whatever the order of the calls, every answer (first contact, contacts, clearance, closest
/// points, the frames the tip is taken from) and every placed pose is the one of a collider
/// that placed the whole arm first, bit for bit. An arm of capsules, spheres, boxes and a mesh
/// part, with obstacles, over random poses visited in random orders.
#[test]
fn checks_that_place_part_of_the_arm_answer_as_a_whole_placement_does() {
    let mut rng = Rng::new(23);
    let chain = mixed_arm(&mut rng);
    let kinds = |f: fn(&Shape) -> bool| chain.collision_shapes().iter().filter(|s| f(&s.shape)).count();
    assert!(
        kinds(|s| matches!(s, Shape::Capsule { .. })) >= 2
            && kinds(|s| matches!(s, Shape::Sphere { .. })) >= 5
    );
    assert!(
        kinds(|s| matches!(s, Shape::Cuboid { .. })) == 1 && kinds(|s| matches!(s, Shape::Convex(_))) >= 1
    );
    let obstacles = [
        Obstacle::sphere(0.1, [0.4, 0.1, 0.4]),
        Obstacle::cuboid([0.1, 0.05, 0.2], [0.2, -0.2, 0.5], Some([0.0, 0.0, 0.38268343, 0.92387953])),
    ];
    // With the floor test first, most contacts are floor contacts; without it, self and
    // obstacle contacts come first (the exact tests of capsules against boxes and meshes).
    for floor in [true, false] {
        let checks = Checks { floor, self_collision: true };
        let (mut c, mut whole) = (ArmCollider::new(&chain, checks), ArmCollider::new(&chain, checks));
        c.set_obstacles(&obstacles);
        whole.set_obstacles(&obstacles);
        let (mut out, mut want) = (Vec::new(), Vec::new());
        let (mut contacts, mut partial_exact) = (0, 0);
        let mut pairs = Vec::new();
        whole.checked_pairs(&mut pairs);
        for _ in 0..1500 {
            let q: Vec<f64> = (0..chain.dof()).map(|_| rng.uniform_range(-2.5, 2.5)).collect();
            // The reference: everything placed first.
            whole.place_at(&chain, &q);
            let first = whole.check(&chain, &q);
            let clearance = whole.contacts(&chain, &q, &mut want);
            contacts += usize::from(first.is_some());
            // A check first (partial placement), then the rest in a random order.
            let got = c.check(&chain, &q);
            assert_eq!(got, first, "q = {q:?}");
            partial_exact += usize::from(matches!(got, Some(Contact::SelfCollision { .. })));
            assert_eq!(
                c.frames_placed_at(&q).map(<[_]>::to_vec),
                whole.frames_placed_at(&q).map(<[_]>::to_vec)
            );
            for step in if rng.uniform() < 0.5 { [0, 1] } else { [1, 0] } {
                if step == 0 {
                    let cl = c.contacts(&chain, &q, &mut out);
                    assert_eq!(
                        (&out, cl.map(f64::to_bits)),
                        (&want, clearance.map(f64::to_bits)),
                        "q = {q:?}"
                    );
                } else {
                    c.place_at(&chain, &q);
                    for &p in &pairs {
                        let (a, b) = (c.closest(p), whole.closest(p));
                        assert_eq!(format!("{a:?}"), format!("{b:?}"), "{p:?} at q = {q:?}");
                    }
                }
            }
            for k in 0..c.len() {
                assert_eq!(c.world[k].map(f64::to_bits), whole.world[k].map(f64::to_bits), "shape {k}");
            }
        }
        assert!(
            contacts > 300 && (floor || partial_exact > 100),
            "{contacts} contacts, {partial_exact} self contacts"
        );
    }
}

/// `check`'s shortcuts (bounding spheres, mesh parts' capsules, partial placement) never change
/// an answer: over random poses of the UR5, the Panda and an arm of every kind of shape, among
/// obstacles and without, the first contact of `check` is the first of `contacts`, which
/// tests and measures every pair.
#[test]
fn the_first_contact_is_the_first_of_all_contacts() {
    let mut rng = Rng::new(31);
    let mixed = mixed_arm(&mut rng);
    let obstacles = [
        Obstacle::sphere(0.1, [0.4, 0.1, 0.4]),
        Obstacle::cuboid([0.1, 0.05, 0.2], [-0.2, -0.3, 0.5], Some([0.0, 0.0, 0.38268343, 0.92387953])),
    ];
    for (name, chain) in [("ur5", Chain::ur5()), ("panda", panda()), ("mixed", mixed)] {
        for among in [&obstacles[..0], &obstacles[..]] {
            let (mut c, mut every) =
                (ArmCollider::new(&chain, Checks::default()), ArmCollider::new(&chain, Checks::default()));
            c.set_obstacles(among);
            every.set_obstacles(among);
            let mut out = Vec::new();
            let (mut contacts, trials) = (0, 3000);
            for _ in 0..trials {
                let q: Vec<f64> = (0..chain.dof())
                    .map(|i| {
                        let (lo, hi) = (chain.lower_limits()[i].max(-3.0), chain.upper_limits()[i].min(3.0));
                        rng.uniform_range(lo, hi)
                    })
                    .collect();
                let got = c.check(&chain, &q);
                every.contacts(&chain, &q, &mut out);
                assert_eq!(got, out.first().copied(), "{name} among {} obstacles at {q:?}", among.len());
                contacts += usize::from(got.is_some());
            }
            assert!(contacts > trials / 20 && contacts < trials - trials / 20, "{name}: {contacts} contacts");
        }
    }
}
