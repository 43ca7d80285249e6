//! The geometry of the software rasterizer behind `render_mode="rgb_array"` ([`crate::render`]):
//! a pinhole camera, and the primitives the scene is made of (spheres, capsules, oriented boxes),
//! each drawn over its screen rectangle by intersecting each pixel's ray with it, with a depth
//! buffer (the distance along the ray, metres). Single precision: a frame's geometry spans a few
//! metres, seen at a few hundred pixels.

/// A point or a direction, metres.
pub(crate) type V3 = [f32; 3];

pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub(crate) fn normalize(a: V3) -> V3 {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// A fixed pinhole camera: `eye`, its orthonormal axes (`fwd` into the picture, `right`, `up`),
/// the focal length in pixels and the image's size.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Camera {
    pub eye: V3,
    pub fwd: V3,
    pub right: V3,
    pub up: V3,
    pub focal_px: f32,
    pub width: usize,
    pub height: usize,
}

/// Points closer to the camera than this (metres, along `fwd`) are not projected.
const NEAR_M: f32 = 0.02;

impl Camera {
    /// A camera at `eye` looking at `at` (world z up), vertical field of view `fov_y_rad`.
    pub fn look_at(eye: V3, at: V3, fov_y_rad: f32, width: usize, height: usize) -> Camera {
        let fwd = normalize(sub(at, eye));
        let right = normalize(cross(fwd, [0.0, 0.0, 1.0]));
        let up = cross(right, fwd);
        let focal_px = 0.5 * height as f32 / (0.5 * fov_y_rad).tan();
        Camera { eye, fwd, right, up, focal_px, width, height }
    }

    /// The unit direction of the ray through the centre of pixel (x, y) (y down).
    #[inline]
    pub fn ray(&self, x: usize, y: usize) -> V3 {
        let u = (x as f32 + 0.5 - 0.5 * self.width as f32) / self.focal_px;
        let v = (0.5 * self.height as f32 - y as f32 - 0.5) / self.focal_px;
        normalize(add(self.fwd, add(scale(self.right, u), scale(self.up, v))))
    }

    /// Pixel coordinates (x right, y down, continuous) and distance from the eye (metres) of a
    /// point, or None when it lies behind the near plane.
    pub fn project(&self, p: V3) -> Option<(f32, f32, f32)> {
        let d = sub(p, self.eye);
        let z = dot(d, self.fwd);
        if z < NEAR_M {
            return None;
        }
        let x = 0.5 * self.width as f32 + self.focal_px * dot(d, self.right) / z;
        let y = 0.5 * self.height as f32 - self.focal_px * dot(d, self.up) / z;
        Some((x, y, dot(d, d).sqrt()))
    }

    /// The pixel rectangle `[x0, x1) x [y0, y1)` covering the box `lo..hi` (the whole image when a
    /// corner is behind the near plane), or None when it is off screen.
    pub fn screen_rect(&self, lo: V3, hi: V3) -> Option<[usize; 4]> {
        let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
        for k in 0..8 {
            let c = [
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
                if k & 4 == 0 { lo[2] } else { hi[2] },
            ];
            let Some((x, y, _)) = self.project(c) else {
                return Some([0, 0, self.width, self.height]);
            };
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        }
        let (w, h) = (self.width as f32, self.height as f32);
        if x1 < 0.0 || y1 < 0.0 || x0 >= w || y0 >= h {
            return None;
        }
        let clamp = |v: f32, m: f32| v.clamp(0.0, m) as usize;
        Some([
            clamp(x0.floor(), w),
            clamp(y0.floor(), h),
            clamp(x1.ceil() + 1.0, w),
            clamp(y1.ceil() + 1.0, h),
        ])
    }
}

/// A solid of the scene.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Prim {
    Sphere {
        c: V3,
        r: f32,
    },
    /// The points within `r` of the segment `a`-`b`.
    Capsule {
        a: V3,
        b: V3,
        r: f32,
    },
    /// A box: centre, rotation (its columns are the box's axes in the world), half sizes.
    Cuboid {
        c: V3,
        rot: [V3; 3],
        half: V3,
    },
}

impl Prim {
    /// Its axis-aligned bounding box (lo, hi).
    pub fn bounds(&self) -> (V3, V3) {
        match *self {
            Prim::Sphere { c, r } => (sub(c, [r; 3]), add(c, [r; 3])),
            Prim::Capsule { a, b, r } => {
                let lo = [a[0].min(b[0]) - r, a[1].min(b[1]) - r, a[2].min(b[2]) - r];
                (lo, [a[0].max(b[0]) + r, a[1].max(b[1]) + r, a[2].max(b[2]) + r])
            }
            Prim::Cuboid { c, rot, half } => {
                // The extent along world axis i: sum over the box axes of |axis_j[i]| half_j.
                let e: V3 = std::array::from_fn(|i| (0..3).map(|j| rot[j][i].abs() * half[j]).sum());
                (sub(c, e), add(c, e))
            }
        }
    }

    /// The nearest hit of the ray `o + t d` (`d` a unit vector) with `t > 0`: (t, unit normal).
    #[inline]
    pub fn hit(&self, o: V3, d: V3) -> Option<(f32, V3)> {
        match *self {
            Prim::Sphere { c, r } => {
                let t = sphere_t(o, d, c, r)?;
                Some((t, normalize(sub(add(o, scale(d, t)), c))))
            }
            Prim::Capsule { a, b, r } => {
                let t = capsule_t(o, d, a, b, r)?;
                let (p, ba) = (add(o, scale(d, t)), sub(b, a));
                let h = (dot(sub(p, a), ba) / dot(ba, ba).max(1e-12)).clamp(0.0, 1.0);
                Some((t, normalize(sub(p, add(a, scale(ba, h))))))
            }
            Prim::Cuboid { c, rot, half } => cuboid_hit(o, d, c, &rot, half),
        }
    }
}

fn sphere_t(o: V3, d: V3, c: V3, r: f32) -> Option<f32> {
    let oc = sub(o, c);
    let b = dot(oc, d);
    let h = b * b - (dot(oc, oc) - r * r);
    if h < 0.0 {
        return None;
    }
    let t = -b - h.sqrt();
    (t > 0.0).then_some(t)
}

/// Ray and capsule (Inigo Quilez's closed form): the side, else the nearer end cap.
fn capsule_t(o: V3, d: V3, a: V3, b: V3, r: f32) -> Option<f32> {
    let (ba, oa) = (sub(b, a), sub(o, a));
    let (baba, bard, baoa) = (dot(ba, ba), dot(ba, d), dot(ba, oa));
    let (rdoa, oaoa) = (dot(d, oa), dot(oa, oa));
    let qa = baba - bard * bard;
    if qa > 1e-9 * baba.max(1e-12) {
        let qb = baba * rdoa - baoa * bard;
        let qc = baba * oaoa - baoa * baoa - r * r * baba;
        let h = qb * qb - qa * qc;
        if h < 0.0 {
            return None;
        }
        let t = (-qb - h.sqrt()) / qa;
        let y = baoa + t * bard;
        if y > 0.0 && y < baba {
            return (t > 0.0).then_some(t);
        }
    }
    let t1 = sphere_t(o, d, a, r);
    let t2 = sphere_t(o, d, b, r);
    match (t1, t2) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, y) => x.or(y),
    }
}

/// Ray and oriented box (slabs in the box's frame).
fn cuboid_hit(o: V3, d: V3, c: V3, rot: &[V3; 3], half: V3) -> Option<(f32, V3)> {
    let oc = sub(o, c);
    let (mut t0, mut t1, mut axis) = (f32::MIN, f32::MAX, 0);
    for j in 0..3 {
        let (ol, dl) = (dot(oc, rot[j]), dot(d, rot[j]));
        let dl = if dl.abs() < 1e-20 { 1e-20 } else { dl };
        let (a, b) = ((-half[j] - ol) / dl, (half[j] - ol) / dl);
        let (near, far) = if a < b { (a, b) } else { (b, a) };
        if near > t0 {
            (t0, axis) = (near, j);
        }
        t1 = t1.min(far);
    }
    if t0 > t1 || t0 <= 0.0 {
        return None;
    }
    let s = if dot(d, rot[axis]) > 0.0 { -1.0 } else { 1.0 };
    Some((t0, scale(rot[axis], s)))
}
