//! Offscreen frames of a reaching environment for `render_mode="rgb_array"`: the arm (its
//! collision shapes, or its link segments when it has none to draw), the target, the end
//! effector's path so far and the episode's obstacles over a floor grid, seen by a fixed
//! perspective camera, as `height x width x 3` bytes (RGB).
//!
//! A small software rasterizer ([`crate::raster`]): each solid is drawn over its screen
//! rectangle by casting each pixel's ray at it, with a depth buffer; the floor and sky are drawn
//! once (the camera does not move) and copied under every frame; the path is a depth-tested
//! polyline. No GPU. Every buffer is made with the renderer (when the environment is made with
//! `render_mode="rgb_array"`) and reused, the list of solids sized for the most obstacles an
//! episode can have: a frame allocates nothing; the caller copies it into a new numpy array.
//! Rendering only reads the environment: its results are the same with or without it.

use stagerl::env::ReachEnv;
use stagerl::robot::{mul_tf, Shape};
use stagerl::sim::scene::{Obstacle, ObstacleShape};

use crate::raster::{add, dot, normalize, scale, Camera, Prim, V3};

/// The default frame size, pixels (width, height).
pub(crate) const DEFAULT_SIZE: (usize, usize) = (480, 360);
/// The smallest and largest width or height, pixels.
pub(crate) const SIDE_RANGE: (usize, usize) = (16, 4096);

/// The radius of the links drawn as segments (an arm without collision shapes), metres.
const LINK_RADIUS_M: f32 = 0.03;
/// The smallest radius the target is drawn with (its radius is the success distance `beta_m`,
/// 1 cm by default: a few pixels).
const MIN_TARGET_RADIUS_M: f32 = 0.025;
/// The floor grid's cell, metres.
const GRID_M: f32 = 0.1;

const ARM: V3 = [0.74, 0.77, 0.82];
const ARM_IN_CONTACT: V3 = [0.92, 0.36, 0.30];
const TARGET: V3 = [0.88, 0.16, 0.14];
const TARGET_REACHED: V3 = [0.20, 0.78, 0.28];
const OBSTACLE: V3 = [0.96, 0.62, 0.18];
const PATH: [u8; 3] = [30, 80, 230];

fn v3(p: [f64; 3]) -> V3 {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

/// The point `t * p` of a row-major 3 x 4 transform.
fn apply(t: &[f64; 12], p: [f64; 3]) -> V3 {
    v3(std::array::from_fn(|r| t[4 * r] * p[0] + t[4 * r + 1] * p[1] + t[4 * r + 2] * p[2] + t[4 * r + 3]))
}

/// Column `j` of a transform's rotation: its local axis `j` in the world.
fn axis(t: &[f64; 12], j: usize) -> V3 {
    v3([t[j], t[4 + j], t[8 + j]])
}

/// The end effector's positions since the episode began, metres; at most `capacity` points (the
/// episode's steps and its start), then the last point follows the end effector.
pub(crate) struct EePath {
    points: Vec<V3>,
}

impl EePath {
    pub fn new(capacity: usize) -> EePath {
        EePath { points: Vec::with_capacity(capacity.max(2)) }
    }

    /// A new episode: the path is the end effector's position.
    pub fn restart(&mut self, env: &ReachEnv) {
        self.points.clear();
        self.push(env);
    }

    /// The end effector moved: add its position.
    pub fn push(&mut self, env: &ReachEnv) {
        let p = env.ee_pose().position;
        let p = [p.x as f32, p.y as f32, p.z as f32];
        if self.points.len() < self.points.capacity() {
            self.points.push(p);
        } else if let Some(last) = self.points.last_mut() {
            *last = p;
        }
    }
}

/// The camera, the static background and the reused buffers of one frame size.
pub(crate) struct Renderer {
    cam: Camera,
    light: V3,
    background: Vec<u8>,
    background_depth: Vec<f32>,
    rgb: Vec<u8>,
    depth: Vec<f32>,
    solids: Vec<(Prim, V3)>,
    frames: Vec<[f64; 12]>,
    /// Draw the link segments (the arm has no collision shape drawn as a primitive).
    skeleton: bool,
}

impl Renderer {
    /// A renderer of `width x height` frames (checked by the caller against [`SIDE_RANGE`]) of
    /// environments with `env`'s arm: the camera sees the arm's reach from the front right, above.
    pub fn new(env: &ReachEnv, width: usize, height: usize) -> Renderer {
        let chain = env.chain();
        let reach = chain.reach_m() as f32;
        let base = chain.first_joint_origin();
        let at = [base.x as f32, base.y as f32, (base.z as f32).max(0.0) + 0.2 * reach];
        let eye = add(at, scale(normalize([1.25, -1.0, 0.8]), 2.2 * reach));
        let cam = Camera::look_at(eye, at, 40f32.to_radians(), width, height);
        let light = normalize([0.35, -0.55, 1.0]);
        let shapes = chain.collision_shapes();
        let drawn = shapes.iter().filter(|s| !matches!(s.shape, Shape::Convex(_))).count();
        let skeleton = drawn == 0 || drawn < shapes.len();
        let solids = Vec::with_capacity(shapes.len() + chain.dof() + 3 + env.task().max_obstacles());
        let mut r = Renderer {
            cam,
            light,
            background: vec![0; width * height * 3],
            background_depth: vec![f32::INFINITY; width * height],
            rgb: vec![0; width * height * 3],
            depth: vec![f32::INFINITY; width * height],
            solids,
            frames: vec![[0.0; 12]; chain.dof()],
            skeleton,
        };
        r.draw_background(reach);
        r
    }

    /// The frame's (width, height), pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.cam.width, self.cam.height)
    }

    /// Sky and floor (z = 0, a 10 cm grid over `2.5 x reach` around the base), drawn once.
    fn draw_background(&mut self, reach: f32) {
        let cam = self.cam;
        let extent = 2.5 * reach;
        for y in 0..cam.height {
            for x in 0..cam.width {
                let d = cam.ray(x, y);
                let i = y * cam.width + x;
                let sky = [0.80 + 0.12 * d[2].max(0.0), 0.86 + 0.08 * d[2].max(0.0), 0.95];
                let (mut c, mut t) = (sky, f32::INFINITY);
                if d[2] < -1e-6 && cam.eye[2] > 0.0 {
                    let tf = -cam.eye[2] / d[2];
                    let p = add(cam.eye, scale(d, tf));
                    if p[0].abs().max(p[1].abs()) < extent {
                        (c, t) = (floor_colour(p, tf / cam.focal_px), tf);
                        let fade = (p[0].hypot(p[1]) / extent).powi(2);
                        c = std::array::from_fn(|k| c[k] * (1.0 - fade) + sky[k] * fade);
                    }
                }
                self.background[3 * i..3 * i + 3].copy_from_slice(&to_bytes(c));
                self.background_depth[i] = t;
            }
        }
    }

    /// The frame of `env`'s current state with `path` (the end effector's positions): RGB bytes,
    /// row by row from the top, `height x width x 3`.
    pub fn render(&mut self, env: &ReachEnv, path: &EePath) -> &[u8] {
        self.rgb.copy_from_slice(&self.background);
        self.depth.copy_from_slice(&self.background_depth);
        self.collect_solids(env);
        for k in 0..self.solids.len() {
            let (prim, colour) = self.solids[k];
            self.draw_solid(&prim, colour);
        }
        self.draw_path(&path.points);
        &self.rgb
    }

    /// The solids of the frame: the arm, the target, the obstacles.
    fn collect_solids(&mut self, env: &ReachEnv) {
        self.solids.clear();
        let chain = env.chain();
        let q = env.joint_positions();
        chain.segment_frames(q, &mut self.frames);
        let arm = if env.contact().is_some() { ARM_IN_CONTACT } else { ARM };
        for s in chain.collision_shapes() {
            let t = match s.segment {
                Some(i) => mul_tf(&self.frames[i], &s.pose),
                None => s.pose,
            };
            let prim = match &s.shape {
                Shape::Capsule { radius_m, half_length_m: h } => Prim::Capsule {
                    a: apply(&t, [0.0, 0.0, -h]),
                    b: apply(&t, [0.0, 0.0, *h]),
                    r: *radius_m as f32,
                },
                Shape::Sphere { radius_m } => Prim::Sphere { c: apply(&t, [0.0; 3]), r: *radius_m as f32 },
                Shape::Cuboid { half_extents_m } => Prim::Cuboid {
                    c: apply(&t, [0.0; 3]),
                    rot: [axis(&t, 0), axis(&t, 1), axis(&t, 2)],
                    half: v3(*half_extents_m),
                },
                Shape::Convex(_) => continue,
            };
            self.solids.push((prim, arm));
        }
        if self.skeleton {
            self.push_skeleton(env, arm);
        }
        let reached = env.distance() < env.reward_config().beta_m;
        let r = (env.reward_config().beta_m as f32).max(MIN_TARGET_RADIUS_M);
        let t = env.target();
        let colour = if reached { TARGET_REACHED } else { TARGET };
        self.solids.push((Prim::Sphere { c: [t.x as f32, t.y as f32, t.z as f32], r }, colour));
        for o in env.obstacles() {
            self.solids.push((obstacle_prim(o), OBSTACLE));
        }
    }

    /// The links as segments: from the floor under the first joint, joint to joint, to the tip.
    fn push_skeleton(&mut self, env: &ReachEnv, colour: V3) {
        let base = env.chain().first_joint_origin();
        let mut prev = [base.x as f32, base.y as f32, 0.0];
        let tip = env.ee_pose().position;
        let points = self.frames.iter().map(|f| v3([f[3], f[7], f[11]]));
        for p in points.chain(std::iter::once([tip.x as f32, tip.y as f32, tip.z as f32])) {
            self.solids.push((Prim::Capsule { a: prev, b: p, r: LINK_RADIUS_M }, colour));
            prev = p;
        }
    }

    /// Cast each pixel's ray of the solid's screen rectangle at it; keep the nearer hits.
    fn draw_solid(&mut self, prim: &Prim, colour: V3) {
        let cam = self.cam;
        let (lo, hi) = prim.bounds();
        let Some([x0, y0, x1, y1]) = cam.screen_rect(lo, hi) else { return };
        for y in y0..y1 {
            for x in x0..x1 {
                let d = cam.ray(x, y);
                let Some((t, n)) = prim.hit(cam.eye, d) else { continue };
                let i = y * cam.width + x;
                if t < self.depth[i] {
                    self.depth[i] = t;
                    let lambert = dot(n, self.light).max(0.0);
                    let facing = (-dot(n, d)).max(0.0);
                    let s = 0.28 + 0.52 * lambert + 0.25 * facing;
                    self.rgb[3 * i..3 * i + 3].copy_from_slice(&to_bytes(scale(colour, s)));
                }
            }
        }
    }

    /// The path as a polyline two pixels wide, drawn where it is not behind a solid (1 cm slack,
    /// so that it shows on the surfaces it runs along).
    fn draw_path(&mut self, points: &[V3]) {
        let cam = self.cam;
        for seg in points.windows(2) {
            let (Some(a), Some(b)) = (cam.project(seg[0]), cam.project(seg[1])) else { continue };
            let n = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().min(4.0 * cam.width as f32) as usize;
            for k in 0..=n {
                let f = if n == 0 { 0.0 } else { k as f32 / n as f32 };
                let (x, y, t) = (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f, a.2 + (b.2 - a.2) * f);
                for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let (px, py) = ((x - 0.5 + dx).floor(), (y - 0.5 + dy).floor());
                    if px < 0.0 || py < 0.0 || px >= cam.width as f32 || py >= cam.height as f32 {
                        continue;
                    }
                    let i = py as usize * cam.width + px as usize;
                    if t - 0.01 < self.depth[i] {
                        self.rgb[3 * i..3 * i + 3].copy_from_slice(&PATH);
                    }
                }
            }
        }
    }
}

/// The floor's colour at `p` (z = 0), where a pixel is `pixel_m` metres wide: light grey, a
/// 10 cm grid, the base frame's x axis red and its y axis green.
fn floor_colour(p: V3, pixel_m: f32) -> V3 {
    let width = (1.2 * pixel_m).max(0.004);
    // Lines closer than a few pixels would alias: the grid fades out there.
    let near_line = |v: f32| {
        let f = (v / GRID_M).rem_euclid(1.0) * GRID_M;
        pixel_m < GRID_M / 5.0 && f.min(GRID_M - f) < 0.5 * width
    };
    if p[1].abs() < width && p[0] > 0.0 {
        [0.85, 0.25, 0.25]
    } else if p[0].abs() < width && p[1] > 0.0 {
        [0.25, 0.7, 0.3]
    } else if near_line(p[0]) || near_line(p[1]) {
        [0.62, 0.64, 0.67]
    } else {
        [0.86, 0.86, 0.84]
    }
}

/// A validated obstacle as a solid.
fn obstacle_prim(o: &Obstacle) -> Prim {
    let c = v3(o.position_m);
    match o.shape {
        ObstacleShape::Sphere => Prim::Sphere { c, r: o.radius_m.unwrap_or(0.0) as f32 },
        ObstacleShape::Cuboid => {
            let [x, y, z, w] = o.rotation_xyzw.unwrap_or([0.0, 0.0, 0.0, 1.0]);
            let n = (x * x + y * y + z * z + w * w).sqrt().max(1e-12);
            let (x, y, z, w) = (x / n, y / n, z / n, w / n);
            // The rotation matrix's columns: the box's axes in the base frame.
            let rot = [
                v3([1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + z * w), 2.0 * (x * z - y * w)]),
                v3([2.0 * (x * y - z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + x * w)]),
                v3([2.0 * (x * z + y * w), 2.0 * (y * z - x * w), 1.0 - 2.0 * (x * x + y * y)]),
            ];
            Prim::Cuboid { c, rot, half: v3(o.half_extents_m.unwrap_or([0.0; 3])) }
        }
    }
}

fn to_bytes(c: V3) -> [u8; 3] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
}
