//! `--shield` end to end: the `shield_*` keys of `plan` and `eval`, `bench plan` among obstacles
//! in the way without contact, and `train --shield` writing `[task.shield]` into the run and
//! each episode's shield counts into its TensorBoard log.

use crate::common;

use common::{run, scratch};
use serde_json::Value;
use stagerl::config::Config;

fn json_lines(o: &std::process::Output) -> Vec<Value> {
    assert!(o.status.success(), "failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).lines().filter_map(|l| serde_json::from_str(l).ok()).collect()
}

const KEYS: [&str; 5] = [
    "shield_steps",
    "shield_interventions",
    "shield_stops",
    "shield_mean_change_rad_per_s",
    "shield_max_change_rad_per_s",
];

#[test]
fn plan_adds_the_shield_counts_only_with_the_flag() {
    let base = ["plan", "--controller", "jacobian", "--target", "0.4,0.2,0.5", "--format", "jsonl"];
    let plain = json_lines(&run(&base));
    let summary = &plain.last().unwrap()["summary"];
    assert!(KEYS.iter().all(|k| summary.get(k).is_none()), "{summary}");
    let mut args = base.to_vec();
    args.push("--shield");
    let shielded = json_lines(&run(&args));
    let s = &shielded.last().unwrap()["summary"];
    assert!(KEYS.iter().all(|k| s.get(k).is_some()), "{s}");
    assert_eq!(s["shield_steps"], s["steps"]);
    // Far from everything: the same plan.
    assert_eq!(plain.len(), shielded.len());
}

#[test]
fn bench_plan_among_obstacles_in_the_way_has_no_contact_with_the_shield() {
    let args = ["bench", "plan", "--controller", "jacobian", "--obstacles-in-path", "--plans", "100"];
    let plain = json_lines(&run(&args));
    let mut with = args.to_vec();
    with.push("--shield");
    let shielded = json_lines(&run(&with));
    let (p, s) = (&plain.last().unwrap(), &shielded.last().unwrap());
    assert!(p["contact_rate"].as_f64().unwrap() > 0.5, "{p}");
    assert_eq!(s["contact_rate"].as_f64().unwrap(), 0.0, "{s}");
    assert!(s["interventions_per_plan"].as_f64().unwrap() > 0.0, "{s}");
}

#[test]
fn train_and_eval_with_the_shield() {
    let dir = scratch("shield-run");
    let mut cfg = Config::default();
    cfg.agent.hidden = vec![16, 16];
    cfg.agent.learning_starts = 200;
    let config = dir.join("config-in.toml");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(&config, cfg.to_toml_string()).unwrap();
    let out = dir.join("run");
    let o = run(&[
        "train",
        "--config",
        config.to_str().unwrap(),
        "--episodes",
        "20",
        "--eval-trials",
        "5",
        "--shield",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Each episode's shield counts are in the run's TensorBoard log.
    let scalars = common::tb_scalars(&out);
    for tag in ["train/shield_interventions", "train/shield_stops", "train/shield_mean_change_rad_per_s"] {
        let mut episodes: Vec<i64> = scalars.iter().filter(|(t, ..)| t == tag).map(|(_, e, _)| *e).collect();
        episodes.sort_unstable();
        assert_eq!(episodes, (1..=20).collect::<Vec<i64>>(), "{tag}");
    }
    let per_episode = |tag: &str| {
        let mut v: Vec<(i64, f32)> =
            scalars.iter().filter(|(t, ..)| t == tag).map(|(_, e, x)| (*e, *x)).collect();
        v.sort_by_key(|p| p.0);
        v
    };
    let (changed, stopped) = (per_episode("train/shield_interventions"), per_episode("train/shield_stops"));
    assert!(changed.iter().zip(&stopped).all(|(c, s)| c.1 >= s.1 && s.1 >= 0.0), "{changed:?} {stopped:?}");
    let written = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(written.contains("[task.shield]") && written.contains("enabled = true"), "{written}");
    let e =
        json_lines(&run(&["eval", "--run", out.to_str().unwrap(), "--trials", "10", "--shield", "--json"]));
    let s = e.last().unwrap();
    assert!(KEYS.iter().all(|k| s.get(k).is_some()), "{s}");
    assert!(s["shield_steps"].as_u64().unwrap() >= 10, "{s}");
    // The run's own setting: its file is the plain one. --no-shield: the policy alone, in a file
    // of its own.
    assert!(out.join("eval-best-trials10-seed0.csv").is_file());
    let o = run(&["eval", "--run", out.to_str().unwrap(), "--trials", "10", "--no-shield"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("without the shield"));
    let args = ["eval", "--run", out.to_str().unwrap(), "--trials", "10", "--no-shield", "--json", "--force"];
    let e = json_lines(&run(&args));
    let s = e.last().unwrap();
    assert!(KEYS.iter().all(|k| s.get(k).is_none()), "no shield counts without the shield: {s}");
    assert!(out.join("eval-best-trials10-seed0-no-shield.csv").is_file());
    let both = run(&["eval", "--run", out.to_str().unwrap(), "--shield", "--no-shield"]);
    let err = String::from_utf8_lossy(&both.stderr);
    assert!(!both.status.success() && err.contains("--no-shield") && err.contains("--shield"), "{err}");
}
