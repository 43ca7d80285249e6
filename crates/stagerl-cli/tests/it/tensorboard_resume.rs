//! After any sequence of kills (SIGKILL, SIGTERM) and resumes, a run's TensorBoard log holds
//! every tag's steps exactly once, with the values of an uninterrupted run.

use crate::common;

use common::{assert_steps_once, bin, scratch, tb_scalars};
use std::process::{Command, Stdio};
use std::time::Duration;

const CONFIG: &str = "[agent]\nalgo = \"sac\"\nhidden = [16, 16]\nlearning_starts = 200\nbatch_size = 32\n\
[train]\nepisodes = 240\neval_every_episodes = 50\neval_trials = 5\ncheckpoint_every_episodes = 20\n";

/// The scalars sorted, values as bits (every value here is deterministic, none depends on wall
/// time).
fn sorted(dir: &std::path::Path) -> Vec<(String, i64, u32)> {
    let mut v: Vec<(String, i64, u32)> =
        tb_scalars(dir).into_iter().map(|(t, s, x)| (t, s, x.to_bits())).collect();
    v.sort();
    v
}

#[test]
fn kills_and_resumes_leave_each_step_once_with_the_uninterrupted_values() {
    let root = scratch("tb-resume");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let (full, cut) = (root.join("full"), root.join("cut"));
    let c = cfg.to_str().unwrap();
    let o = bin()
        .args(["train", "--config", c, "--out", full.to_str().unwrap(), "--eval-trials", "0"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_steps_once(&tb_scalars(&full), 240, 50, "uninterrupted");

    // Kill when episodes.csv reaches these episodes (never a checkpoint boundary), by SIGKILL
    // (episodes after the last checkpoint are logged again) or SIGTERM (saved mid-episode).
    let rows =
        || std::fs::read_to_string(cut.join("episodes.csv")).map(|t| t.lines().count() as u64).unwrap_or(0);
    for (k, (target, signal)) in
        [(33, "KILL"), (58, "TERM"), (71, "KILL"), (107, "KILL"), (150, "TERM"), (191, "KILL")]
            .into_iter()
            .enumerate()
    {
        let mut cmd = bin();
        if k == 0 {
            cmd.args(["train", "--config", c, "--out", cut.to_str().unwrap()]);
        } else {
            cmd.args(["train", "--resume", cut.to_str().unwrap()]);
        }
        let mut child =
            cmd.args(["--eval-trials", "0"]).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
        while rows() <= target && child.try_wait().unwrap().is_none() {
            std::thread::sleep(Duration::from_millis(2));
        }
        assert!(child.try_wait().unwrap().is_none(), "session {k} finished before its kill at {target}");
        assert!(Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap()
            .success());
        let status = child.wait().unwrap();
        if signal == "TERM" {
            assert_eq!(status.code(), Some(130), "session {k}");
        }
    }
    let o = bin().args(["train", "--resume", cut.to_str().unwrap(), "--eval-trials", "0"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let scalars = tb_scalars(&cut);
    assert_steps_once(&scalars, 240, 50, "killed and resumed");
    assert_eq!(sorted(&cut), sorted(&full), "(tag, step, value) differ from the uninterrupted run");
    std::fs::remove_dir_all(&root).ok();
}
