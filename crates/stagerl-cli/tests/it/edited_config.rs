//! A run whose `config.toml` was edited after training: `eval` refuses an edit that changes the
//! policy's inputs or outputs (naming the field), and evaluates under any other edit with a
//! warning naming it (train --resume refuses both: the config hash differs).

use crate::common;

use common::{bin, scratch};
use stagerl::config::Config;
use stagerl::run::dir::RunDir;

#[test]
fn eval_of_an_edited_run_warns_or_refuses_naming_the_field() {
    let dir = scratch("edited-config");
    let run = dir.join("run");
    let mut cfg = Config::default();
    cfg.agent.hidden = vec![8, 8];
    cfg.agent.batch_size = 8;
    cfg.agent.buffer_size = 1000;
    cfg.agent.learning_starts = 30;
    cfg.train.episodes = 2;
    cfg.train.eval_every_episodes = 0;
    stagerl::train::train(&cfg, &run, |_| {}).unwrap();
    let r = run.to_str().unwrap();
    // Each evaluation on its own seed (its own file).
    let eval =
        |seed: &str| bin().args(["eval", "--run", r, "--trials", "2", "--seed", seed]).output().unwrap();
    // As trained: no warning.
    let out = eval("0");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    let path = RunDir::new(&run).config();
    let text = std::fs::read_to_string(&path).unwrap();
    // Another reward: evaluated, with a warning naming the field.
    assert!(text.contains("function = \"sar\""), "{text}");
    std::fs::write(&path, text.replace("function = \"sar\"", "function = \"har\"")).unwrap();
    let out = eval("1");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("warning") && err.contains("`reward.function` = \"sar\" there, \"har\" here"),
        "{err}"
    );
    // Another observation scale: refused, naming it.
    std::fs::write(&path, text.replace("obs_delta_scale = 10.0", "obs_delta_scale = 3.0")).unwrap();
    let out = eval("2");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("`task.obs_delta_scale` = 10.0 there, 3.0 here") && err.contains("refused"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
