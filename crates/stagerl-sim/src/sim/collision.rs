//! Collisions of the arm in the kinematic simulation: with the floor (the plane z = 0 of the base
//! frame), with itself (links that no joint connects) and with obstacles (boxes and spheres at
//! fixed poses). The arm's shapes are its URDF's `<collision>` primitives
//! ([`crate::robot::LinkShape`]). The floor test is exact (the lowest point of each shape); so
//! are the tests of a capsule or sphere against another, a sphere obstacle or a box obstacle
//! (closed forms in f64, [`distance`]: parry's GJK in f32 saw contacts up to 6.5 mm apart for
//! capsules and boxes); the others (boxes and mesh parts of the arm) are parry3d's (f32).
//!
//! Which links are adjacent: links move with the frame of the last actuated joint before them
//! (their *segment*; the root link and the links fixed to it form segment -1). Two shapes are
//! tested against each other when their segments differ by 2 or more: shapes of one segment are
//! rigidly joined, and consecutive segments meet at a joint, where the shapes of real arms
//! touch. The root's shapes are not tested against the floor (the arm stands on it).

use std::sync::Arc;

use parry3d::math::{Pose3, Rot3, Vec3};
use parry3d::query::details::intersection_test_support_map_support_map_with_params;
use parry3d::query::gjk::VoronoiSimplex;
use parry3d::query::intersection_test;
use parry3d::shape::{Ball, Capsule, Cuboid, Shape as ParryShape, SupportMap};
use std::sync::atomic::AtomicU32;

use climb::{Climber, Warm};
use serde::{Deserialize, Serialize};

mod climb;
pub mod distance;

use super::scene::Obstacle;
use crate::robot::{Chain, ConvexPart, Shape};

/// What the arm touched first in a check; `shape`s are indices into
/// [`Chain::collision_shapes`] (see [`Contact::describe`] for the links' names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "with", rename_all = "snake_case")]
pub enum Contact {
    /// A shape reaches below z = 0.
    Floor { shape: usize },
    /// Shapes of two links that no joint connects overlap.
    SelfCollision { shape_a: usize, shape_b: usize },
    /// A shape overlaps obstacle `obstacle` (its index in the task's obstacles).
    Obstacle { shape: usize, obstacle: usize },
}

impl Contact {
    /// In words, with the links' names: "link `wrist_3_link` with the floor".
    pub fn describe(&self, chain: &Chain) -> String {
        let link = |k: usize| chain.collision_shapes().get(k).map_or("?", |s| s.link.as_str()).to_string();
        match *self {
            Contact::Floor { shape } => format!("link `{}` with the floor", link(shape)),
            Contact::SelfCollision { shape_a, shape_b } => {
                format!("link `{}` with link `{}`", link(shape_a), link(shape_b))
            }
            Contact::Obstacle { shape, obstacle } => {
                format!("link `{}` with obstacle {obstacle}", link(shape))
            }
        }
    }

    pub fn kind(&self) -> CollisionKind {
        match self {
            Contact::Floor { .. } => CollisionKind::Floor,
            Contact::SelfCollision { .. } => CollisionKind::SelfCollision,
            Contact::Obstacle { .. } => CollisionKind::Obstacle,
        }
    }
}

/// A parry primitive (a concrete type, so that the collider is `Clone`).
#[derive(Clone, Debug)]
enum Prim {
    Capsule(Capsule),
    Ball(Ball),
    Cuboid(Cuboid),
    /// A mesh part's hull, shared.
    Convex(Arc<ConvexPart>),
}

impl Prim {
    fn of(s: &Shape) -> Prim {
        match *s {
            Shape::Capsule { radius_m, half_length_m } => {
                Prim::Capsule(Capsule::new_z(half_length_m as f32, radius_m as f32))
            }
            Shape::Sphere { radius_m } => Prim::Ball(Ball::new(radius_m as f32)),
            Shape::Cuboid { half_extents_m: [x, y, z] } => {
                Prim::Cuboid(Cuboid::new(Vec3::new(x as f32, y as f32, z as f32)))
            }
            Shape::Convex(ref part) => Prim::Convex(part.clone()),
        }
    }

    fn shape(&self) -> &dyn ParryShape {
        match self {
            Prim::Capsule(c) => c,
            Prim::Ball(b) => b,
            Prim::Cuboid(c) => c,
            Prim::Convex(p) => p.hull(),
        }
    }

    fn support_map(&self) -> &dyn SupportMap {
        match self {
            Prim::Capsule(c) => c,
            Prim::Ball(b) => b,
            Prim::Cuboid(c) => c,
            Prim::Convex(p) => p.hull(),
        }
    }
}

/// Warm starts of [`climb`] (hull vertex indices; unused for primitives).
#[derive(Debug, Default)]
struct WarmStarts(Vec<AtomicU32>);

impl Clone for WarmStarts {
    fn clone(&self) -> Self {
        use std::sync::atomic::Ordering::Relaxed;
        WarmStarts(self.0.iter().map(|a| AtomicU32::new(a.load(Relaxed))).collect())
    }
}

/// One of the arm's shapes, ready for the tests.
#[derive(Clone, Debug)]
struct ArmShape {
    /// Into [`Chain::collision_shapes`].
    index: usize,
    /// -1 for the root's segment.
    segment: i64,
    local: [f64; 12],
    shape: Shape,
    parry: Prim,
    /// A mesh part's hull for the support by hill climbing.
    climber: Option<Arc<Climber>>,
    /// A mesh part's capsule ends and sphere centre in its segment's frame (`local` applied),
    /// for [`ArmCollider::check`]'s placement without the whole pose.
    segment_points: [[f64; 3]; 3],
}

/// The lowest z of a primitive at the row-major 3 x 4 pose `m`, metres.
fn lowest_z(s: &Shape, m: &[f64; 12]) -> f64 {
    let (zx, zy, zz, z0) = (m[8], m[9], m[10], m[11]);
    match *s {
        Shape::Capsule { radius_m, half_length_m } => z0 - half_length_m * zz.abs() - radius_m,
        Shape::Sphere { radius_m } => z0 - radius_m,
        Shape::Cuboid { half_extents_m: [x, y, z] } => z0 - x * zx.abs() - y * zy.abs() - z * zz.abs(),
        Shape::Convex(ref part) => convex_lowest_z(part, m),
    }
}

/// How far above the floor the lowest vertex the f32 search finds must be for the verdict to
/// skip the scan of every vertex, metres (the search's rounding is about 1e-7 m).
const FLOOR_ROOM_M: f64 = 1e-5;

/// [`lowest_z`] of a mesh part: its lowest hull vertex (out of line: the primitives' path stays
/// as small as it was).
#[inline(never)]
fn convex_lowest_z(part: &ConvexPart, m: &[f64; 12]) -> f64 {
    let (zx, zy, zz, z0) = (m[8], m[9], m[10], m[11]);
    z0 + part.points_m.iter().map(|p| zx * p[0] + zy * p[1] + zz * p[2]).fold(f64::INFINITY, f64::min)
}

/// Whether two posed shapes overlap (parry supports every pair of our primitives).
fn overlap(p1: &Pose3, s1: &dyn ParryShape, p2: &Pose3, s2: &dyn ParryShape) -> bool {
    intersection_test(p1, s1, p2, s2).is_ok_and(|i| i.intersecting)
}

/// The distance between two posed shapes (metres, f32 precision), negative by the penetration
/// depth when they overlap; `NaN` for a pair parry does not support (none of ours).
fn signed_distance(p1: &Pose3, s1: &dyn ParryShape, p2: &Pose3, s2: &dyn ParryShape) -> f64 {
    match parry3d::query::contact(p1, s1, p2, s2, 0.0) {
        Ok(Some(c)) if c.dist <= 0.0 => c.dist as f64,
        Ok(_) => parry3d::query::distance(p1, s1, p2, s2).map_or(f64::NAN, |d| d.distance as f64),
        Err(_) => f64::NAN,
    }
}

pub(crate) fn pose3(m: &[f64; 12]) -> Pose3 {
    let r = parry3d::math::Mat3::from_cols(
        Vec3::new(m[0] as f32, m[4] as f32, m[8] as f32),
        Vec3::new(m[1] as f32, m[5] as f32, m[9] as f32),
        Vec3::new(m[2] as f32, m[6] as f32, m[10] as f32),
    );
    Pose3::from_parts(Vec3::new(m[3] as f32, m[7] as f32, m[11] as f32), Rot3::from_mat3(&r).normalize())
}

/// `[task.collision]`: which contacts of the arm are looked for (all are recorded, none
/// changes the episode: the paper's task has no collision term). Unset: both.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Checks {
    /// The floor, the plane z = 0 of the base frame.
    pub floor: bool,
    /// Links that no joint connects.
    pub self_collision: bool,
}

impl Default for Checks {
    fn default() -> Self {
        Checks { floor: true, self_collision: true }
    }
}

/// What a step's arm touched (the details: [`Contact`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CollisionKind {
    Floor,
    SelfCollision,
    Obstacle,
}

/// An obstacle ready for the tests: parry's shape at its (f32) pose, its bounding sphere (and
/// sphere centre) and, for a box, the f64 frame of the closed forms ([`distance::BoxFrame`]).
#[derive(Clone, Debug)]
struct PlacedObstacle {
    pose: Pose3,
    prim: Prim,
    geo: Geo,
    cuboid: Option<distance::BoxFrame>,
}

/// The arm's collision checker, with the obstacles it is tested against (scratch included: a
/// check allocates nothing).
#[derive(Clone, Debug)]
pub struct ArmCollider {
    shapes: Vec<ArmShape>,
    obstacles: Vec<PlacedObstacle>,
    /// Pairs of indices into `shapes` tested for self-collision.
    pairs: Vec<(usize, usize)>,
    checks: Checks,
    frames: Vec<[f64; 12]>,
    world: Vec<[f64; 12]>,
    geo: Vec<Geo>,
    /// Each joint's reach, metres ([`motion`]).
    reach: Vec<f64>,
    /// Scratch joint values of [`ArmCollider::check_motion`].
    motion_q: Vec<f64>,
    /// The joint values of the last placement, when `framed` (a placement at the same values,
    /// bit for bit, is skipped: the shield places the arm where the last check left it).
    placed_q: Vec<f64>,
    /// The segment frames and every shape's [`Geo`] are those of `placed_q` (and `world` is,
    /// but for the capsules' and spheres' first two columns after a check:
    /// [`ArmCollider::place_for_check`]).
    framed: bool,
    /// `framed`, and every entry of `world` too.
    placed: bool,
    /// Where the support searches of mesh parts start ([`climb`]): each self pair's two sides
    /// (`2 p`, `2 p + 1`), then each shape's against the obstacles (`2 pairs + k`), then each
    /// shape's lowest vertex (`2 pairs + n + k`).
    warm: WarmStarts,
    /// The axis that separated the last exact test found apart (`f32` bits, four a slot: the
    /// unit axis in the first shape's frame, then that shape's support along it, which stays
    /// the same while the axis does): each self pair's (slot `p`), then each shape's against
    /// the obstacles (`pairs + k`); a zero axis: none ([`ArmCollider::exact_overlap`]).
    axes: WarmStarts,
    /// The exact tests the separating axes answered (for the tests).
    #[cfg(test)]
    axis_skips: WarmStarts,
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
                shape: s.shape.clone(),
                parry: Prim::of(&s.shape),
                climber: match &s.shape {
                    Shape::Convex(part) => Some(Arc::new(Climber::of(part.hull()))),
                    _ => None,
                },
                segment_points: match &s.shape {
                    Shape::Convex(part) => {
                        let (a, b, _) = part.capsule_m;
                        [a, b, part.centre_m].map(|p| apply(&s.pose, p))
                    }
                    _ => [[0.0; 3]; 3],
                },
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
        let reach = motion::joint_reach(chain, &shapes);
        ArmCollider {
            warm: WarmStarts((0..2 * pairs.len() + 2 * n).map(|_| AtomicU32::new(0)).collect()),
            axes: WarmStarts((0..4 * (pairs.len() + n)).map(|_| AtomicU32::new(0)).collect()),
            #[cfg(test)]
            axis_skips: WarmStarts(vec![AtomicU32::new(0)]),
            reach,
            motion_q: vec![0.0; chain.dof()],
            placed_q: vec![0.0; chain.dof()],
            framed: false,
            placed: false,
            shapes,
            obstacles: Vec::new(),
            pairs,
            checks,
            frames: vec![[0.0; 12]; chain.dof()],
            world: vec![[0.0; 12]; n],
            geo: vec![Geo::default(); n],
        }
    }

    /// The pairs of shapes (indices into [`Chain::collision_shapes`]) the self-collision check
    /// tests: those of links two or more actuated joints apart.
    pub fn self_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.pairs.iter().map(|&(a, b)| (self.shapes[a].index, self.shapes[b].index))
    }

    /// Shapes of the arm (0: nothing to collide).
    pub fn len(&self) -> usize {
        self.shapes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }

    /// The obstacles later checks test against (validated ones: see [`Obstacle::validate`]).
    /// Allocates only when there are more than ever before.
    pub fn set_obstacles(&mut self, obstacles: &[Obstacle]) {
        self.obstacles.clear();
        self.obstacles.extend(obstacles.iter().map(Self::prepare));
    }

    fn prepare(o: &Obstacle) -> PlacedObstacle {
        let (shape, m) = (o.primitive(), o.transform());
        let (pose, prim) = (pose3(&m), Prim::of(&shape));
        let cuboid = match &prim {
            Prim::Cuboid(c) => Some(distance::BoxFrame::of(&pose, c)),
            _ => None,
        };
        PlacedObstacle { pose, prim, geo: Geo::of(&shape, &m), cuboid }
    }

    /// Put the arm's shapes where joint values `q` take them.
    fn place(&mut self, chain: &Chain, q: &[f64]) {
        if self.placed && self.same_q(q) {
            return;
        }
        if self.framed && self.same_q(q) {
            // After a check: only the capsules' and spheres' poses are partial.
            for k in 0..self.shapes.len() {
                if self.partial(k) {
                    self.place_shape(k);
                }
            }
        } else {
            self.set_frames(chain, q);
            for k in 0..self.shapes.len() {
                self.place_shape(k);
            }
        }
        self.placed = self.framed;
    }

    /// Whether arm shape `k`'s `world` pose is partial: a moving capsule or sphere after
    /// [`ArmCollider::place_for_check`].
    #[inline(always)]
    fn partial(&self, k: usize) -> bool {
        let s = &self.shapes[k];
        self.framed
            && !self.placed
            && s.segment >= 0
            && matches!(s.shape, Shape::Capsule { .. } | Shape::Sphere { .. } | Shape::Convex(_))
    }

    /// Placed arm shape `k`'s pose for parry (a partial one completed: the same bits as
    /// [`ArmCollider::place_shape`]'s).
    fn parry_pose(&self, k: usize) -> Pose3 {
        if self.partial(k) {
            let s = &self.shapes[k];
            pose3(&crate::robot::mul_tf(&self.frames[s.segment as usize], &s.local))
        } else {
            pose3(&self.world[k])
        }
    }

    /// Whether `q` is, bit for bit, the joint values of the last placement.
    #[inline(always)]
    fn same_q(&self, q: &[f64]) -> bool {
        self.placed_q.len() == q.len() && self.placed_q.iter().zip(q).all(|(a, b)| a.to_bits() == b.to_bits())
    }

    /// The segment frames at `q` (the shapes not placed yet).
    #[inline(always)]
    fn set_frames(&mut self, chain: &Chain, q: &[f64]) {
        self.placed = false;
        self.framed = self.placed_q.len() == q.len();
        if self.framed {
            self.placed_q.copy_from_slice(q);
        }
        chain.segment_frames(q, &mut self.frames);
    }

    /// [`ArmCollider::place`] as [`ArmCollider::check`] needs it: a capsule's or a sphere's
    /// tests read only the third and fourth columns of its pose (its axis and centre), so only
    /// those are computed for them ([`crate::robot::mul_tf_z_and_origin`]: the same bits as the
    /// whole product); the next [`ArmCollider::place`] at the same `q` completes the poses.
    #[inline(always)]
    fn place_for_check(&mut self, chain: &Chain, q: &[f64]) {
        if self.framed && self.same_q(q) {
            return;
        }
        self.set_frames(chain, q);
        let partial = self.framed;
        for k in 0..self.shapes.len() {
            let s = &self.shapes[k];
            match (&s.shape, s.segment) {
                (Shape::Capsule { .. } | Shape::Sphere { .. }, i) if i >= 0 && partial => {
                    crate::robot::mul_tf_z_and_origin(&self.frames[i as usize], &s.local, &mut self.world[k]);
                    self.geo[k] = Geo::of(&s.shape, &self.world[k]);
                }
                // A mesh part: its capsule and sphere only (the pose when a test needs it).
                (Shape::Convex(part), i) if i >= 0 && partial => {
                    let f = &self.frames[i as usize];
                    let [a, b, centre] = s.segment_points.map(|p| apply(f, p));
                    let g = Geo {
                        round: false,
                        enclosed: true,
                        a,
                        b,
                        radius: part.capsule_m.2,
                        centre,
                        bound: part.radius_m,
                    };
                    self.geo[k] = g;
                }
                _ => self.place_shape(k),
            }
        }
    }

    /// Put arm shape `k` where the frames of the last placement take it.
    #[inline(always)]
    fn place_shape(&mut self, k: usize) {
        let s = &self.shapes[k];
        self.world[k] = match s.segment {
            -1 => s.local,
            i => crate::robot::mul_tf(&self.frames[i as usize], &s.local),
        };
        self.geo[k] = Geo::of(&s.shape, &self.world[k]);
    }

    /// Put only the arm shapes `k` with `needed[k]` where joint values `q` take them (the
    /// segment frames up to the last of theirs): the others keep the placement they had, which
    /// the next full placement replaces. For the samples of the shield's verification, which
    /// look at a few pairs only. No allocation.
    pub fn place_some_at(&mut self, chain: &Chain, q: &[f64], needed: &[bool]) {
        let segments = self.shapes.iter().zip(needed).filter(|(_, &n)| n).map(|(s, _)| s.segment);
        let Some(last) = segments.max() else { return };
        (self.placed, self.framed) = (false, false);
        let upto = usize::try_from(last + 1).unwrap_or(0).min(self.frames.len());
        chain.segment_frames(q, &mut self.frames[..upto]);
        for k in 0..self.shapes.len().min(needed.len()) {
            if needed[k] {
                self.place_shape(k);
            }
        }
    }

    /// The first placed arm shape (index into `shapes`) that overlaps an obstacle.
    fn hit_obstacle(&self, o: &PlacedObstacle) -> Option<usize> {
        (0..self.shapes.len()).find(|&k| self.overlap_obstacle(k, o))
    }

    /// Whether placed arm shape `k` overlaps obstacle `o`: bounding spheres first, then the
    /// exact test: in closed form (f64) for a capsule or sphere against a sphere (a segment's
    /// distance to a point) or a box ([`distance::round_box_overlap`]), parry's (f32) for a
    /// mesh part or a box-shaped link.
    #[inline(always)]
    fn overlap_obstacle(&self, k: usize, o: &PlacedObstacle) -> bool {
        let (g, geo) = (&self.geo[k], &o.geo);
        if !g.bounds_overlap(geo) {
            return false;
        }
        match (g.round, geo.round, &o.cuboid) {
            (true, true, _) => point_segment_distance2(geo.a, g.a, g.b) < (g.radius + geo.radius).powi(2),
            (true, false, Some(b)) => distance::round_box_overlap(g, b),
            // A mesh part whose capsule is clear of the obstacle is too.
            (false, true, _)
                if g.enclosed
                    && point_segment_distance2(geo.a, g.a, g.b) >= (g.radius + geo.radius).powi(2) =>
            {
                false
            }
            (false, false, Some(b)) if g.enclosed && !distance::round_box_overlap(g, b) => false,
            _ => {
                let slot = self.pairs.len() + k;
                let axis = &self.axes.0[4 * slot..4 * slot + 4];
                let warm = &self.warm.0[2 * self.pairs.len() + k];
                self.exact_overlap(k, warm, axis, Body { pose: &o.pose, prim: &o.prim, geo: &o.geo }, None)
            }
        }
    }

    /// Whether the arm at joint values `q` touches obstacle `o` (whatever the checks and the
    /// obstacles set): the test random obstacles are placed with. No allocation.
    pub fn touches(&mut self, chain: &Chain, q: &[f64], o: &Obstacle) -> bool {
        if self.shapes.is_empty() {
            return false;
        }
        self.place(chain, q);
        self.hit_obstacle(&Self::prepare(o)).is_some()
    }

    /// The first contact of the arm at joint values `q` (one per joint) with the floor, itself
    /// or the obstacles, in that order of tests; `None` when it is clear.
    pub fn check(&mut self, chain: &Chain, q: &[f64]) -> Option<Contact> {
        #[cfg(target_arch = "x86_64")]
        if crate::base::simd::avx2_enabled() {
            // SAFETY: the CPU has AVX2 (`avx2_enabled` checked it).
            return unsafe { self.check_avx2(chain, q) };
        }
        self.check_body(chain, q)
    }

    /// [`ArmCollider::check`] compiled for AVX2 (the same operations, so the same bits: no
    /// fused multiply-adds).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn check_avx2(&mut self, chain: &Chain, q: &[f64]) -> Option<Contact> {
        self.check_body(chain, q)
    }

    #[inline(always)]
    fn check_body(&mut self, chain: &Chain, q: &[f64]) -> Option<Contact> {
        if self.shapes.is_empty()
            || !(self.checks.floor || self.checks.self_collision || !self.obstacles.is_empty())
        {
            return None;
        }
        self.place_for_check(chain, q);
        if self.checks.floor {
            for (k, s) in self.shapes.iter().enumerate() {
                if s.segment >= 0 && self.below_floor(k) {
                    return Some(Contact::Floor { shape: s.index });
                }
            }
        }
        if self.checks.self_collision {
            for (p, &(a, b)) in self.pairs.iter().enumerate() {
                if self.overlap_arm(p, a, b) {
                    let (sa, sb) = (&self.shapes[a], &self.shapes[b]);
                    return Some(Contact::SelfCollision { shape_a: sa.index, shape_b: sb.index });
                }
            }
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            if let Some(k) = self.hit_obstacle(o) {
                return Some(Contact::Obstacle { shape: self.shapes[k].index, obstacle: i });
            }
        }
        None
    }

    /// Whether placed shape `k` reaches below z = 0: a mesh part only when its bounding sphere
    /// does (a scan of its hull's vertices otherwise), a primitive in closed form.
    #[inline(always)]
    fn below_floor(&self, k: usize) -> bool {
        match &self.shapes[k].shape {
            Shape::Convex(_) => {
                let g = &self.geo[k];
                // (The filters' rounding differs from the whole pose's by far less than the
                // room the sphere and the capsule leave.)
                g.centre[2] - g.bound < 0.0 && g.a[2].min(g.b[2]) - g.radius < 0.0 && {
                    let s = &self.shapes[k];
                    let placed;
                    let m = if self.partial(k) {
                        placed = crate::robot::mul_tf(&self.frames[s.segment as usize], &s.local);
                        &placed
                    } else {
                        &self.world[k]
                    };
                    match self.lowest_vertex_verdict(k, m) {
                        Some(below) => below,
                        None => lowest_z(&s.shape, m) < 0.0,
                    }
                }
            }
            s => lowest_z(s, &self.world[k]) < 0.0,
        }
    }

    /// The floor's verdict for mesh part `k` at pose `m` from its lowest vertex by hill climbing
    /// (f32, from where the last search ended), when that settles it: `z`, that vertex's height
    /// computed as [`convex_lowest_z`] computes each vertex's, below 0 (the lowest is no higher:
    /// `Some(true)`), or more than [`FLOOR_ROOM_M`] above (the f32 search's choice is within
    /// about 1e-7 m of the lowest: `Some(false)`); `None`: the scan decides.
    #[inline]
    fn lowest_vertex_verdict(&self, k: usize, m: &[f64; 12]) -> Option<bool> {
        let (Shape::Convex(part), Some(climber)) = (&self.shapes[k].shape, &self.shapes[k].climber) else {
            return None;
        };
        use std::sync::atomic::Ordering::Relaxed;
        let warm = &self.warm.0[2 * self.pairs.len() + self.shapes.len() + k];
        let i = climber.support(Vec3::new(-m[8] as f32, -m[9] as f32, -m[10] as f32), warm.load(Relaxed));
        warm.store(i, Relaxed);
        let p = part.points_m.get(i as usize)?;
        let z = m[11] + (m[8] * p[0] + m[9] * p[1] + m[10] * p[2]);
        if z < 0.0 {
            Some(true)
        } else if z - FLOOR_ROOM_M > 0.0 {
            Some(false)
        } else {
            None
        }
    }

    /// Every contact of the arm at joint values `q` (one per joint) into `out` (cleared first):
    /// each moving shape below the floor, each pair of shapes that overlap, each shape in an
    /// obstacle, as the checks say; and the clearance: the smallest signed distance (metres,
    /// negative: the depth of a penetration) over what was checked (a moving shape's lowest
    /// point above the floor, the self pairs, shape and obstacle), `None` if nothing was.
    /// For tools and tests (it allocates for the contacts found); a step uses [`ArmCollider::check`].
    pub fn contacts(&mut self, chain: &Chain, q: &[f64], out: &mut Vec<Contact>) -> Option<f64> {
        out.clear();
        if self.shapes.is_empty() {
            return None;
        }
        self.place(chain, q);
        let mut clearance: Option<f64> = None;
        let mut seen = |d: f64| clearance = Some(clearance.map_or(d, |c: f64| c.min(d)));
        if self.checks.floor {
            for (k, s) in self.shapes.iter().enumerate().filter(|(_, s)| s.segment >= 0) {
                let z = lowest_z(&s.shape, &self.world[k]);
                seen(z);
                if z < 0.0 {
                    out.push(Contact::Floor { shape: s.index });
                }
            }
        }
        if self.checks.self_collision {
            for (p, &(a, b)) in self.pairs.iter().enumerate() {
                let d = self.distance_arm(a, b);
                seen(d);
                if self.overlap_arm(p, a, b) {
                    out.push(Contact::SelfCollision {
                        shape_a: self.shapes[a].index,
                        shape_b: self.shapes[b].index,
                    });
                }
            }
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            for (k, s) in self.shapes.iter().enumerate() {
                // The distance of the shield and the plans' clearance, the verdict of `check`.
                let pair = distance::Pair::Obstacle { shape: k, obstacle: i };
                seen(self.closest(pair).map_or_else(
                    || signed_distance(&pose3(&self.world[k]), s.parry.shape(), &o.pose, o.prim.shape()),
                    |c| c.distance_m,
                ));
                if self.overlap_obstacle(k, o) {
                    out.push(Contact::Obstacle { shape: s.index, obstacle: i });
                }
            }
        }
        clearance
    }

    /// The signed distance between placed arm shapes `a` and `b` (metres; negative: depth).
    fn distance_arm(&self, a: usize, b: usize) -> f64 {
        let (ga, gb) = (&self.geo[a], &self.geo[b]);
        if ga.round && gb.round {
            return segment_segment_distance2(ga.a, ga.b, gb.a, gb.b).sqrt() - ga.radius - gb.radius;
        }
        signed_distance(
            &pose3(&self.world[a]),
            self.shapes[a].parry.shape(),
            &pose3(&self.world[b]),
            self.shapes[b].parry.shape(),
        )
    }

    /// Whether the arm shapes `a` and `b` of self pair `p` overlap: bounding spheres first, then the exact
    /// test (segments for capsules and spheres; a mesh part's capsule, then GJK; parry for the
    /// rest).
    // Inlined into `check` as it was when `check` was its only caller (a step's hot loop).
    #[inline(always)]
    fn overlap_arm(&self, p: usize, a: usize, b: usize) -> bool {
        self.geo[a].bounds_overlap(&self.geo[b]) && self.overlap_arm_near(p, a, b)
    }

    /// [`ArmCollider::overlap_arm`] after its bounding spheres' test.
    #[inline(always)]
    fn overlap_arm_near(&self, p: usize, a: usize, b: usize) -> bool {
        let (ga, gb) = (&self.geo[a], &self.geo[b]);
        if ga.round && gb.round {
            return segment_segment_distance2(ga.a, ga.b, gb.a, gb.b) < (ga.radius + gb.radius).powi(2);
        }
        if (ga.round || ga.enclosed)
            && (gb.round || gb.enclosed)
            && segment_segment_distance2(ga.a, ga.b, gb.a, gb.b) >= (ga.radius + gb.radius).powi(2)
        {
            // A mesh part's capsule clear of the other shape (or its capsule): so is the part.
            return false;
        }
        self.exact_overlap_arm(p, a, b)
    }

    /// [`ArmCollider::overlap_arm`]'s exact test of a pair with a box or a mesh part (out of
    /// line: the capsules' path stays as small as it was).
    #[inline(never)]
    fn exact_overlap_arm(&self, p: usize, a: usize, b: usize) -> bool {
        let (sb, pb) = (&self.shapes[b], self.parry_pose(b));
        // Each pair's walks start where that pair's last ended (GJK's directions are the pair's).
        let (wa, wb) = (&self.warm.0[2 * p], &self.warm.0[2 * p + 1]);
        let axis = &self.axes.0[4 * p..4 * p + 4];
        let other = Body { pose: &pb, prim: &sb.parry, geo: &self.geo[b] };
        self.exact_overlap(a, wa, axis, other, sb.climber.as_deref().map(|c| (c, wb)))
    }

    /// parry's exact test of placed arm shape `a` against shape `other` at `pose` (with its
    /// hull's climber and warm start when it is a mesh part): a mesh part against a mesh part,
    /// a capsule or a box by GJK with the parts' supports by hill climbing ([`climb`]), the
    /// rest by parry's dispatcher.
    ///
    /// Before GJK, two axes that may separate the pair: the one that separated it at its last
    /// test apart (steps move the arm little, so it often still does), then the direction
    /// from `a`'s capsule (or bounding sphere) to the other's, between their
    /// closest points. With `d` such a unit axis in `a`'s frame, the pair is apart when
    /// `max_{x in A} d.x + m < min_{y in B} d.y`: two support points (the same hulls and pose
    /// as GJK's); `m` = [`crate::robot::mesh::CAPSULE_MARGIN_M`], the room the hulls' capsules
    /// already leave GJK (f32) before they skip it. The axis that separated, or GJK's own, is
    /// kept for the next test; GJK's verdict is never changed (it starts as it would).
    #[inline]
    fn exact_overlap(
        &self,
        a: usize,
        warm_a: &AtomicU32,
        axis: &[AtomicU32],
        other: Body,
        climbing: Option<(&Climber, &AtomicU32)>,
    ) -> bool {
        let Body { pose, prim: other, geo: other_geo } = other;
        let sa = &self.shapes[a];
        let pa = self.parry_pose(a);
        let ball = matches!(sa.parry, Prim::Ball(_)) || matches!(other, Prim::Ball(_));
        if ball || (sa.climber.is_none() && climbing.is_none()) {
            return overlap(&pa, sa.parry.shape(), pose, other.shape());
        }
        let wa = sa.climber.as_deref().map(|c| Warm { climber: c, at: warm_a });
        let wb = climbing.map(|(c, at)| Warm { climber: c, at });
        let ga: &dyn SupportMap = match &wa {
            Some(w) => w,
            None => sa.parry.support_map(),
        };
        let gb: &dyn SupportMap = match &wb {
            Some(w) => w,
            None => other.support_map(),
        };
        let pos12 = pa.inv_mul(pose);
        use std::sync::atomic::Ordering::Relaxed;
        let d = Vec3::new(
            f32::from_bits(axis[0].load(Relaxed)),
            f32::from_bits(axis[1].load(Relaxed)),
            f32::from_bits(axis[2].load(Relaxed)),
        );
        const MARGIN_M: f32 = crate::robot::mesh::CAPSULE_MARGIN_M as f32;
        // `h_a`: A's support along `d` (A's frame, so it does not move with the pose).
        let separates = |d: Vec3, h_a: f32| h_a + MARGIN_M < d.dot(gb.support_point(&pos12, -d));
        let keep = |d: Vec3, h_a: f32| {
            axis[0].store(d.x.to_bits(), Relaxed);
            axis[1].store(d.y.to_bits(), Relaxed);
            axis[2].store(d.z.to_bits(), Relaxed);
            axis[3].store(h_a.to_bits(), Relaxed);
        };
        if d != Vec3::ZERO && separates(d, f32::from_bits(axis[3].load(Relaxed))) {
            #[cfg(test)]
            self.axis_skips.0[0].fetch_add(1, Relaxed);
            return false;
        }
        let (g1, g2) = (&self.geo[a], other_geo);
        let (c1, c2) = if (g1.round || g1.enclosed) && (g2.round || g2.enclosed) {
            distance::segment_closest_points(g1.a, g1.b, g2.a, g2.b)
        } else {
            (g1.centre, g2.centre)
        };
        let w = sub(c2, c1);
        let d =
            (pa.rotation.inverse() * Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32)).normalize_or_zero();
        if d != Vec3::ZERO && d.is_finite() {
            let h_a = d.dot(ga.local_support_point(d));
            if separates(d, h_a) {
                #[cfg(test)]
                self.axis_skips.0[0].fetch_add(1, Relaxed);
                keep(d, h_a);
                return false;
            }
        }
        let (hit, dir) = intersection_test_support_map_support_map_with_params(
            &pos12,
            ga,
            gb,
            &mut VoronoiSimplex::new(),
            None,
        );
        let d = if hit || !dir.is_finite() { Vec3::ZERO } else { dir.normalize_or_zero() };
        keep(d, if d == Vec3::ZERO { 0.0 } else { d.dot(ga.local_support_point(d)) });
        hit
    }
}

/// The other side of an exact test: its pose, shape and placed [`Geo`].
#[derive(Clone, Copy)]
struct Body<'a> {
    pose: &'a Pose3,
    prim: &'a Prim,
    geo: &'a Geo,
}

/// A shape placed in the world, as the fast tests need it: capsules and spheres (`round`) as a
/// segment `a`-`b` (a point for a sphere) and a radius; every shape's bounding sphere.
#[derive(Clone, Copy, Debug, Default)]
struct Geo {
    round: bool,
    /// A mesh part: `a`-`b` and `radius` are then the capsule around its hull
    /// ([`ConvexPart::capsule_m`]), for the broad phase only.
    enclosed: bool,
    a: [f64; 3],
    b: [f64; 3],
    radius: f64,
    centre: [f64; 3],
    bound: f64,
}

impl Geo {
    #[inline(always)]
    fn of(s: &Shape, m: &[f64; 12]) -> Geo {
        let c = [m[3], m[7], m[11]];
        match *s {
            Shape::Capsule { radius_m, half_length_m: h } => {
                let z = [m[2] * h, m[6] * h, m[10] * h];
                Geo {
                    round: true,
                    enclosed: false,
                    a: [c[0] - z[0], c[1] - z[1], c[2] - z[2]],
                    b: [c[0] + z[0], c[1] + z[1], c[2] + z[2]],
                    radius: radius_m,
                    centre: c,
                    bound: h + radius_m,
                }
            }
            Shape::Sphere { radius_m } => {
                Geo { round: true, enclosed: false, a: c, b: c, radius: radius_m, centre: c, bound: radius_m }
            }
            Shape::Cuboid { half_extents_m: [x, y, z] } => {
                Geo { round: false, centre: c, bound: (x * x + y * y + z * z).sqrt(), ..Geo::default() }
            }
            Shape::Convex(ref part) => Geo::of_convex(part, m),
        }
    }

    /// [`Geo::of`] a mesh part: its bounding sphere placed (out of line, as [`convex_lowest_z`]).
    #[inline(never)]
    fn of_convex(part: &ConvexPart, m: &[f64; 12]) -> Geo {
        let place = |l: [f64; 3]| apply(m, l);
        let (a, b, radius) = part.capsule_m;
        Geo {
            round: false,
            enclosed: true,
            a: place(a),
            b: place(b),
            radius,
            centre: place(part.centre_m),
            bound: part.radius_m,
        }
    }
    fn bounds_overlap(&self, o: &Geo) -> bool {
        let d = [self.centre[0] - o.centre[0], self.centre[1] - o.centre[1], self.centre[2] - o.centre[2]];
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= (self.bound + o.bound).powi(2)
    }
}

/// The row-major 3 x 4 transform `m` applied to point `p` (written out: `[0, 1, 2].map(..)` was
/// not inlined, a call per point).
#[inline(always)]
fn apply(m: &[f64; 12], p: [f64; 3]) -> [f64; 3] {
    [
        m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3],
        m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
        m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11],
    ]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Squared distance from point `p` to the segment `a`-`b`.
fn point_segment_distance2(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let (ab, ap) = (sub(b, a), sub(p, a));
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 { (dot(ap, ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
    dot(d, d)
}

/// Squared distance between segments `p1`-`q1` and `p2`-`q2` (Ericson, Real-Time Collision
/// Detection, 5.1.9: the closest points' parameters, clamped).
#[inline]
pub(crate) fn segment_segment_distance2(p1: [f64; 3], q1: [f64; 3], p2: [f64; 3], q2: [f64; 3]) -> f64 {
    let (c1, c2) = distance::segment_closest_points(p1, q1, p2, q2);
    let d = sub(c1, c2);
    dot(d, d)
}

pub mod motion;

#[cfg(test)]
pub(crate) mod tests;
