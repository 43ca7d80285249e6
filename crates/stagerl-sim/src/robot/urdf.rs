//! URDF parsing and compilation into a flat serial chain.

use std::collections::{HashMap, HashSet};

use urdf_rs::JointType;

use super::kin::{self, Kinematics, Step, Tf};
use super::mesh::{self, MeshSource, MissingCollision};
use super::{JointInfo, JointKind, LinkShape, Shape, UnloadedMesh};
use crate::{Error, Result};

/// A URDF compiled into a serial chain from its root link to a tip link.
pub(crate) struct Compiled {
    pub joints: Vec<JointInfo>,
    pub base_link: String,
    pub tip_link: String,
    pub kin: Kinematics,
    pub shapes: Vec<LinkShape>,
    pub unloaded: Vec<UnloadedMesh>,
}

/// The largest length (metres) a URDF may hold in a joint origin or a prismatic joint's limits:
/// beyond it forward kinematics can overflow f64 (an origin of 1e308 m does).
pub const MAX_LENGTH_M: f64 = 1e6;

/// A URDF error; names echoed from the document are cut to excerpts.
fn urdf_err(msg: impl Into<String>) -> Error {
    Error::Urdf(crate::base::text::bound_message(&msg.into()))
}

/// `a`, `b`, `c` as "`a`, `b`, `c`".
fn quoted_list<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    names.into_iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ")
}

/// An error naming the joints and links of a cycle, if any link has no path up to `root` (with
/// one root and one parent joint per link, such a link is on a cycle or below one), whether or
/// not the cycle touches the chain that will be compiled.
fn check_no_cycle(
    robot: &urdf_rs::Robot,
    parent_joint: &HashMap<&str, &urdf_rs::Joint>,
    root: &str,
) -> Result<()> {
    let mut reaches_root: HashSet<&str> = HashSet::from([root]);
    for l in &robot.links {
        let mut trail: Vec<&str> = Vec::new();
        let mut link = l.name.as_str();
        while !reaches_root.contains(link) {
            if let Some(at) = trail.iter().position(|t| *t == link) {
                let links = &trail[at..];
                let joints = links.iter().map(|l| parent_joint[l].name.as_str());
                return Err(urdf_err(format!(
                    "joints {} form a cycle through links {}; a URDF must be a tree",
                    quoted_list(joints),
                    quoted_list(links.iter().copied())
                )));
            }
            trail.push(link);
            // Every link but the root has a parent joint (`root` is the only link without one).
            link = parent_joint[link].parent.link.as_str();
        }
        reaches_root.extend(trail);
    }
    Ok(())
}

/// The deepest element nesting a URDF may have (a URDF needs 4: robot, joint, limit; a deeper
/// document could overflow the stack of the recursive XML parser).
pub const MAX_XML_DEPTH: usize = 64;

/// The largest URDF file read, bytes (64 MiB).
pub const MAX_URDF_BYTES: u64 = 64 << 20;

/// An error if `xml` nests elements deeper than [`MAX_XML_DEPTH`]: a scan of its tags (comments,
/// CDATA, declarations and quoted attribute values skipped) without recursion. Malformed markup
/// is left to the parser to report.
fn check_xml_depth(xml: &str) -> Result<()> {
    let b = xml.as_bytes();
    let find = |from: usize, pat: &str| xml[from..].find(pat).map(|k| from + k);
    let (mut depth, mut i) = (0usize, 0usize);
    while let Some(open) = find(i, "<") {
        let rest = &xml[open..];
        let skip_to = |pat: &str| find(open, pat).map(|k| k + pat.len());
        let next = if rest.starts_with("<!--") {
            skip_to("-->")
        } else if rest.starts_with("<![CDATA[") {
            skip_to("]]>")
        } else if rest.starts_with("<?") || rest.starts_with("<!") || rest.starts_with("</") {
            if rest.starts_with("</") {
                depth = depth.saturating_sub(1);
            }
            skip_to(">")
        } else {
            // A start tag: its end is the first `>` outside a quoted attribute value.
            let mut quote = None;
            let end = (open + 1..b.len()).find(|&k| match (quote, b[k]) {
                (None, q @ (b'"' | b'\'')) => {
                    quote = Some(q);
                    false
                }
                (Some(q), c) if c == q => {
                    quote = None;
                    false
                }
                (None, b'>') => true,
                _ => false,
            });
            if let Some(end) = end {
                if b[end - 1] != b'/' {
                    depth += 1;
                    if depth > MAX_XML_DEPTH {
                        return Err(urdf_err(format!(
                            "elements are nested more than {MAX_XML_DEPTH} deep (at byte {open}); \
                             a URDF needs a handful of levels"
                        )));
                    }
                }
            }
            end.map(|e| e + 1)
        };
        match next {
            Some(n) => i = n,
            None => break,
        }
    }
    Ok(())
}

/// A joint's origin (xyz metres, rpy radians): finite, and within [`MAX_LENGTH_M`].
fn checked_origin(j: &urdf_rs::Joint) -> Result<([f64; 3], [f64; 3])> {
    let xyz = j.origin.xyz.0;
    let rpy = j.origin.rpy.0;
    if xyz.iter().chain(rpy.iter()).any(|v| !v.is_finite()) {
        return Err(urdf_err(format!(
            "joint `{}` has a non-finite origin: xyz = {xyz:?}, rpy = {rpy:?}",
            j.name
        )));
    }
    if xyz.iter().any(|v| v.abs() > MAX_LENGTH_M) {
        return Err(urdf_err(format!(
            "joint `{}` has origin xyz = {xyz:?} m; each coordinate must be within \
             +-{MAX_LENGTH_M:e} m",
            j.name
        )));
    }
    Ok((xyz, rpy))
}

/// An actuated joint's effort limit (N m or N): the URDF's `<limit effort>`, `+inf` when it is
/// 0 (urdf-rs reads a missing attribute as 0); an error when negative or NaN.
fn checked_effort(j: &urdf_rs::Joint) -> Result<f64> {
    let effort = j.limit.effort;
    if effort.is_nan() || effort < 0.0 {
        return Err(urdf_err(format!(
            "joint `{}` has <limit effort=\"{effort}\">; the effort limit must be >= 0 (0 or \
             absent: unlimited)",
            j.name
        )));
    }
    Ok(if effort == 0.0 { f64::INFINITY } else { effort })
}

/// An actuated joint's (lower, upper, velocity) limits (rad or m, rad/s or m/s): usable, and a
/// prismatic joint's within [`MAX_LENGTH_M`]. Continuous joints are unbounded.
fn checked_limits(j: &urdf_rs::Joint, kind: JointKind) -> Result<(f64, f64, f64)> {
    let lim = &j.limit;
    if j.joint_type == JointType::Continuous {
        if !(lim.velocity.is_finite() && lim.velocity > 0.0) {
            return Err(urdf_err(format!(
                "continuous joint `{}` has no usable velocity limit (velocity = {}); \
                 a finite <limit velocity> > 0 is required",
                j.name, lim.velocity
            )));
        }
        Ok((f64::NEG_INFINITY, f64::INFINITY, lim.velocity))
    } else {
        let usable = lim.lower.is_finite()
            && lim.upper.is_finite()
            && lim.velocity.is_finite()
            && lim.lower < lim.upper
            && lim.velocity > 0.0;
        if !usable {
            return Err(urdf_err(format!(
                "joint `{}` ({:?}) has no usable <limit>: lower = {}, upper = {}, \
                 velocity = {}; finite lower < upper and velocity > 0 are required",
                j.name, j.joint_type, lim.lower, lim.upper, lim.velocity
            )));
        }
        if kind == JointKind::Prismatic && lim.lower.abs().max(lim.upper.abs()) > MAX_LENGTH_M {
            return Err(urdf_err(format!(
                "prismatic joint `{}` has limits [{:?}, {:?}] m; they must be within +-{MAX_LENGTH_M:e} m",
                j.name, lim.lower, lim.upper
            )));
        }
        Ok((lim.lower, lim.upper, lim.velocity))
    }
}

/// Parse a URDF document and compile the chain from its root to `tip` (`None`: the only leaf);
/// collision meshes are read from `meshes` (`None`: not read, listed as unloaded).
pub(crate) fn compile_str(xml: &str, tip: Option<&str>, meshes: Option<&MeshSource>) -> Result<Compiled> {
    check_xml_depth(xml)?;
    let robot = urdf_rs::read_from_string(xml)
        .map_err(|e| urdf_err(format!("cannot parse the URDF document: {e}")))?;
    compile(&robot, tip, meshes)
}

/// Compile a parsed URDF into the chain from its root link to `tip`.
pub(crate) fn compile(
    robot: &urdf_rs::Robot,
    tip: Option<&str>,
    meshes: Option<&MeshSource>,
) -> Result<Compiled> {
    if robot.links.is_empty() {
        return Err(urdf_err(format!("robot `{}` has no links", robot.name)));
    }
    let tree = Tree::index(robot)?;
    let root = tree.root()?;
    let tip = tree.tip(tip)?;
    let path = tree.path(root, tip)?;
    // A cycle elsewhere in the document (beside the chain) is refused too.
    check_no_cycle(robot, &tree.parent_joint, root)?;
    fold_chain(robot, &path, root, tip, meshes)
}

/// The links and joints of a URDF, checked to form a tree.
struct Tree<'r> {
    robot: &'r urdf_rs::Robot,
    links: HashSet<&'r str>,
    /// The joint whose child each link is.
    parent_joint: HashMap<&'r str, &'r urdf_rs::Joint>,
    /// Links that are the parent of some joint.
    has_children: HashSet<&'r str>,
}

impl<'r> Tree<'r> {
    fn index(robot: &'r urdf_rs::Robot) -> Result<Tree<'r>> {
        // Links, in document order, unique.
        let mut links: HashSet<&str> = HashSet::new();
        for l in &robot.links {
            if !links.insert(l.name.as_str()) {
                return Err(urdf_err(format!("link `{}` is defined twice", l.name)));
            }
        }

        // Joints: unique names, existing links, at most one parent joint per link.
        let mut joint_names: HashSet<&str> = HashSet::new();
        let mut parent_joint: HashMap<&str, &urdf_rs::Joint> = HashMap::new();
        let mut has_children: HashSet<&str> = HashSet::new();
        for j in &robot.joints {
            if !joint_names.insert(j.name.as_str()) {
                return Err(urdf_err(format!("joint `{}` is defined twice", j.name)));
            }
            for (role, link) in [("parent", &j.parent.link), ("child", &j.child.link)] {
                if !links.contains(link.as_str()) {
                    return Err(urdf_err(format!(
                        "joint `{}` names {role} link `{link}`, which does not exist",
                        j.name
                    )));
                }
            }
            if let Some(other) = parent_joint.insert(j.child.link.as_str(), j) {
                return Err(urdf_err(format!(
                    "link `{}` is the child of two joints, `{}` and `{}`; a URDF must be a tree",
                    j.child.link, other.name, j.name
                )));
            }
            has_children.insert(j.parent.link.as_str());
        }
        Ok(Tree { robot, links, parent_joint, has_children })
    }

    /// The only link that is no joint's child.
    fn root(&self) -> Result<&'r str> {
        let (robot, parent_joint) = (self.robot, &self.parent_joint);
        let roots: Vec<&str> =
            robot.links.iter().map(|l| l.name.as_str()).filter(|l| !parent_joint.contains_key(l)).collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => {
                return Err(urdf_err(
                    "no root link: every link is the child of a joint, so the joints form a cycle",
                ))
            }
            _ => {
                return Err(urdf_err(format!(
                    "more than one root link ({}); a URDF must be a tree with a single root",
                    quoted_list(roots.iter().copied())
                )))
            }
        };
        Ok(root)
    }

    /// The tip link: the one given, else the only leaf.
    fn tip(&self, tip: Option<&'r str>) -> Result<&'r str> {
        let (robot, links, has_children) = (self.robot, &self.links, &self.has_children);
        let tip: &str = match tip {
            Some(t) => {
                if !links.contains(t) {
                    return Err(urdf_err(format!(
                        "unknown tip link `{t}`; the links are {}",
                        quoted_list(robot.links.iter().map(|l| l.name.as_str()))
                    )));
                }
                t
            }
            None => {
                let leaves: Vec<&str> = robot
                    .links
                    .iter()
                    .map(|l| l.name.as_str())
                    .filter(|l| !has_children.contains(l))
                    .collect();
                match leaves.as_slice() {
                    [leaf] => leaf,
                    [] => {
                        return Err(urdf_err(
                            "no leaf link: every link is the parent of a joint; pass the tip link",
                        ))
                    }
                    _ => {
                        return Err(urdf_err(format!(
                            "several leaf links ({}); pass the tip link to use",
                            quoted_list(leaves.iter().copied())
                        )))
                    }
                }
            }
        };
        Ok(tip)
    }

    /// The joints from `root` down to `tip`.
    fn path(&self, root: &'r str, tip: &'r str) -> Result<Vec<&'r urdf_rs::Joint>> {
        let parent_joint = &self.parent_joint;
        let mut path: Vec<&urdf_rs::Joint> = Vec::new();
        let mut link = tip;
        let mut seen: HashSet<&str> = HashSet::new();
        while link != root {
            if !seen.insert(link) {
                let cycle: Vec<&str> =
                    path.iter().skip_while(|j| j.child.link != link).map(|j| j.name.as_str()).collect();
                return Err(urdf_err(format!(
                    "link `{tip}` has no path to the root link `{root}`: joints {} form a cycle",
                    quoted_list(cycle)
                )));
            }
            // Every non-root link has a parent joint (the root is the only link without one).
            let Some(j) = parent_joint.get(link) else {
                return Err(urdf_err(format!("link `{link}` has no path to the root link `{root}`")));
            };
            path.push(j);
            link = j.parent.link.as_str();
        }
        path.reverse();
        Ok(path)
    }
}

/// An actuated joint's kind, unit axis, limits `(lower, upper, velocity)` and effort limit.
type Actuated = (JointKind, [f64; 3], (f64, f64, f64), f64);

/// An actuated joint's kind, unit axis, limits (lower, upper, velocity) and effort limit; `None`
/// for a fixed joint; an error for what the chain cannot hold.
fn actuated(j: &urdf_rs::Joint, root: &str, tip: &str) -> Result<Option<Actuated>> {
    let kind = match j.joint_type {
        JointType::Fixed => return Ok(None),
        JointType::Revolute | JointType::Continuous => JointKind::Revolute,
        JointType::Prismatic => JointKind::Prismatic,
        JointType::Floating | JointType::Planar | JointType::Spherical => {
            return Err(urdf_err(format!(
                "joint `{}` on the chain from `{root}` to `{tip}` has unsupported type {:?}; \
                 only revolute, continuous, prismatic and fixed joints are supported",
                j.name, j.joint_type
            )));
        }
    };
    if let Some(m) = &j.mimic {
        return Err(urdf_err(format!(
            "joint `{}` on the chain from `{root}` to `{tip}` mimics joint `{}`; \
             mimic joints are not supported",
            j.name, m.joint
        )));
    }
    let axis = j.axis.xyz.0;
    if axis.iter().any(|v| !v.is_finite()) {
        return Err(urdf_err(format!("joint `{}` has a non-finite axis {axis:?}", j.name)));
    }
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    if norm < 1e-9 {
        return Err(urdf_err(format!(
            "joint `{}` has a zero axis {axis:?}; an actuated joint needs a nonzero axis",
            j.name
        )));
    }
    let axis = [axis[0] / norm, axis[1] / norm, axis[2] / norm];
    let (lower, upper, velocity) = checked_limits(j, kind)?;
    Ok(Some((kind, axis, (lower, upper, velocity), checked_effort(j)?)))
}

/// Compile the joints of `path`: fold fixed joints and the axis-alignment rotations into the
/// constants of the kinematics, and place the collision shapes of the links on the path.
///
/// `pending` is, after each joint, the frame of that joint's child link in its segment's frame
/// (the root's frame before the first actuated joint; after actuated joint `i`, its moving
/// z-aligned frame, in which the child link's frame is the transpose of the axis-alignment
/// basis): the constant folded into the kinematics, and where the link's shapes sit.
fn fold_chain(
    robot: &urdf_rs::Robot,
    path: &[&urdf_rs::Joint],
    root: &str,
    tip: &str,
    meshes: Option<&MeshSource>,
) -> Result<Compiled> {
    let mut joints = Vec::new();
    let mut steps = Vec::new();
    let mut base: Option<Tf> = None;
    let mut pending: Tf = kin::IDENTITY;
    let mut out = Shapes { meshes, shapes: Vec::new(), unloaded: Vec::new(), files: 0 };
    out.add_link(robot, root, None, &pending)?;
    for j in path {
        let (xyz, rpy) = checked_origin(j)?;
        pending = kin::mul(&pending, &kin::origin(xyz, rpy));
        if let Some((kind, axis, (lower, upper, velocity), effort)) = actuated(j, root, tip)? {
            joints.push(JointInfo { name: j.name.clone(), kind, lower, upper, velocity, effort });
            let a = kin::basis_for_axis(axis);
            let before = kin::mul(&pending, &a);
            match steps.last_mut() {
                None => base = Some(before),
                Some(Step { after, .. }) => *after = before,
            }
            steps.push(Step { prismatic: kind == JointKind::Prismatic, after: kin::IDENTITY });
            pending = kin::rotation_transpose(&a);
        }
        let segment = steps.len().checked_sub(1);
        out.add_link(robot, &j.child.link, segment, &pending)?;
    }
    let Some(base) = base else {
        return Err(urdf_err(format!(
            "the chain from root link `{root}` to tip link `{tip}` has no actuated joint"
        )));
    };
    if let Some(last) = steps.last_mut() {
        last.after = pending;
    }
    Ok(Compiled {
        joints,
        base_link: root.to_string(),
        tip_link: tip.to_string(),
        kin: Kinematics::new(&base, &steps),
        shapes: out.shapes,
        unloaded: out.unloaded,
    })
}

/// The collision shapes of the chain's links as they are gathered.
struct Shapes<'m, 's> {
    meshes: Option<&'m MeshSource<'s>>,
    shapes: Vec<LinkShape>,
    unloaded: Vec<UnloadedMesh>,
    /// Mesh files read so far.
    files: usize,
}

impl Shapes<'_, '_> {
    /// The collision shapes (`<collision>` elements) of link `name`, placed at `frame` (the
    /// link's frame in its segment's: see [`super::LinkShape`]); a mesh becomes its convex
    /// parts, or, when it cannot be read, an error (or an entry of `unloaded`, as
    /// `robot.missing_collision` says; always when there is no `MeshSource`).
    fn add_link(
        &mut self,
        robot: &urdf_rs::Robot,
        name: &str,
        segment: Option<usize>,
        frame: &Tf,
    ) -> Result<()> {
        let link = robot.links.iter().find(|l| l.name == name);
        for c in link.map(|l| l.collision.as_slice()).unwrap_or_default() {
            let (xyz, rpy) = (c.origin.xyz.0, c.origin.rpy.0);
            if xyz.iter().chain(rpy.iter()).any(|v| !v.is_finite() || v.abs() > MAX_LENGTH_M) {
                return Err(urdf_err(format!(
                    "link `{name}`: a collision origin xyz = {xyz:?}, rpy = {rpy:?} is not finite or beyond +-{MAX_LENGTH_M:e}"
                )));
            }
            let link_pose = kin::origin(xyz, rpy);
            let pose = kin::mul(frame, &link_pose);
            let shapes = match &c.geometry {
                urdf_rs::Geometry::Mesh { filename, scale } => {
                    let scale = scale.map_or([1.0; 3], |s| s.0);
                    match self.mesh_shapes(name, filename, scale)? {
                        Some(s) => s,
                        None => continue,
                    }
                }
                g => vec![shape_of(name, g)?],
            };
            for shape in shapes {
                self.shapes.push(LinkShape { link: name.to_string(), segment, pose, link_pose, shape });
            }
        }
        Ok(())
    }

    /// The convex parts of mesh `filename` of link `link`; `None` when it is not loaded and that
    /// is allowed (recorded in `unloaded`).
    fn mesh_shapes(&mut self, link: &str, filename: &str, scale: [f64; 3]) -> Result<Option<Vec<Shape>>> {
        let Some(src) = self.meshes else {
            let why = "the URDF was given as text, with no folder to read meshes from".to_string();
            self.unloaded.push(UnloadedMesh { link: link.into(), file: filename.into(), reason: why });
            return Ok(None);
        };
        self.files += 1;
        if self.files > mesh::MAX_MESH_FILES {
            return Err(urdf_err(format!(
                "link `{link}`: more than {} collision mesh files on the chain",
                mesh::MAX_MESH_FILES
            )));
        }
        let loaded = src.load(filename).and_then(|parts| mesh::convex_parts(filename, &parts, scale));
        match loaded {
            Ok(parts) => Ok(Some(parts.into_iter().map(Shape::Convex).collect())),
            Err(why) if src.options.missing == MissingCollision::Ignore => {
                self.unloaded.push(UnloadedMesh { link: link.into(), file: filename.into(), reason: why });
                Ok(None)
            }
            Err(why) => Err(urdf_err(format!(
                "link `{link}`: collision mesh `{filename}` cannot be used: {why} \
                 (robot.missing_collision = \"ignore\" goes on without it)"
            ))),
        }
    }
}

/// A URDF geometry other than a mesh as a collision primitive.
fn shape_of(link: &str, g: &urdf_rs::Geometry) -> Result<Shape> {
    let ok = |v: f64| v.is_finite() && v > 0.0 && v <= MAX_LENGTH_M;
    let bad = |what: &str| {
        urdf_err(format!(
            "link `{link}`: collision {what} must be finite, > 0 and at most {MAX_LENGTH_M:e} m"
        ))
    };
    Ok(match g {
        // A cylinder is taken as the capsule of its radius and length (caps added: a little
        // conservative at the ends).
        urdf_rs::Geometry::Cylinder { radius, length } | urdf_rs::Geometry::Capsule { radius, length } => {
            if !(ok(*radius) && length.is_finite() && *length >= 0.0 && *length <= MAX_LENGTH_M) {
                return Err(bad("radius and length"));
            }
            Shape::Capsule { radius_m: *radius, half_length_m: length / 2.0 }
        }
        urdf_rs::Geometry::Sphere { radius } => {
            if !ok(*radius) {
                return Err(bad("radius"));
            }
            Shape::Sphere { radius_m: *radius }
        }
        urdf_rs::Geometry::Box { size } => {
            if !size.0.iter().all(|&v| ok(v)) {
                return Err(bad("box size"));
            }
            Shape::Cuboid { half_extents_m: [size.0[0] / 2.0, size.0[1] / 2.0, size.0[2] / 2.0] }
        }
        // Read by `Shapes::mesh_shapes`, never passed here.
        urdf_rs::Geometry::Mesh { .. } => {
            return Err(urdf_err(format!("link `{link}`: a mesh is not a primitive")))
        }
    })
}
