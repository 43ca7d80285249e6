//! `stagerl bench obstacles` end to end: the table has a row per planner and set, the problem
//! file replays through `stagerl plan` with the same verdicts, and the per-plan file agrees with
//! the table.

use crate::common::{bin, run, scratch};
use serde_json::Value;
use std::io::Write;
use std::process::Stdio;

#[test]
fn bench_obstacles_writes_the_table_the_problems_and_the_plans() {
    let dir = scratch("bench-obstacles");
    let (problems_path, plans_path) = (dir.join("problems.jsonl"), dir.join("plans.jsonl"));
    let out = run(&[
        "bench",
        "obstacles",
        "--problems",
        "8",
        "--sets",
        "free,in-the-way,narrow-gap",
        "--solvable-budget-s",
        "0.5",
        "--problems-out",
        problems_path.to_str().unwrap(),
        "--out",
        plans_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let table = String::from_utf8_lossy(&out.stdout).into_owned();
    for set in ["free", "in-the-way", "narrow-gap"] {
        assert!(table.contains(&format!("| jacobian | {set} |")), "{table}");
        // Every problem was solved by RRT-Connect when drawn; with its table budget it solves
        // the free and in-the-way sets without a contact (none with a contact in any set).
        assert!(table.contains(&format!("| rrt-connect | {set} |")), "{table}");
    }
    assert!(table.contains("| rrt-connect | free | 100.0 | 0.0 |"), "{table}");
    assert!(table.contains("| rrt-connect | in-the-way | 100.0 | 0.0 |"), "{table}");
    assert!(table.contains("candidates it could not solve, drawn again: free 0, in-the-way "), "{table}");
    assert!(!table.contains("random-3"), "{table}");
    let problems: Vec<Value> = std::fs::read_to_string(&problems_path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let plans: Vec<Value> = std::fs::read_to_string(&plans_path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!((problems.len(), plans.len()), (24, 72));
    // Each problem carries the goal RRT-Connect reached, one value per joint.
    assert!(problems.iter().all(|p| p["goal_rad"].as_array().is_some_and(|g| g.len() == 6)));
    assert!(plans.iter().filter(|p| p["planner"] == "rrt-connect").all(|p| p["collision"] == false));
    // The shield: no contact on any set, its counts on its lines only, and it changed commands
    // where an obstacle is in the way.
    let shielded: Vec<&Value> = plans.iter().filter(|p| p["planner"] == "jacobian+shield").collect();
    assert_eq!(shielded.len(), 24);
    assert!(shielded.iter().all(|p| p["collision"] == false && p["shield_steps"].as_u64().unwrap() > 0));
    assert!(shielded
        .iter()
        .any(|p| p["set"] == "in-the-way" && p["shield_interventions"].as_u64().unwrap() > 0));
    assert!(plans
        .iter()
        .filter(|p| p["planner"] != "jacobian+shield")
        .all(|p| p.get("shield_steps").is_none()));
    for set in ["free", "in-the-way", "narrow-gap"] {
        let row =
            table.lines().find(|l| l.starts_with(&format!("| jacobian+shield | {set} |"))).expect(&table);
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert_eq!(cells[4], "0.0", "{row}");
        assert!(cells[9].parse::<f64>().is_ok() && cells[10].parse::<f64>().is_ok(), "{row}");
    }
    assert!(table.contains("| jacobian | free | 100.0 | 0.0 |") && table.contains("| - | - |"), "{table}");
    let plans: Vec<Value> = plans.into_iter().filter(|p| p["planner"] == "jacobian").collect();
    // The free set: the Jacobian controller reaches every target without contact.
    let free: Vec<&Value> = plans.iter().filter(|p| p["set"] == "free").collect();
    assert!(free.iter().all(|p| p["success"] == true && p["collision"] == false), "{free:?}");
    assert!(table.contains("| jacobian | free | 100.0 | 0.0 |"), "{table}");
    // Each problem replayed through `stagerl plan --controller jacobian` gives the same verdict.
    let mut input = String::new();
    for p in &problems {
        input.push_str(&serde_json::json!({"target": p["target_m"], "start": p["start_rad"], "obstacles": p["obstacles"]}).to_string());
        input.push('\n');
    }
    let mut child = bin()
        .args(["plan", "--controller", "jacobian", "--targets", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    let replay = child.wait_with_output().unwrap();
    assert!(replay.status.success(), "{}", String::from_utf8_lossy(&replay.stderr));
    let replayed: Vec<Value> =
        String::from_utf8_lossy(&replay.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(replayed.len(), 24);
    for (p, r) in plans.iter().zip(&replayed) {
        assert_eq!(p["collision"], r["collision"], "{p} / {r}");
        assert_eq!(p["reached"], r["reached"], "{p} / {r}");
    }
    // Run again: the per-plan file (plan times differ) is not overwritten without --force.
    let p2 = dir.join("p2.jsonl");
    let again = |force: bool| {
        let mut args = vec!["bench", "obstacles", "--problems", "2", "--sets", "free"];
        args.extend(["--problems-out", p2.to_str().unwrap(), "--out", plans_path.to_str().unwrap()]);
        if force {
            args.push("--force");
        }
        run(&args)
    };
    let refused = again(false);
    assert!(
        !refused.status.success() && String::from_utf8_lossy(&refused.stderr).contains("--force"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
    assert_eq!(std::fs::read_to_string(&plans_path).unwrap().lines().count(), 72, "overwritten");
    assert!(again(true).status.success());
    assert_eq!(std::fs::read_to_string(&plans_path).unwrap().lines().count(), 6);
    // --planners keeps the table's rows of the planners named, with the same figures.
    let only = run(&[
        "bench",
        "obstacles",
        "--problems",
        "2",
        "--sets",
        "free",
        "--planners",
        "rrt-connect,jacobian",
    ]);
    let only = String::from_utf8(only.stdout).unwrap();
    let rows: Vec<&str> = only.lines().filter(|l| l.starts_with("| ") && l.contains("| free |")).collect();
    assert_eq!(rows.len(), 2, "{only}");
    assert!(
        rows[0].starts_with("| jacobian | free | 100.0 | 0.0 |")
            && rows[1].starts_with("| rrt-connect | free |")
    );
    let e = run(&["bench", "obstacles", "--problems", "2", "--planners", "policy+shield"]);
    assert!(
        !e.status.success()
            && String::from_utf8_lossy(&e.stderr)
                .contains("--planners policy+shield: the policy's planners need --run")
    );
    // The Jacobian controller succeeds on no narrow-gap problem here: no path length to average.
    let gap = table.lines().find(|l| l.starts_with("| jacobian | narrow-gap |")).expect(&table);
    assert!(
        gap.starts_with("| jacobian | narrow-gap | 0.0 |")
            && gap.contains("| - | - |")
            && !gap.contains("NaN"),
        "{gap}"
    );
    // An in-the-way problem blocks the straight line: the controller touches its obstacle.
    assert!(plans.iter().filter(|p| p["set"] == "in-the-way").any(|p| p["collision"] == true));
    std::fs::remove_dir_all(&dir).ok();
}

/// A run trained behind the shield (`[task.shield] enabled = true`): its `policy` row is the
/// policy alone (no shield counts on its plans) and `policy+shield` the policy behind it; `plan`
/// plans behind it, and alone with `--no-shield`.
#[test]
fn bench_obstacles_plans_a_shield_trained_policy_alone_and_behind_the_shield() {
    let dir = scratch("bench-obstacles-shielded-run");
    let config = dir.join("shielded.toml");
    std::fs::write(
        &config,
        "[task]\non_collision = \"terminate\"\n[task.shield]\nenabled = true\n\
         [task.random_obstacles]\ncount = [1, 1]\n[train]\nepisodes = 2\neval_trials = 2\n",
    )
    .unwrap();
    let run_dir = dir.join("run");
    let out = run(&[
        "train",
        "--config",
        config.to_str().unwrap(),
        "--seed",
        "1",
        "--out",
        run_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let plans_path = dir.join("plans.jsonl");
    let out = run(&[
        "bench",
        "obstacles",
        "--problems",
        "3",
        "--sets",
        "in-the-way",
        "--solvable-budget-s",
        "0.5",
        "--planners",
        "policy,policy+shield",
        "--run",
        run_dir.to_str().unwrap(),
        "--out",
        plans_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let plans: Vec<Value> = std::fs::read_to_string(&plans_path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(plans.len(), 6);
    for p in &plans {
        let shielded = p["planner"] == "policy+shield";
        assert_eq!(p.get("shield_steps").is_some(), shielded, "{p}");
    }
    // `stagerl plan` with the run: behind its shield, unless --no-shield.
    let plan = |extra: &[&str]| {
        let mut args = vec!["plan", "--run", run_dir.to_str().unwrap(), "--target", "0.4,0.2,0.5"];
        args.extend_from_slice(extra);
        let out = run(&args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8(out.stdout).unwrap();
        serde_json::from_str::<Value>(text.lines().last().unwrap()).unwrap()["summary"].clone()
    };
    assert!(plan(&[]).get("shield_steps").is_some());
    assert!(plan(&["--no-shield"]).get("shield_steps").is_none());
    std::fs::remove_dir_all(&dir).ok();
}
