//! SIGTERM at random moments (mid-episode, mid-update, mid-evaluation), then resume, many times
//! over: the run ends identical (but wall time) to an uninterrupted one. The state saved on
//! SIGTERM is the exact mid-episode state (random generators, environment, floats in JSON), so
//! any lost bit shows up as a different episodes.csv.

use crate::common;

use common::{assert_same_run, bin, run, scratch};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const EPISODES: u64 = 160;
const CONFIG: &str =
    "[agent]\nhidden = [16, 16]\nlearning_starts = 150\nbatch_size = 16\nbuffer_size = 20000\n\
[train]\nepisodes = 160\neval_every_episodes = 40\neval_trials = 4\ncheckpoint_every_episodes = 1000\n";

#[test]
fn sigterm_at_random_moments_then_resume_gives_the_uninterrupted_run() {
    sigterms_then_resume("resume-sigterm", CONFIG, 88);
}

/// With hindsight relabelling the episode under way is part of the saved state (what has been
/// seen of it is relabelled when it ends): DDPG on the sparse reward, the `future` strategy.
#[test]
fn sigterm_then_resume_with_her_gives_the_uninterrupted_run() {
    let config = format!(
        "{}\n[agent.her]\nstrategy = \"future\"\nk = 4\n[reward]\nfunction = \"basic\"\n",
        CONFIG.replace("[agent]\n", "[agent]\nalgo = \"ddpg\"\n")
    );
    sigterms_then_resume("resume-sigterm-her", &config, 89);
}

/// PPO: the environments mid-episode, the rollout so far and the episodes ended but not yet
/// logged are all part of the saved state.
#[test]
fn sigterm_then_resume_with_ppo_gives_the_uninterrupted_run() {
    let config = format!(
        "{}\n[agent.ppo]\nnum_envs = 4\nnum_steps = 32\n",
        CONFIG.replace("[agent]\n", "[agent]\nalgo = \"ppo\"\n").replace("episodes = 160", "episodes = 400")
    );
    sigterms_then_resume_n("resume-sigterm-ppo", &config, 90, 400);
}

fn sigterms_then_resume(name: &str, config: &str, seed: u64) {
    sigterms_then_resume_n(name, config, seed, EPISODES)
}

fn sigterms_then_resume_n(name: &str, config: &str, seed: u64, episodes: u64) {
    let root = scratch(name);
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, config).unwrap();
    let (full, cut) = (root.join("full"), root.join("cut"));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = run(&["train", "--config", &s(&cfg), "--out", &s(&full), "--eval-trials", "0"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    // Nine stops, each 1 to 12 episodes after the episode the process started from (drawn from a
    // fixed seed), then a short random delay so the signal lands anywhere inside the episode (or
    // its update, or an evaluation). Waiting for a new row also means the process is past its
    // start-up, signal handler installed.
    let mut rng = stagerl::base::rng::Rng::new(seed);
    let rows =
        || std::fs::read_to_string(cut.join("episodes.csv")).map(|t| t.lines().count() as u64).unwrap_or(0);
    let mut stops = Vec::new();
    for k in 0..9 {
        // Rows = header + episodes done. The last quarter of the run is left alone: a process
        // that outruns the signal there (a loaded machine: each stop lands a few episodes past
        // its row) would finish and exit 0 before it lands.
        let target = (rows().max(1) + rng.below(12)).min(episodes - episodes / 4);
        stops.push(target);
        let mut cmd = bin();
        if k == 0 {
            cmd.args(["train", "--config", &s(&cfg), "--out", &s(&cut)]);
        } else {
            cmd.args(["train", "--resume", &s(&cut)]);
        }
        cmd.args(["--eval-trials", "0"]).stdout(Stdio::null()).stderr(Stdio::piped());
        let mut child = cmd.spawn().unwrap();
        while rows() <= target && child.try_wait().unwrap().is_none() {
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_micros(rng.below(3000)));
        assert!(child.try_wait().unwrap().is_none(), "stop {k} came after the run finished");
        let pid = child.id().to_string();
        assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(130), "stop {k} at episode {target}: {err}");
        assert!(err.contains("--resume"), "{err}");
    }
    let out = run(&["train", "--resume", &s(&cut), "--eval-trials", "0"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    assert_same_run(
        &full,
        &cut,
        episodes as usize,
        (episodes / 40) as usize,
        &format!("after SIGTERMs after episodes {stops:?}"),
    );
    std::fs::remove_dir_all(&root).ok();
}
