//! The arm's scene: obstacles (boxes and spheres at fixed poses, `[[task.obstacles]]`), how each
//! episode's random obstacles are drawn (`[task.random_obstacles]`), and their placement, clear
//! of the arm and the target, the first one possibly in the way from the start to the target
//! (`train.obstacles_in_path`). Collision checks against the scene are in [`super::collision`].

use serde::{Deserialize, Serialize};

use super::collision::ArmCollider;
use crate::base::rng::Rng;
use crate::robot::{Chain, Shape};
use crate::{Error, Result};

/// An obstacle's kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ObstacleShape {
    /// A box: `half_extents_m`.
    Cuboid,
    /// A ball: `radius_m`.
    Sphere,
}

/// An obstacle: a box or a sphere at a fixed pose in the base frame (`[[task.obstacles]]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    pub shape: ObstacleShape,
    /// A cuboid's half size along its axes, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_extents_m: Option<[f64; 3]>,
    /// A sphere's radius, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
    /// Centre, metres, base frame.
    pub position_m: [f64; 3],
    /// Orientation as a unit quaternion (x, y, z, w); unset: the base frame's axes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_xyzw: Option<[f64; 4]>,
}

impl Obstacle {
    /// A sphere of `radius_m` at `position_m`.
    pub fn sphere(radius_m: f64, position_m: [f64; 3]) -> Obstacle {
        Obstacle {
            shape: ObstacleShape::Sphere,
            half_extents_m: None,
            radius_m: Some(radius_m),
            position_m,
            rotation_xyzw: None,
        }
    }

    /// A box of half extents `half_extents_m` at `position_m`, turned by `rotation_xyzw`.
    pub fn cuboid(
        half_extents_m: [f64; 3],
        position_m: [f64; 3],
        rotation_xyzw: Option<[f64; 4]>,
    ) -> Obstacle {
        Obstacle {
            shape: ObstacleShape::Cuboid,
            half_extents_m: Some(half_extents_m),
            radius_m: None,
            position_m,
            rotation_xyzw,
        }
    }

    /// The obstacle grown by `margin_m` metres: a sphere's radius, a box's half extents (a
    /// superset of every point within the margin).
    pub fn grown(&self, margin_m: f64) -> Obstacle {
        let mut o = self.clone();
        o.radius_m = o.radius_m.map(|r| r + margin_m);
        o.half_extents_m = o.half_extents_m.map(|h| h.map(|v| v + margin_m));
        o
    }

    /// Its primitive (of a validated obstacle).
    pub fn primitive(&self) -> Shape {
        match self.shape {
            ObstacleShape::Sphere => Shape::Sphere { radius_m: self.radius_m.unwrap_or(0.0) },
            ObstacleShape::Cuboid => {
                Shape::Cuboid { half_extents_m: self.half_extents_m.unwrap_or([0.0; 3]) }
            }
        }
    }

    /// Check the values; `field` names the obstacle in errors (`task.obstacles[2]`).
    pub fn validate(&self, field: &str) -> Result<()> {
        let size_ok = |v: f64| v.is_finite() && v > 0.0 && v <= 100.0;
        let unset = |what: &str, v: String, has: &str| {
            Err(Error::config(
                format!("{field}.{what}"),
                v,
                format!("unset: a {:?} has {has}", self.shape).to_lowercase(),
            ))
        };
        match self.shape {
            ObstacleShape::Sphere => {
                if let Some(h) = self.half_extents_m {
                    return unset("half_extents_m", format!("{h:?}"), "radius_m");
                }
                match self.radius_m {
                    Some(r) if size_ok(r) => {}
                    r => {
                        let v = r.map_or("(unset)".to_string(), |r| r.to_string());
                        return Err(Error::config(
                            format!("{field}.radius_m"),
                            v,
                            "a number in (0, 100] metres",
                        ));
                    }
                }
            }
            ObstacleShape::Cuboid => {
                if let Some(r) = self.radius_m {
                    return unset("radius_m", r.to_string(), "half_extents_m");
                }
                match self.half_extents_m {
                    Some(h) if h.iter().all(|&v| size_ok(v)) => {}
                    h => {
                        let v = h.map_or("(unset)".to_string(), |h| format!("{h:?}"));
                        return Err(Error::config(
                            format!("{field}.half_extents_m"),
                            v,
                            "three numbers in (0, 100] metres",
                        ));
                    }
                }
            }
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

    /// Half its size along each of its axes, metres (a sphere's radius three times).
    pub fn half_size_m(&self) -> [f64; 3] {
        match self.primitive() {
            Shape::Sphere { radius_m } => [radius_m; 3],
            Shape::Cuboid { half_extents_m } => half_extents_m,
            Shape::Capsule { radius_m, half_length_m } => [radius_m, radius_m, half_length_m + radius_m],
            // Obstacles are spheres and boxes; a mesh part's bounding sphere otherwise.
            Shape::Convex(part) => [part.radius_m; 3],
        }
    }

    /// Distance from point `p` (metres, base frame) to the obstacle's surface, metres; negative
    /// inside (a box's: the depth to its nearest face).
    pub fn distance_to_point_m(&self, p: [f64; 3]) -> f64 {
        let m = self.transform();
        let d = [p[0] - m[3], p[1] - m[7], p[2] - m[11]];
        // Into the obstacle's frame: the transposed rotation.
        let local = [0, 1, 2].map(|c| m[c] * d[0] + m[4 + c] * d[1] + m[8 + c] * d[2]);
        match self.primitive() {
            Shape::Sphere { radius_m } => local.iter().map(|x| x * x).sum::<f64>().sqrt() - radius_m,
            _ => {
                let h = self.half_size_m();
                let q = [0, 1, 2].map(|k| local[k].abs() - h[k]);
                let outside = q.iter().map(|x| x.max(0.0).powi(2)).sum::<f64>().sqrt();
                outside + q[0].max(q[1]).max(q[2]).min(0.0)
            }
        }
    }

    /// Its pose as a row-major 3 x 4 transform (metres).
    pub(crate) fn transform(&self) -> [f64; 12] {
        let p = self.position_m;
        let [x, y, z, w] = self.rotation_xyzw.unwrap_or([0.0, 0.0, 0.0, 1.0]);
        let n = (x * x + y * y + z * z + w * w).sqrt();
        let (x, y, z, w) = (x / n, y / n, z / n, w / n);
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
            p[0],
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
            p[1],
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
            p[2],
        ]
    }
}

/// Most `[[task.obstacles]]`.
pub const MAX_OBSTACLES: usize = 256;

/// Most random obstacles per episode.
pub const MAX_RANDOM_OBSTACLES: u32 = 32;

/// `[task.random_obstacles]`: how many obstacles each episode gets, their shapes, sizes and
/// region. A candidate is drawn again (up to [`PLACEMENT_TRIES`] times, then the obstacle is left
/// out of that episode) while it touches the arm at the episode's start pose or comes closer to
/// the target than `target_clearance_m`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RandomObstacles {
    /// Obstacles per episode, an integer drawn uniformly from `[count[0], count[1]]`.
    pub count: [u32; 2],
    /// The shapes drawn from, uniformly (`"sphere"`, `"cuboid"`).
    pub shapes: Vec<ObstacleShape>,
    /// A sphere's radius, or each half extent of an (axis-aligned) box, uniform in this range,
    /// metres.
    pub size_m: [f64; 2],
    /// Centres are uniform in the box from `region_min_m` to `region_max_m` (base frame, metres).
    pub region_min_m: [f64; 3],
    pub region_max_m: [f64; 3],
    /// Least distance from the target to an obstacle's surface, metres.
    pub target_clearance_m: f64,
}

/// Candidates drawn for one random obstacle before it is left out of the episode.
pub const PLACEMENT_TRIES: u32 = 100;

/// The index of the side stream of the obstacles placed in the way ([`Rng::derived`]).
const IN_PATH_STREAM: u64 = 0x0B57_AC1E;

impl Default for RandomObstacles {
    fn default() -> Self {
        RandomObstacles {
            count: [1, 3],
            shapes: vec![ObstacleShape::Sphere, ObstacleShape::Cuboid],
            size_m: [0.04, 0.1],
            region_min_m: [-0.6, -0.6, 0.0],
            region_max_m: [0.6, 0.6, 0.7],
            target_clearance_m: 0.05,
        }
    }
}

impl RandomObstacles {
    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<()> {
        let f = "task.random_obstacles";
        let [lo, hi] = self.count;
        if lo > hi || hi > MAX_RANDOM_OBSTACLES {
            return Err(Error::config(
                format!("{f}.count"),
                format!("{:?}", self.count),
                format!("[min, max] with min <= max <= {MAX_RANDOM_OBSTACLES}"),
            ));
        }
        if self.shapes.is_empty() {
            return Err(Error::config(format!("{f}.shapes"), "[]", "one or more of \"sphere\", \"cuboid\""));
        }
        let [a, b] = self.size_m;
        if !(a.is_finite() && b.is_finite() && a > 0.0 && a <= b && b <= 10.0) {
            return Err(Error::config(
                format!("{f}.size_m"),
                format!("{:?}", self.size_m),
                "[min, max] metres with 0 < min <= max <= 10",
            ));
        }
        let (lo, hi) = (self.region_min_m, self.region_max_m);
        let ok = (0..3).all(|k| {
            lo[k].is_finite()
                && hi[k].is_finite()
                && lo[k] <= hi[k]
                && hi[k].abs() <= 100.0
                && lo[k].abs() <= 100.0
        });
        if !ok {
            return Err(Error::config(
                format!("{f}.region_min_m/region_max_m"),
                format!("{lo:?} / {hi:?}"),
                "finite corners within +-100 metres, each min <= its max",
            ));
        }
        if !(self.target_clearance_m.is_finite() && self.target_clearance_m >= 0.0) {
            return Err(Error::config(
                format!("{f}.target_clearance_m"),
                self.target_clearance_m,
                "a finite number of metres >= 0",
            ));
        }
        Ok(())
    }

    /// One candidate obstacle from `rng`: its shape and size, then its centre uniform in the
    /// region.
    fn draw(&self, rng: &mut Rng) -> Obstacle {
        let mut o = self.draw_body(rng);
        let (lo, hi) = (self.region_min_m, self.region_max_m);
        o.position_m = [0, 1, 2].map(|k| rng.uniform_range(lo[k], hi[k]));
        o
    }

    /// One candidate obstacle in the way from `from` to `to` (metres, base frame): its shape and
    /// size as [`RandomObstacles::draw`], its centre on the segment at a uniform fraction in
    /// [1/4, 3/4] of its length, then moved along each axis by up to its radius (largest half
    /// extent), so that it stands across the straight line or touches it; then clamped to the
    /// region, which bounds every random obstacle's centre (and the observation's entries).
    fn draw_in_path(&self, rng: &mut Rng, from: [f64; 3], to: [f64; 3]) -> Obstacle {
        let mut o = self.draw_body(rng);
        let reach = o.half_size_m().into_iter().fold(0.0, f64::max);
        let u = rng.uniform_range(0.25, 0.75);
        let (lo, hi) = (self.region_min_m, self.region_max_m);
        o.position_m = [0, 1, 2].map(|k| {
            (from[k] + u * (to[k] - from[k]) + rng.uniform_range(-reach, reach)).clamp(lo[k], hi[k])
        });
        o
    }

    /// A candidate's shape and size, at the origin.
    fn draw_body(&self, rng: &mut Rng) -> Obstacle {
        let shape = self.shapes[rng.below(self.shapes.len() as u64) as usize];
        let [a, b] = self.size_m;
        let mut size = || rng.uniform_range(a, b);
        let (radius, half) = match shape {
            ObstacleShape::Sphere => (Some(size()), None),
            ObstacleShape::Cuboid => (None, Some([size(), size(), size()])),
        };
        Obstacle { shape, half_extents_m: half, radius_m: radius, position_m: [0.0; 3], rotation_xyzw: None }
    }
}

/// Where an episode's obstacles are placed around: the arm and its start pose `q` (radians),
/// the target (metres, base frame) and the probability `in_path` that the first random obstacle
/// stands in the way.
pub struct Placement<'a> {
    pub chain: &'a Chain,
    pub q: &'a [f64],
    pub target: nalgebra::Vector3<f64>,
    pub in_path: f64,
}

/// Draw the episode's random obstacles after the fixed ones into `out` (cleared first, fixed
/// ones copied): each clear of the arm at `q` (the start pose) and of `target` by the
/// clearance; a placement that fails [`PLACEMENT_TRIES`] times is left out.
///
/// With `in_path > 0` (a probability; `train.obstacles_in_path`), the first random obstacle
/// is, with that probability, one drawn in the way from the start pose's end effector to the
/// target instead ([`RandomObstacles::draw_in_path`]; the region's if none fits in
/// [`PLACEMENT_TRIES`] tries). Those draws come from a side stream seeded by the next value
/// of `rng`, which they leave where it would be without them: the episode's other obstacles
/// and the following targets are those of `in_path = 0`. No allocation once `out` has the
/// capacity of `fixed.len()` plus the largest random count.
pub fn place_obstacles(
    fixed: &[Obstacle],
    random: Option<&RandomObstacles>,
    p: &Placement<'_>,
    collider: Option<&mut ArmCollider>,
    rng: &mut Rng,
    out: &mut Vec<Obstacle>,
) {
    out.clear();
    out.extend(fixed.iter().cloned());
    let Some(r) = random else { return };
    let (chain, q, target, in_path) = (p.chain, p.q, p.target, p.in_path);
    let n = r.count[0] + rng.below(u64::from(r.count[1] - r.count[0]) + 1) as u32;
    let mut side = (in_path > 0.0).then(|| Rng::derived(rng.clone().next_u64(), IN_PATH_STREAM));
    let mut collider = collider;
    let mut fits = |o: &Obstacle| {
        o.distance_to_point_m(target.into()) >= r.target_clearance_m
            && !collider.as_deref_mut().is_some_and(|c| c.touches(chain, q, o))
    };
    for i in 0..n {
        let anywhere = (0..PLACEMENT_TRIES).map(|_| r.draw(rng)).find(&mut fits);
        let mut in_the_way = None;
        if let Some(side) = side.as_mut().filter(|_| i == 0) {
            if side.uniform() < in_path {
                let from = chain.fk(q).position.into();
                in_the_way =
                    (0..PLACEMENT_TRIES).map(|_| r.draw_in_path(side, from, target.into())).find(&mut fits);
            }
        }
        out.extend(in_the_way.or(anywhere));
    }
}
