//! Killing `stagerl train` at any moment loses nothing: resumed runs end identical (but wall
//! time) to an uninterrupted one.

use crate::common;

use common::{assert_same_run, bin, run, scratch};
use std::process::{Command, Stdio};
use std::time::Duration;

const CONFIG: &str = "[agent]\nhidden = [16, 16]\nlearning_starts = 200\nbatch_size = 32\n\
[train]\nepisodes = 300\neval_every_episodes = 100\neval_trials = 5\ncheckpoint_every_episodes = 20\n";

#[test]
fn sigkill_at_random_moments_then_resume_gives_the_uninterrupted_run() {
    sigkills_then_resume("resume-kill", CONFIG);
}

/// The same with hindsight relabelling: SAC on the sparse reward, the `episode` strategy.
#[test]
fn sigkill_then_resume_with_her_gives_the_uninterrupted_run() {
    let config =
        format!("{CONFIG}[agent.her]\nstrategy = \"episode\"\nk = 2\n[reward]\nfunction = \"basic\"\n");
    sigkills_then_resume("resume-kill-her", &config);
}

/// The same under a budget in environment steps (14 000, 280 episodes or more), evaluated every
/// 3500 environment steps: after the episodes that pass 3500, 7000 and 10 500, and the last.
#[test]
fn sigkill_then_resume_with_an_env_step_budget_gives_the_uninterrupted_run() {
    let config = CONFIG.replace(
        "episodes = 300\neval_every_episodes = 100\n",
        "episodes = 50\nenv_steps = 14000\neval_every_env_steps = 3500\n",
    );
    assert!(config.contains("env_steps = 14000"));
    sigkills_then_resume_expecting("resume-kill-env-steps", &config, 0, 4);
}

/// The same with REDQ (ten critics, two drawn per target: the draws come from the agent's
/// random stream, which the checkpoint holds) at 3 updates per step.
#[test]
fn sigkill_then_resume_with_redq_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[agent.sac]\nn_critics = 10\ncritic_subset = 2\n",
        CONFIG.replace("[agent]\n", "[agent]\nupdates_per_step = 3\n")
    );
    assert!(config.contains("updates_per_step = 3"));
    sigkills_then_resume("resume-kill-redq", &config);
}

/// The same with DroQ (dropout and layer normalisation in the critics: the dropout streams of
/// the critics and their targets are in the checkpoint).
#[test]
fn sigkill_then_resume_with_droq_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[agent.sac]\ncritic_dropout = 0.01\ncritic_layer_norm = true\nactor_q = \"mean\"\n",
        CONFIG.replace("[agent]\n", "[agent]\nupdates_per_step = 3\n")
    );
    sigkills_then_resume("resume-kill-droq", &config);
}

/// The same with DroQ as sbx's recipe has it: its actor's log-std clip to [-20, 2] and the
/// actor and entropy coefficient stepped every 2nd update at 3 updates per step, so that the
/// policy delay's phase runs across environment steps (its update count is in the checkpoint).
#[test]
fn sigkill_then_resume_with_droq_clip_and_policy_delay_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[agent.sac]\ncritic_dropout = 0.01\ncritic_layer_norm = true\nactor_log_std = \"clip\"\npolicy_delay = 2\n",
        CONFIG.replace("[agent]\n", "[agent]\nupdates_per_step = 3\n")
    );
    assert!(config.contains("updates_per_step = 3"));
    sigkills_then_resume("resume-kill-droq-clip-delay", &config);
}

/// The same with CrossQ (batch-renormalised critics and actor: their running statistics and
/// the update count of the policy delay are in the checkpoint), its renormalisation's warm-up
/// short enough that the kills land after it, at 2 updates per step.
#[test]
fn sigkill_then_resume_with_crossq_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[agent.crossq]\ncritic_hidden = [32, 32]\nrenorm_warmup_steps = 2000\n",
        CONFIG.replace("[agent]\n", "[agent]\nalgo = \"crossq\"\nupdates_per_step = 2\n")
    );
    assert!(config.contains("algo = \"crossq\""));
    sigkills_then_resume("resume-kill-crossq", &config);
}

/// The same with PPO (small rollouts, so that kills land between updates and inside rollouts),
/// with observation normalisation, whose running statistics must survive the kills too (the
/// SIGTERM test runs PPO without it).
#[test]
fn sigkill_then_resume_with_ppo_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[agent.ppo]\nnum_envs = 4\nnum_steps = 16\nnorm_obs = {{ clip = 5.0 }}\n",
        CONFIG.replace("[agent]\n", "[agent]\nalgo = \"ppo\"\n")
    );
    sigkills_then_resume("resume-kill-ppo", &config);
}

/// The same with SAC on normalised observations (`agent.norm_obs`): the running statistics,
/// updated at every step collected, must survive the kills (and mid-episode checkpoints) too.
#[test]
fn sigkill_then_resume_with_sac_norm_obs_gives_the_uninterrupted_run() {
    let config = CONFIG.replace("[agent]\n", "[agent]\nnorm_obs = { clip = 5.0 }\n");
    assert!(config.contains("norm_obs"));
    sigkills_then_resume("resume-kill-sac-norm", &config);
}

/// The same among random obstacles placed in the way half the time (`train.obstacles_in_path`,
/// a side stream of the environment's): a checkpoint mid-episode holds the episode's obstacles,
/// and the placements after a resume are those of the uninterrupted run.
#[test]
fn sigkill_then_resume_with_obstacles_in_the_way_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[task]\non_collision = \"terminate\"\nobserve_obstacles = true\nobstacle_observation = \"nearest\"\n\
         [task.random_obstacles]\ncount = [1, 3]\n[reward]\ncollision_penalty = 10.0\n",
        CONFIG.replace("[train]\n", "[train]\nobstacles_in_path = 0.5\n")
    );
    sigkills_then_resume("resume-kill-in-path", &config);
}

/// The same with the obstacle curriculum (`[train.curriculum]`): its stage and window of
/// outcomes are in the checkpoints, so the stages (the `curriculum_stage` column) and the
/// obstacles of the resumed run are those of the uninterrupted one.
#[test]
fn sigkill_then_resume_with_a_curriculum_gives_the_uninterrupted_run() {
    // Networks of 64 (the stages advance at episodes 73 and 225, between the kills).
    let config = format!(
        "{}[task]\nobserve_obstacles = true\nobstacle_observation = \"per_link\"\n\
         [task.random_obstacles]\ncount = [1, 3]\n\
         [train.curriculum]\nwindow = 10\nadvance_at = 0.1\nobstacles_in_path = [0.0, 0.5, 1.0]\n\
         max_obstacles = [1, 2, 3]\n",
        CONFIG.replace("hidden = [16, 16]", "hidden = [64, 64]")
    );
    let (root, printed) = sigkills_then_resume_keeping("resume-kill-curriculum", &config, 300, 3);
    // The uninterrupted run says when each stage begins.
    let advances: Vec<&str> = printed.lines().filter(|l| l.contains("curriculum stage")).collect();
    assert_eq!(advances.len(), 2, "{printed}");
    assert!(advances[0].contains("curriculum stage 1 of 0-2 from the next episode"), "{printed}");
    assert!(advances[1].contains("with probability 1, at most 3 random obstacles"), "{printed}");
    let rows = common::episodes_without_wall(&root.join("cut"));
    assert!(rows[0].ends_with(",collision_steps,curriculum_stage"), "{}", rows[0]);
    let stages: std::collections::BTreeSet<&str> =
        rows[1..].iter().map(|r| r.rsplit_once(',').unwrap().1).collect();
    assert_eq!(stages.len(), 3, "the run went through every stage: {stages:?}");
    std::fs::remove_dir_all(&root).ok();
}

/// The same with demonstrations from RRT-Connect in the replay buffer
/// (`[train.demonstrations]`): planned once before the first episode, then part of the
/// checkpoints' buffer (a resumed run does not plan them again), reported in one line.
#[test]
fn sigkill_then_resume_with_demonstrations_gives_the_uninterrupted_run() {
    let config = format!(
        "{}[task]\non_collision = \"terminate\"\nobserve_obstacles = true\nobstacle_observation = \"per_link\"\n\
         [task.random_obstacles]\ncount = [1, 2]\n[reward]\ncollision_penalty = 10.0\n\
         [train.demonstrations]\nepisodes = 40\nobstacles_in_path = 1.0\n",
        CONFIG.replace("[train]\n", "[train]\nobstacles_in_path = 0.5\n")
    );
    let (root, printed) = sigkills_then_resume_keeping("resume-kill-demos", &config, 300, 3);
    let lines: Vec<&str> = printed.lines().filter(|l| l.starts_with("demonstrations:")).collect();
    assert_eq!(lines.len(), 1, "{printed}");
    assert!(
        lines[0].contains("40 episode(s) planned by RRT-Connect") && lines[0].contains("0 with a contact"),
        "{}",
        lines[0]
    );
    std::fs::remove_dir_all(&root).ok();
}

fn sigkills_then_resume(name: &str, config: &str) {
    sigkills_then_resume_expecting(name, config, 300, 3);
}

/// [`sigkills_then_resume`] of a run of `episodes` episodes (0: as many as the uninterrupted run
/// has) and `evals` periodic evaluations.
fn sigkills_then_resume_expecting(name: &str, config: &str, episodes: usize, evals: usize) {
    let (root, _) = sigkills_then_resume_keeping(name, config, episodes, evals);
    std::fs::remove_dir_all(&root).ok();
}

/// [`sigkills_then_resume_expecting`], leaving the runs (`full`, `cut`) in the directory it
/// returns, with what the uninterrupted run printed.
fn sigkills_then_resume_keeping(
    name: &str,
    config: &str,
    episodes: usize,
    evals: usize,
) -> (std::path::PathBuf, String) {
    let root = scratch(name);
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, config).unwrap();
    let (full, cut) = (root.join("full"), root.join("cut"));
    let out = run(&[
        "train",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        full.to_str().unwrap(),
        "--eval-trials",
        "0",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let printed = String::from_utf8_lossy(&out.stdout).into_owned();

    // Kill at moments tied to progress (not to wall time, so any machine speed works): when
    // episodes.csv has reached an episode drawn from a fixed seed, never a checkpoint boundary.
    let mut rng = stagerl::base::rng::Rng::new(2026);
    let mut target = 0u64;
    for k in 0..3 {
        target += 25 + rng.below(60);
        if target.is_multiple_of(20) {
            target += 7;
        }
        let mut cmd = bin();
        if k == 0 {
            cmd.args(["train", "--config", cfg.to_str().unwrap(), "--out", cut.to_str().unwrap()]);
        } else {
            cmd.args(["train", "--resume", cut.to_str().unwrap()]);
        }
        cmd.args(["--eval-trials", "0"]).stdout(Stdio::null()).stderr(Stdio::null());
        let mut child = cmd.spawn().unwrap();
        let rows = || {
            std::fs::read_to_string(cut.join("episodes.csv")).map(|t| t.lines().count() as u64).unwrap_or(0)
        };
        while rows() <= target && child.try_wait().unwrap().is_none() {
            std::thread::sleep(Duration::from_millis(2));
        }
        assert!(child.try_wait().unwrap().is_none(), "run {k} finished before its kill at episode {target}");
        child.kill().unwrap(); // SIGKILL: no chance to save anything
        child.wait().unwrap();
    }
    let out = run(&["train", "--resume", cut.to_str().unwrap(), "--eval-trials", "0"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let episodes = if episodes > 0 { episodes } else { common::episodes_without_wall(&full).len() - 1 };
    assert_same_run(&full, &cut, episodes, evals, "after SIGKILLs");

    // Resuming a finished run does nothing and says so (no closing evaluation asked for).
    let out = run(&["train", "--resume", cut.to_str().unwrap(), "--eval-trials", "0"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("already finished"));
    (root, printed)
}

#[test]
fn sigterm_saves_and_exits_130_and_existing_runs_are_protected() {
    let root = scratch("resume-term");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, CONFIG.replace("episodes = 300", "episodes = 100000")).unwrap();
    let dir = root.join("run");
    let child = bin()
        .args([
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            dir.to_str().unwrap(),
            "--eval-trials",
            "0",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--resume") && err.contains("interrupted"), "{err}");
    assert!(dir.join("checkpoints/latest.safetensors").exists());

    // A second train into the same directory is refused; the run is untouched.
    let before = std::fs::read(dir.join("episodes.csv")).unwrap();
    let out = run(&["train", "--config", cfg.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--force"));
    assert_eq!(before, std::fs::read(dir.join("episodes.csv")).unwrap());
    // --resume with other settings is a usage error.
    let out = run(&["train", "--resume", dir.to_str().unwrap(), "--seed", "3"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    std::fs::remove_dir_all(&root).ok();
}
