//! Collision meshes: the files a URDF's `<mesh filename>` names, found ([`MeshSource`]), read
//! (STL, binary and ASCII; Wavefront OBJ) and made into convex parts ([`ConvexPart`]).
//!
//! A file is one or more parts: an STL file is one, an OBJ file one per object or group
//! (`o`/`g`) that has faces (how V-HACD writes a convex decomposition), or one of all its
//! vertices if it has no faces. Each part becomes the convex hull of its vertices, scaled by the
//! URDF's `scale`: exact for a part that is convex, a conservative stand-in for one that is not.
//!
//! Paths ([`MeshSource::resolve`]): `package://PKG/rest` is looked for in each of
//! `robot.package_paths` (as `DIR/PKG/rest`), then in each folder of `ROS_PACKAGE_PATH` (as
//! `DIR/PKG/rest`, or `DIR/rest` when `DIR` is itself named `PKG`), then in the URDF's folder and
//! its parents (a folder `PKG` inside one of them, or one of them named `PKG`), then as `rest`
//! relative to the URDF's folder (as PyBullet does); `file://PATH`, absolute and relative paths
//! (relative to the URDF's folder) are read as they are. Whatever the rule, the file, with every
//! symbolic link followed, must lie below the URDF's folder, a configured package path, a folder
//! of `ROS_PACKAGE_PATH`, or the package folder the rule found; a path that leaves them (an
//! absolute path elsewhere, `..` out of them, a symbolic link out of them) is refused.
//!
//! Bounds: [`MAX_MESH_BYTES`] per file, [`MAX_MESH_TRIANGLES`] and [`MAX_MESH_VERTICES`] per
//! file, [`MAX_MESH_PARTS`] per file, [`MAX_MESH_FILES`] and [`MAX_MESH_TOTAL_BYTES`] per URDF.

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use parry3d::math::Vec3;
use parry3d::shape::ConvexPolyhedron;
use serde::{Deserialize, Serialize};

/// The largest mesh file read, bytes (64 MiB).
pub const MAX_MESH_BYTES: u64 = 64 << 20;
/// The most triangles (STL) or faces (OBJ) a mesh file may have.
pub const MAX_MESH_TRIANGLES: usize = 1_000_000;
/// The most vertices (OBJ `v` lines, STL triangle corners) a mesh file may have.
pub const MAX_MESH_VERTICES: usize = 3_000_000;
/// The most convex parts (OBJ objects or groups with faces) a mesh file may have.
pub const MAX_MESH_PARTS: usize = 1024;
/// The most mesh files (`<collision>` meshes) a URDF's chain may name.
pub const MAX_MESH_FILES: usize = 1024;
/// The most bytes of mesh files a URDF's chain may have read, all files together (256 MiB).
pub const MAX_MESH_TOTAL_BYTES: u64 = 256 << 20;

/// The bounds a mesh file is read under (the constants above; smaller in tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Limits {
    pub bytes: u64,
    pub triangles: usize,
    pub vertices: usize,
    pub parts: usize,
}

impl Limits {
    pub const DEFAULT: Limits = Limits {
        bytes: MAX_MESH_BYTES,
        triangles: MAX_MESH_TRIANGLES,
        vertices: MAX_MESH_VERTICES,
        parts: MAX_MESH_PARTS,
    };
}

/// What to do with a link whose collision mesh cannot be found or read (`robot.missing_collision`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum MissingCollision {
    /// Stop with an error naming the link, the file and why.
    #[default]
    Error,
    /// Go on without that geometry (the link is listed by `Chain::unloaded_collision`).
    Ignore,
}

/// Where meshes are looked for and what a missing one does.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshOptions {
    /// Folders holding package folders (`robot.package_paths`), searched first.
    pub package_paths: Vec<PathBuf>,
    /// The folders of `ROS_PACKAGE_PATH`, searched next ([`MeshOptions::with_ros_package_path`]).
    pub ros_package_path: Vec<PathBuf>,
    pub missing: MissingCollision,
}

impl MeshOptions {
    /// `self` with the folders of the environment's `ROS_PACKAGE_PATH` (none if it is unset).
    pub fn with_ros_package_path(mut self) -> MeshOptions {
        if let Some(v) = std::env::var_os("ROS_PACKAGE_PATH") {
            self.ros_package_path = std::env::split_paths(&v).filter(|p| !p.as_os_str().is_empty()).collect();
        }
        self
    }
}

/// One convex part of a link's collision mesh, in metres, in the mesh's frame (the
/// `<collision>` element's origin places it in the link's).
#[derive(Clone)]
pub struct ConvexPart {
    /// The file as the URDF names it.
    pub source: String,
    /// The part's index in the file (OBJ objects and groups in order).
    pub part: usize,
    /// The hull's vertices (scaled), metres.
    pub points_m: Vec<[f64; 3]>,
    /// The centre and radius (metres) of a sphere around the hull.
    pub centre_m: [f64; 3],
    pub radius_m: f64,
    /// A capsule around the hull (segment ends and radius, metres), for the checks' broad phase:
    /// along the hull's principal axis, as thin as holds every vertex, 0.1 mm wider.
    pub capsule_m: ([f64; 3], [f64; 3], f64),
    hull: ConvexPolyhedron,
}

impl ConvexPart {
    /// The hull as parry's shape (f32).
    pub fn hull(&self) -> &ConvexPolyhedron {
        &self.hull
    }

    /// The convex hull of `points` (metres, finite), or `None` when they do not span a volume.
    pub fn of_points(source: &str, part: usize, points: &[[f64; 3]]) -> Option<ConvexPart> {
        if is_flat(points) {
            return None;
        }
        let pts: Vec<Vec3> =
            points.iter().map(|p| Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32)).collect();
        // parry's hull code is not ours: a degenerate input must not take the process down.
        let hull = std::panic::catch_unwind(|| ConvexPolyhedron::from_convex_hull(&pts)).ok()??;
        let points_m: Vec<[f64; 3]> =
            hull.points().iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect();
        if points_m.len() < 4 {
            return None;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in &points_m {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let centre_m = [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0);
        let radius_m = points_m
            .iter()
            .map(|p| (0..3).map(|k| (p[k] - centre_m[k]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max)
            // The f32 hull is tested against it: a hair of room for the rounding.
            * (1.0 + 1e-6)
            + 1e-9;
        let capsule_m = enclosing_capsule(&points_m, centre_m);
        Some(ConvexPart { source: source.to_string(), part, points_m, centre_m, radius_m, capsule_m, hull })
    }
}

/// The margin of [`ConvexPart::capsule_m`] over the vertices, metres: room for the f32 hull the
/// exact test uses (its points are within about 1e-7 m of these) and its tolerances.
pub const CAPSULE_MARGIN_M: f64 = 1e-4;

/// A capsule that holds every point: its axis the points' principal direction (power iteration
/// on their covariance about `centre`), its radius the largest distance from that axis, its
/// ends as far in as the radius lets them (a point past an end must lie in that end's ball).
fn enclosing_capsule(points: &[[f64; 3]], centre: [f64; 3]) -> ([f64; 3], [f64; 3], f64) {
    let d = |p: &[f64; 3]| [p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]];
    let mut cov = [[0.0; 3]; 3];
    for p in points {
        let v = d(p);
        for r in 0..3 {
            for c in 0..3 {
                cov[r][c] += v[r] * v[c];
            }
        }
    }
    let mut axis = [1.0, 1e-3, 1e-6];
    for _ in 0..100 {
        let n = [0, 1, 2].map(|r| cov[r][0] * axis[0] + cov[r][1] * axis[1] + cov[r][2] * axis[2]);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if !(len > 0.0 && len.is_finite()) {
            break;
        }
        axis = n.map(|x| x / len);
    }
    let len = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let axis = axis.map(|x| x / len);
    let along = |v: [f64; 3]| v[0] * axis[0] + v[1] * axis[1] + v[2] * axis[2];
    let tr: Vec<(f64, f64)> = points
        .iter()
        .map(|p| {
            let v = d(p);
            let t = along(v);
            let q = [v[0] - t * axis[0], v[1] - t * axis[1], v[2] - t * axis[2]];
            (t, (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt())
        })
        .collect();
    let r = tr.iter().map(|x| x.1).fold(0.0, f64::max);
    let room = |dist: f64| (r * r - dist * dist).max(0.0).sqrt();
    let hi = tr.iter().map(|&(t, dist)| t - room(dist)).fold(f64::NEG_INFINITY, f64::max);
    let lo = tr.iter().map(|&(t, dist)| t + room(dist)).fold(f64::INFINITY, f64::min);
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.5 * (lo + hi), 0.5 * (lo + hi)) };
    let end = |t: f64| [centre[0] + t * axis[0], centre[1] + t * axis[1], centre[2] + t * axis[2]];
    (end(lo), end(hi), r * (1.0 + 1e-6) + CAPSULE_MARGIN_M)
}

/// Whether `points` lie on a plane (or a line, or a point), to a millionth of their extent.
fn is_flat(points: &[[f64; 3]]) -> bool {
    let Some(&a) = points.first() else { return true };
    let sub = |p: [f64; 3], q: [f64; 3]| [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let dot = |p: [f64; 3], q: [f64; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
    let cross = |p: [f64; 3], q: [f64; 3]| {
        [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]
    };
    // The point farthest from `a`, then the one farthest from the line through both.
    let far = |from: &dyn Fn([f64; 3]) -> f64| {
        points.iter().copied().fold((0.0, a), |(bd, bp), p| {
            let d = from(p);
            if d > bd {
                (d, p)
            } else {
                (bd, bp)
            }
        })
    };
    let (d2, b) = far(&|p| dot(sub(p, a), sub(p, a)));
    let extent = d2.sqrt();
    if extent == 0.0 {
        return true;
    }
    let ab = sub(b, a);
    let (_, c) = far(&|p| dot(cross(ab, sub(p, a)), cross(ab, sub(p, a))));
    let n = cross(ab, sub(c, a));
    let norm = dot(n, n).sqrt();
    if norm <= 1e-12 * extent * extent {
        return true;
    }
    let thickness = points.iter().map(|&p| (dot(n, sub(p, a)) / norm).abs()).fold(0.0, f64::max);
    thickness <= 1e-6 * extent
}

impl PartialEq for ConvexPart {
    fn eq(&self, o: &ConvexPart) -> bool {
        self.source == o.source && self.part == o.part && self.points_m == o.points_m
    }
}

impl std::fmt::Debug for ConvexPart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConvexPart")
            .field("source", &self.source)
            .field("part", &self.part)
            .field("hull_vertices", &self.points_m.len())
            .field("radius_m", &self.radius_m)
            .finish()
    }
}

/// A mesh file's parts: each a list of vertices (the file's units, unscaled).
pub(crate) type Parts = Vec<Vec<[f64; 3]>>;

/// Where a URDF's meshes come from: its folder and the options.
pub(crate) struct MeshSource<'a> {
    /// The URDF's folder, canonical.
    pub dir: PathBuf,
    pub options: &'a MeshOptions,
    pub limits: Limits,
    /// Bytes of mesh files read so far (bounded by [`MAX_MESH_TOTAL_BYTES`]).
    pub read: std::cell::Cell<u64>,
}

/// A reason a mesh could not be used (the caller names the link and the file).
pub(crate) type Why = String;

impl MeshSource<'_> {
    /// The file `filename` (as a URDF writes it) names, canonical, checked to lie in an allowed
    /// folder (see the module docs).
    pub fn resolve(&self, filename: &str) -> Result<PathBuf, Why> {
        if let Some(rest) = filename.strip_prefix("package://") {
            return self.resolve_package(rest);
        }
        let path = filename.strip_prefix("file://").unwrap_or(filename);
        if path.is_empty() {
            return Err("the file name is empty".into());
        }
        let p = Path::new(path);
        let full = if p.is_absolute() { p.to_path_buf() } else { self.dir.join(p) };
        let canon = canonical_file(&full)?;
        let mut roots = vec![self.dir.clone()];
        roots.extend(
            self.options
                .package_paths
                .iter()
                .chain(&self.options.ros_package_path)
                .filter_map(|d| d.canonicalize().ok()),
        );
        if roots.iter().any(|r| canon.starts_with(r)) {
            Ok(canon)
        } else {
            Err(format!(
                "{} is outside the folders meshes are read from (the URDF's folder {} and robot.package_paths); \
                 add its folder to robot.package_paths to allow it",
                canon.display(),
                self.dir.display()
            ))
        }
    }

    fn resolve_package(&self, rest: &str) -> Result<PathBuf, Why> {
        let Some((pkg, inner)) = rest.split_once('/') else {
            return Err("a package:// URL needs a package name and a path: package://PKG/path".into());
        };
        let inner_path = Path::new(inner);
        let plain = |p: &Path| p.components().all(|c| matches!(c, Component::Normal(_)));
        if pkg.is_empty() || !plain(Path::new(pkg)) || inner.is_empty() || !plain(inner_path) {
            return Err(format!(
                "package `{pkg}`, path `{inner}`: both must be plain relative names (no `..`, no leading `/`)"
            ));
        }
        // (package folder, root the file must stay below, the root is configured): a folder
        // found among the URDF's parents is itself canonical and must stay so (not a link).
        let mut candidates: Vec<(PathBuf, PathBuf, bool)> = Vec::new();
        for d in self.options.package_paths.iter().chain(&self.options.ros_package_path) {
            candidates.push((d.join(pkg), d.clone(), true));
        }
        for d in &self.options.ros_package_path {
            if d.file_name().is_some_and(|n| n == pkg) {
                candidates.push((d.clone(), d.clone(), true));
            }
        }
        for d in self.dir.ancestors() {
            candidates.push((d.join(pkg), d.join(pkg), false));
            if d.file_name().is_some_and(|n| n == pkg) {
                candidates.push((d.to_path_buf(), d.to_path_buf(), false));
            }
        }
        candidates.push((self.dir.clone(), self.dir.clone(), false));
        for (folder, root, configured) in &candidates {
            let full = folder.join(inner_path);
            if !full.is_file() {
                continue;
            }
            let canon = canonical_file(&full)?;
            let real_root = root.canonicalize().map_err(|e| format!("{}: {e}", root.display()))?;
            if canon.starts_with(&real_root) && (*configured || real_root == *root) {
                return Ok(canon);
            }
            return Err(format!(
                "{} leads to {}, outside {} (a symbolic link out of the folder is not followed; \
                 add the folder to robot.package_paths to allow it)",
                full.display(),
                canon.display(),
                root.display()
            ));
        }
        Err(format!(
            "package `{pkg}` file `{inner}` is in none of robot.package_paths ({}), ROS_PACKAGE_PATH ({}), \
             the URDF's folder {} or its parents",
            list(&self.options.package_paths),
            list(&self.options.ros_package_path),
            self.dir.display()
        ))
    }

    /// The parts of the mesh file `filename` names (resolved, read, parsed, bounded).
    pub fn load(&self, filename: &str) -> Result<Parts, Why> {
        let path = self.resolve(filename)?;
        let left = MAX_MESH_TOTAL_BYTES.saturating_sub(self.read.get());
        let size = std::fs::metadata(&path).map_err(|e| format!("{}: {e}", path.display()))?.len();
        if size > left && size <= self.limits.bytes {
            return Err(format!(
                "{}: {size} bytes, more than the {left} left of the {MAX_MESH_TOTAL_BYTES} bytes all mesh files \
                 of a chain may have",
                path.display()
            ));
        }
        let parts = read_mesh(&path, &self.limits)?;
        self.read.set(self.read.get() + size);
        Ok(parts)
    }
}

fn list(v: &[PathBuf]) -> String {
    if v.is_empty() {
        return "none".into();
    }
    v.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
}

/// `p` with every link followed; an error if it is not an existing regular file.
fn canonical_file(p: &Path) -> Result<PathBuf, Why> {
    let canon = p.canonicalize().map_err(|e| format!("{}: {e}", p.display()))?;
    if !canon.is_file() {
        return Err(format!("{} is not a file", canon.display()));
    }
    Ok(canon)
}

/// Read and parse a mesh file by its extension (`.stl`, `.obj`, any case).
pub(crate) fn read_mesh(path: &Path, lim: &Limits) -> Result<Parts, Why> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let kind = match ext.as_deref() {
        Some("stl") => Kind::Stl,
        Some("obj") => Kind::Obj,
        _ => {
            return Err(format!(
                "{}: unsupported mesh format (read: .stl binary or ASCII, .obj)",
                path.display()
            ))
        }
    };
    // Read at most one byte more than allowed (the file may grow after a size check).
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(file, lim.bytes + 1), &mut bytes)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if bytes.len() as u64 > lim.bytes {
        return Err(format!("{}: more than the {} bytes a mesh file may have", path.display(), lim.bytes));
    }
    let parts = match kind {
        Kind::Stl => parse_stl(&bytes, lim),
        Kind::Obj => parse_obj(&bytes, lim),
    };
    parts.map_err(|e| format!("{}: {e}", path.display()))
}

enum Kind {
    Stl,
    Obj,
}

fn too_many(what: &str, max: usize) -> Why {
    format!("more than {max} {what} (the most a mesh file may have)")
}

/// An STL file (binary when its size is 84 + 50 x its triangle count, else ASCII) as one part.
pub(crate) fn parse_stl(bytes: &[u8], lim: &Limits) -> Result<Parts, Why> {
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if bytes.len() as u64 == 84 + 50 * n as u64 {
            if n > lim.triangles || 3 * n > lim.vertices {
                return Err(too_many("triangles", lim.triangles.min(lim.vertices / 3)));
            }
            let mut pts = Vec::with_capacity(3 * n);
            for t in 0..n {
                let tri = &bytes[84 + 50 * t..84 + 50 * t + 50];
                for v in 0..3 {
                    let at = 12 + 12 * v;
                    let f = |k: usize| {
                        let o = at + 4 * k;
                        f32::from_le_bytes([tri[o], tri[o + 1], tri[o + 2], tri[o + 3]]) as f64
                    };
                    pts.push(checked_point([f(0), f(1), f(2)], || format!("triangle {t}"))?);
                }
            }
            return Ok(vec![pts]);
        }
    }
    let text = std::str::from_utf8(bytes).map_err(|_| {
        "neither binary STL (84 + 50 x the triangle count bytes) nor ASCII STL (text starting with `solid`)".to_string()
    })?;
    if !text.trim_start().starts_with("solid") {
        return Err("neither binary STL (84 + 50 x the triangle count bytes) nor ASCII STL (text starting with `solid`)".into());
    }
    let mut pts = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if words.next() != Some("vertex") {
            continue;
        }
        if pts.len() >= 3 * lim.triangles || pts.len() >= lim.vertices {
            return Err(too_many("triangles", lim.triangles.min(lim.vertices / 3)));
        }
        pts.push(parse_xyz(&mut words, i)?);
    }
    if pts.is_empty() {
        return Err("an ASCII STL file without a `vertex`".into());
    }
    Ok(vec![pts])
}

fn checked_point(p: [f64; 3], at: impl Fn() -> String) -> Result<[f64; 3], Why> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(p)
    } else {
        Err(format!("{}: a vertex {p:?} is not finite", at()))
    }
}

/// Three numbers from `words` (an `x y z` on line `i`, 0-based), finite.
fn parse_xyz<'a>(words: &mut impl Iterator<Item = &'a str>, i: usize) -> Result<[f64; 3], Why> {
    let mut p = [0.0; 3];
    for v in &mut p {
        let w = words.next().ok_or_else(|| format!("line {}: a vertex needs three numbers", i + 1))?;
        *v = w.parse::<f64>().map_err(|_| format!("line {}: `{w}` is not a number", i + 1))?;
    }
    checked_point(p, || format!("line {}", i + 1))
}

/// A Wavefront OBJ file: one part per object or group (`o`, `g`) with faces, each the vertices
/// its faces use; a file without faces is one part of all its vertices.
pub(crate) fn parse_obj(bytes: &[u8], lim: &Limits) -> Result<Parts, Why> {
    let text = String::from_utf8_lossy(bytes);
    let mut verts: Vec<[f64; 3]> = Vec::new();
    // Per part: indices into `verts`.
    let mut parts: Vec<Vec<usize>> = vec![Vec::new()];
    let mut corners = 0usize;
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                if verts.len() >= lim.vertices {
                    return Err(too_many("vertices", lim.vertices));
                }
                verts.push(parse_xyz(&mut words, i)?);
            }
            // A new object or group starts a part (unless the last one has no faces yet).
            Some("o" | "g") if parts.last().is_some_and(|p| !p.is_empty()) => {
                if parts.len() >= lim.parts {
                    return Err(too_many("parts (objects or groups with faces)", lim.parts));
                }
                parts.push(Vec::new());
            }
            Some("f") => {
                // `parts` starts with one part and only grows.
                let Some(part) = parts.last_mut() else { continue };
                for w in words {
                    corners += 1;
                    if corners > 3 * lim.triangles {
                        return Err(too_many("face corners", 3 * lim.triangles));
                    }
                    part.push(obj_index(w, verts.len(), i)?);
                }
            }
            _ => {}
        }
    }
    if verts.is_empty() {
        return Err("an OBJ file without a vertex (`v` line)".into());
    }
    parts.retain(|p| !p.is_empty());
    if parts.is_empty() {
        return Ok(vec![verts]);
    }
    Ok(parts
        .into_iter()
        .map(|mut p| {
            p.sort_unstable();
            p.dedup();
            p.into_iter().map(|k| verts[k]).collect()
        })
        .collect())
}

/// A face corner (`v`, `v/vt`, `v//vn`, `v/vt/vn`; 1-based, or negative: from the end) as an
/// index into the `n` vertices read so far.
fn obj_index(w: &str, n: usize, i: usize) -> Result<usize, Why> {
    let v = w.split('/').next().unwrap_or("");
    let k: i64 = v.parse().map_err(|_| format!("line {}: face corner `{w}` is not a vertex index", i + 1))?;
    let idx = if k > 0 { k - 1 } else { n as i64 + k };
    if k == 0 || idx < 0 || idx >= n as i64 {
        return Err(format!(
            "line {}: face corner `{w}` names a vertex that does not exist ({n} so far)",
            i + 1
        ));
    }
    Ok(idx as usize)
}

/// The convex parts of a parsed mesh, `scale`d (per axis), as the link's shapes; an error if a
/// part is flat or out of bounds.
pub(crate) fn convex_parts(
    source: &str,
    parts: &Parts,
    scale: [f64; 3],
) -> Result<Vec<Arc<ConvexPart>>, Why> {
    if !scale.iter().all(|s| s.is_finite() && *s != 0.0) {
        return Err(format!("scale {scale:?} must be three finite nonzero numbers"));
    }
    let mut out = Vec::with_capacity(parts.len());
    for (k, p) in parts.iter().enumerate() {
        let pts: Vec<[f64; 3]> =
            p.iter().map(|v| [v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]]).collect();
        if pts.iter().flatten().any(|v| v.abs() > super::MAX_LENGTH_M) {
            return Err(format!("part {k}: a scaled vertex is beyond +-{:e} m", super::MAX_LENGTH_M));
        }
        let part = ConvexPart::of_points(source, k, &pts).ok_or_else(|| {
            format!("part {k} ({} vertices) is flat or degenerate: its convex hull has no volume", pts.len())
        })?;
        out.push(Arc::new(part));
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
