//! The agent's config sections through the binary: `stagerl config` prints a config that `train
//! --config` accepts and writes back unchanged; an algorithm's setting in the wrong place, or a
//! section of another algorithm than the run's, is refused with where it belongs.

use crate::common;

use common::{bin, scratch};
use stagerl::config::Config;
use std::path::Path;

fn train(config: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["train", "--config", config.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(&["--episodes", "1", "--eval-trials", "2", "--force"]);
    args.extend_from_slice(extra);
    bin().args(&args).output().unwrap()
}

#[test]
fn the_printed_config_trains_and_is_written_back_unchanged() {
    let dir = scratch("agent-config-print");
    let printed = bin().arg("config").output().unwrap();
    assert!(printed.status.success());
    let text = String::from_utf8(printed.stdout).unwrap();
    // Every algorithm's section, commented out (unset: the algorithm's defaults).
    assert!(text.contains("\n# [agent.sac]\n") && text.contains("\n# [agent.td3]\n"), "{text}");
    let path = dir.join("printed.toml");
    std::fs::write(&path, &text).unwrap();
    let out = dir.join("run");
    let o = train(&path, &out, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let printed = Config::from_toml_str(&text, &path).unwrap();
    let written = Config::load(&out.join("config.toml")).unwrap();
    // `--episodes` is the only setting the command line changed.
    assert_eq!(written.train.episodes, 1);
    let resolved = |c: Config| Config { agent: c.agent.resolved(), ..c };
    assert_eq!(resolved(Config { train: printed.train.clone(), ..written }), resolved(printed));
}

#[test]
fn misplaced_settings_and_other_algorithms_sections_are_refused() {
    let dir = scratch("agent-config-refused");
    let cases: [(&str, &[&str], &[&str]); 4] = [
        (
            "[agent]\nalgo = \"sac\"\n[agent.td3]\npolicy_delay = 3\n",
            &[],
            &["agent.td3", "agent.algo = \"sac\""],
        ),
        ("[agent.td3]\npolicy_delay = 3\n", &["--algo", "ddpg"], &["agent.td3", "agent.algo = \"ddpg\""]),
        (
            "[agent]\npolicy_delay = 3\n",
            &["--algo", "td3"],
            &["`policy_delay` in [agent]", "belongs in [agent.td3]"],
        ),
        ("[agent]\nfixed_alpha = true\n", &[], &["`fixed_alpha` in [agent]", "belongs in [agent.sac]"]),
    ];
    for (i, (toml, extra, expect)) in cases.iter().enumerate() {
        let path = dir.join(format!("case{i}.toml"));
        std::fs::write(&path, toml).unwrap();
        let out = dir.join(format!("run{i}"));
        let o = train(&path, &out, extra);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{toml:?}: {stderr}");
        assert!(expect.iter().all(|e| stderr.contains(e)), "{toml:?}: {stderr} should name {expect:?}");
        assert!(!out.join("config.toml").exists(), "{toml:?}: a refused config writes no run");
    }
    // The section of the run's algorithm is taken.
    let path = dir.join("td3.toml");
    std::fs::write(&path, "[agent.td3]\npolicy_delay = 3\n").unwrap();
    let out = dir.join("td3");
    let o = train(&path, &out, &["--algo", "td3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(Config::load(&out.join("config.toml")).unwrap().agent.td3().policy_delay, 3);
}

/// The bundled obstacle preset (`configs/obstacles.toml`, issue 34) trains as it is, with its
/// settings in the run's config: SAC (256 x 256) with layer-normalised critics and its entropy
/// coefficient starting at 0.01, the sparse reward with hindsight relabelling, the per-link
/// obstacle observation and the curriculum (whose stage `episodes.csv` records).
#[test]
fn the_obstacle_preset_trains_as_it_is() {
    let preset = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/obstacles.toml");
    let dir = scratch("obstacle-preset");
    let out = dir.join("run");
    let o = bin()
        .args(["train", "--config", preset.to_str().unwrap(), "--seed", "1", "--episodes", "30"])
        .args(["--eval-trials", "5", "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cfg = Config::load(&out.join("config.toml")).unwrap();
    let preset_cfg = Config::load(&preset).unwrap();
    assert_eq!(preset_cfg.train.episodes, 15000, "the preset's own budget");
    assert_eq!(cfg.agent.hidden, [256, 256]);
    assert!(cfg.agent.sac.as_ref().is_some_and(|s| s.critic_layer_norm && s.init_alpha == 0.01));
    let her = cfg.agent.her.as_ref().expect("the preset relabels with HER");
    assert_eq!((her.strategy, her.k), (stagerl::agent::HerStrategy::Future, 4));
    assert_eq!(cfg.reward.function, stagerl::reward::RewardFunction::Basic);
    assert!(cfg.task.observe_obstacles && cfg.task.random_obstacles.is_some());
    assert!(cfg.train.curriculum.is_some());
    let log = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert!(log.lines().next().unwrap().contains("curriculum_stage"), "{}", log.lines().next().unwrap());
    assert_eq!(log.lines().count(), 31, "a header and 30 episodes");
    std::fs::remove_dir_all(&dir).ok();
}

/// The preset for planning behind the shield (`configs/obstacles-shield.toml`) is
/// `configs/obstacles.toml` trained behind the shield: the same settings but `[task.shield]`
/// (enabled) and the shield's penalty, and it trains as it is behind the shield.
#[test]
fn the_shielded_obstacle_preset_is_the_obstacle_preset_behind_the_shield() {
    let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
    let plain = Config::load(&configs.join("obstacles.toml")).unwrap();
    let preset = configs.join("obstacles-shield.toml");
    let mut shielded = Config::load(&preset).unwrap();
    assert!(shielded.task.shield.as_ref().is_some_and(|s| s.enabled), "trained behind the shield");
    assert!(plain.task.shield.as_ref().is_none_or(|s| !s.enabled));
    assert_eq!(shielded.reward.shield_penalty, Some(0.25), "the penalty its figures were measured with");
    shielded.task.shield = plain.task.shield;
    shielded.reward.shield_penalty = plain.reward.shield_penalty;
    assert_eq!(shielded, plain, "nothing else differs from configs/obstacles.toml");
    let dir = scratch("obstacle-shield-preset");
    let out = dir.join("run");
    let o = bin()
        .args(["train", "--config", preset.to_str().unwrap(), "--seed", "1", "--episodes", "20"])
        .args(["--eval-trials", "5", "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cfg = Config::load(&out.join("config.toml")).unwrap();
    assert!(cfg.task.shield.as_ref().is_some_and(|s| s.enabled), "the run's config keeps the shield");
    std::fs::remove_dir_all(&dir).ok();
}
