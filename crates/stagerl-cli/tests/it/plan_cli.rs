//! `stagerl plan` end to end, on a short trained SAC run made here and with the Jacobian
//! controller: the trajectory agrees with `stagerl fk` and with its own joint velocities, the
//! summary with the rows, CSV with JSON lines, batch mode with single plans; bad input is an
//! error naming it, never a panic.

use crate::common;

use common::{bin, run, scratch};
use serde_json::Value;
use stagerl::agent::Algo;
use stagerl::config::Config;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

/// A SAC run of 150 episodes with small networks, trained once for all tests.
fn trained_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = scratch("plan-run").join("sac");
        let mut cfg = Config::default();
        cfg.agent.algo = Algo::Sac;
        cfg.agent.hidden = vec![32, 32];
        cfg.agent.batch_size = 64;
        cfg.agent.learning_starts = 500;
        cfg.train.episodes = 150;
        cfg.train.eval_every_episodes = 50;
        cfg.train.eval_trials = 20;
        cfg.train.seed = 3;
        stagerl::train::train(&cfg, &dir, |_| {}).unwrap();
        dir
    })
}

fn stdout_of(o: &Output) -> String {
    assert!(o.status.success(), "failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout.clone()).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn with_stdin(args: &[&str], input: &str) -> Output {
    common::feed(common::spawn_piped(bin().args(args)), input)
}

/// `stagerl fk` of joint positions.
fn fk(q: &[f64]) -> Vec<f64> {
    let line = serde_json::json!({ "joints": q }).to_string();
    let out: Value = serde_json::from_str(stdout_of(&with_stdin(&["fk"], &(line + "\n"))).trim()).unwrap();
    floats(&out["position"])
}

/// The rows and the summary of a JSON-lines plan, checked for the invariants of the issue.
fn check_jsonl(text: &str) -> (Vec<Value>, Value) {
    let mut rows: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert!(text.lines().last().unwrap().starts_with("{\"summary\":{\"reached\":"));
    let summary = rows.pop().unwrap()["summary"].clone();
    let keys: Vec<&str> = summary.as_object().unwrap().keys().map(String::as_str).collect();
    for k in ["reached", "steps", "final_distance", "episode_reward", "path_length_m", "joint_travel_rad"] {
        assert!(keys.contains(&k), "{k} missing from {summary}");
    }
    assert_eq!(rows.len() as u64, summary["steps"].as_u64().unwrap() + 1);
    assert!(floats(&rows[0]["joint_vel"]).iter().all(|&v| v == 0.0));
    assert_eq!(rows[0]["reward"].as_f64(), Some(0.0));
    let (dt, limit) = (0.05, std::f64::consts::PI);
    for (k, pair) in rows.windows(2).enumerate() {
        assert_eq!(pair[1]["step"].as_u64(), Some(k as u64 + 1));
        let (q0, q1, v) = (floats(&pair[0]["q"]), floats(&pair[1]["q"]), floats(&pair[1]["joint_vel"]));
        for i in 0..q0.len() {
            if q1[i].abs() < limit {
                assert!((q1[i] - (q0[i] + v[i] * dt)).abs() <= 1e-12, "row {} joint {i}", k + 1);
            }
        }
    }
    let last = rows.last().unwrap();
    let p = fk(&floats(&last["q"]));
    let ee = floats(&last["ee_pos"]);
    assert!(p.iter().zip(&ee).all(|(a, b)| (a - b).abs() <= 1e-9), "fk {p:?}, plan {ee:?}");
    let d = last["distance"].as_f64().unwrap();
    assert_eq!(summary["final_distance"].as_f64(), Some(d));
    assert_eq!(summary["reached"].as_bool(), Some(d < 0.01), "{summary}");
    (rows, summary)
}

#[test]
fn a_trained_policy_plans_consistent_trajectories() {
    let run_dir = trained_run().to_str().unwrap();
    let mut reached = 0;
    for (target, start) in [
        ("-0.45,-0.1,0.4", None),
        ("-0.5,0.15,0.3", None),
        ("-0.35,-0.3,0.45", Some("0.1,-1.4,1.4,-1.6,-1.5,0")),
        ("-0.55,0.0,0.25", None),
    ] {
        let mut args = vec!["plan", "--run", run_dir, "--target", target];
        if let Some(s) = start {
            args.extend(["--start", s]);
        }
        let out = run(&args);
        let (rows, summary) = check_jsonl(&stdout_of(&out));
        if let Some(s) = start {
            let q: Vec<f64> = s.split(',').map(|x| x.parse().unwrap()).collect();
            assert_eq!(floats(&rows[0]["q"]), q);
        }
        reached += usize::from(summary["reached"].as_bool().unwrap());
    }
    // --max-steps bounds a plan.
    let out = run(&["plan", "--run", run_dir, "--target", "-0.5,0.15,0.3", "--max-steps", "3"]);
    let (rows, summary) = check_jsonl(&stdout_of(&out));
    assert!(rows.len() <= 4 && summary["steps"].as_u64().unwrap() <= 3, "{summary}");
    // Plans that end at the target and plans that run out of steps both keep the invariants;
    // this run reaches some targets.
    eprintln!("reached {reached} of 4");
}

#[test]
fn csv_and_jsonl_carry_the_same_numbers() {
    let run_dir = trained_run().to_str().unwrap();
    for base in [vec!["plan", "--run", run_dir], vec!["plan", "--controller", "jacobian"]] {
        let args = |f: &'static str| [&base[..], &["--target", "-0.4,0.1,0.35", "--format", f]].concat();
        let json = stdout_of(&run(&args("jsonl")));
        let (rows, summary) = check_jsonl(&json);
        let csv_out = run(&args("csv"));
        let csv = stdout_of(&csv_out);
        let stderr = String::from_utf8(csv_out.stderr).unwrap();
        let mut summary_line: Value = serde_json::from_str(stderr.trim()).unwrap();
        let (mut summary, mut csv_summary) = (summary, summary_line["summary"].take());
        // Everything but the wall time agrees.
        assert!(summary["plan_time_s"].as_f64().unwrap() > 0.0);
        summary["plan_time_s"] = Value::Null;
        csv_summary["plan_time_s"] = Value::Null;
        assert_eq!(csv_summary, summary);
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(header[..4], ["step", "t_s", "q0", "q1"]);
        assert_eq!(header.len(), 2 + 6 + 6 + 3 + 4 + 2);
        let mut n = 0;
        for (line, row) in lines.zip(&rows) {
            let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            let mut expect = vec![row["step"].as_f64().unwrap(), row["t_s"].as_f64().unwrap()];
            for key in ["q", "joint_vel", "ee_pos", "ee_quat"] {
                expect.extend(floats(&row[key]));
            }
            expect.extend([row["distance"].as_f64().unwrap(), row["reward"].as_f64().unwrap()]);
            assert!(v.iter().zip(&expect).all(|(a, b)| a.to_bits() == b.to_bits()), "{line}");
            n += 1;
        }
        assert_eq!(n, rows.len());
    }
}

#[test]
fn batch_mode_equals_single_plans() {
    let run_dir = trained_run().to_str().unwrap();
    let requests = [
        ("[-0.45,-0.1,0.4]", None),
        ("[-0.5,0.15,0.3]", Some("[0.1,-1.4,1.4,-1.6,-1.5,0]")),
        ("[-0.4,0.1,0.35]", None),
    ];
    for base in [vec!["plan", "--run", run_dir], vec!["plan", "--controller", "jacobian"]] {
        let mut input = String::new();
        for (t, s) in requests {
            match s {
                Some(s) => input.push_str(&format!("{{\"target\":{t},\"start\":{s}}}\n")),
                None => input.push_str(&format!("{{\"target\":{t}}}\n")),
            }
        }
        let file = scratch("plan-batch").join("targets.jsonl");
        std::fs::write(&file, &input).unwrap();
        let from_stdin = stdout_of(&with_stdin(&[&base[..], &["--targets", "-"]].concat(), &input));
        let from_file = stdout_of(&run(&[&base[..], &["--targets", file.to_str().unwrap()]].concat()));
        // Everything but the wall time agrees.
        let untimed = |text: &str| -> Vec<Value> {
            let mut v: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
            v.iter_mut().for_each(|p| p["plan_time_s"] = Value::Null);
            v
        };
        assert_eq!(untimed(&from_stdin), untimed(&from_file));
        let lines: Vec<Value> = from_stdin.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        assert_eq!(lines.len(), requests.len());
        for ((t, s), b) in requests.iter().zip(&lines) {
            let target = t.trim_matches(['[', ']']);
            let mut args = [&base[..], &["--target", target]].concat();
            let start = s.map(|s| s.trim_matches(['[', ']']).to_string());
            if let Some(s) = &start {
                args.extend(["--start", s.as_str()]);
            }
            let (rows, summary) = check_jsonl(&stdout_of(&run(&args)));
            for k in ["reached", "steps", "final_distance", "episode_reward", "collision", "min_clearance_m"]
            {
                assert_eq!(b[k], summary[k], "{k}");
            }
            let q: Vec<Value> = rows.iter().map(|r| r["q"].clone()).collect();
            let ee: Vec<Value> = rows.iter().map(|r| r["ee_pos"].clone()).collect();
            assert_eq!(b["q"], Value::Array(q));
            assert_eq!(b["ee_pos"], Value::Array(ee));
            let keys: Vec<&str> = b.as_object().unwrap().keys().map(String::as_str).collect();
            assert_eq!(keys.len(), 9, "{keys:?}");
        }
    }
}

/// A failed command: exit code 1 (an error, not a panic's 101), the message on stderr.
fn failure(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let run_dir = trained_run().to_str().unwrap();
    let cases: &[(&[&str], &str, &[&str])] = &[
        (&["--target", "3,0,0.5"], "", &["[3, 0, 0.5]", "out of reach", "reaches at most 1.1925 m"]),
        (&["--target", "0.3,0.2,-0.05"], "", &["[0.3, 0.2, -0.05]", "below the floor", "reaches at most"]),
        (&["--target", "0.3,0.2"], "", &["target has 2 values, expected 3"]),
        (&["--target", "0.3,0.2,0.4,0.1"], "", &["target has 4 values, expected 3"]),
        (&["--target", "0.3,abc,0.4"], "", &["--target", "`abc` is not a number"]),
        (&["--target", "-0.4,0.1,0.35", "--start", "0,0,0"], "", &["start pose has 3 values, expected 6"]),
        (
            &["--target", "-0.4,0.1,0.35", "--start", "0,0,4,0,0,0"],
            "",
            &["joint 2 `elbow_joint` = 4", "outside its limits [-3.141592653589793, 3.141592653589793]"],
        ),
        (&["--targets", "-"], "{\"target\":[0.1,0.2]}\n", &["line 1", "target has 2 values, expected 3"]),
        (
            &["--targets", "-"],
            "{\"target\":[0.4,0.1,0.3]}\n{\"target\":[0,0,-1]}\n",
            &["line 2", "below the floor"],
        ),
        (&["--targets", "-"], "{\"target\":[5,5,5]}\n", &["line 1", "out of reach"]),
        (
            &["--targets", "-"],
            "{\"target\":[-0.4,0.1,0.35],\"start\":[0,0]}\n",
            &["start pose has 2 values, expected 6"],
        ),
        (
            &["--targets", "-"],
            "{\"target\":[-0.4,0.1,0.35],\"start\":[0,0,0,0,9,0]}\n",
            &["joint 4 `wrist_2_joint` = 9"],
        ),
        (&["--targets", "-"], "{\"goal\":[1,2,3]}\n", &["line 1", "malformed"]),
        (&["--targets", "/nonexistent/t.jsonl"], "", &["/nonexistent/t.jsonl"]),
        (&["--targets", "-", "--format", "csv"], "", &["batch mode"]),
        (&["--target", "-0.4,0.1,0.35", "--max-steps", "0"], "", &["--max-steps"]),
    ];
    for base in [vec!["plan", "--run", run_dir], vec!["plan", "--controller", "jacobian"]] {
        for (args, stdin, expect) in cases {
            let o = with_stdin(&[&base[..], args].concat(), stdin);
            let err = if args.contains(&"0") && args.contains(&"--max-steps") {
                assert_eq!(o.status.code(), Some(2));
                String::from_utf8_lossy(&o.stderr).to_string()
            } else {
                failure(&o)
            };
            for e in *expect {
                assert!(err.contains(e), "{args:?}: expected `{e}` in: {err}");
            }
        }
    }
    let err = failure(&run(&["plan", "--run", "/nonexistent/run", "--target", "0.4,0.1,0.3"]));
    assert!(err.contains("/nonexistent/run"), "{err}");
    let o = run(&["plan", "--target", "0.4,0.1,0.3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--run"));
}

#[test]
fn a_target_outside_the_training_distribution_warns_and_still_plans() {
    let run_dir = trained_run().to_str().unwrap();
    // In front of the arm, where the home pose's training targets never are (they lie at x < 0).
    let out = run(&["plan", "--run", run_dir, "--target", "0.45,0.1,0.4"]);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(err.contains("warning") && err.contains("outside the training target distribution"), "{err}");
    check_jsonl(&stdout_of(&out));
    // A training-like target: no warning.
    let out = run(&["plan", "--run", run_dir, "--target", "-0.45,-0.1,0.4"]);
    assert!(out.stderr.is_empty(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = with_stdin(&["plan", "--run", run_dir, "--targets", "-"], "{\"target\":[0.45,0.1,0.4]}\n");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(err.contains("warning: plan 1"), "{err}");
    assert_eq!(stdout_of(&out).lines().count(), 1);
}

#[test]
fn closed_or_full_stdout_is_an_error() {
    let single = ["plan", "--controller", "jacobian", "--target", "-0.4,0.1,0.35"];
    let csv = ["plan", "--controller", "jacobian", "--target", "-0.4,0.1,0.35", "--format", "csv"];
    let batch = ["plan", "--controller", "jacobian", "--targets", "-"];
    let input = "{\"target\":[-0.4,0.1,0.35]}\n".repeat(50);
    for args in [&single[..], &csv[..], &batch[..]] {
        for (redirect, needle) in
            [(">&-", "standard output is closed"), (">/dev/full", "No space left on device")]
        {
            let err = failure(&common::redirected(args, redirect, &input));
            assert!(err.contains(needle), "{args:?} {redirect}: {err}");
        }
        assert!(common::redirected(args, ">/dev/null", &input).status.success());
    }
}

#[test]
fn a_batch_view_beyond_its_limit_says_what_it_left_out() {
    let dir = scratch("plan-view-limit");
    let view = dir.join("view.html");
    let targets: String =
        (0..502).map(|i| format!("{{\"target\":[0.4,{:.3},0.3]}}\n", 0.001 * i as f64)).collect();
    let args = ["plan", "--controller", "jacobian", "--max-steps", "2", "--targets", "-", "--view"];
    let args: Vec<&str> = args.into_iter().chain([view.to_str().unwrap()]).collect();
    let o = with_stdin(&args, &targets);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(stdout_of(&o).lines().count(), 502, "the output has every plan");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("the view holds the first 500 of the 502 plans"), "{err}");
    let html = std::fs::read_to_string(&view).unwrap();
    assert!(html.contains("\"plan 500\"") && !html.contains("\"plan 501\""), "the view holds plans 1-500");
    // Within the limit, no such warning.
    let forced: Vec<&str> = args.iter().copied().chain(["--force"]).collect();
    let o = with_stdin(&forced, "{\"target\":[0.4,0.2,0.3]}\n");
    assert!(o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("the view holds"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn scenes_per_request_and_from_a_file_are_reported_and_bad_ones_named_by_line() {
    let dir = scratch("plan-scene");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("scene.toml");
    std::fs::write(
        &scene,
        "[[obstacles]]\nshape = \"sphere\"\nradius_m = 0.05\nposition_m = [-0.4, -0.4, 0.6]\n",
    )
    .unwrap();
    let scene_arg = scene.to_str().unwrap();
    let lines = concat!(
        "{\"target\":[0.4,0.2,0.3]}\n",
        "{\"target\":[0.4,0.2,0.3],\"obstacles\":[{\"shape\":\"cuboid\",\"half_extents_m\":[0.05,0.05,0.05],",
        "\"position_m\":[-0.4,0.4,0.6],\"rotation_xyzw\":[0,0,0,1]}]}\n"
    );
    let args = ["plan", "--controller", "jacobian", "--targets", "-", "--scene", scene_arg];
    let out = stdout_of(&with_stdin(&args, lines));
    let plans: Vec<Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(plans.len(), 2);
    for p in &plans {
        assert_eq!(p["collision"], false, "{p}");
        assert!(p["min_clearance_m"].as_f64().unwrap() > 0.05 && p["plan_time_s"].as_f64().unwrap() > 0.0);
    }
    // The line's box adds to the scene's ball: it is the nearer of the two to some of the path.
    assert!(plans[1]["min_clearance_m"].as_f64() <= plans[0]["min_clearance_m"].as_f64());
    // Without a scene, nothing to be near.
    let free = stdout_of(&with_stdin(&args[..5], "{\"target\":[0.4,0.2,0.3]}\n"));
    let free: Value = serde_json::from_str(free.trim()).unwrap();
    assert!(free["min_clearance_m"].is_null() && free["collision"] == false);
    // Bad obstacles: the line and the field named, nothing planned after them.
    let cases = [
        ("{\"shape\":\"sphere\",\"radius_m\":-1,\"position_m\":[0,0,1]}", "`obstacles[0].radius_m` = -1"),
        ("{\"shape\":\"sphere\",\"radius_m\":0.05,\"position_m\":[0.4,0.2,0.3]}", "encloses the target"),
        ("{\"shape\":\"cuboid\",\"half_extents_m\":[0.1,0.1,0.1],\"position_m\":[0,0,0.1]}", "start pose"),
        ("{\"shape\":\"cone\",\"radius_m\":0.1,\"position_m\":[0,0,1]}", "unknown variant `cone`"),
    ];
    for (o, want) in cases {
        let input =
            format!("{{\"target\":[0.4,0.2,0.3]}}\n{{\"target\":[0.4,0.2,0.3],\"obstacles\":[{o}]}}\n");
        let e = failure(&with_stdin(&args, &input));
        assert!(e.contains("line 2") && e.contains(want), "{e}");
    }
    std::fs::write(&scene, "[[obstacles]]\nshape = \"sphere\"\nradius_m = 0.05\n").unwrap();
    let e = failure(&with_stdin(&args, lines));
    assert!(e.contains(scene_arg) && e.contains("position_m"), "{e}");
}

#[test]
fn rrt_connect_plans_round_an_obstacle_deterministically_and_the_bench_runs() {
    // A ball across the straight way of the Jacobian controller.
    let target = "{\"target\":[-0.4,0.1,0.35]";
    // Halfway between the home pose's end effector and the target.
    let ball = "[{\"shape\":\"sphere\",\"radius_m\":0.04,\"position_m\":[-0.4435,-0.0046,0.391]}]";
    let line = format!("{target},\"obstacles\":{ball}}}\n");
    let blocked = stdout_of(&with_stdin(&["plan", "--controller", "jacobian", "--targets", "-"], &line));
    let blocked: Value = serde_json::from_str(blocked.trim()).unwrap();
    assert_eq!(blocked["collision"], true, "{blocked}");
    let args = ["plan", "--planner", "rrt-connect", "--targets", "-", "--seed", "4"];
    let a = stdout_of(&with_stdin(&args, &line));
    let b = stdout_of(&with_stdin(&args, &line));
    let (a, b): (Value, Value) =
        (serde_json::from_str(a.trim()).unwrap(), serde_json::from_str(b.trim()).unwrap());
    assert_eq!(
        (a["reached"].clone(), a["collision"].clone()),
        (Value::Bool(true), Value::Bool(false)),
        "{a}"
    );
    assert!(a["min_clearance_m"].as_f64().unwrap() > 0.0);
    assert_eq!(a["q"], b["q"]);
    assert_eq!(a["rrt_connect"], b["rrt_connect"]);
    assert_eq!(a["rrt_connect"]["seed"], 4);
    for k in ["iterations", "tree_nodes", "shortcuts", "ik_attempts"] {
        assert!(a["rrt_connect"][k].is_u64(), "{k}: {a}");
    }
    // --controller and --planner are one choice; budgets are checked.
    let both =
        run(&["plan", "--controller", "jacobian", "--planner", "rrt-connect", "--target", "0.4,0.2,0.3"]);
    assert_eq!(both.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&both.stderr).contains("cannot be used with"));
    let e = failure(&run(&[
        "plan",
        "--planner",
        "rrt-connect",
        "--planner-budget-s",
        "0",
        "--target",
        "0.4,0.2,0.3",
    ]));
    assert!(e.contains("--planner-budget-s") && e.contains("(0, 3600]"), "{e}");
    let e = failure(&run(&["plan", "--planner", "policy", "--target", "0.4,0.2,0.3"]));
    assert!(e.contains("--run"), "{e}");
    let out = stdout_of(&run(&["bench", "rrt-connect", "--problems", "10"]));
    let last: Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    assert_eq!((last["problems"].as_u64(), last["contacts"].as_u64()), (Some(10), Some(0)), "{out}");
    assert!(last["solved"].as_u64().unwrap() >= 9, "{out}");
}

/// `stagerl view --plans FILE` passes each line's obstacles to the planner and the page, as
/// `stagerl plan --targets FILE --view` does: the same scenes, contacts and closest approaches
/// for the same trained policy, and a line without obstacles has none.
#[test]
fn view_plans_draws_each_lines_scene_as_plan_view_does() {
    let dir = scratch("view-plans-scene");
    std::fs::create_dir_all(&dir).unwrap();
    let run_dir = trained_run().to_str().unwrap();
    let plans = dir.join("plans.jsonl");
    std::fs::write(
        &plans,
        concat!(
            "{\"target\":[-0.4,0.1,0.35],\"obstacles\":[{\"shape\":\"sphere\",\"radius_m\":0.04,",
            "\"position_m\":[-0.4435,-0.0046,0.391]},{\"shape\":\"cuboid\",\"half_extents_m\":[0.05,0.1,0.02],",
            "\"position_m\":[-0.2,-0.3,0.3],\"rotation_xyzw\":[0,0,0.3826834,0.9238795]}]}\n",
            "{\"target\":[0.4,0.2,0.3]}\n",
            "{\"target\":[0.4,0.2,0.3],\"obstacles\":[{\"shape\":\"sphere\",\"radius_m\":0.05,\"position_m\":[0.3,-0.3,0.9]}]}\n"
        ),
    )
    .unwrap();
    let (a, b) = (dir.join("view.html"), dir.join("plan.html"));
    stdout_of(&run(&[
        "view",
        "--run",
        run_dir,
        "--plans",
        plans.to_str().unwrap(),
        "--out",
        a.to_str().unwrap(),
    ]));
    stdout_of(&run(&[
        "plan",
        "--run",
        run_dir,
        "--targets",
        plans.to_str().unwrap(),
        "--view",
        b.to_str().unwrap(),
    ]));
    let (a, b) = (
        common::view_data(&std::fs::read_to_string(a).unwrap()),
        common::view_data(&std::fs::read_to_string(b).unwrap()),
    );
    let (ta, tb) = (a["trajectories"].as_array().unwrap(), b["trajectories"].as_array().unwrap());
    assert_eq!(ta.len(), 3);
    for (i, want) in [(0, 2), (1, 0), (2, 1)] {
        assert_eq!(ta[i]["obstacles"].as_array().map_or(0, Vec::len), want, "line {}", i + 1);
        for key in ["obstacles", "collision", "min_clearance_m", "closest", "contact", "frames", "reached"] {
            assert_eq!(ta[i][key], tb[i][key], "line {}: {key}", i + 1);
        }
    }
    assert!(ta[0]["min_clearance_m"].as_f64().is_some() && ta[1]["min_clearance_m"].is_null());
    std::fs::remove_dir_all(&dir).ok();
}
