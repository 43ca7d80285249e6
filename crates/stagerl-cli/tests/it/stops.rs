//! SIGINT/SIGTERM stop within about a second anywhere: between updates, between evaluation
//! trials (periodic, closing, `eval`, `demo`), and a run stopped there resumes bit-identically.
//! A run killed during its closing evaluation is evaluated on resume.

use crate::common;

use common::{assert_steps_once, bin, episodes_without_wall, scratch, tb_scalars};
use stagerl::io::checkpoint::Checkpoint;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Many updates per step and a long periodic evaluation (100 000 trials, seconds): a stop
/// arrives inside one or the other.
const CONFIG: &str = "[agent]\nalgo = \"td3\"\nhidden = [16, 16]\nlearning_starts = 100\nbatch_size = 32\n\
updates_per_step = 100\n\
[train]\nepisodes = 30\neval_every_episodes = 20\neval_trials = 100000\ncheckpoint_every_episodes = 10\n";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn rows(dir: &Path) -> usize {
    std::fs::read_to_string(dir.join("episodes.csv")).map(|t| t.lines().count()).unwrap_or(0)
}

/// Send `signal` to `child`; its exit code and the seconds it took to exit.
fn signal(child: &mut Child, signal: &str) -> (Option<i32>, f64) {
    let t0 = Instant::now();
    assert!(Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap().success());
    let status = child.wait().unwrap();
    (status.code(), t0.elapsed().as_secs_f64())
}

fn wait_rows(dir: &Path, child: &mut Child, n: usize) {
    while rows(dir) <= n {
        assert!(child.try_wait().unwrap().is_none(), "ended before episode {n}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn train_state(dir: &Path) -> String {
    Checkpoint::load(&dir.join("checkpoints/latest.safetensors"))
        .unwrap()
        .meta("train_state")
        .unwrap()
        .to_string()
}

#[test]
fn sigterm_inside_evaluations_and_updates_stops_and_resumes_bit_identically() {
    let root = scratch("stops");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let (full, cut) = (root.join("full"), root.join("cut"));
    let o =
        bin().args(["train", "--config", s(&cfg), "--out", s(&full), "--eval-trials", "0"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    // During the periodic evaluation after episode 20 (it starts once row 20 is written).
    let quiet = |c: &mut Command| c.stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let mut child = quiet(bin().args(["train", "--config", s(&cfg), "--out", s(&cut), "--eval-trials", "0"]));
    wait_rows(&cut, &mut child, 20);
    let (code, secs) = signal(&mut child, "-TERM");
    eprintln!("SIGTERM during a periodic evaluation: exit after {secs:.2} s");
    assert_eq!(code, Some(130));
    let eval_rows = std::fs::read_to_string(cut.join("eval.csv")).map(|t| t.lines().count()).unwrap_or(0);
    assert!(eval_rows <= 1, "the evaluation of episode 20 finished before the stop took effect");
    assert!(train_state(&cut).contains("\"eval_due\":true"), "{}", train_state(&cut));

    // Between updates: stop resumed sessions until one stops inside a step's 100 updates.
    let mut mid_update = 0;
    for k in 0..4 {
        let mut child = quiet(bin().args(["train", "--resume", s(&cut), "--eval-trials", "0"]));
        wait_rows(&cut, &mut child, 21 + k);
        let (code, _) = signal(&mut child, "-TERM");
        assert_eq!(code, Some(130), "session {k}");
        mid_update += usize::from(train_state(&cut).contains("\"step_under_way\":{"));
    }
    assert!(mid_update > 0, "no stop landed between updates");
    let o = bin().args(["train", "--resume", s(&cut), "--eval-trials", "0"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    assert_eq!(episodes_without_wall(&cut), episodes_without_wall(&full), "episodes.csv differs");
    let eval = |d: &Path| std::fs::read_to_string(d.join("eval.csv")).unwrap();
    assert_eq!(eval(&cut), eval(&full), "eval.csv differs");
    assert_eq!(eval(&cut).lines().count(), 3);
    let ck = |d: &Path, f: &str| Checkpoint::load(&d.join("checkpoints").join(f)).unwrap();
    assert!(ck(&cut, "final.safetensors").same_contents(&ck(&full, "final.safetensors")));
    assert!(ck(&cut, "best.safetensors").same_contents(&ck(&full, "best.safetensors")));
    assert_steps_once(&tb_scalars(&cut), 30, 20, "stopped and resumed");
    std::fs::remove_dir_all(&root).ok();
}

const SHORT: &str = "[agent]\nhidden = [16, 16]\nlearning_starts = 100\nbatch_size = 32\n\
[train]\nepisodes = 10\neval_every_episodes = 0\ncheckpoint_every_episodes = 5\n";

#[test]
fn a_run_killed_during_its_closing_evaluation_is_evaluated_on_resume() {
    let root = scratch("stops-closing");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, SHORT).unwrap();
    let dir = root.join("run");
    let record = dir.join("eval-final-seed0.json");
    let huge = "5000000"; // trials: minutes of evaluation
    let spawn = |args: &[&str]| bin().args(args).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let in_closing_eval = |child: &mut Child| {
        while !dir.join("checkpoints/final.safetensors").exists() {
            assert!(child.try_wait().unwrap().is_none(), "ended before its closing evaluation");
            std::thread::sleep(Duration::from_millis(5));
        }
        std::thread::sleep(Duration::from_millis(300));
        assert!(child.try_wait().unwrap().is_none(), "the closing evaluation ended");
    };
    // SIGTERM during the closing evaluation: exit 130, nothing of it written.
    let mut child = spawn(&["train", "--config", s(&cfg), "--out", s(&dir), "--eval-trials", huge]);
    in_closing_eval(&mut child);
    let (code, secs) = signal(&mut child, "-TERM");
    eprintln!("SIGTERM during a closing evaluation: exit after {secs:.2} s");
    assert_eq!(code, Some(130));
    assert!(!record.exists() && !dir.join("eval-final-seed0.csv").exists());
    // SIGKILL during the closing evaluation a resume started.
    let mut child = spawn(&["train", "--resume", s(&dir), "--eval-trials", huge]);
    std::thread::sleep(Duration::from_millis(500));
    assert!(child.try_wait().unwrap().is_none());
    assert_eq!(signal(&mut child, "-KILL").0, None);
    assert!(!record.exists());
    // The next resume runs it.
    let o = bin().args(["train", "--resume", s(&dir), "--eval-trials", "50"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("not evaluated") && out.contains("evaluation: success"), "{out}");
    assert!(std::fs::read_to_string(&record).unwrap().contains("\"trials\": 50"));
    assert_eq!(std::fs::read_to_string(dir.join("eval-final-seed0.csv")).unwrap().lines().count(), 51);
    let o = bin().args(["train", "--resume", s(&dir)]).output().unwrap();
    assert!(String::from_utf8_lossy(&o.stdout).contains("already finished"));

    // `eval` and `demo` stop between trials too; `eval` writes nothing then.
    for args in
        [vec!["eval", "--run", s(&dir), "--trials", huge], vec!["demo", "--show", "0", "--trials", huge]]
    {
        let mut child = spawn(&args);
        std::thread::sleep(Duration::from_millis(500));
        assert!(child.try_wait().unwrap().is_none(), "{args:?} ended");
        let (code, secs) = signal(&mut child, "-INT");
        eprintln!("SIGINT during {}: exit after {secs:.2} s", args[0]);
        assert_eq!(code, Some(130), "{args:?}");
    }
    let evals: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("eval-"))
        .collect();
    // The closing evaluation's files (selected and final checkpoint, its record); the stopped
    // `eval` wrote none.
    let mut evals = evals;
    evals.sort();
    assert_eq!(
        evals,
        ["eval-final-seed0-final-checkpoint.csv", "eval-final-seed0.csv", "eval-final-seed0.json"],
        "{evals:?}"
    );
    std::fs::remove_dir_all(&root).ok();
}
