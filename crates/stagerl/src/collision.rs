//! Collisions of the arm in the kinematic simulation: with the floor (the plane z = 0 of the base
//! frame), with itself (links that no joint connects) and with obstacles (boxes and spheres at
//! fixed poses). The arm's shapes are its URDF's `<collision>` primitives
//! ([`crate::robot::LinkShape`]); the tests between shapes are parry3d's (f32), the floor test
//! is exact (the lowest point of each shape).
//!
//! Which links are adjacent: links move with the frame of the last actuated joint before them
//! (their *segment*; the root link and the links fixed to it form segment -1). Two shapes are
//! tested against each other when their segments differ by 2 or more: shapes of one segment are
//! rigidly joined, and consecutive segments meet at a joint, where the shapes of real arms
//! touch. The root's shapes are not tested against the floor (the arm stands on it).

use parry3d::math::{Pose3, Rot3, Vec3};
use parry3d::query::intersection_test;
use parry3d::shape::{Ball, Capsule, Cuboid, Shape as ParryShape};
use serde::{Deserialize, Serialize};

use crate::robot::{Chain, Shape};
use crate::{Error, Result};

/// What the arm touched first in a check (shape indices are into
/// [`Chain::collision_shapes`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "with", rename_all = "snake_case")]
pub enum Contact {
    /// A shape of `link` reaches below z = 0.
    Floor { link: String },
    /// Shapes of two links that no joint connects overlap.
    SelfCollision { link_a: String, link_b: String },
    /// A shape of `link` overlaps obstacle `obstacle` (its index in the task's obstacles).
    Obstacle { link: String, obstacle: usize },
}

impl Contact {
    /// `floor`, `self` or `obstacle`.
    pub fn kind(&self) -> &'static str {
        match self {
            Contact::Floor { .. } => "floor",
            Contact::SelfCollision { .. } => "self",
            Contact::Obstacle { .. } => "obstacle",
        }
    }
}

/// An obstacle: a box or a sphere at a fixed pose in the base frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    /// `{ shape = "cuboid", half_extents_m = [x, y, z] }` or `{ shape = "sphere", radius_m = r }`.
    #[serde(flatten)]
    pub shape: Shape,
    /// Centre, metres, base frame.
    pub position_m: [f64; 3],
    /// Orientation as a unit quaternion (x, y, z, w); unset: the base frame's axes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_xyzw: Option<[f64; 4]>,
}

impl Obstacle {
    /// Check the values; `field` names the obstacle in errors (`task.obstacles[2]`).
    pub fn validate(&self, field: &str) -> Result<()> {
        let size_ok = |v: f64| v.is_finite() && v > 0.0 && v <= 100.0;
        match self.shape {
            Shape::Sphere { radius_m } if !size_ok(radius_m) => {
                return Err(Error::config(
                    format!("{field}.radius_m"),
                    radius_m,
                    "a number in (0, 100] metres",
                ));
            }
            Shape::Cuboid { half_extents_m } if !half_extents_m.iter().all(|&v| size_ok(v)) => {
                return Err(Error::config(
                    format!("{field}.half_extents_m"),
                    format!("{half_extents_m:?}"),
                    "three numbers in (0, 100] metres",
                ));
            }
            Shape::Capsule { .. } => {
                return Err(Error::config(format!("{field}.shape"), "capsule", "\"cuboid\" or \"sphere\""));
            }
            _ => {}
        }
        if !self.position_m.iter().all(|v| v.is_finite() && v.abs() <= 100.0) {
            return Err(Error::config(
                format!("{field}.position_m"),
                format!("{:?}", self.position_m),
                "three finite numbers within +-100 metres",
            ));
        }
        if let Some(q) = self.rotation_xyzw {
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(norm - 1.0).abs().le(&1e-6) {
                return Err(Error::config(
                    format!("{field}.rotation_xyzw"),
                    format!("{q:?}"),
                    "a unit quaternion (x, y, z, w), |norm - 1| <= 1e-6",
                ));
            }
        }
        Ok(())
    }

    fn pose(&self) -> Pose3 {
        let t = Vec3::new(self.position_m[0] as f32, self.position_m[1] as f32, self.position_m[2] as f32);
        let r = self.rotation_xyzw.map_or(Rot3::IDENTITY, |[x, y, z, w]| {
            Rot3::from_xyzw(x as f32, y as f32, z as f32, w as f32).normalize()
        });
        Pose3::from_parts(t, r)
    }
}

/// One of the arm's shapes, ready for the tests.
struct ArmShape {
    /// Into [`Chain::collision_shapes`].
    index: usize,
    /// -1 for the root's segment.
    segment: i64,
    local: [f64; 12],
    shape: Shape,
    parry: Box<dyn ParryShape>,
}

/// A parry shape of a primitive (capsules along their local z).
fn parry_shape(s: &Shape) -> Box<dyn ParryShape> {
    match *s {
        Shape::Capsule { radius_m, half_length_m } => {
            Box::new(Capsule::new_z(half_length_m as f32, radius_m as f32))
        }
        Shape::Sphere { radius_m } => Box::new(Ball::new(radius_m as f32)),
        Shape::Cuboid { half_extents_m: [x, y, z] } => {
            Box::new(Cuboid::new(Vec3::new(x as f32, y as f32, z as f32)))
        }
    }
}

/// The lowest z of a primitive at the row-major 3 x 4 pose `m`, metres.
fn lowest_z(s: &Shape, m: &[f64; 12]) -> f64 {
    let (zx, zy, zz, z0) = (m[8], m[9], m[10], m[11]);
    match *s {
        Shape::Capsule { radius_m, half_length_m } => z0 - half_length_m * zz.abs() - radius_m,
        Shape::Sphere { radius_m } => z0 - radius_m,
        Shape::Cuboid { half_extents_m: [x, y, z] } => z0 - x * zx.abs() - y * zy.abs() - z * zz.abs(),
    }
}

/// Whether two posed shapes overlap (parry supports every pair of our primitives).
fn overlap(p1: &Pose3, s1: &dyn ParryShape, p2: &Pose3, s2: &dyn ParryShape) -> bool {
    intersection_test(p1, s1, p2, s2).is_ok_and(|i| i.intersecting)
}

fn pose3(m: &[f64; 12]) -> Pose3 {
    let r = parry3d::math::Mat3::from_cols(
        Vec3::new(m[0] as f32, m[4] as f32, m[8] as f32),
        Vec3::new(m[1] as f32, m[5] as f32, m[9] as f32),
        Vec3::new(m[2] as f32, m[6] as f32, m[10] as f32),
    );
    Pose3::from_parts(Vec3::new(m[3] as f32, m[7] as f32, m[11] as f32), Rot3::from_mat3(&r).normalize())
}

/// Which collisions to look for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Checks {
    pub floor: bool,
    pub self_collision: bool,
}

/// The arm's collision checker, with the obstacles it is tested against (scratch included: a
/// check allocates nothing).
pub struct ArmCollider {
    shapes: Vec<ArmShape>,
    obstacles: Vec<(Pose3, Box<dyn ParryShape>)>,
    /// Pairs of indices into `shapes` tested for self-collision.
    pairs: Vec<(usize, usize)>,
    checks: Checks,
    frames: Vec<[f64; 12]>,
    world: Vec<[f64; 12]>,
    poses: Vec<Pose3>,
}

impl ArmCollider {
    pub fn new(chain: &Chain, checks: Checks) -> ArmCollider {
        let shapes: Vec<ArmShape> = chain
            .collision_shapes()
            .iter()
            .enumerate()
            .map(|(index, s)| ArmShape {
                index,
                segment: s.segment.map_or(-1, |i| i as i64),
                local: s.pose,
                shape: s.shape,
                parry: parry_shape(&s.shape),
            })
            .collect();
        let mut pairs = Vec::new();
        for a in 0..shapes.len() {
            for b in a + 1..shapes.len() {
                if (shapes[a].segment - shapes[b].segment).abs() >= 2 {
                    pairs.push((a, b));
                }
            }
        }
        let n = shapes.len();
        ArmCollider {
            shapes,
            obstacles: Vec::new(),
            pairs,
            checks,
            frames: vec![[0.0; 12]; chain.dof()],
            world: vec![[0.0; 12]; n],
            poses: vec![Pose3::IDENTITY; n],
        }
    }

    /// Shapes of the arm (0: nothing to collide).
    pub fn len(&self) -> usize {
        self.shapes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }

    /// The obstacles later checks test against (validated ones: see [`Obstacle::validate`]).
    pub fn set_obstacles(&mut self, obstacles: &[Obstacle]) {
        self.obstacles = obstacles.iter().map(|o| (o.pose(), parry_shape(&o.shape))).collect();
    }

    /// The first contact of the arm at joint values `q` (one per joint) with the floor, itself
    /// or the obstacles, in that order of tests; `None` when it is clear.
    pub fn check(&mut self, chain: &Chain, q: &[f64]) -> Option<Contact> {
        if self.shapes.is_empty() {
            return None;
        }
        chain.segment_frames(q, &mut self.frames);
        for (k, s) in self.shapes.iter().enumerate() {
            self.world[k] = match s.segment {
                -1 => s.local,
                i => crate::robot::mul_tf(&self.frames[i as usize], &s.local),
            };
            self.poses[k] = pose3(&self.world[k]);
        }
        let link = |chain: &Chain, k: usize| chain.collision_shapes()[self.shapes[k].index].link.clone();
        if self.checks.floor {
            for (k, s) in self.shapes.iter().enumerate() {
                if s.segment >= 0 && lowest_z(&s.shape, &self.world[k]) < 0.0 {
                    return Some(Contact::Floor { link: link(chain, k) });
                }
            }
        }
        if self.checks.self_collision {
            for &(a, b) in &self.pairs {
                let (sa, sb) = (&self.shapes[a], &self.shapes[b]);
                if overlap(&self.poses[a], sa.parry.as_ref(), &self.poses[b], sb.parry.as_ref()) {
                    return Some(Contact::SelfCollision { link_a: link(chain, a), link_b: link(chain, b) });
                }
            }
        }
        for (i, (pose, shape)) in self.obstacles.iter().enumerate() {
            for (k, s) in self.shapes.iter().enumerate() {
                if overlap(&self.poses[k], s.parry.as_ref(), pose, shape.as_ref()) {
                    return Some(Contact::Obstacle { link: link(chain, k), obstacle: i });
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn panda() -> Chain {
        Chain::from_urdf_file(
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/robots/panda.urdf")),
            None,
        )
        .unwrap()
    }

    const PANDA_HOME: [f64; 7] = [0.0, -0.785_398, 0.0, -2.356_194, 0.0, 1.570_796, 0.785_398];

    /// The closest distance between segments p0-p1 and q0-q1 (clamped parameters, by a fine
    /// search: an independent check of parry's capsule test).
    fn segment_distance(p: [[f64; 3]; 2], q: [[f64; 3]; 2]) -> f64 {
        let at = |s: [[f64; 3]; 2], t: f64| [0, 1, 2].map(|i| s[0][i] + t * (s[1][i] - s[0][i]));
        let mut best = f64::INFINITY;
        for i in 0..=200 {
            let a = at(p, i as f64 / 200.0);
            for j in 0..=200 {
                let b = at(q, j as f64 / 200.0);
                best =
                    best.min(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt());
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
        let near = Obstacle {
            shape: Shape::Sphere { radius_m: 0.05 },
            position_m: [tool.x, tool.y, tool.z - 0.02],
            rotation_xyzw: None,
        };
        let far = Obstacle { position_m: [2.0, 2.0, 0.5], ..near.clone() };
        let cube = Obstacle {
            shape: Shape::Cuboid { half_extents_m: [0.05, 0.3, 0.02] },
            position_m: [tool.x, tool.y, tool.z + 0.2],
            rotation_xyzw: Some([0.0, 0.0, 0.382_683_4, 0.923_879_5]),
        };
        c.set_obstacles(&[far.clone()]);
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
}
