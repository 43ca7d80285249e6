//! `stagerl export` end to end on a small trained run: the ONNX model's first fields (the
//! independent checks, onnxruntime and the ONNX checker, are in python/tests/test_onnx.py), the
//! same model again is left as it is, another one is refused without --force and replaced with
//! it, and --checkpoint picks the checkpoint (a run without evaluations has no best: its final one).

use crate::common;

use common::{bin, scratch};
use stagerl::agent::Algo;
use stagerl::config::Config;
use std::process::Output;

fn ok(o: Output) -> String {
    assert!(o.status.success(), "failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

#[test]
fn export_writes_once_and_refuses_to_overwrite_another_model() {
    let dir = scratch("export");
    let run = dir.join("run");
    let mut cfg = Config::default();
    cfg.agent.algo = Algo::Sac;
    cfg.agent.hidden = vec![8, 8];
    cfg.agent.learning_starts = 30;
    cfg.train.episodes = 4;
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 1;
    stagerl::train::train(&cfg, &run, |_| {}).unwrap();
    cfg.train.seed = 2;
    let other = dir.join("other");
    stagerl::train::train(&cfg, &other, |_| {}).unwrap();
    let (r, model) = (run.to_str().unwrap(), dir.join("policy.onnx"));
    let m = model.to_str().unwrap();
    let text = ok(bin().args(["export", "--run", r, "--out", m]).output().unwrap());
    assert!(text.contains("written") && text.contains("final.safetensors"), "{text}");
    let bytes = std::fs::read(&model).unwrap();
    // ModelProto: ir_version 7 (field 1), then producer_name "stagerl" (field 2).
    assert_eq!(bytes[..4], [0x08, 0x07, 0x12, 0x07]);
    assert_eq!(&bytes[4..11], b"stagerl");
    // The checkpoint is named as the run directory names it, with no absolute path of this machine.
    let has = |text: &str| bytes.windows(text.len()).any(|w| w == text.as_bytes());
    assert!(has("checkpoints/final.safetensors") && !has(dir.to_str().unwrap()), "the checkpoint's name");
    for name in
        ["observation", "joint_velocity", "actor.layer2.weight", "speed_limits", "config_hash", "Slice"]
    {
        assert!(bytes.windows(name.len()).any(|w| w == name.as_bytes()), "{name} missing");
    }
    // The same model again: unchanged. Another run's checkpoint of the same config: another
    // model, refused without --force.
    let text = ok(bin().args(["export", "--run", r, "--out", m]).output().unwrap());
    assert!(text.contains("unchanged"), "{text}");
    let theirs = other.join("checkpoints/final.safetensors");
    let args = ["export", "--run", r, "--checkpoint", theirs.to_str().unwrap(), "--out", m];
    let refused = bin().args(args).output().unwrap();
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--force"));
    assert_eq!(std::fs::read(&model).unwrap(), bytes);
    let text = ok(bin().args(args).arg("--force").output().unwrap());
    assert!(text.contains("replaced"), "{text}");
    assert_ne!(std::fs::read(&model).unwrap(), bytes);
    std::fs::remove_dir_all(&dir).ok();
}
