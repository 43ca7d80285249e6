//! Tests of `robot::mesh`: meshes and URDFs written into temporary folders.

use super::*;
use crate::robot::{Chain, Shape};
use crate::Error;

/// A fresh, empty temporary folder for test `name` (canonical).
fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stagerl-mesh-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d.canonicalize().unwrap()
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// The 12 triangles of the axis-aligned cube of side `side` centred at `c`.
fn cube_triangles(c: [f64; 3], side: f64) -> Vec<[[f64; 3]; 3]> {
    let h = side / 2.0;
    let v = |i: usize| [0, 1, 2].map(|k| c[k] + if i >> k & 1 == 1 { h } else { -h });
    // Each face: 4 corners (bit patterns), as 2 triangles.
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    faces.iter().flat_map(|f| [[v(f[0]), v(f[1]), v(f[2])], [v(f[0]), v(f[2]), v(f[3])]]).collect()
}

fn binary_stl(tris: &[[[f64; 3]; 3]]) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b[..5].copy_from_slice(b"solid"); // as some exporters write it: still binary
    b.extend((tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend([0u8; 12]);
        for p in t {
            for x in p {
                b.extend((*x as f32).to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    b
}

fn ascii_stl(tris: &[[[f64; 3]; 3]]) -> Vec<u8> {
    let mut s = String::from("solid cube\n");
    for t in tris {
        s.push_str("  facet normal 0 0 0\n    outer loop\n");
        for p in t {
            s.push_str(&format!("      vertex {} {} {}\n", p[0], p[1], p[2]));
        }
        s.push_str("    endloop\n  endfacet\n");
    }
    s.push_str("endsolid cube\n");
    s.into_bytes()
}

/// An OBJ file with one object per cube (`(centre, side)`), faces as quads.
fn obj_cubes(cubes: &[([f64; 3], f64)]) -> Vec<u8> {
    let mut s = String::from("# two convex parts, as V-HACD writes them\n");
    for (n, (c, side)) in cubes.iter().enumerate() {
        s.push_str(&format!("o part{n}\n"));
        let h = side / 2.0;
        for i in 0..8 {
            let p = [0, 1, 2].map(|k| c[k] + if i >> k & 1 == 1 { h } else { -h });
            s.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
        }
        let base = 8 * n + 1;
        for f in [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]] {
            let idx: Vec<String> = f.iter().map(|k| format!("{}//1", base + k)).collect();
            s.push_str(&format!("f {}\n", idx.join(" ")));
        }
    }
    s.into_bytes()
}

/// A one-joint URDF whose moving link `l1` has the collision mesh `filename` (with `scale`).
fn urdf_with_mesh(filename: &str, scale: Option<&str>) -> String {
    let scale = scale.map(|s| format!(" scale=\"{s}\"")).unwrap_or_default();
    format!(
        r#"<robot name="m">
  <link name="base"/>
  <link name="l1"><collision><origin xyz="0 0 0.5"/><geometry><mesh filename="{filename}"{scale}/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1"/></joint>
</robot>"#
    )
}

/// The chain of `urdf` written at `dir/name`.
fn load_at(dir: &Path, name: &str, urdf: &str, options: &MeshOptions) -> crate::Result<Chain> {
    let path = dir.join(name);
    write(&path, urdf.as_bytes());
    Chain::from_urdf_file_with(&path, None, options)
}

fn convex_parts_of(chain: &Chain) -> Vec<Arc<ConvexPart>> {
    chain
        .collision_shapes()
        .iter()
        .map(|s| match &s.shape {
            Shape::Convex(p) => p.clone(),
            other => panic!("not a mesh part: {other:?}"),
        })
        .collect()
}

/// The bounding box (lo, hi) of a part's hull vertices.
fn bounds(p: &ConvexPart) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in &p.points_m {
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    (lo, hi)
}

fn assert_box(p: &ConvexPart, lo: [f64; 3], hi: [f64; 3]) {
    let (l, h) = bounds(p);
    for k in 0..3 {
        assert!((l[k] - lo[k]).abs() < 1e-6 && (h[k] - hi[k]).abs() < 1e-6, "{l:?} {h:?} vs {lo:?} {hi:?}");
    }
    assert_eq!(p.points_m.len(), 8, "a cube's hull has 8 vertices");
}

fn urdf_message<T: std::fmt::Debug>(r: crate::Result<T>) -> String {
    match r {
        Err(Error::Urdf(m)) => m,
        other => panic!("expected a URDF error, got {other:?}"),
    }
}

#[test]
fn unit_cube_stl_binary_and_ascii_load_as_the_same_hull() {
    let d = tmp("stl");
    let tris = cube_triangles([0.0; 3], 1.0);
    write(&d.join("meshes/bin.stl"), &binary_stl(&tris));
    write(&d.join("meshes/ascii.STL"), &ascii_stl(&tris));
    let opts = MeshOptions::default();
    for file in ["meshes/bin.stl", "meshes/ascii.STL"] {
        let chain = load_at(&d, "r.urdf", &urdf_with_mesh(file, None), &opts).unwrap();
        let parts = convex_parts_of(&chain);
        assert_eq!(parts.len(), 1, "{file}");
        assert_box(&parts[0], [-0.5; 3], [0.5; 3]);
        assert_eq!(parts[0].source, file);
        assert!(chain.unloaded_collision().is_empty());
        // Placed by the collision origin, in joint 0's frame.
        assert_eq!(chain.collision_shapes()[0].link_pose[11], 0.5);
        assert_eq!(chain.collision_shapes()[0].segment, Some(0));
    }
}

#[test]
fn obj_objects_are_convex_parts_and_scale_applies() {
    let d = tmp("obj");
    write(&d.join("two.obj"), &obj_cubes(&[([0.0, 0.0, 0.0], 1.0), ([3.0, 0.0, 0.0], 2.0)]));
    let chain = load_at(&d, "r.urdf", &urdf_with_mesh("two.obj", None), &MeshOptions::default()).unwrap();
    let parts = convex_parts_of(&chain);
    assert_eq!(parts.len(), 2);
    assert_box(&parts[0], [-0.5; 3], [0.5; 3]);
    assert_box(&parts[1], [2.0, -1.0, -1.0], [4.0, 1.0, 1.0]);
    assert_eq!((parts[0].part, parts[1].part), (0, 1));
    // `scale` per axis, and `file://` relative to the URDF.
    let chain =
        load_at(&d, "r.urdf", &urdf_with_mesh("file://two.obj", Some("2 1 0.5")), &MeshOptions::default())
            .unwrap();
    let parts = convex_parts_of(&chain);
    assert_box(&parts[1], [4.0, -1.0, -0.5], [8.0, 1.0, 0.5]);
    // Groups (`g`) split too; a file without faces is one part of all its vertices.
    let text = "g a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\ng b\nv 5 5 5\nv 6 5 5\nv 5 6 5\nv 5 5 6\nf -4 -3 -2 -1\n";
    assert_eq!(parse_obj(text.as_bytes(), &Limits::DEFAULT).unwrap().len(), 2);
    let cloud = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n";
    assert_eq!(
        parse_obj(cloud.as_bytes(), &Limits::DEFAULT).unwrap(),
        vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]]
    );
}

#[test]
fn bad_meshes_are_errors_naming_link_and_file() {
    let d = tmp("bad");
    let flat = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
    write(&d.join("flat.obj"), flat.as_bytes());
    write(&d.join("junk.stl"), b"not a mesh at all, just text");
    write(&d.join("bad.obj"), b"v 0 0 0\nf 1 2 3\n");
    write(&d.join("nan.obj"), b"v 0 0 nan\n");
    write(&d.join("m.dae"), b"<COLLADA/>");
    let cases = [
        ("flat.obj", "flat or degenerate"),
        ("junk.stl", "neither binary STL"),
        ("bad.obj", "does not exist"),
        ("nan.obj", "not finite"),
        ("m.dae", "unsupported mesh format"),
        ("missing.stl", "No such file"),
        ("package://nopkg/x.stl", "is in none of"),
    ];
    for (file, why) in cases {
        let m = urdf_message(load_at(&d, "r.urdf", &urdf_with_mesh(file, None), &MeshOptions::default()));
        assert!(m.contains("link `l1`") && m.contains(file) && m.contains(why), "{file}: {m}");
        assert!(m.contains("missing_collision"), "{m}");
        // `ignore` goes on without it, and says so.
        let ignore = MeshOptions { missing: MissingCollision::Ignore, ..MeshOptions::default() };
        let chain = load_at(&d, "r.urdf", &urdf_with_mesh(file, None), &ignore).unwrap();
        assert!(chain.collision_shapes().is_empty());
        assert_eq!(chain.mesh_collision_links(), ["l1"]);
        let u = &chain.unloaded_collision()[0];
        assert!(u.file == file && u.reason.contains(why), "{u:?}");
    }
    write(&d.join("c.obj"), &obj_cubes(&[([0.0; 3], 1.0)]));
    let m =
        urdf_message(load_at(&d, "r.urdf", &urdf_with_mesh("c.obj", Some("1 0 1")), &MeshOptions::default()));
    assert!(m.contains("scale"), "{m}");
}

#[test]
fn size_and_count_bounds_are_enforced() {
    let d = tmp("bounds");
    let tris = cube_triangles([0.0; 3], 1.0);
    write(&d.join("c.stl"), &binary_stl(&tris));
    write(&d.join("a.stl"), &ascii_stl(&tris));
    write(&d.join("two.obj"), &obj_cubes(&[([0.0; 3], 1.0), ([3.0, 0.0, 0.0], 1.0)]));
    let opts = MeshOptions::default();
    let src = |limits| MeshSource { dir: d.clone(), options: &opts, limits, read: Default::default() };
    let small = |f: fn(&mut Limits)| {
        let mut l = Limits::DEFAULT;
        f(&mut l);
        l
    };
    let e = src(small(|l| l.bytes = 100)).load("c.stl").unwrap_err();
    assert!(e.contains("more than the 100 bytes") && e.contains("c.stl"), "{e}");
    // All files of a chain together are bounded too.
    let full = src(Limits::DEFAULT);
    full.read.set(MAX_MESH_TOTAL_BYTES - 100);
    let e = full.load("c.stl").unwrap_err();
    assert!(e.contains("left of the") && e.contains("c.stl"), "{e}");
    let e = src(small(|l| l.triangles = 11)).load("c.stl").unwrap_err();
    assert!(e.contains("more than 11 triangles"), "{e}");
    let e = src(small(|l| l.triangles = 11)).load("a.stl").unwrap_err();
    assert!(e.contains("more than 11 triangles"), "{e}");
    let e = src(small(|l| l.vertices = 15)).load("two.obj").unwrap_err();
    assert!(e.contains("more than 15 vertices"), "{e}");
    let e = src(small(|l| l.parts = 1)).load("two.obj").unwrap_err();
    assert!(e.contains("more than 1 parts"), "{e}");
    assert_eq!(src(small(|l| l.triangles = 12)).load("c.stl").unwrap()[0].len(), 36);
    // A binary STL whose header claims more triangles than the file holds is not binary.
    let mut lying = binary_stl(&tris);
    lying[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(parse_stl(&lying, &Limits::DEFAULT).unwrap_err().contains("neither binary STL"));
    assert_eq!(MAX_MESH_BYTES, 64 << 20);
}

#[test]
fn package_urls_resolve_through_each_rule() {
    let d = tmp("pkg");
    let cube = binary_stl(&cube_triangles([0.0; 3], 1.0));
    let url = "package://arm_description/meshes/l1.stl";
    // 1. robot.package_paths: a folder holding package folders.
    write(&d.join("pp/arm_description/meshes/l1.stl"), &cube);
    // 2. ROS_PACKAGE_PATH: the same, elsewhere.
    write(&d.join("ros/arm_description/meshes/l1.stl"), &cube);
    let urdf = urdf_with_mesh(url, None);
    let both = MeshOptions {
        package_paths: vec![d.join("pp")],
        ros_package_path: vec![d.join("ros")],
        missing: MissingCollision::Error,
    };
    let found = |chain: &Chain| chain.collision_shapes().len();
    let at = |opts: &MeshOptions, dir: &Path| {
        let path = dir.join("r.urdf");
        write(&path, urdf.as_bytes());
        let src = MeshSource {
            dir: dir.to_path_buf(),
            options: opts,
            limits: Limits::DEFAULT,
            read: Default::default(),
        };
        (src.resolve(url), Chain::from_urdf_file_with(&path, None, opts).map(|c| found(&c)))
    };
    let elsewhere = d.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let (p, n) = at(&both, &elsewhere);
    assert_eq!((p.unwrap(), n.unwrap()), (d.join("pp/arm_description/meshes/l1.stl"), 1));
    let ros_only = MeshOptions { package_paths: vec![], ..both.clone() };
    assert_eq!(at(&ros_only, &elsewhere).0.unwrap(), d.join("ros/arm_description/meshes/l1.stl"));
    // A ROS_PACKAGE_PATH folder that is the package itself.
    let ros_pkg =
        MeshOptions { ros_package_path: vec![d.join("ros/arm_description")], ..MeshOptions::default() };
    assert_eq!(at(&ros_pkg, &elsewhere).0.unwrap(), d.join("ros/arm_description/meshes/l1.stl"));
    // 3. The URDF's folder and its parents: the URDF inside the package (`pkg/urdf/r.urdf`)...
    let none = MeshOptions::default();
    write(&d.join("ws/src/arm_description/meshes/l1.stl"), &cube);
    let inside = d.join("ws/src/arm_description/urdf");
    std::fs::create_dir_all(&inside).unwrap();
    let (p, n) = at(&none, &inside);
    assert_eq!((p.unwrap(), n.unwrap()), (d.join("ws/src/arm_description/meshes/l1.stl"), 1));
    // ... a package folder beside a parent of the URDF's folder ...
    let beside = d.join("ws/src/other/urdf");
    std::fs::create_dir_all(&beside).unwrap();
    assert_eq!(at(&none, &beside).0.unwrap(), d.join("ws/src/arm_description/meshes/l1.stl"));
    // ... and the path after the package name relative to the URDF (PyBullet's rule).
    let flat = d.join("flat");
    write(&flat.join("meshes/l1.stl"), &cube);
    let (p, n) = at(&none, &flat);
    assert_eq!((p.unwrap(), n.unwrap()), (flat.join("meshes/l1.stl"), 1));
    // Earlier rules win: package_paths over the URDF's own package.
    let pp_first = MeshOptions { package_paths: vec![d.join("pp")], ..MeshOptions::default() };
    assert_eq!(at(&pp_first, &inside).0.unwrap(), d.join("pp/arm_description/meshes/l1.stl"));
}

#[test]
fn paths_out_of_the_allowed_folders_are_refused() {
    let d = tmp("refuse");
    let cube = binary_stl(&cube_triangles([0.0; 3], 1.0));
    let robot = d.join("robot");
    write(&d.join("outside/secret.stl"), &cube);
    write(&robot.join("meshes/ok.stl"), &cube);
    let opts = MeshOptions::default();
    let outside = d.join("outside/secret.stl");
    let abs = outside.display().to_string();
    let file_url = format!("file://{abs}");
    #[cfg(unix)]
    std::os::unix::fs::symlink(&outside, robot.join("meshes/link.stl")).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(d.join("outside"), robot.join("pkgdir")).unwrap();
    let cases: Vec<(&str, &str)> = vec![
        (abs.as_str(), "outside the folders"),
        (file_url.as_str(), "outside the folders"),
        ("/etc/shadow", ""),
        ("../outside/secret.stl", "outside the folders"),
        ("meshes/../../outside/secret.stl", "outside the folders"),
        ("package://robot/../outside/secret.stl", "plain relative names"),
        ("package://x/../../outside/secret.stl", "plain relative names"),
        ("package:///etc/shadow", "plain relative names"),
        #[cfg(unix)]
        ("meshes/link.stl", "outside the folders"),
        #[cfg(unix)]
        ("package://pkgdir/secret.stl", "symbolic link"),
    ];
    for (file, why) in cases {
        let m = urdf_message(load_at(&robot, "r.urdf", &urdf_with_mesh(file, None), &opts));
        assert!(m.contains("link `l1`") && m.contains(why), "{file}: {m}");
    }
    // The same file is read once its folder is a package path.
    let allowed = MeshOptions { package_paths: vec![d.join("outside")], ..MeshOptions::default() };
    let chain = load_at(&robot, "r.urdf", &urdf_with_mesh(&abs, None), &allowed).unwrap();
    assert_eq!(chain.collision_shapes().len(), 1);
    assert_eq!(
        load_at(&robot, "r.urdf", &urdf_with_mesh("meshes/ok.stl", None), &opts)
            .unwrap()
            .collision_shapes()
            .len(),
        1
    );
}

#[test]
fn a_urdf_given_as_text_lists_its_meshes_as_unloaded() {
    let chain = Chain::from_urdf_str(&urdf_with_mesh("meshes/l1.stl", None), None).unwrap();
    assert!(chain.collision_shapes().is_empty());
    assert_eq!(chain.mesh_collision_links(), ["l1"]);
    assert!(chain.unloaded_collision()[0].reason.contains("as text"));
}

/// The capsule around a part holds every hull vertex with its margin to spare, and is thin:
/// for a long box its radius is about the box's half diagonal across, not its half length.
#[test]
fn the_capsule_around_a_part_holds_every_vertex() {
    let mut rng = crate::base::rng::Rng::new(5);
    for case in 0..50 {
        let (len, w) = (rng.uniform_range(0.01, 1.0), rng.uniform_range(0.005, 0.3));
        let pts: Vec<[f64; 3]> = (0..100)
            .map(|_| {
                let p =
                    [len * rng.uniform_range(-0.5, 0.5), w * rng.normal(), w * rng.uniform_range(-1.0, 1.0)];
                // Turned about z by the case's angle.
                let t = case as f64;
                [p[0] * t.cos() - p[1] * t.sin(), p[0] * t.sin() + p[1] * t.cos(), p[2] + 0.3]
            })
            .collect();
        let part = ConvexPart::of_points("p.obj", 0, &pts).unwrap();
        let (a, b, r) = part.capsule_m;
        for p in &part.points_m {
            let (ab, ap) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [p[0] - a[0], p[1] - a[1], p[2] - a[2]]);
            let l2 = ab.iter().map(|x| x * x).sum::<f64>();
            let t = if l2 > 0.0 {
                ((0..3).map(|k| ap[k] * ab[k]).sum::<f64>() / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = (0..3).map(|k| (ap[k] - t * ab[k]).powi(2)).sum::<f64>().sqrt();
            assert!(
                d <= r - 0.99 * CAPSULE_MARGIN_M,
                "case {case}: a vertex {d} m from the axis, radius {r}"
            );
        }
        assert!(r <= part.radius_m + CAPSULE_MARGIN_M + 1e-9, "case {case}: {r} vs sphere {}", part.radius_m);
    }
    // A 1 m x 0.1 m x 0.1 m box: radius about 0.0707 m (+ margin), not 0.5 m.
    let corners: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            [
                if i & 1 == 1 { 0.5 } else { -0.5 },
                if i & 2 == 2 { 0.05 } else { -0.05 },
                if i & 4 == 4 { 0.05 } else { -0.05 },
            ]
        })
        .collect();
    let (_, _, r) = ConvexPart::of_points("box.obj", 0, &corners).unwrap().capsule_m;
    assert!((r - (0.05f64.hypot(0.05) + CAPSULE_MARGIN_M)).abs() < 1e-6, "{r}");
}
