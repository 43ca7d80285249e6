//! End-to-end tests of the `stagerl` binary's fixed interfaces.

use serde_json::Value;
use std::process::{Command, Output, Stdio};

fn stagerl(args: &[&str], stdin: &str) -> Output {
    let child = Command::new(env!("CARGO_BIN_EXE_stagerl"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn stagerl");
    crate::common::feed(child, stdin)
}

fn lines(out: &Output) -> Vec<Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l:?}: {e}")))
        .collect()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn fk_ur5_zero_pose_matches_dh() {
    let out = stagerl(&["fk"], "{\"joints\":[0,0,0,0,0,0]}\n\n{\"joints\":[0,-1.5707963267948966,1.5707963267948966,-1.5707963267948966,-1.5707963267948966,0]}\n");
    assert!(out.status.success(), "{}", stderr(&out));
    let v = lines(&out);
    assert_eq!(v.len(), 2, "one output line per input line, blank lines skipped");
    let obj = v[0].as_object().unwrap();
    assert_eq!(obj.keys().collect::<Vec<_>>(), ["position", "quaternion"]);
    // Standard DH at q = 0: x = a2 + a3, y = -(d4 + d6), z = d1 - d5; R = Rx(pi/2).
    let p: Vec<f64> = v[0]["position"].as_array().unwrap().iter().map(f).collect();
    for (got, want) in p.iter().zip([-0.81725, -0.19145, -0.005491]) {
        assert!((got - want).abs() < 1e-12, "{p:?}");
    }
    let q: Vec<f64> = v[0]["quaternion"].as_array().unwrap().iter().map(f).collect();
    let h = std::f64::consts::FRAC_1_SQRT_2;
    for (got, want) in q.iter().zip([h, 0.0, 0.0, h]) {
        assert!((got - want).abs() < 1e-12, "{q:?}");
    }
    // Home pose: (-0.4869, -0.10915, 0.431859).
    let p: Vec<f64> = v[1]["position"].as_array().unwrap().iter().map(f).collect();
    for (got, want) in p.iter().zip([-0.4869, -0.10915, 0.431859]) {
        assert!((got - want).abs() < 1e-12, "{p:?}");
    }
}

#[test]
fn fk_accepts_a_urdf_path_and_tip() {
    let dir = std::env::temp_dir().join(format!("stagerl-cli-fk-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("two.urdf");
    std::fs::write(
        &path,
        r#"<robot name="two">
  <link name="base"/><link name="l1"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="prismatic"><parent link="l1"/><child link="tip"/>
    <origin xyz="0.5 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.3" effort="1" velocity="0.2"/></joint>
</robot>"#,
    )
    .unwrap();
    let out = stagerl(
        &["fk", "--robot", path.to_str().unwrap(), "--tip", "tip"],
        "{\"joints\":[1.5707963267948966, 0.1]}\n",
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let v = lines(&out);
    let p: Vec<f64> = v[0]["position"].as_array().unwrap().iter().map(f).collect();
    assert!(p[0].abs() < 1e-12 && (p[1] - 0.6).abs() < 1e-12 && p[2].abs() < 1e-12, "{p:?}");
    let out = stagerl(&["fk", "--robot", path.to_str().unwrap(), "--tip", "nope"], "");
    assert!(!out.status.success());
    assert!(stderr(&out).contains("nope"), "{}", stderr(&out));
    std::fs::remove_dir_all(&dir).ok();
}

/// The axis-aligned cube of side `side` centred at the origin, as an OBJ file.
fn cube_obj(side: f64) -> String {
    let h = side / 2.0;
    let mut obj = String::from("o cube\n");
    for i in 0..8 {
        let p = [0, 1, 2].map(|k| if i >> k & 1 == 1 { h } else { -h });
        obj.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for f in ["1 2 4 3", "5 7 8 6", "1 5 6 2", "3 4 8 7", "1 3 7 5", "2 6 8 4"] {
        obj.push_str(&format!("f {f}\n"));
    }
    obj
}

/// `fk --collisions` on an arm of mesh links: a 0.1 m cube lifted along z (prismatic joint
/// `lift`, origin 0.5 m up) above a 0.2 m cube at the base. The gap between them is
/// `0.35 + lift` m, the lifted cube's bottom is `0.45 + lift` m above the floor.
#[test]
fn fk_collisions_reports_contacts_and_clearance_of_mesh_links() {
    let dir = std::env::temp_dir().join(format!("stagerl-cli-fk-mesh-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("robot/meshes")).unwrap();
    std::fs::create_dir_all(dir.join("pkgs/parts")).unwrap();
    std::fs::write(dir.join("robot/meshes/base.obj"), cube_obj(0.2)).unwrap();
    std::fs::write(dir.join("pkgs/parts/small.obj"), cube_obj(0.1)).unwrap();
    let path = dir.join("robot/lift.urdf");
    std::fs::write(
        &path,
        r#"<robot name="lift">
  <link name="base"><collision><geometry><mesh filename="meshes/base.obj"/></geometry></collision></link>
  <link name="turn"/>
  <link name="lifted"><collision><geometry><mesh filename="package://parts/small.obj"/></geometry></collision></link>
  <joint name="turn" type="revolute"><parent link="base"/><child link="turn"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1"/></joint>
  <joint name="lift" type="prismatic"><parent link="turn"/><child link="lifted"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 0 1"/><limit lower="-0.6" upper="0.2" velocity="1"/></joint>
</robot>"#,
    )
    .unwrap();
    let (robot, pkgs) = (path.to_str().unwrap(), dir.join("pkgs"));
    let args = ["fk", "--robot", robot, "--package-path", pkgs.to_str().unwrap(), "--collisions"];
    let out = stagerl(&args, "{\"joints\":[0.3, 0]}\n{\"joints\":[1, -0.4]}\n{\"joints\":[0, -0.47]}\n");
    assert!(out.status.success(), "{}", stderr(&out));
    let v = lines(&out);
    assert_eq!(v.len(), 3);
    let clearance: Vec<f64> = v.iter().map(|l| f(&l["clearance_m"])).collect();
    for (c, want) in clearance.iter().zip([0.35, -0.05, -0.12]) {
        assert!((c - want).abs() < 1e-4, "{clearance:?}");
    }
    assert_eq!(v[0]["contacts"], serde_json::json!([]));
    assert_eq!(v[1]["contacts"], serde_json::json!([{"with": "self", "links": ["base", "lifted"]}]));
    assert_eq!(
        v[2]["contacts"],
        serde_json::json!([{"with": "floor", "link": "lifted"}, {"with": "self", "links": ["base", "lifted"]}])
    );
    assert!((f(&v[1]["position"][2]) - 0.1).abs() < 1e-12);
    // Without --collisions the lines are as before.
    let out = stagerl(&args[..5], "{\"joints\":[0, 0]}\n");
    assert!(lines(&out)[0].get("contacts").is_none() && lines(&out)[0].get("clearance_m").is_none());
    // ROS_PACKAGE_PATH is searched too.
    let out = Command::new(env!("CARGO_BIN_EXE_stagerl"))
        .args(["fk", "--robot", robot, "--collisions"])
        .env("ROS_PACKAGE_PATH", format!("/no/such/dir:{}", pkgs.display()))
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    // Without the package path the mesh is not found: an error naming the link and the file.
    let out = Command::new(env!("CARGO_BIN_EXE_stagerl"))
        .args(["fk", "--robot", robot])
        .env_remove("ROS_PACKAGE_PATH")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = stderr(&out);
    assert!(
        !out.status.success() && err.contains("`lifted`") && err.contains("package://parts/small.obj"),
        "{err}"
    );
    // An arm without collision shapes has nothing to check.
    std::fs::write(
        &path,
        r#"<robot name="bare"><link name="a"/><link name="b"/>
  <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1"/></joint></robot>"#,
    )
    .unwrap();
    let out = stagerl(&["fk", "--robot", robot, "--collisions"], "");
    assert!(!out.status.success() && stderr(&out).contains("no collision shapes"), "{}", stderr(&out));
    std::fs::remove_dir_all(&dir).ok();
}

/// `stagerl robot` on a three-joint arm of mesh links prints the chain, the shapes per link with
/// their files and the self-collision pairs, and `--config-out` writes a config that trains.
#[test]
fn robot_prints_the_arm_and_writes_a_config_that_trains() {
    let dir = std::env::temp_dir().join(format!("stagerl-cli-robot-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("robot/meshes")).unwrap();
    std::fs::create_dir_all(dir.join("pkgs/parts")).unwrap();
    std::fs::write(dir.join("robot/meshes/base.obj"), cube_obj(0.2)).unwrap();
    std::fs::write(dir.join("pkgs/parts/small.obj"), cube_obj(0.1)).unwrap();
    let path = dir.join("robot/arm.urdf");
    let link = |name: &str| {
        format!(
            r#"<link name="{name}"><collision><origin xyz="0.15 0 0"/><geometry><mesh filename="package://parts/small.obj" scale="3 1 1"/></geometry></collision></link>"#
        )
    };
    let urdf = format!(
        r#"<robot name="arm">
  <link name="base"><collision><geometry><mesh filename="meshes/base.obj"/></geometry></collision></link>
  <link name="l1"/>{}{}<link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/><limit lower="-2" upper="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" velocity="1"/></joint>
  <joint name="jt" type="fixed"><parent link="l3"/><child link="tip"/><origin xyz="0.3 0 0"/></joint>
</robot>"#,
        link("l2"),
        link("l3")
    );
    std::fs::write(&path, urdf).unwrap();
    let (cfg, pkgs) = (dir.join("arm.toml"), dir.join("pkgs"));
    // The URDF as the positional argument (`stagerl robot URDF`), the same as `--robot URDF`.
    let args = ["robot", path.to_str().unwrap(), "--package-path", pkgs.to_str().unwrap()];
    let out = stagerl(&[&args[..], &["--config-out", cfg.to_str().unwrap()]].concat(), "");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{}", stderr(&out));
    for want in [
        "chain: `base` -> `tip`, 3 actuated joints",
        "joint `j2` revolute: [-2, 1] rad, speed 1 rad/s",
        "link `base`: 1 shape(s): convex (8 hull vertices) from `meshes/base.obj`",
        "link `l3`: 1 shape(s): convex (8 hull vertices) from `package://parts/small.obj`",
        "self-collision pairs (links two or more joints apart): base-l2, base-l3",
        "home_pose_rad = [0.0, -0.5, 0.0]",
    ] {
        assert!(text.contains(want), "{want:?} not in:\n{text}");
    }
    let written = std::fs::read_to_string(&cfg).unwrap();
    assert!(written.contains("[task]") && written.contains("package_paths"), "{written}");
    let both = stagerl(&["robot", path.to_str().unwrap(), "--robot", "ur5"], "");
    assert!(!both.status.success() && stderr(&both).contains("cannot be used with"), "{}", stderr(&both));
    let run = dir.join("run");
    let out = stagerl(
        &[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--episodes",
            "2",
            "--eval-trials",
            "2",
            "--out",
            run.to_str().unwrap(),
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("warning"), "{}", stderr(&out));
    std::fs::remove_dir_all(&dir).ok();
}

/// A run on an arm without any collision shape says so before it starts (its demonstrations too).
#[test]
fn train_warns_when_the_arm_has_no_collision_shape() {
    let dir = std::env::temp_dir().join(format!("stagerl-cli-bare-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("bare.urdf"),
        r#"<robot name="bare"><link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" velocity="1"/></joint>
</robot>"#,
    )
    .unwrap();
    let cfg = dir.join("bare.toml");
    let urdf = dir.join("bare.urdf").display().to_string();
    let toml = format!(
        "[robot]\nurdf = {urdf:?}\n[task]\nhome_pose_rad = [0.0, 0.0]\ntarget_joint_range_rad = [1.0, 0.5]\n\
         [train.demonstrations]\nepisodes = 3\n"
    );
    std::fs::write(&cfg, toml).unwrap();
    let run = dir.join("run");
    let out = stagerl(
        &[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--episodes",
            "1",
            "--eval-trials",
            "1",
            "--out",
            run.to_str().unwrap(),
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("no link of `a` to `c` has a collision shape") && err.contains("NOT checked"),
        "{err}"
    );
    // Episodes and the evaluation record no collision count: not a 0.
    let episodes = std::fs::read_to_string(run.join("episodes.csv")).unwrap();
    let row: Vec<&str> = episodes.lines().nth(1).unwrap().split(',').collect();
    assert_eq!(row[6], "", "{episodes}");
    assert!(String::from_utf8_lossy(&out.stdout).contains("collisions not checked"), "{out:?}");
    // Nor do the planner's demonstrations claim 0 contacts.
    let demos = String::from_utf8_lossy(&out.stdout)
        .lines()
        .find(|l| l.starts_with("demonstrations:"))
        .map(str::to_owned);
    assert!(demos.as_deref().is_some_and(|l| l.contains("contacts not checked")), "{out:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn fk_malformed_lines_report_their_number() {
    let cases = [
        ("{\"joints\":[0,0,0,0,0,0]}\n{\"joints\":[0,0,0]}\n", "line 2", "6"),
        ("{\"joints\":[0,0,0,0,0,0]}\n\n{\"joint\":[0,0,0,0,0,0]}\n", "line 3", "joint"),
        ("not json\n", "line 1", "malformed"),
        ("{\"joints\":[0,0,0,0,0,\"x\"]}\n", "line 1", "malformed"),
        ("{\"joints\":[0,0,0,0,0,1e999]}\n", "line 1", ""),
    ];
    for (input, where_, what) in cases {
        let out = stagerl(&["fk"], input);
        assert!(!out.status.success(), "{input:?} should fail");
        let err = stderr(&out);
        assert!(err.contains(where_) && err.contains(what), "{input:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let out = stagerl(&["fk", "--robot", "/no/such.urdf"], "");
    assert!(!out.status.success());
    assert!(stderr(&out).contains("/no/such.urdf"));
}

const REWARD_KEYS: [&str; 12] = [
    "distance",
    "reached",
    "position",
    "direction",
    "posture",
    "move",
    "stride",
    "alpha1",
    "alpha2",
    "reward",
    "bonus",
    "total",
];

#[test]
fn reward_lines_hand_computed() {
    // Axis +z, target 0.3 m along +x: phi = pi/2 -> direction 1/4. V = 1 rad/s each -> move 0.05.
    let (s, c) = (0.5f64.sin(), 0.5f64.cos());
    let line = format!(
        "{{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,{s},{c}],\"target\":[0.3,0,0],\"joint_vel\":[1,1,1,1,1,1]}}\n"
    );
    let expect = [
        ("basic", 0.0),
        ("posture", -0.3 - 0.25),
        ("stride", -0.3 - 0.05),
        ("har", -0.3 - 0.05),
        ("sar", 0.7 * -0.35 + 0.3 * -0.55),
    ];
    for (function, want) in expect {
        let out = stagerl(&["reward", "--function", function], &line);
        assert!(out.status.success(), "{}", stderr(&out));
        let v = lines(&out);
        let obj = v[0].as_object().unwrap();
        let mut keys: Vec<&str> = obj.keys().map(String::as_str).collect();
        keys.sort_unstable();
        let mut want_keys = REWARD_KEYS.to_vec();
        want_keys.sort_unstable();
        assert_eq!(keys, want_keys, "exactly the specified keys");
        // And in the specified order on the wire.
        let raw = String::from_utf8_lossy(&out.stdout).into_owned();
        let pos: Vec<usize> = REWARD_KEYS.iter().map(|k| raw.find(&format!("\"{k}\":")).unwrap()).collect();
        assert!(pos.windows(2).all(|w| w[0] < w[1]), "{raw}");
        assert!((f(&v[0]["reward"]) - want).abs() < 1e-12, "{function}: {}", v[0]);
        assert!((f(&v[0]["total"]) - want).abs() < 1e-12);
        assert_eq!(v[0]["reached"], Value::Bool(false));
        assert!((f(&v[0]["direction"]) - 0.25).abs() < 1e-12);
        assert!((f(&v[0]["move"]) - 0.05).abs() < 1e-12);
        assert!((f(&v[0]["alpha1"]) - 0.7).abs() < 1e-12);
    }
    // Reached: bonus 20, total = reward + bonus.
    let out = stagerl(
        &["reward", "--function", "stride"],
        "{\"ee_pos\":[0.1,0.2,0.3],\"ee_quat\":[0,0,0,1],\"target\":[0.1,0.2,0.305],\"joint_vel\":[0,0,0,0,0,0]}\n",
    );
    let v = lines(&out);
    assert_eq!(v[0]["reached"], Value::Bool(true));
    assert_eq!(f(&v[0]["bonus"]), 20.0);
    assert!((f(&v[0]["total"]) - (1.0 - 0.005 + 20.0)).abs() < 1e-12);
}

#[test]
fn reward_uses_the_config_constants() {
    let dir = std::env::temp_dir().join(format!("stagerl-cli-reward-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("c.toml");
    std::fs::write(&cfg, "[task]\ndt_s = 0.1\n[reward]\nbeta_m = 0.05\nsuccess_bonus = 5\n").unwrap();
    let out = stagerl(
        &["reward", "--function", "stride", "--config", cfg.to_str().unwrap()],
        "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.04,0,0],\"joint_vel\":[2,0,0,0,0,0]}\n",
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let v = lines(&out);
    assert_eq!(v[0]["reached"], Value::Bool(true));
    assert_eq!(f(&v[0]["bonus"]), 5.0);
    assert!((f(&v[0]["move"]) - 0.1 * 4.0 / 6.0).abs() < 1e-12);
    std::fs::write(&cfg, "[reward]\nbeta_m = -1\n").unwrap();
    let out = stagerl(&["reward", "--function", "sar", "--config", cfg.to_str().unwrap()], "");
    assert!(!out.status.success());
    assert!(stderr(&out).contains("reward.beta_m"), "{}", stderr(&out));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn reward_malformed_lines_report_their_number() {
    let good =
        "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n";
    let cases = [
        (format!("{good}{{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0]}}\n"), "line 2", "joint_vel"),
        (format!("{good}{good}{{\"ee_pos\":[0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0],\"joint_vel\":[0]}}\n"), "line 3", "malformed"),
        ("{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,2],\"target\":[0.3,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n".to_string(), "line 1", "norm"),
        ("{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0],\"joint_vel\":[]}\n".to_string(), "line 1", "joint_vel"),
        ("[1,2,3]\n".to_string(), "line 1", "malformed"),
    ];
    for (input, where_, what) in &cases {
        let out = stagerl(&["reward", "--function", "sar"], input);
        assert!(!out.status.success(), "{input:?} should fail");
        let err = stderr(&out);
        assert!(err.contains(where_) && err.contains(what), "{input:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    // The lines before the bad one were answered.
    let out = stagerl(&["reward", "--function", "sar"], &cases[1].0);
    assert_eq!(lines(&out).len(), 2);
    // Unknown reward function: clap error listing what is allowed.
    let out = stagerl(&["reward", "--function", "sparse"], "");
    assert!(!out.status.success());
    assert!(stderr(&out).contains("basic, posture, stride, har, sar"), "{}", stderr(&out));
}

#[test]
fn demo_runs_and_reaches() {
    let out = stagerl(&["demo", "--trials", "50", "--seed", "3"], "");
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("reached after"), "{text}");
    assert!(text.contains("success 100.0 %"), "{text}");
}

#[test]
fn bench_env_prints_a_json_line() {
    let out = stagerl(&["bench", "env", "--steps", "20000"], "");
    assert!(out.status.success(), "{}", stderr(&out));
    let last = String::from_utf8_lossy(&out.stdout).lines().last().unwrap().to_string();
    let v: Value = serde_json::from_str(&last).unwrap();
    assert!(f(&v["steps_per_sec"]) > 0.0);
}

/// `bench env --num-envs`: a vector env's rewards (their checksum) are those of one thread on two.
#[test]
fn bench_env_times_a_vector_env_on_any_thread_count() {
    let checksum = |threads: &str| {
        let out =
            stagerl(&["bench", "env", "--steps", "40000", "--num-envs", "40", "--threads", threads], "");
        assert!(out.status.success(), "{}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        assert!(
            text.contains("a vector env of 40 environments, 1000 calls (40000 environment steps)"),
            "{text}"
        );
        let v: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
        assert!(f(&v["steps_per_sec"]) > 0.0);
        text.split("checksum ").nth(1).unwrap().split(')').next().unwrap().to_string()
    };
    assert_eq!(checksum("1"), checksum("2"));
}

#[test]
fn unwritable_output_directory_is_refused_before_training() {
    // Paths no process can create, root included: under a regular file, and inside /proc.
    let file = std::env::temp_dir().join(format!("stagerl-cli-notadir-{}", std::process::id()));
    std::fs::write(&file, b"x").unwrap();
    let under_file = file.join("run");
    for out in [under_file.to_str().unwrap(), "/proc/stagerl-run"] {
        let o = stagerl(&["train", "--episodes", "100000", "--out", out], "");
        assert!(!o.status.success(), "{out}");
        let err = stderr(&o);
        assert!(err.contains(out) && !err.contains("panicked"), "{out}: {err}");
        // `train` announces "training ..." once it starts: it must not have got there.
        assert!(!String::from_utf8_lossy(&o.stdout).contains("training "), "refused before training");
    }
    std::fs::remove_file(&file).ok();
}

#[test]
fn help_lists_the_allowed_values_of_every_enumerated_option() {
    let algos = "[possible values: ddpg, td3, sac, ppo, crossq]";
    let rewards = "[possible values: basic, posture, stride, har, sar]";
    for (args, wanted) in [
        (&["train", "--help"][..], &[algos, rewards, "[possible values: future, final, episode]"][..]),
        (&["reward", "--help"], &[rewards]),
        (&["bench", "update", "--help"], &[algos]),
        (&["bench", "env", "--help"], &[rewards]),
        (
            &["plan", "--help"],
            &["[possible values: csv, jsonl]", "- jacobian: The damped-least-squares Jacobian controller"],
        ),
    ] {
        let out = stagerl(args, "");
        let text = String::from_utf8_lossy(&out.stdout).split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(out.status.success(), "{args:?}");
        for w in wanted {
            assert!(text.contains(w), "{args:?} --help lacks {w}: {text}");
        }
    }
}

/// `train --threads 2` trains the same run as one thread (wide networks, so the products are
/// split and the twin critics run at once), and a thread count outside 1..=64 is refused.
#[test]
fn threads_change_nothing_but_the_speed() {
    let dir = std::env::temp_dir().join(format!("stagerl-cli-threads-{}", std::process::id()));
    let config = dir.join("wide.toml");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(&config, "[agent]\nhidden = [128, 128]\nlearning_starts = 200\n").unwrap();
    let mut runs = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.join(format!("sac-{threads}"));
        let args = ["train", "--algo", "sac", "--episodes", "20", "--eval-trials", "5", "--threads", threads];
        let o = stagerl(
            &[&args[..], &["--config", config.to_str().unwrap(), "--out", out.to_str().unwrap()]].concat(),
            "",
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let csv = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
        // Every column but the wall time.
        runs.push(csv.lines().map(|l| l.rsplit_once(',').unwrap().0.to_string()).collect::<Vec<_>>());
    }
    assert_eq!(runs[0].len(), 21);
    assert_eq!(runs[0], runs[1], "--threads 2 trained another run");
    for bad in ["0", "65", "x"] {
        let o = stagerl(&["train", "--threads", bad, "--out", dir.join("never").to_str().unwrap()], "");
        assert!(!o.status.success());
        assert!(stderr(&o).contains("--threads") && !dir.join("never").exists(), "{bad}: {}", stderr(&o));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `--env-steps N` trains until N environment steps whatever the episode count (the run ends
/// with the episode in which the N-th step falls), `--eval-every-env-steps K` evaluates after
/// each episode that passes a multiple of K and after the last; bad values are refused naming
/// the field, and `--episodes` with `--env-steps` is refused.
#[test]
fn an_env_step_budget_ends_the_run_by_environment_steps() {
    let dir = crate::common::scratch("env-steps");
    let out = dir.join("run");
    let o = stagerl(
        &[
            "train",
            "--algo",
            "sac",
            "--env-steps",
            "1000",
            "--eval-every-env-steps",
            "400",
            "--eval-trials",
            "3",
            "--out",
            out.to_str().unwrap(),
        ],
        "",
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("1000 environment steps"));
    let col = |file: &str, name: &str| -> Vec<u64> {
        let text = std::fs::read_to_string(out.join(file)).unwrap();
        let mut lines = text.lines();
        let i = lines.next().unwrap().split(',').position(|h| h == name).unwrap();
        lines.map(|l| l.split(',').nth(i).unwrap().parse().unwrap()).collect()
    };
    let steps = col("episodes.csv", "env_steps");
    let (last, before) = (steps[steps.len() - 1], steps[steps.len() - 2]);
    assert!(before < 1000 && last >= 1000, "the run ends with the episode reaching 1000: {before}, {last}");
    assert!(steps.len() >= 20, "at most 50 steps an episode: {} episodes", steps.len());
    // One evaluation after each episode passing 400 and 800, and one after the last.
    let first_past = |k: u64| *steps.iter().find(|&&s| s >= k).unwrap();
    assert_eq!(col("eval.csv", "env_steps"), vec![first_past(400), first_past(800), last]);
    let never = dir.join("never");
    for (args, field) in [
        (&["--env-steps", "0"][..], "train.env_steps"),
        (&["--eval-every-env-steps", "0"][..], "train.eval_every_env_steps"),
    ] {
        let mut all = vec!["train", "--out", never.to_str().unwrap()];
        all.extend_from_slice(args);
        let o = stagerl(&all, "");
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("`{field}` = 0 is invalid")), "{}", stderr(&o));
    }
    let o = stagerl(
        &["train", "--episodes", "5", "--env-steps", "100", "--out", dir.join("never").to_str().unwrap()],
        "",
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
    assert!(!never.exists());
    std::fs::remove_dir_all(&dir).ok();
}
