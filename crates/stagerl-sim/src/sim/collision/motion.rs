//! Continuous collision checks of a motion between two joint configurations: the motion of a
//! control step (and of a planner's edge) is linear in joint space, `q(t) = a + t (b - a)`,
//! `t` in [0, 1], and is checked at poses close enough that no point of the arm moves more than
//! [`MOTION_RESOLUTION_M`] between two of them.
//!
//! The bound: a point `p` of a link moves at speed `|sum_i dq_i (z_i x (p - o_i))| <= sum_i
//! |dq_i| |p - o_i|` along the motion (revolute joint `i` with axis `z_i` through `o_i`; a
//! prismatic joint moves it by `|dq_i|`). `|p - o_i|` is at most the reach `R_i` of joint `i`:
//! the largest distance from its origin of any collision shape that moves with it, through the
//! (constant) distances between consecutive joint origins, the shape's centre in its segment's
//! frame and its bounding radius, whatever the joint values. So every point moves at most
//! `D = sum_i |b_i - a_i| R_i` (metres) over the motion, and `ceil(D / resolution)` equal steps
//! in `t` keep each under the resolution. A point that crosses an obstacle along 1 cm or more of
//! its path (a 1 cm thick obstacle, crossed) therefore has a checked pose inside it; the arm's
//! shapes add their own thickness to that margin.
//!
//! Poses are checked in a coarse-to-fine order (the end pose first, then the midpoints of ever
//! finer halvings), so that a motion that collides is usually refused after a few checks. The
//! clearance along a motion (arm shapes against obstacles only) is sampled by conservative
//! advancement: from a pose at distance `d`, with `m` the least distance seen so far, the next
//! pose is `d - m + CLEARANCE_TOLERANCE_M` metres of arm motion further (no pose in between can
//! come closer than `m - CLEARANCE_TOLERANCE_M`): the minimum is found within that tolerance.

use super::{pose3, ArmCollider, Contact, Geo};
use crate::robot::{Chain, JointKind};

/// Largest motion of any point of the arm between two checked poses of a motion, metres.
pub const MOTION_RESOLUTION_M: f64 = 0.01;

/// How far below the reported minimum the true minimum clearance of a motion can be, metres.
pub const CLEARANCE_TOLERANCE_M: f64 = 0.002;

/// Most poses one motion is checked at (a motion longer than this many resolutions is checked
/// at this many evenly spaced poses; no arm within its limits moves that far in one motion).
pub const MAX_MOTION_POSES: usize = 1 << 20;

/// Each joint's reach (see the module's doc): the largest distance from joint `i`'s origin of a
/// point of a collision shape moved by joint `i`, metres; 1 for a prismatic joint (its motion
/// moves every point by `|dq_i|`).
pub(super) fn joint_reach(chain: &Chain, shapes: &[super::ArmShape]) -> Vec<f64> {
    let n = chain.dof();
    let mut frames = vec![[0.0; 12]; n];
    chain.segment_frames(&vec![0.0; n], &mut frames);
    let joints = chain.joints();
    let origin = |m: usize| [frames[m][3], frames[m][7], frames[m][11]];
    // Distance from joint m's origin to joint m+1's, whatever the joint values.
    let link: Vec<f64> = (0..n.saturating_sub(1))
        .map(|m| {
            let (a, b) = (origin(m), origin(m + 1));
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            let travel = match joints[m + 1].kind {
                JointKind::Prismatic => joints[m + 1].lower.abs().max(joints[m + 1].upper.abs()),
                JointKind::Revolute => 0.0,
            };
            d + travel
        })
        .collect();
    (0..n)
        .map(|i| {
            if joints[i].kind == JointKind::Prismatic {
                return 1.0;
            }
            shapes
                .iter()
                .filter(|s| s.segment >= i as i64)
                .map(|s| {
                    let j = s.segment as usize;
                    let g = Geo::of(&s.shape, &s.local);
                    let centre = (g.centre[0].powi(2) + g.centre[1].powi(2) + g.centre[2].powi(2)).sqrt();
                    link[i..j].iter().sum::<f64>() + centre + g.bound
                })
                .fold(0.0, f64::max)
        })
        .collect()
}

/// The closest points of the arm and the obstacles at one pose (see
/// [`ArmCollider::closest_obstacle`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Closest {
    /// Signed distance, metres (negative: a penetration's depth).
    pub distance_m: f64,
    /// The arm's point and the obstacle's, metres, base frame.
    pub arm_point_m: [f64; 3],
    pub obstacle_point_m: [f64; 3],
    /// Index into [`Chain::collision_shapes`], and the obstacle's index.
    pub shape: usize,
    pub obstacle: usize,
}

impl ArmCollider {
    /// The closest pair of the arm's shapes at joint values `q` and the obstacles, with its
    /// points (parry's contact query, f32); `None` without shapes or obstacles. For views and
    /// reports (not allocation-free).
    pub fn closest_obstacle(&mut self, chain: &Chain, q: &[f64]) -> Option<Closest> {
        if self.shapes.is_empty() || self.obstacles.is_empty() {
            return None;
        }
        self.place(chain, q);
        let mut best: Option<Closest> = None;
        for (i, o) in self.obstacles.iter().enumerate() {
            for (k, s) in self.shapes.iter().enumerate() {
                let p = pose3(&self.world[k]);
                let Ok(Some(c)) = parry3d::query::contact(&p, s.parry.shape(), &o.pose, o.prim.shape(), 1e3)
                else {
                    continue;
                };
                let d = f64::from(c.dist);
                if best.is_none_or(|b| d < b.distance_m) {
                    let v = |x: parry3d::math::Vec3| [f64::from(x.x), f64::from(x.y), f64::from(x.z)];
                    best = Some(Closest {
                        distance_m: d,
                        arm_point_m: v(c.point1),
                        obstacle_point_m: v(c.point2),
                        shape: s.index,
                        obstacle: i,
                    });
                }
            }
        }
        best
    }

    /// The bound on how far any point of the arm moves along the linear joint motion from `a`
    /// to `b` (metres; see the module's doc).
    pub fn motion_bound_m(&self, a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).zip(&self.reach).map(|((x, y), r)| (y - x).abs() * r).sum()
    }

    /// The first contact (as [`ArmCollider::check`] finds them: floor, self, obstacles) of the
    /// arm anywhere along the linear joint motion from `a` to `b`, checked at poses no more
    /// than [`MOTION_RESOLUTION_M`] of arm motion apart, `b` included and `a` not (it is where
    /// the previous motion ended; check it with [`ArmCollider::check`]). No allocation.
    pub fn check_motion(&mut self, chain: &Chain, a: &[f64], b: &[f64]) -> Option<Contact> {
        if self.shapes.is_empty() {
            return None;
        }
        let steps = self.motion_steps(a, b);
        let mut q = std::mem::take(&mut self.motion_q);
        let mut at = |c: &mut ArmCollider, k: usize| {
            let t = k as f64 / steps as f64;
            for ((x, &u), &v) in q.iter_mut().zip(a).zip(b) {
                *x = u + t * (v - u);
            }
            if k == steps {
                q.copy_from_slice(b);
            }
            c.check(chain, &q)
        };
        let mut hit = at(self, steps);
        let mut stride = steps.next_power_of_two();
        while hit.is_none() && stride > 1 {
            let half = stride / 2;
            let mut k = half;
            while hit.is_none() && k < steps {
                hit = at(self, k);
                k += stride;
            }
            stride = half;
        }
        self.motion_q = q;
        hit
    }

    /// Steps in `t` that keep every point's motion under the resolution (at least 1).
    fn motion_steps(&self, a: &[f64], b: &[f64]) -> usize {
        let d = self.motion_bound_m(a, b);
        if d.is_finite() {
            ((d / MOTION_RESOLUTION_M).ceil() as usize).clamp(1, MAX_MOTION_POSES)
        } else {
            MAX_MOTION_POSES
        }
    }

    /// The smallest signed distance (metres, negative: a penetration's depth) between the arm's
    /// shapes and the obstacles along the linear joint motion from `a` to `b`, both included,
    /// within [`CLEARANCE_TOLERANCE_M`] (the true minimum is at most that much smaller); `None`
    /// without obstacles or shapes. The floor and the arm's own pairs do not count.
    pub fn motion_clearance_m(&mut self, chain: &Chain, a: &[f64], b: &[f64]) -> Option<f64> {
        if self.shapes.is_empty() || self.obstacles.is_empty() {
            return None;
        }
        let total = self.motion_bound_m(a, b);
        let mut q = std::mem::take(&mut self.motion_q);
        let (mut t, mut best) = (0.0_f64, f64::INFINITY);
        let mut poses = 0;
        loop {
            for ((x, &u), &v) in q.iter_mut().zip(a).zip(b) {
                *x = u + t * (v - u);
            }
            self.place(chain, &q);
            let d = self.placed_obstacle_distance();
            best = best.min(d);
            poses += 1;
            if t >= 1.0 || total.is_nan() || total <= 0.0 || poses >= MAX_MOTION_POSES {
                break;
            }
            let step = (d - best).max(0.0) + CLEARANCE_TOLERANCE_M;
            t = (t + step / total).min(1.0);
        }
        self.motion_q = q;
        Some(best)
    }

    /// The clearance of the placed arm to the obstacles: the least signed distance over shape
    /// and obstacle pairs, pairs whose bounding spheres are farther apart than the least so far
    /// skipped.
    fn placed_obstacle_distance(&self) -> f64 {
        let mut best = f64::INFINITY;
        for (i, geo) in self.obstacles.iter().map(|o| &o.geo).enumerate() {
            for k in 0..self.shapes.len() {
                let g = &self.geo[k];
                let c =
                    [g.centre[0] - geo.centre[0], g.centre[1] - geo.centre[1], g.centre[2] - geo.centre[2]];
                let lower = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() - g.bound - geo.bound;
                if lower >= best {
                    continue;
                }
                let d = if g.round && geo.round {
                    super::point_segment_distance2(geo.a, g.a, g.b).sqrt() - g.radius - geo.radius
                } else {
                    // Closed form for a capsule or sphere against a box, parry for the rest.
                    self.closest(super::distance::Pair::Obstacle { shape: k, obstacle: i })
                        .map_or(f64::NAN, |c| c.distance_m)
                };
                if d < best {
                    best = d;
                }
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::rng::Rng;
    use crate::sim::collision::Checks;
    use crate::sim::scene::Obstacle;

    const HOME: [f64; 6] = {
        use std::f64::consts::FRAC_PI_2;
        [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0]
    };

    fn lerp(a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
        a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect()
    }

    #[test]
    fn a_thin_obstacle_between_the_ends_is_found() {
        let chain = Chain::ur5();
        let mut c = ArmCollider::new(&chain, Checks::default());
        let (a, mut b) = (HOME, HOME);
        b[0] += 0.8;
        // A 1 cm ball where the tool is halfway, far from both ends.
        let mid = chain.fk(&lerp(&a, &b, 0.5)).position;
        c.set_obstacles(&[Obstacle::sphere(0.005, [mid.x, mid.y, mid.z])]);
        assert_eq!(c.check(&chain, &a), None);
        assert_eq!(c.check(&chain, &b), None, "the end pose alone misses it");
        let hit = c.check_motion(&chain, &a, &b);
        assert!(matches!(hit, Some(Contact::Obstacle { obstacle: 0, .. })), "{hit:?}");
        assert!(c.motion_clearance_m(&chain, &a, &b).unwrap() < 0.0);
        // And a thin slab, 1 cm thick across the tool's way, likewise.
        let p = chain.fk(&lerp(&a, &b, 0.37)).position;
        let slab = Obstacle::cuboid(
            [0.08, 0.08, 0.005],
            [p.x, p.y, p.z],
            Some([std::f64::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f64::consts::FRAC_1_SQRT_2]),
        );
        c.set_obstacles(&[slab]);
        assert_eq!((c.check(&chain, &a), c.check(&chain, &b)), (None, None));
        assert!(c.check_motion(&chain, &a, &b).is_some());
    }

    #[test]
    fn the_bound_holds_and_free_motions_are_free() {
        let chain = Chain::ur5();
        let mut c = ArmCollider::new(&chain, Checks::default());
        let far = Obstacle::sphere(0.05, [0.3, -0.3, 0.2]);
        c.set_obstacles(std::slice::from_ref(&far));
        let mut rng = Rng::new(7);
        let (mut free, mut hit) = (0, 0);
        for _ in 0..300 {
            let a: Vec<f64> = HOME.iter().map(|h| h + rng.uniform_range(-0.6, 0.6)).collect();
            let b: Vec<f64> = a.iter().map(|x| x + rng.uniform_range(-0.4, 0.4)).collect();
            let bound = c.motion_bound_m(&a, &b);
            let tip = |t: f64| chain.joint_origins(&lerp(&a, &b, t)).unwrap();
            // Every joint origin and the tip move less than the bound (the chord of a path
            // is shorter than the path, itself within the bound).
            let mut travelled = vec![0.0; chain.dof() + 1];
            let mut prev = tip(0.0);
            for k in 1..=200 {
                let now = tip(k as f64 / 200.0);
                for (d, (p, q)) in travelled.iter_mut().zip(prev.iter().zip(&now)) {
                    *d += ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                }
                prev = now;
            }
            assert!(travelled.iter().all(|&d| d <= bound + 1e-9), "{travelled:?} > {bound}");
            // A dense check (0.1 % steps) agrees with the continuous one, whichever way.
            if c.check(&chain, &a).is_some() {
                continue;
            }
            let dense = (1..=1000).any(|k| c.check(&chain, &lerp(&a, &b, k as f64 / 1000.0)).is_some());
            assert_eq!(dense, c.check_motion(&chain, &a, &b).is_some(), "{a:?} -> {b:?}");
            if dense {
                hit += 1;
            } else {
                free += 1;
            }
            // The clearance is the least sampled one within the tolerance.
            let dense_min = (0..=400)
                .map(|k| {
                    let q = lerp(&a, &b, k as f64 / 400.0);
                    let mut out = Vec::new();
                    let mut only = ArmCollider::new(&chain, Checks { floor: false, self_collision: false });
                    only.set_obstacles(std::slice::from_ref(&far));
                    only.contacts(&chain, &q, &mut out).unwrap()
                })
                .fold(f64::INFINITY, f64::min);
            let m = c.motion_clearance_m(&chain, &a, &b).unwrap();
            assert!(
                m <= dense_min + 1e-4 && m >= dense_min - CLEARANCE_TOLERANCE_M - 1e-3,
                "{m} vs {dense_min}"
            );
        }
        assert!(free > 50, "free {free}, hit {hit}");
    }
}
