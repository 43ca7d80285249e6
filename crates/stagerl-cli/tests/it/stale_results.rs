//! No result is overwritten or stale: `train --force` removes everything the older run wrote,
//! `eval` never replaces the evaluation a report reads (nor another evaluation, without
//! --force), `reproduce` writes nothing when it refuses, and a change of the evaluation settings
//! alone re-runs the evaluation only.

use crate::common;

use common::{assert_steps_once, bin, scratch, tb_scalars};
use std::path::Path;
use std::process::Output;

const CONFIG: &str = "[agent]\nhidden = [16, 16]\nlearning_starts = 100\nbatch_size = 32\n\
[train]\nepisodes = 30\neval_every_episodes = 10\neval_trials = 5\ncheckpoint_every_episodes = 10\n";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn ok(args: &[&str]) -> Output {
    let o = bin().args(args).output().unwrap();
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    o
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn force_removes_the_older_run_and_eval_never_replaces_another_evaluation() {
    let root = scratch("stale-force");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let dir = root.join("run");
    ok(&["train", "--config", s(&cfg), "--out", s(&dir), "--eval-trials", "7", "--seed", "1"]);
    ok(&["eval", "--run", s(&dir), "--trials", "3", "--seed", "5"]);
    std::fs::write(dir.join("notes.md"), "mine").unwrap();
    let older: Vec<String> = names(&dir);
    for f in ["eval-final-seed0.csv", "eval-final-seed0.json", "eval-best-trials3-seed5.csv", "eval.csv"] {
        assert!(older.contains(&f.to_string()), "{f} in {older:?}");
    }

    // A shorter run, without evaluations, replaces it: nothing of the older one is left.
    let o = ok(&[
        "train",
        "--config",
        s(&cfg),
        "--out",
        s(&dir),
        "--eval-trials",
        "0",
        "--seed",
        "2",
        "--episodes",
        "12",
        "--force",
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("--force: removed") && text.contains("eval-final-seed0.csv"), "{text}");
    let now = names(&dir);
    for f in ["eval-final-seed0.csv", "eval-final-seed0.json", "eval-best-trials3-seed5.csv"] {
        assert!(!now.contains(&f.to_string()), "{f} of the older run left: {now:?}");
    }
    assert!(now.contains(&"notes.md".to_string()));
    assert_eq!(std::fs::read_dir(dir.join("tb")).unwrap().count(), 1);
    assert_steps_once(&tb_scalars(&dir), 12, 10, "after --force");
    let eval = std::fs::read_to_string(dir.join("eval.csv")).unwrap();
    assert_eq!(
        eval.lines().map(|l| l.split(',').next().unwrap()).collect::<Vec<_>>(),
        ["episode", "10", "12"]
    );

    // `eval` writes its own file; the closing evaluation a report reads stays as it was.
    ok(&["train", "--config", s(&cfg), "--out", s(&dir), "--eval-trials", "9", "--force"]);
    let closing = std::fs::read(dir.join("eval-final-seed0.csv")).unwrap();
    let o = ok(&["eval", "--run", s(&dir), "--trials", "4", "--seed", "0"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("(written)"));
    assert_eq!(std::fs::read(dir.join("eval-final-seed0.csv")).unwrap(), closing);
    let mine = dir.join("eval-best-trials4-seed0.csv");
    let first = std::fs::read(&mine).unwrap();
    assert_eq!(first.iter().filter(|&&b| b == b'\n').count(), 5);
    // The same evaluation again leaves the file as is; another one is refused without --force.
    let o = ok(&["eval", "--run", s(&dir), "--trials", "4", "--seed", "0"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("unchanged"));
    let edited = String::from_utf8(first.clone()).unwrap().replacen("\n1,", "\n1,1", 1);
    std::fs::write(&mine, &edited).unwrap();
    let o = bin().args(["eval", "--run", s(&dir), "--trials", "4", "--seed", "0"]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--force") && err.contains(s(&mine)), "{err}");
    assert_eq!(std::fs::read_to_string(&mine).unwrap(), edited);
    ok(&["eval", "--run", s(&dir), "--trials", "4", "--seed", "0", "--force"]);
    assert_eq!(std::fs::read(&mine).unwrap(), first);
    std::fs::remove_dir_all(&root).ok();
}

const PRESET: &str =
    "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1, 2]\neval_trials = 10\n\
[agent]\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 100\n\
[train]\nepisodes = 20\neval_every_episodes = 10\neval_trials = 5\ncheckpoint_every_episodes = 10\n";

#[test]
fn reproduce_refuses_before_writing_and_reevaluates_only_when_evaluation_settings_change() {
    let root = scratch("stale-sweep");
    let (p1, p2) = (root.join("p1.toml"), root.join("p2.toml"));
    std::fs::write(&p1, PRESET).unwrap();
    std::fs::write(&p2, PRESET.replace("eval_trials = 10", "eval_trials = 12")).unwrap();
    let out = root.join("sweep");
    ok(&["reproduce", "--preset", s(&p1), "--out", s(&out)]);
    let run = out.join("sac-sar-seed1");
    let episodes = std::fs::read(run.join("episodes.csv")).unwrap();
    assert_eq!(std::fs::read_to_string(run.join("eval-final-seed0.csv")).unwrap().lines().count(), 11);

    // Only the evaluation trials changed: each run is evaluated again, not trained again.
    let o = ok(&["reproduce", "--preset", s(&p2), "--out", s(&out)]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(text.matches("re-evaluated").count(), 2, "{text}");
    assert!(!text.contains("already done"), "{text}");
    assert_eq!(std::fs::read_to_string(run.join("eval-final-seed0.csv")).unwrap().lines().count(), 13);
    assert!(std::fs::read_to_string(run.join("eval-final-seed0.json")).unwrap().contains("\"trials\": 12"));
    assert_eq!(std::fs::read(run.join("episodes.csv")).unwrap(), episodes);
    assert_eq!(std::fs::read_dir(run.join("tb")).unwrap().count(), 1, "trained again");
    assert_eq!(
        std::fs::read_to_string(out.join("preset.toml")).unwrap(),
        std::fs::read_to_string(&p2).unwrap()
    );
    let o = ok(&["reproduce", "--preset", s(&p2), "--out", s(&out)]);
    assert_eq!(String::from_utf8_lossy(&o.stdout).matches("already done").count(), 2);

    // A preset whose runs disagree with the directory's is refused, and nothing is written.
    let other = PRESET.replace("episodes = 20", "episodes = 25");
    let p3 = root.join("p3.toml");
    std::fs::write(&p3, &other).unwrap();
    let before = names(&out);
    let preset_before = std::fs::read(out.join("preset.toml")).unwrap();
    let o = bin().args(["reproduce", "--preset", s(&p3), "--out", s(&out)]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("sac-sar-seed1") && err.contains("sac-sar-seed2"), "{err}");
    assert_eq!(std::fs::read(out.join("preset.toml")).unwrap(), preset_before);
    assert_eq!(names(&out), before);
    std::fs::remove_dir_all(&root).ok();
}

/// Trial records of a per-trial CSV: (target columns, collision steps) per trial.
fn trials(csv: &Path) -> Vec<(String, u32)> {
    let text = std::fs::read_to_string(csv).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[6..9].join(","), f[9].parse().unwrap())
        })
        .collect()
}

/// `train.obstacles_in_path` trains, and `eval --obstacles-in-path` evaluates on the same
/// targets with the first obstacle in the way: its own file beside the plain evaluation, which
/// it leaves alone, and more trials in contact; bad probabilities are refused by name.
#[test]
fn eval_with_obstacles_in_the_way_writes_its_own_file() {
    let root = scratch("stale-in-path");
    let cfg = root.join("c.toml");
    let config = "[agent]\nhidden = [16, 16]\nlearning_starts = 100\nbatch_size = 32\n\
        [task.random_obstacles]\ncount = [1, 1]\n\
        [train]\nepisodes = 20\neval_every_episodes = 10\neval_trials = 5\nobstacles_in_path = 1\n";
    std::fs::write(&cfg, config).unwrap();
    let dir = root.join("run");
    ok(&["train", "--config", s(&cfg), "--out", s(&dir), "--seed", "1"]);
    ok(&["eval", "--run", s(&dir), "--trials", "150"]);
    let plain = dir.join("eval-best-trials150-seed0.csv");
    let before = std::fs::read(&plain).unwrap();
    let o = ok(&["eval", "--run", s(&dir), "--trials", "150", "--obstacles-in-path", "1"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("first obstacle in the way with probability 1"), "{text}");
    let (a, b) = (trials(&plain), trials(&dir.join("eval-best-trials150-seed0-in-path-1.csv")));
    assert_eq!(std::fs::read(&plain).unwrap(), before, "the plain evaluation is left as it was");
    assert_eq!(a.iter().map(|t| &t.0).collect::<Vec<_>>(), b.iter().map(|t| &t.0).collect::<Vec<_>>());
    let touched = |v: &[(String, u32)]| v.iter().filter(|t| t.1 > 0).count();
    assert!(touched(&b) >= touched(&a) + 20, "in contact: {} plain, {} in the way", touched(&a), touched(&b));
    for bad in ["1.5", "-1", "nan"] {
        let o =
            bin().args(["eval", "--run", s(&dir), &format!("--obstacles-in-path={bad}")]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("--obstacles-in-path") && err.contains("[0, 1]"),
            "{bad}: {err}"
        );
    }
}
