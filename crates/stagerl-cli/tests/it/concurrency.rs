//! Run directories are locked while a process writes them: a second `train` fails fast, several
//! `reproduce` processes share one sweep (each run trained by exactly one of them), and a killed
//! writer leaves no stale lock and no temporary file that outlives the next process.

use crate::common;

use common::{assert_steps_once, bin, episodes_without_wall, scratch, tb_scalars};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

const LONG: &str = "[agent]\nhidden = [16, 16]\nlearning_starts = 100\nbatch_size = 32\n\
[train]\nepisodes = 100000\neval_every_episodes = 0\ncheckpoint_every_episodes = 5\n";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn wait_for(path: &Path, child: &mut Child) {
    while !path.exists() {
        assert!(child.try_wait().unwrap().is_none(), "ended before writing {}", path.display());
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn a_second_writer_of_a_run_fails_fast_naming_the_directory_and_the_holder() {
    let root = scratch("lock-train");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, LONG).unwrap();
    let dir = root.join("run");
    let mut first = bin()
        .args(["train", "--config", s(&cfg), "--out", s(&dir), "--eval-trials", "0"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for(&dir.join("checkpoints/latest.safetensors"), &mut first);
    let pid = format!("pid {}", first.id());
    // The same command, with --force, and --resume, and eval: all refused while the first runs.
    for args in [
        vec!["train", "--config", s(&cfg), "--out", s(&dir), "--eval-trials", "0"],
        vec!["train", "--config", s(&cfg), "--out", s(&dir), "--force"],
        vec!["train", "--resume", s(&dir)],
        vec!["eval", "--run", s(&dir), "--trials", "2"],
    ] {
        let o = bin().args(&args).stdin(Stdio::null()).output().unwrap();
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(err.contains(s(&dir)) && err.contains(&pid) && err.contains("in use"), "{args:?}: {err}");
        assert!(!String::from_utf8_lossy(&o.stdout).contains("training "), "{args:?} started training");
    }
    assert!(first.try_wait().unwrap().is_none(), "the first run goes on");
    // Its episodes.csv has one header and strictly increasing episodes: nothing interleaved.
    let rows = episodes_without_wall(&dir);
    for (k, row) in rows.iter().enumerate().skip(1) {
        assert!(row.starts_with(&format!("{k},")), "row {k}: {row}");
    }
    // SIGKILL leaves no stale lock: the next process takes the run at once.
    first.kill().unwrap();
    first.wait().unwrap();
    let o = bin().args(["eval", "--run", s(&dir), "--trials", "2"]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_dir_all(&root).ok();
}

const PRESET: &str =
    "[sweep]\nalgorithms = [\"ddpg\", \"sac\"]\nrewards = [\"sar\"]\nseeds = [1, 2, 3]\neval_trials = 10\n\
[agent]\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 100\n\
[train]\nepisodes = 60\neval_every_episodes = 20\neval_trials = 5\ncheckpoint_every_episodes = 10\n";
const RUNS: [&str; 6] =
    ["ddpg-sar-seed1", "ddpg-sar-seed2", "ddpg-sar-seed3", "sac-sar-seed1", "sac-sar-seed2", "sac-sar-seed3"];

#[test]
fn two_reproduce_processes_share_a_sweep_and_train_each_run_once() {
    let root = scratch("lock-sweep");
    let preset = root.join("p.toml");
    std::fs::write(&preset, PRESET).unwrap();
    let (single, shared) = (root.join("single"), root.join("shared"));
    let o = bin().args(["reproduce", "--preset", s(&preset), "--out", s(&single)]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));

    let spawn = || {
        bin()
            .args(["reproduce", "--preset", s(&preset), "--out", s(&shared)])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    assert!(a.status.success() && b.status.success(), "{}\n{}", stderr(&a), stderr(&b));
    let out = format!("{}{}", String::from_utf8_lossy(&a.stdout), String::from_utf8_lossy(&b.stdout));
    for run in RUNS {
        // Trained by exactly one process: "done" once; the other skipped it or found it done.
        let trained = out.lines().filter(|l| l.contains(run) && l.contains(": done in")).count();
        assert_eq!(trained, 1, "{run} trained {trained} times:\n{out}");
        let dir = shared.join(run);
        let rows = episodes_without_wall(&dir);
        assert_eq!(rows.len(), 61, "{run}: episodes.csv rows");
        assert_eq!(rows, episodes_without_wall(&single.join(run)), "{run}: differs from the single sweep");
        let eval = |d: &Path| std::fs::read(d.join(run).join("eval-final-seed0.csv")).unwrap();
        assert_eq!(eval(&shared), eval(&single), "{run}: evaluation differs");
        let tb_files = std::fs::read_dir(dir.join("tb")).unwrap().count();
        assert_eq!(tb_files, 1, "{run}: one session, one event file");
        assert_steps_once(&tb_scalars(&dir), 60, 20, run);
    }
    assert!(out.contains("taken by another process"), "the processes never met:\n{out}");
    assert_eq!(std::fs::read_to_string(shared.join("preset.toml")).unwrap(), PRESET);
    let r = bin().args(["report", s(&shared)]).output().unwrap();
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(shared.join("report/table1.md").exists());
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn stale_temporary_files_are_removed_when_a_process_takes_the_run() {
    let root = scratch("stale-tmp");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, LONG).unwrap();
    let dir = root.join("run");
    let mut child = bin()
        .args(["train", "--config", s(&cfg), "--out", s(&dir), "--eval-trials", "0"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for(&dir.join("checkpoints/latest.safetensors"), &mut child);
    child.kill().unwrap();
    child.wait().unwrap();
    // What a SIGKILL during atomic writes leaves, and a user's file that must stay.
    let stale = [
        "checkpoints/latest.safetensors.tmp-999999",
        "checkpoints/best.safetensors.tmp-12",
        "eval.csv.tmp-4242",
        "tb/events.out.tfevents.1.host.1.tmp-77",
    ];
    for f in stale {
        std::fs::write(dir.join(f), vec![7u8; 4096]).unwrap();
    }
    std::fs::write(dir.join("notes.tmp-x.txt"), b"mine").unwrap();
    // Resume (stopped by SIGTERM once it trains further: the run has 100000 episodes).
    let rows = || std::fs::read_to_string(dir.join("episodes.csv")).unwrap().lines().count();
    let killed_at = rows();
    let mut child = bin()
        .args(["train", "--resume", s(&dir), "--eval-trials", "0"])
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    while rows() <= killed_at + 2 {
        assert!(child.try_wait().unwrap().is_none(), "the resumed run ended");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap().success());
    assert_eq!(child.wait().unwrap().code(), Some(130));
    for f in stale {
        assert!(!dir.join(f).exists(), "{f} left");
    }
    assert!(dir.join("checkpoints/latest.safetensors").exists());
    assert_eq!(std::fs::read(dir.join("notes.tmp-x.txt")).unwrap(), b"mine");
    // And in a sweep directory, by reproduce.
    let sweep = root.join("sweep");
    std::fs::create_dir_all(&sweep).unwrap();
    std::fs::write(sweep.join("preset.toml.tmp-31337"), b"half").unwrap();
    let preset = root.join("p.toml");
    std::fs::write(&preset, PRESET.replace("seeds = [1, 2, 3]", "seeds = [1]").replace("\"ddpg\", ", ""))
        .unwrap();
    let o = bin().args(["reproduce", "--preset", s(&preset), "--out", s(&sweep)]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!sweep.join("preset.toml.tmp-31337").exists());
    std::fs::remove_dir_all(&root).ok();
}
