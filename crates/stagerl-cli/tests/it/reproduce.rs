//! `stagerl reproduce`: resumable sweeps. Killing it loses no finished run and repeats none.

use crate::common;

use common::{bin, episodes_without_wall, scratch};
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

const PRESET: &str = "[sweep]\nalgorithms = [\"ddpg\", \"sac\"]\nrewards = [\"posture\", \"sar\"]\nseeds = [1, 2]\neval_trials = 10\n\
[agent]\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 100\n\
[train]\nepisodes = 150\neval_every_episodes = 50\neval_trials = 5\ncheckpoint_every_episodes = 10\n";

fn finished(out: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().join("eval-final-seed0.csv").exists())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn killed_sweep_loses_and_repeats_nothing() {
    let root = scratch("repro-kill");
    let preset = root.join("p.toml");
    std::fs::write(&preset, PRESET).unwrap();
    let (full, cut) = (root.join("full"), root.join("cut"));
    let p = preset.to_str().unwrap();
    let out = bin()
        .args(["reproduce", "--preset", p, "--out", full.to_str().unwrap(), "--jobs", "2"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(finished(&full).len(), 8);

    // Kill it once some runs have finished and others are under way.
    let mut child = bin()
        .args(["reproduce", "--preset", p, "--out", cut.to_str().unwrap(), "--jobs", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut waited = 0;
    while finished_or_empty(&cut) < 2 && waited < 600 {
        std::thread::sleep(Duration::from_millis(50));
        waited += 1;
    }
    std::thread::sleep(Duration::from_millis(150));
    child.kill().unwrap();
    child.wait().unwrap();
    let done_before = finished(&cut);
    assert!(!done_before.is_empty() && done_before.len() < 8, "killed mid-sweep: {done_before:?}");
    let kept: Vec<Vec<u8>> = done_before
        .iter()
        .map(|r| std::fs::read(cut.join(r).join("eval-final-seed0.csv")).unwrap())
        .collect();

    let out = bin()
        .args(["reproduce", "--preset", p, "--out", cut.to_str().unwrap(), "--jobs", "2"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    for (r, bytes) in done_before.iter().zip(&kept) {
        assert!(
            text.lines().any(|l| l.contains(r.as_str()) && l.contains("already done")),
            "{r} repeated?\n{text}"
        );
        assert_eq!(&std::fs::read(cut.join(r).join("eval-final-seed0.csv")).unwrap(), bytes, "{r} changed");
    }
    assert_eq!(finished(&cut), finished(&full));
    // provenance.json records both sessions of the cut sweep: the killed one as such (it never
    // finished), the second with its outcome, each with the code's git commit.
    let prov: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cut.join("provenance.json")).unwrap()).unwrap();
    let sessions = prov["sessions"].as_array().unwrap();
    assert_eq!(sessions.len(), 2, "{prov}");
    assert_eq!(sessions[0]["end"], serde_json::Value::Null, "{prov}");
    assert!(sessions[1]["outcome"].as_str().unwrap().starts_with("finished"), "{prov}");
    assert!(sessions
        .iter()
        .all(|s| s["command"][1] == "reproduce" && s["code"]["git_commit"].as_str().is_some()));
    assert!(prov["total_wall_s"].as_f64().unwrap() > 0.0);
    for r in finished(&full) {
        assert_eq!(episodes_without_wall(&full.join(&r)), episodes_without_wall(&cut.join(&r)), "{r}");
        assert_eq!(
            std::fs::read(full.join(&r).join("eval-final-seed0.csv")).unwrap(),
            std::fs::read(cut.join(&r).join("eval-final-seed0.csv")).unwrap(),
            "{r}: evaluation differs"
        );
    }
    std::fs::remove_dir_all(&root).ok();
}

/// The names of the directories in `out`, sorted.
fn run_dirs(out: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn finished_or_empty(out: &Path) -> usize {
    if out.exists() {
        finished(out).len()
    } else {
        0
    }
}

#[test]
fn sharding_splits_the_sweep_and_bad_arguments_are_refused() {
    let root = scratch("repro-shard");
    let out = root.join("o");
    let o = out.to_str().unwrap();
    let a = bin()
        .args(["reproduce", "--preset", "smoke", "--out", o, "--task-index", "1", "--task-count", "3"])
        .output()
        .unwrap();
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    // Smoke: 10 runs (ddpg then sac; basic, posture, stride, har, sar); shard 1 of 3 holds runs 1, 4, 7.
    assert_eq!(run_dirs(&out), ["ddpg-posture-seed1", "ddpg-sar-seed1", "sac-stride-seed1"]);
    // Slurm's variables select the shard when no flag does.
    let out2 = root.join("o2");
    let b = bin()
        .args(["reproduce", "--preset", "smoke", "--out", out2.to_str().unwrap()])
        .env("SLURM_ARRAY_TASK_ID", "10")
        .env("SLURM_ARRAY_TASK_MIN", "1")
        .env("SLURM_ARRAY_TASK_COUNT", "10")
        .output()
        .unwrap();
    assert!(b.status.success(), "{}", String::from_utf8_lossy(&b.stderr));
    assert!(out2.join("sac-sar-seed1").exists() && !out2.join("ddpg-basic-seed1").exists());
    for (args, needle) in [
        (vec!["--preset", "nope"], "nope"),
        (vec!["--preset", "smoke", "--task-index", "3", "--task-count", "3"], "task index 3 of 3"),
        (vec!["--preset", "smoke", "--jobs", "0"], "--jobs"),
    ] {
        let mut full = vec!["reproduce", "--out", o];
        full.extend(args);
        let r = bin().args(&full).output().unwrap();
        assert!(!r.status.success());
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains(needle) && !err.contains("panicked"), "{full:?}: {err}");
    }
    std::fs::remove_dir_all(&root).ok();
}

/// Slurm job arrays with a step (`--array=0-19:2`), and explicit flags that win over the
/// variables (a malformed variable is then not read).
#[test]
fn slurm_step_and_explicit_flags_over_the_environment() {
    let root = scratch("repro-slurm");
    // Task id 4 of --array=0-19:2 is task 2 of 10: smoke's run 2.
    let stepped = root.join("stepped");
    let r = bin()
        .args(["reproduce", "--preset", "smoke", "--out", stepped.to_str().unwrap()])
        .env("SLURM_ARRAY_TASK_ID", "4")
        .env("SLURM_ARRAY_TASK_MIN", "0")
        .env("SLURM_ARRAY_TASK_STEP", "2")
        .env("SLURM_ARRAY_TASK_COUNT", "10")
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(run_dirs(&stepped), ["ddpg-stride-seed1"]);
    let flags = root.join("flags");
    let r = bin()
        .args(["reproduce", "--preset", "smoke", "--out", flags.to_str().unwrap()])
        .args(["--task-index", "9", "--task-count", "10"])
        .env("SLURM_ARRAY_TASK_ID", "not-a-number")
        .env("SLURM_ARRAY_TASK_COUNT", "")
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(run_dirs(&flags), ["sac-sar-seed1"]);
    // Without the flags the malformed variable is an error that names it.
    let r = bin()
        .args(["reproduce", "--preset", "smoke", "--out", root.join("bad").to_str().unwrap()])
        .env("SLURM_ARRAY_TASK_ID", "not-a-number")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success() && err.contains("SLURM_ARRAY_TASK_ID"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

/// The CI path of the paper pipeline: the smoke preset, then the report on its output.
#[test]
fn smoke_preset_then_report_writes_every_file() {
    let root = scratch("repro-smoke");
    let out = root.join("smoke");
    let r = bin()
        .args(["reproduce", "--preset", "smoke", "--out", out.to_str().unwrap(), "--jobs", "2"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let runs = std::fs::read_dir(&out)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().join("eval-final-seed0.csv").exists())
        .count();
    assert_eq!(runs, 10, "2 algorithms x 5 rewards x 1 seed, each evaluated");
    let r = bin().args(["report", out.to_str().unwrap()]).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let rep = out.join("report");
    for f in [
        "table1.md",
        "table1.csv",
        "table1.json",
        "claims.md",
        "figure7.png",
        "figure7.svg",
        "figure8.png",
        "figure8.svg",
        "trajectories.png",
        "trajectories.svg",
        "trajectories.csv",
    ] {
        let bytes = std::fs::read(rep.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(bytes.len() > 100, "{f} is nearly empty");
        if f.ends_with(".png") {
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{f} is a PNG");
        }
    }
    let table = std::fs::read_to_string(rep.join("table1.md")).unwrap();
    for row in ["SAC", "DDPG", "SAR", "HAR", "Posture", "Stride", "Basic"] {
        assert!(table.contains(row), "table1.md lacks {row}");
    }
    // The closing evaluation covers the final checkpoint too (the paper's protocol), on the same
    // targets, and the table shows it beside the best checkpoint's.
    let run = out.join("sac-sar-seed1");
    let (best, last) = (run.join("eval-final-seed0.csv"), run.join("eval-final-seed0-final-checkpoint.csv"));
    let rows = |p: &std::path::Path| std::fs::read_to_string(p).unwrap().lines().count();
    assert_eq!(rows(&best), rows(&last), "the same trials for both checkpoints");
    assert!(table.contains("## Best and final checkpoint") && table.contains("| SAC | SAR | 1 |"), "{table}");

    // Archived: every run stripped of its resumable checkpoint and TensorBoard events, and half
    // of them of every checkpoint (what a results directory keeps). The sweep is done: nothing
    // trains or evaluates again, and the report reads the same Table 1.
    let table_csv = std::fs::read(rep.join("table1.csv")).unwrap();
    let names = run_dirs(&out).into_iter().filter(|n| n != "report").collect::<Vec<_>>();
    let kept: Vec<Vec<u8>> =
        names.iter().map(|n| std::fs::read(out.join(n).join("episodes.csv")).unwrap()).collect();
    for (i, n) in names.iter().enumerate() {
        let dir = out.join(n);
        std::fs::remove_file(dir.join("checkpoints/latest.safetensors")).unwrap();
        std::fs::remove_dir_all(dir.join("tb")).unwrap();
        if i % 2 == 1 {
            std::fs::remove_dir_all(dir.join("checkpoints")).unwrap();
        }
    }
    let r = bin()
        .args(["reproduce", "--preset", "smoke", "--out", out.to_str().unwrap(), "--jobs", "2"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let text = String::from_utf8_lossy(&r.stdout);
    assert_eq!(text.lines().filter(|l| l.contains("already done")).count(), 10, "{text}");
    for (n, bytes) in names.iter().zip(&kept) {
        assert_eq!(&std::fs::read(out.join(n).join("episodes.csv")).unwrap(), bytes, "{n} trained again");
        assert!(!out.join(n).join("checkpoints/latest.safetensors").exists(), "{n} trained again");
    }
    let r = bin()
        .args(["report", out.to_str().unwrap(), "--out", root.join("again").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(
        std::fs::read(root.join("again/table1.csv")).unwrap(),
        table_csv,
        "the same Table 1 from the archive"
    );
    std::fs::remove_dir_all(&root).ok();
}

/// A sweep on an arm that is not six-jointed, without its per-joint settings: one message naming
/// both fields, before any run starts (no run directory, no preset.toml).
#[test]
fn a_sweep_on_an_arm_without_its_settings_fails_once_before_any_run() {
    let root = scratch("repro-arm");
    let preset = root.join("p.toml");
    std::fs::write(&preset, format!("{PRESET}[robot]\nurdf = \"panda\"\n")).unwrap();
    let out_dir = root.join("out");
    let out = bin()
        .args(["reproduce", "--preset", preset.to_str().unwrap(), "--out", out_dir.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(err.matches("task.home_pose_rad and task.target_joint_range_rad").count(), 1, "{err}");
    assert!(err.contains("7 joints") && err.contains("stagerl robot URDF"), "{err}");
    assert!(!out_dir.exists(), "nothing written");
}
