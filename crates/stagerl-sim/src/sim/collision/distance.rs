//! Signed distances and closest points between the arm's collision shapes and what they are
//! checked against (the floor, the obstacles, the arm's other links), with the direction that
//! separates them: what the safety shield ([`crate::sim::shield`]) linearises.
//!
//! For a pair (arm shape `A`, other body `B`) placed at joint values `q`:
//! 1. `d = min_{a in A, b in B} |a - b|` when they are apart, minus the penetration depth when
//!    they overlap (the signed distance, metres);
//! 2. `p_A`, `p_B`: the closest points (world frame); `n = (p_A - p_B) / |p_A - p_B|` (for an
//!    overlap: the direction that separates them fastest), so that a motion of `A` by `dx`
//!    changes the distance by `n . dx` to first order: `d' = n . (v(p_A) - v(p_B))`;
//! 3. the floor (`z = 0`): `p_A` the shape's lowest point, `p_B` below it on the floor,
//!    `n = +z`, `d = p_A.z` (exact for every primitive and mesh hull);
//! 4. capsules and spheres against capsules and spheres (a segment and a radius each): the
//!    closest points of the two segments (Ericson, Real-Time Collision Detection, 5.1.9),
//!    `d = |c_A - c_B| - r_A - r_B`, in f64 and closed form;
//! 5. a capsule or a sphere against a box obstacle, apart: the segment in the box's frame,
//!    `min_s |p(s) - clip(p(s), -h, h)|^2`, a convex piecewise quadratic in `s` whose pieces
//!    end where `p(s)` crosses a face's plane: each piece's minimum in closed form, exact (f64;
//!    parry's GJK answer was measured up to 6 mm off for such pairs, with its own intersection
//!    test disagreeing); overlapping with its segment reaching into the box: the penetration
//!    depth of the segment by the separating axes of the box and the segment (the box's three
//!    face normals and `u x e_j`, `u` the segment's direction: the face normals of the
//!    Minkowski difference, so the smallest overlap along them is the exact depth), plus the
//!    radius, in f64 and without allocation; anything else with a box or a mesh part: parry3d's
//!    contact query (f32; a mesh part is its convex hull, the same hull the contact check
//!    tests, so nothing is bounded loosely);
//! 6. a lower bound for every pair from bounding spheres, `d >= |c_A - c_B| - R_A - R_B`
//!    (floor: `c_A.z - R_A`), to skip far pairs without an exact query; for a capsule or sphere
//!    and a box, the larger of that and the gap between the box and the segment along one of
//!    the box's axes less the radius, when there is such a gap (a thin, long box's bounding
//!    sphere is far larger than the box).
//!
//! The bound on how far a shape can move when the joints move by `dq` ([`ArmCollider::levers`]):
//! a point `x` carried by joint `i` moves at `|z_i x (x - o_i)| <= |x - o_i|` per rad/s (1 per
//! m/s for a prismatic joint), and `|x - o_i|` is at most the sum of the link lengths from joint
//! `i` to the shape's segment, the prismatic joints' travel on the way and the shape's bounding
//! sphere about its segment's origin: `|dx| <= sum_i lever_ki |dq_i|`, for any `q`.

use super::{ArmCollider, Geo, Prim};
use crate::robot::{Chain, JointKind, Shape};

/// A pair of bodies the checks test: indices into [`Chain::collision_shapes`] and the task's
/// obstacles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pair {
    /// A moving arm shape and the floor.
    Floor { shape: usize },
    /// Two arm shapes of links that no joint connects.
    SelfPair { a: usize, b: usize },
    /// An arm shape and an obstacle.
    Obstacle { shape: usize, obstacle: usize },
}

impl Pair {
    /// The arm shape of the pair (the first of a self pair).
    pub fn shape_a(&self) -> usize {
        match *self {
            Pair::Floor { shape } | Pair::Obstacle { shape, .. } => shape,
            Pair::SelfPair { a, .. } => a,
        }
    }

    /// The second arm shape of a self pair.
    pub fn shape_b(&self) -> Option<usize> {
        match *self {
            Pair::SelfPair { b, .. } => Some(b),
            _ => None,
        }
    }
}

/// The closest points of a pair (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Closest {
    /// Signed distance, metres (negative: the depth of an overlap).
    pub distance_m: f64,
    /// On the arm shape (the first of a self pair), world frame, metres.
    pub point_a_m: [f64; 3],
    /// On the other body, world frame, metres.
    pub point_b_m: [f64; 3],
    /// Unit direction from `point_b_m` to `point_a_m`: moving shape A along it separates them.
    pub normal: [f64; 3],
}

impl ArmCollider {
    /// Place the arm at joint values `q` for [`ArmCollider::closest`] and
    /// [`ArmCollider::lower_bound`]. No allocation.
    pub fn place_at(&mut self, chain: &Chain, q: &[f64]) {
        self.place(chain, q);
    }

    /// The segment frames of the last placement (joint `i`'s frame after its motion: its axis
    /// is the third column, its origin the translation).
    pub fn placed_frames(&self) -> &[[f64; 12]] {
        &self.frames
    }

    /// The segment frames of the last placement when it was a whole one at joint values `q`
    /// (bit for bit), else `None`: what [`Chain::tip_pose_from_frames`] needs for the tip's
    /// pose at `q` without another pass.
    pub fn frames_placed_at(&self, q: &[f64]) -> Option<&[[f64; 12]]> {
        (self.framed && self.same_q(q)).then_some(&self.frames[..])
    }

    /// The bounding sphere of arm shape `k` at the last placement: its centre (world frame)
    /// and radius, metres.
    pub fn bounding_sphere(&self, k: usize) -> ([f64; 3], f64) {
        (self.geo[k].centre, self.geo[k].bound)
    }

    /// The segment (actuated joint) arm shape `k` moves with; `None` for the root's.
    pub fn segment_of(&self, k: usize) -> Option<usize> {
        usize::try_from(self.shapes[k].segment).ok()
    }

    /// Every pair the checks test, in the order [`ArmCollider::check`] tests them, into `out`
    /// (cleared first): the moving shapes with the floor, the self pairs, each shape with each
    /// obstacle.
    pub fn checked_pairs(&self, out: &mut Vec<Pair>) {
        out.clear();
        if self.checks.floor {
            let moving = self.shapes.iter().enumerate().filter(|(_, s)| s.segment >= 0);
            out.extend(moving.map(|(k, _)| Pair::Floor { shape: k }));
        }
        if self.checks.self_collision {
            out.extend(self.pairs.iter().map(|&(a, b)| Pair::SelfPair { a, b }));
        }
        for obstacle in 0..self.obstacles.len() {
            out.extend((0..self.shapes.len()).map(|shape| Pair::Obstacle { shape, obstacle }));
        }
    }

    /// The most pairs [`ArmCollider::checked_pairs`] can give with `obstacles` obstacles.
    pub fn max_pairs(&self, obstacles: usize) -> usize {
        self.shapes.len() * (1 + obstacles) + self.pairs.len()
    }

    /// A lower bound on the pair's signed distance at the last placement, from bounding
    /// spheres and the boxes' axes (step 6).
    pub fn lower_bound(&self, pair: Pair) -> f64 {
        let apart = |g: &Geo, o: &Geo| {
            let d = super::sub(g.centre, o.centre);
            super::dot(d, d).sqrt() - g.bound - o.bound
        };
        match pair {
            Pair::Floor { shape } => self.geo[shape].centre[2] - self.geo[shape].bound,
            Pair::SelfPair { a, b } => apart(&self.geo[a], &self.geo[b]),
            Pair::Obstacle { shape, obstacle } => {
                let (g, o) = (&self.geo[shape], &self.obstacles[obstacle]);
                let spheres = apart(g, &o.geo);
                // A capsule or sphere apart from a box along one of its axes: that gap too
                // (overlapping, the signed distance is below -radius: the spheres' bound only).
                match &o.cuboid {
                    Some(b) if g.round => match b.gap(g) {
                        gap if gap > 0.0 => spheres.max(gap - g.radius),
                        _ => spheres,
                    },
                    _ => spheres,
                }
            }
        }
    }

    /// The pair's signed distance, closest points and separating direction at the last
    /// placement (steps 1-5); `None` when parry cannot tell (no pair of our primitives).
    pub fn closest(&self, pair: Pair) -> Option<Closest> {
        match pair {
            Pair::Floor { shape } => Some(self.floor_closest(shape)),
            Pair::SelfPair { a, b } => {
                let (ga, gb) = (&self.geo[a], &self.geo[b]);
                if ga.round && gb.round {
                    return Some(round_closest(ga, gb));
                }
                let pb = super::pose3(&self.world[b]);
                self.parry_closest(a, &pb, self.shapes[b].parry.shape())
            }
            Pair::Obstacle { shape, obstacle } => {
                let o = &self.obstacles[obstacle];
                let g = &self.geo[shape];
                match (g.round, o.geo.round, &o.cuboid) {
                    (true, true, _) => Some(round_closest(g, &o.geo)),
                    (true, false, Some(b)) => round_box_closest(g, b)
                        .or_else(|| self.parry_closest(shape, &o.pose, Prim::shape(&o.prim))),
                    _ => self.parry_closest(shape, &o.pose, Prim::shape(&o.prim)),
                }
            }
        }
    }

    /// The pair's signed distance at the last placement: `closest(pair).map(|c| c.distance_m)`,
    /// the same value to the bit, without the points and the direction where that is cheaper
    /// (the floor, capsules and spheres against each other and against boxes).
    pub fn distance(&self, pair: Pair) -> Option<f64> {
        match pair {
            Pair::Floor { shape } if self.geo[shape].round => {
                let g = &self.geo[shape];
                // The lowest end of the segment as `floor_closest` picks it, less the radius.
                let low = match g.a[2] - g.b[2] {
                    x if x.abs() <= 1e-12 || x < 0.0 => g.a[2],
                    _ => g.b[2],
                };
                Some(low - g.radius)
            }
            Pair::SelfPair { a, b } if self.geo[a].round && self.geo[b].round => {
                let (ga, gb) = (&self.geo[a], &self.geo[b]);
                Some(super::segment_segment_distance2(ga.a, ga.b, gb.a, gb.b).sqrt() - ga.radius - gb.radius)
            }
            Pair::Obstacle { shape, obstacle } => {
                let (o, g) = (&self.obstacles[obstacle], &self.geo[shape]);
                match (g.round, o.geo.round, &o.cuboid) {
                    (true, true, _) => {
                        let d2 = super::segment_segment_distance2(g.a, g.b, o.geo.a, o.geo.b);
                        Some(d2.sqrt() - g.radius - o.geo.radius)
                    }
                    (true, false, Some(b)) => match round_box_distance(g, b) {
                        Some(d) => Some(d),
                        None => self.closest(pair).map(|c| c.distance_m),
                    },
                    _ => self.closest(pair).map(|c| c.distance_m),
                }
            }
            _ => self.closest(pair).map(|c| c.distance_m),
        }
    }

    /// Each arm shape's nearest obstacle at the last placement, by the signed distance of
    /// [`ArmCollider::closest`] (steps 1-5): `out[k]` for shape `k` of
    /// [`Chain::collision_shapes`] is `Some((obstacle, closest))` for the obstacle nearest to it
    /// (ties: the lower index) when one is nearer than `cutoff_m`, else `None`. A pair whose
    /// bound (step 6) is `cutoff_m` or more, or than the nearest found so far, is not queried.
    /// Returns the smallest distance found (`f64::INFINITY` when none is below `cutoff_m`): the
    /// arm's clearance from the obstacles. `out` holds one entry per shape; no allocation for
    /// capsules and spheres (mesh parts and box-shaped links go to parry, step 5).
    pub fn nearest_obstacles(&self, cutoff_m: f64, out: &mut [Option<(usize, Closest)>]) -> f64 {
        let mut smallest = f64::INFINITY;
        for (shape, slot) in out.iter_mut().enumerate().take(self.shapes.len()) {
            *slot = None;
            let mut best = cutoff_m;
            for obstacle in 0..self.obstacles.len() {
                let pair = Pair::Obstacle { shape, obstacle };
                if self.lower_bound(pair) >= best {
                    continue;
                }
                if let Some(c) = self.closest(pair).filter(|c| c.distance_m < best) {
                    best = c.distance_m;
                    *slot = Some((obstacle, c));
                }
            }
            if slot.is_some() {
                smallest = smallest.min(best);
            }
        }
        smallest
    }

    /// Step 5: arm shape `k` against a posed parry shape.
    fn parry_closest(
        &self,
        k: usize,
        pose_b: &parry3d::math::Pose3,
        shape_b: &dyn parry3d::shape::Shape,
    ) -> Option<Closest> {
        let pa = super::pose3(&self.world[k]);
        let c = parry3d::query::contact(&pa, self.shapes[k].parry.shape(), pose_b, shape_b, f32::MAX)
            .ok()
            .flatten()?;
        let v = |p: parry3d::math::Vec3| [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
        let n = v(c.normal1);
        Some(Closest {
            distance_m: f64::from(c.dist),
            point_a_m: v(c.point1),
            point_b_m: v(c.point2),
            normal: [-n[0], -n[1], -n[2]],
        })
    }

    /// Step 3: placed shape `k`'s lowest point over the floor.
    fn floor_closest(&self, k: usize) -> Closest {
        let (g, m) = (&self.geo[k], &self.world[k]);
        let p = match &self.shapes[k].shape {
            Shape::Capsule { radius_m, .. } | Shape::Sphere { radius_m } => {
                let low = match g.a[2] - g.b[2] {
                    x if x.abs() <= 1e-12 => [0.5 * (g.a[0] + g.b[0]), 0.5 * (g.a[1] + g.b[1]), g.a[2]],
                    x if x < 0.0 => g.a,
                    _ => g.b,
                };
                [low[0], low[1], low[2] - radius_m]
            }
            Shape::Cuboid { half_extents_m: h } => {
                let mut p = [m[3], m[7], m[11]];
                for j in 0..3 {
                    // Towards the floor along each axis (a level face: its centre).
                    let s = -m[8 + j].signum() * f64::from(u8::from(m[8 + j].abs() > 1e-12));
                    for (r, v) in p.iter_mut().enumerate() {
                        *v += s * h[j] * m[4 * r + j];
                    }
                }
                p
            }
            Shape::Convex(part) => {
                let world = |l: &[f64; 3]| {
                    [0, 1, 2]
                        .map(|r| m[4 * r] * l[0] + m[4 * r + 1] * l[1] + m[4 * r + 2] * l[2] + m[4 * r + 3])
                };
                let lowest = part.points_m.iter().map(world).min_by(|a, b| a[2].total_cmp(&b[2]));
                lowest.unwrap_or([m[3], m[7], m[11]])
            }
        };
        Closest { distance_m: p[2], point_a_m: p, point_b_m: [p[0], p[1], 0.0], normal: [0.0, 0.0, 1.0] }
    }

    /// The levers of the motion bound (see the module docs): `out[k * dof + i]` bounds how far
    /// a point of arm shape `k` moves per unit of joint `i`'s motion (m/rad; 1 for a prismatic
    /// joint; 0 for a joint that does not carry it; infinite behind a prismatic joint without
    /// limits). Allocates; once per shield.
    pub fn levers(&mut self, chain: &Chain) -> Vec<f64> {
        let n = chain.dof();
        // At q = 0 prismatic joints add no offset: each link length is its constant `after`.
        self.place(chain, &vec![0.0; n]);
        let origin = |f: &[f64; 12]| [f[3], f[7], f[11]];
        let joints = chain.joints();
        let prismatic = |j: usize| joints[j].kind == JointKind::Prismatic;
        let travel = |j: usize| joints[j].lower.abs().max(joints[j].upper.abs());
        let mut out = vec![0.0; self.shapes.len() * n];
        for (k, s) in self.shapes.iter().enumerate() {
            let Ok(seg) = usize::try_from(s.segment) else { continue };
            let d = super::sub(self.geo[k].centre, origin(&self.frames[seg]));
            let own = super::dot(d, d).sqrt() + self.geo[k].bound;
            for i in 0..=seg {
                out[k * n + i] = if prismatic(i) {
                    1.0
                } else {
                    let links: f64 = (i..seg)
                        .map(|j| {
                            let l = super::sub(origin(&self.frames[j + 1]), origin(&self.frames[j]));
                            super::dot(l, l).sqrt() + if prismatic(j + 1) { travel(j + 1) } else { 0.0 }
                        })
                        .sum();
                    links + own
                };
            }
        }
        out
    }
}

/// Step 4: two capsules or spheres (segments `a`-`b` with radii).
fn round_closest(ga: &Geo, gb: &Geo) -> Closest {
    let (ca, cb) = segment_closest_points(ga.a, ga.b, gb.a, gb.b);
    let d = super::sub(ca, cb);
    let len = super::dot(d, d).sqrt();
    // Coincident axes: any direction separates; +z, deterministically.
    let normal = if len > 1e-12 { d.map(|v| v / len) } else { [0.0, 0.0, 1.0] };
    Closest {
        distance_m: len - ga.radius - gb.radius,
        point_a_m: [0, 1, 2].map(|r| ca[r] - ga.radius * normal[r]),
        point_b_m: [0, 1, 2].map(|r| cb[r] + gb.radius * normal[r]),
        normal,
    }
}

/// A box obstacle as the closed forms of step 5 use it: the rotation `r` (rows; world from
/// box), the centre `t` and the half extents `h`, in f64, from the f32 pose and half extents
/// parry holds (the box every test of the checker sees), computed once per scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct BoxFrame {
    r: [[f64; 3]; 3],
    t: [f64; 3],
    h: [f64; 3],
}

impl BoxFrame {
    pub(crate) fn of(pose: &parry3d::math::Pose3, c: &parry3d::shape::Cuboid) -> BoxFrame {
        let (qr, t) = (pose.rotation, pose.translation);
        let (x, y, z, w) = (f64::from(qr.x), f64::from(qr.y), f64::from(qr.z), f64::from(qr.w));
        let n2 = x * x + y * y + z * z + w * w;
        let (x, y, z, w) = (x / n2.sqrt(), y / n2.sqrt(), z / n2.sqrt(), w / n2.sqrt());
        BoxFrame {
            r: [
                [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
                [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
                [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
            ],
            t: [f64::from(t.x), f64::from(t.y), f64::from(t.z)],
            h: [f64::from(c.half_extents.x), f64::from(c.half_extents.y), f64::from(c.half_extents.z)],
        }
    }

    /// A lower bound on the distance of the segment of `g` from the box, metres: the largest
    /// gap between the box and the segment's extent along one of the box's axes (0 when they
    /// overlap along all three), a hair less (1e-12 m) for rounding.
    #[inline]
    fn gap(&self, g: &Geo) -> f64 {
        let (a, b) = (self.local(g.a), self.local(g.b));
        let mut gap = 0.0f64;
        for j in 0..3 {
            gap = gap.max(a[j].min(b[j]) - self.h[j]).max(-self.h[j] - a[j].max(b[j]));
        }
        if gap > 0.0 {
            gap - 1e-12
        } else {
            0.0
        }
    }

    /// A world point in the box's frame.
    #[inline(always)]
    fn local(&self, p: [f64; 3]) -> [f64; 3] {
        let (r, d) = (&self.r, super::sub(p, self.t));
        [0, 1, 2].map(|j| r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2])
    }

    /// A point of the box's frame in the world.
    fn world(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.r;
        [0, 1, 2].map(|i| self.t[i] + r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2])
    }

    /// A direction of the box's frame in the world.
    fn turn(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.r;
        [0, 1, 2].map(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }
}

/// Whether a capsule or sphere (segment and radius `g`) overlaps the box `b`: the segment's
/// squared distance to the box (step 5's closed form, exact in f64) below the radius squared;
/// the contact test of [`ArmCollider::check`] for such pairs.
#[inline]
pub(super) fn round_box_overlap(g: &Geo, b: &BoxFrame) -> bool {
    let (a, e) = (b.local(g.a), b.local(g.b));
    // Apart along one of the box's axes by the radius or more: no contact, without the search.
    for j in 0..3 {
        if a[j].min(e[j]) - b.h[j] >= g.radius || -b.h[j] - a[j].max(e[j]) >= g.radius {
            return false;
        }
    }
    let (_, _, d2) = segment_box(a, e, b.h);
    d2 < g.radius * g.radius
}

/// The distance of [`round_box_closest`] alone (the same value to the bit).
#[inline]
fn round_box_distance(g: &Geo, b: &BoxFrame) -> Option<f64> {
    let (a, e) = (b.local(g.a), b.local(g.b));
    let (_, _, d2) = segment_box(a, e, b.h);
    if d2 <= 1e-24 {
        let (depth, _, _) = segment_in_box(a, e, b.h)?;
        return Some(-(depth + g.radius));
    }
    Some(d2.sqrt() - g.radius)
}

/// Step 5: a capsule or sphere (segment and radius `g`) against the box `b`: apart or
/// overlapping, in closed form (`None` only for a degenerate box).
fn round_box_closest(g: &Geo, b: &BoxFrame) -> Option<Closest> {
    let (a, e) = (b.local(g.a), b.local(g.b));
    let (p, on_box, d2) = segment_box(a, e, b.h);
    if d2 <= 1e-24 {
        let (depth, n, deepest) = segment_in_box(a, e, b.h)?;
        let normal = b.turn(n);
        let pa = b.world(deepest);
        let pa = [0, 1, 2].map(|i| pa[i] - g.radius * normal[i]);
        let d = -(depth + g.radius);
        return Some(Closest {
            distance_m: d,
            point_a_m: pa,
            point_b_m: [0, 1, 2].map(|i| pa[i] - d * normal[i]),
            normal,
        });
    }
    let len = d2.sqrt();
    let normal = b.turn([0, 1, 2].map(|j| (p[j] - on_box[j]) / len));
    let pw = b.world(p);
    Some(Closest {
        distance_m: len - g.radius,
        point_a_m: [0, 1, 2].map(|i| pw[i] - g.radius * normal[i]),
        point_b_m: b.world(on_box),
        normal,
    })
}

/// The penetration of the segment `a`-`b` into the box `[-h, h]` (its frame), which it reaches
/// into (step 5): the depth (m, >= 0), the unit direction that moves the segment out along it
/// and the segment's deepest point along that direction; the smallest overlap over the
/// separating axes (the box's face normals, then `u x e_j`; ties: the first). `None` for a
/// box without volume.
pub(crate) fn segment_in_box(a: [f64; 3], b: [f64; 3], h: [f64; 3]) -> Option<(f64, [f64; 3], [f64; 3])> {
    let u = super::sub(b, a);
    let mut axes = [[0.0f64; 3]; 6];
    for j in 0..3 {
        axes[j][j] = 1.0;
        let e = axes[j];
        let c = [u[1] * e[2] - u[2] * e[1], u[2] * e[0] - u[0] * e[2], u[0] * e[1] - u[1] * e[0]];
        let len = super::dot(c, c).sqrt();
        // Parallel to a box axis: that face normal covers it (an empty axis is skipped).
        axes[3 + j] =
            if len > 1e-9 * (1.0 + super::dot(u, u).sqrt()) { c.map(|v| v / len) } else { [0.0; 3] };
    }
    let mut best: Option<(f64, [f64; 3], [f64; 3])> = None;
    for l in axes.iter().filter(|l| super::dot(**l, **l) > 0.5) {
        let rho = h[0] * l[0].abs() + h[1] * l[1].abs() + h[2] * l[2].abs();
        let (pa, pb) = (super::dot(a, *l), super::dot(b, *l));
        // Out along +l: the segment's lowest point must rise past rho; along -l: its highest
        // must fall past -rho.
        let up = (rho - pa.min(pb), *l, if pa <= pb { a } else { b });
        let down = (pa.max(pb) + rho, l.map(|v| -v), if pa >= pb { a } else { b });
        for cand in [up, down] {
            if best.is_none_or(|(d, _, _)| cand.0 < d) {
                best = Some(cand);
            }
        }
    }
    best.filter(|(d, _, _)| d.is_finite() && h.iter().all(|&x| x > 0.0)).map(|(d, n, p)| (d.max(0.0), n, p))
}

/// The closest points of the segment `a`-`b` and the box `[-h, h]` (its frame): the point on
/// the segment, the point on the box and their squared distance (step 5).
pub(crate) fn segment_box(a: [f64; 3], b: [f64; 3], h: [f64; 3]) -> ([f64; 3], [f64; 3], f64) {
    let u = super::sub(b, a);
    let mut cuts = [0.0f64; 8];
    let mut n = 0;
    cuts[n] = 0.0;
    n += 1;
    for j in 0..3 {
        if u[j] != 0.0 {
            for plane in [-h[j], h[j]] {
                let s = (plane - a[j]) / u[j];
                if s > 0.0 && s < 1.0 {
                    cuts[n] = s;
                    n += 1;
                }
            }
        }
    }
    cuts[n] = 1.0;
    n += 1;
    cuts[..n].sort_unstable_by(f64::total_cmp);
    let at = |s: f64| [0, 1, 2].map(|j| a[j] + s * u[j]);
    let clip = |p: [f64; 3]| [0, 1, 2].map(|j| p[j].clamp(-h[j], h[j]));
    let (mut best, mut best_s) = (f64::INFINITY, 0.0);
    for k in 0..n - 1 {
        let (s0, s1) = (cuts[k], cuts[k + 1]);
        let mid = at(0.5 * (s0 + s1));
        // On this piece the clamped axes are fixed: sum of (a_j - c_j + s u_j)^2 over them.
        let (mut qa, mut qb) = (0.0, 0.0);
        for j in 0..3 {
            let c = if mid[j] > h[j] {
                h[j]
            } else if mid[j] < -h[j] {
                -h[j]
            } else {
                continue;
            };
            qa += u[j] * u[j];
            qb += 2.0 * u[j] * (a[j] - c);
        }
        let s = if qa > 0.0 { (-qb / (2.0 * qa)).clamp(s0, s1) } else { s0 };
        let p = at(s);
        let d = super::sub(p, clip(p));
        let d2 = super::dot(d, d);
        if d2 < best {
            (best, best_s) = (d2, s);
        }
    }
    let p = at(best_s);
    (p, clip(p), best)
}

/// The closest points of segments `p1`-`q1` and `p2`-`q2` (Ericson, Real-Time Collision
/// Detection, 5.1.9: the closest points' parameters, clamped); [`super::segment_segment_distance2`]
/// is their squared distance.
#[inline(always)]
pub(crate) fn segment_closest_points(
    p1: [f64; 3],
    q1: [f64; 3],
    p2: [f64; 3],
    q2: [f64; 3],
) -> ([f64; 3], [f64; 3]) {
    use super::{dot, sub};
    let (d1, d2, r) = (sub(q1, p1), sub(q2, p2), sub(p1, p2));
    let (a, e, f) = (dot(d1, d1), dot(d2, d2), dot(d2, r));
    const EPS: f64 = 1e-18;
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = dot(d1, r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            let mut s = if denom > EPS { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    ([0, 1, 2].map(|i| p1[i] + d1[i] * s), [0, 1, 2].map(|i| p2[i] + d2[i] * t))
}

#[cfg(test)]
mod tests;
