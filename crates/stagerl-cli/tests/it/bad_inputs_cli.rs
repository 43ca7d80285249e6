//! Bad input to the `stagerl` binary: arguments, files and JSON lines. Every case must exit with
//! an error (non-zero, not 101, the code of a panic, and not killed by a signal such as an
//! allocation abort), print no "panicked", name what is wrong (each listed substring appears on
//! stderr), and leave every file of the fixture directory as it was.
//!
//! The cases are data: adding one is adding one line to a table. In arguments, `$DIR` is the
//! fixture directory, `$RUN` a small trained SAC run (hidden [8, 8]) and `$EMPTY` a run directory
//! with a config but no checkpoint.

use crate::common;

use common::{bin, snapshot, spawn_piped};
use std::path::Path;
use std::process::Output;

use stagerl::agent::Algo;
use stagerl::config::Config;
use stagerl::io::checkpoint::Checkpoint;
use stagerl::run::dir::RunDir;
use stagerl::train::train;

struct Case {
    args: &'static [&'static str],
    stdin: &'static str,
    expect: &'static [&'static str],
}

const GOOD_REWARD: &str =
    r#"{"ee_pos":[0,0,0],"ee_quat":[0,0,0,1],"target":[0.3,0,0],"joint_vel":[0,0,0,0,0,0]}"#;

#[rustfmt::skip]
const ARGS: &[Case] = &[
    // Unknown algorithm or reward, bad numbers.
    Case { args: &["train", "--algo", "a2c"], stdin: "", expect: &["a2c", "ddpg, td3, sac, ppo"] },
    Case { args: &["train", "--algo", "ppo", "--her", "future"], stdin: "", expect: &["agent.her", "ppo"] },
    Case { args: &["train", "--her", "sometimes"], stdin: "", expect: &["sometimes", "future, final, episode"] },
    Case { args: &["train", "--reward", "sparse"], stdin: "", expect: &["sparse", "basic, posture, stride, har, sar"] },
    Case { args: &["train", "--episodes=-5"], stdin: "", expect: &["--episodes", "-5"] },
    Case { args: &["train", "--episodes", "-5"], stdin: "", expect: &["-5"] },
    Case { args: &["train", "--episodes", "many"], stdin: "", expect: &["--episodes", "many"] },
    Case { args: &["train", "--episodes", "0", "--out", "$DIR/out/zero"], stdin: "", expect: &["train.episodes"] },
    Case { args: &["train", "--seed=-1"], stdin: "", expect: &["--seed", "-1"] },
    Case { args: &["train", "--eval-trials=-1"], stdin: "", expect: &["--eval-trials", "-1"] },
    Case { args: &["train", "--frobnicate"], stdin: "", expect: &["--frobnicate"] },
    // Config files: missing, malformed, out of range (and once an allocation abort).
    Case { args: &["train", "--config", "$DIR/missing.toml"], stdin: "", expect: &["missing.toml", "No such file"] },
    Case { args: &["train", "--config", "$DIR/bad.toml", "--out", "$DIR/out/bad"], stdin: "", expect: &["bad.toml", "unknown field `max_step`"] },
    Case { args: &["train", "--config", "$DIR/huge_buffer.toml", "--out", "$DIR/out/huge"], stdin: "", expect: &["agent.buffer_size"] },
    Case { args: &["demo", "--config", "$DIR/bad.toml"], stdin: "", expect: &["bad.toml", "max_step"] },
    Case { args: &["reward", "--function", "sar", "--config", "$DIR/missing.toml"], stdin: "", expect: &["missing.toml"] },
    // A run that exists is not replaced without --force.
    Case { args: &["train", "--out", "$RUN", "--episodes", "1"], stdin: "", expect: &["already holds a run", "--force"] },
    // Missing required arguments, unknown commands.
    Case { args: &["eval"], stdin: "", expect: &["--run"] },
    Case { args: &["reward"], stdin: "", expect: &["--function"] },
    // The clearance term needs the whole arm and the obstacles: refused, not ignored.
    Case { args: &["reward", "--function", "sar", "--config", "$DIR/clearance.toml"], stdin: "", expect: &["reward.clearance", "stagerl reward", "end effector"] },
    Case { args: &["frobnicate"], stdin: "", expect: &["frobnicate"] },
    Case { args: &[], stdin: "", expect: &["Usage"] },
    // Eval: run directories and checkpoints.
    Case { args: &["eval", "--run", "$DIR/nope"], stdin: "", expect: &["nope", "config.toml"] },
    Case { args: &["eval", "--run", "$EMPTY"], stdin: "", expect: &["holds no checkpoint"] },
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/runs/td3/checkpoints/final.safetensors"], stdin: "", expect: &["td3/checkpoints/final.safetensors", "checkpoint of algorithm `td3`, the config says `sac`"] },
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/runs/wide/checkpoints/final.safetensors"], stdin: "", expect: &["wide/checkpoints/final.safetensors", "has shape [16, 16], this agent's has [8, 16]"] },
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/garbage.safetensors"], stdin: "", expect: &["garbage.safetensors", "not a valid checkpoint"] },
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/truncated.safetensors"], stdin: "", expect: &["truncated.safetensors", "not a valid checkpoint"] },
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/nan.safetensors"], stdin: "", expect: &["nan.safetensors", "`actor.layer1.weight`[3] = NaN is not finite"] },
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/missing.safetensors"], stdin: "", expect: &["missing.safetensors", "No such file"] },
    Case { args: &["eval", "--run", "$RUN", "--trials", "0"], stdin: "", expect: &["--trials", "0 is not in 1..=10000000"] },
    Case { args: &["eval", "--run", "$RUN", "--obstacles-in-path", "0.5"], stdin: "", expect: &["--obstacles-in-path", "task.random_obstacles"] },
    Case { args: &["eval", "--run", "$RUN", "--trials", "4000000000"], stdin: "", expect: &["--trials", "4000000000"] },
    // Robots.
    Case { args: &["fk", "--robot", "$DIR/missing.urdf"], stdin: "", expect: &["missing.urdf"] },
    Case { args: &["fk", "--robot", "$DIR/branchy.urdf"], stdin: "", expect: &["branchy.urdf", "several leaf links (`tip`, `side`)"] },
    Case { args: &["fk", "--robot", "ur5", "--tip", "flange"], stdin: "", expect: &["unknown tip link `flange`"] },
    // Benchmarks take their values through the same validation.
    Case { args: &["bench", "env", "--steps=-1"], stdin: "", expect: &["--steps", "-1"] },
    Case { args: &["bench", "env", "--threads", "2"], stdin: "", expect: &["--threads", "1 for one environment"] },
    Case { args: &["bench", "env", "--num-envs", "0"], stdin: "", expect: &["--num-envs", "0"] },
    Case { args: &["bench", "update", "--hidden", "0"], stdin: "", expect: &["agent.hidden"] },
    Case { args: &["bench", "update", "--batch", "0"], stdin: "", expect: &["agent.batch_size"] },
    Case { args: &["bench", "update", "--algo", "ppo"], stdin: "", expect: &["ppo", "off-policy"] },
    // Unbounded resources: refused before allocating, with the estimate.
    Case { args: &["train", "--config", "$DIR/huge_hidden.toml", "--out", "$DIR/out/hh"], stdin: "", expect: &["agent.hidden", "would need about 60.8 GiB"] },
    Case { args: &["train", "--config", "$DIR/huge_replay.toml", "--out", "$DIR/out/hr"], stdin: "", expect: &["agent.buffer_size", "replay buffer or rollout 14.9"] },
    Case { args: &["bench", "update", "--hidden", "16384"], stdin: "", expect: &["agent.hidden", "GiB"] },
    Case { args: &["bench", "train", "--hidden", "16384"], stdin: "", expect: &["agent.hidden", "GiB"] },
    Case { args: &["bench", "update", "--updates", "4294967295"], stdin: "", expect: &["--updates", "4294967295"] },
    Case { args: &["bench", "env", "--steps", "18446744073709551615"], stdin: "", expect: &["--steps"] },
    Case { args: &["bench", "train", "--steps", "18446744073709551615"], stdin: "", expect: &["--steps"] },
    Case { args: &["demo", "--show", "4294967295"], stdin: "", expect: &["--show", "4294967295"] },
    Case { args: &["demo", "--trials", "4294967295"], stdin: "", expect: &["--trials", "4294967295"] },
    Case { args: &["demo", "--trials", "0"], stdin: "", expect: &["--trials"] },
    Case { args: &["report", "$DIR/runs", "--trajectories", "4294967295", "--out", "$DIR/out/report"], stdin: "", expect: &["--trajectories", "4294967295"] },
    Case { args: &["report", "$DIR/empty-dir", "--out", "$DIR/out/report"], stdin: "", expect: &["empty-dir", "no runs to report on"] },
    Case { args: &["fk", "--robot", "$DIR/deep.urdf"], stdin: "", expect: &["deep.urdf", "nested more than 64 deep"] },
    Case { args: &["reward", "--function", "sar", "--robot", "$DIR/deep.urdf"], stdin: "", expect: &["deep.urdf", "nested more than 64 deep"] },
];

#[rustfmt::skip]
const FK_LINES: &[Case] = &[
    Case { args: &["fk"], stdin: "{}\n", expect: &["line 1", "missing field `joints`"] },
    Case { args: &["fk"], stdin: "{\"joints\":[0,0,0]}\n", expect: &["line 1", "q has 3 values", "6 joints"] },
    Case { args: &["fk"], stdin: "{\"joints\":[]}\n", expect: &["line 1", "q has 0 values"] },
    Case { args: &["fk"], stdin: "{\"joints\":[0,0,0,0,0,0]}\n{\"joints\":\"0,0,0,0,0,0\"}\n", expect: &["line 2", "malformed"] },
    Case { args: &["fk"], stdin: "{\"joints\":[0,0,0,0,0,null]}\n", expect: &["line 1", "malformed"] },
    Case { args: &["fk"], stdin: "{\"joints\":[0,0,0,0,0,true]}\n", expect: &["line 1", "malformed"] },
    Case { args: &["fk"], stdin: "{\"joints\":[0,0,0,0,0,0],\"speed\":1}\n", expect: &["line 1", "unknown field `speed`"] },
    Case { args: &["fk"], stdin: "[0,0,0,0,0,0]\n", expect: &["line 1", "malformed"] },
    Case { args: &["fk"], stdin: "{\"joints\":[0,0,0,0,0,1e999]}\n", expect: &["line 1"] },
    Case { args: &["fk"], stdin: "\n\n{\"joints\":[0,0,0,0,0,0]\n", expect: &["line 3", "malformed"] },
    Case { args: &["fk", "--robot", "$DIR/two.urdf"], stdin: "{\"joints\":[0,0,0,0,0,0]}\n", expect: &["line 1", "q has 6 values", "2 joints"] },
    // Finite input whose pose overflows f64; a URDF origin too large to compute with.
    Case { args: &["fk", "--robot", "$DIR/slider.urdf"], stdin: "{\"joints\":[1e308,1e308]}\n", expect: &["line 1", "forward kinematics overflows", "`s1` [-1, 1]"] },
    Case { args: &["fk", "--robot", "$DIR/far.urdf"], stdin: "{\"joints\":[0,0]}\n", expect: &["far.urdf", "joint `j2` has origin xyz = [1e308, 0.0, 0.2]", "within +-1e6 m"] },
    Case { args: &["fk", "--robot", "$DIR/long_slider.urdf"], stdin: "{\"joints\":[0,0]}\n", expect: &["long_slider.urdf", "prismatic joint `s1` has limits [-1e300, 1.0]"] },
];

#[rustfmt::skip]
const REWARD_LINES: &[Case] = &[
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "missing field `target`"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "`ee_pos` has 2 values, expected 3"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,1],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "`ee_quat` has 3 values, expected 4"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "`target` has 4 values, expected 3"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,2],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "ee_quat has norm 2"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,0],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "ee_quat has norm 0"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1.00001],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "ee_quat has norm 1.00001"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":[]}\n", expect: &["line 1", "`joint_vel` has 0 values, expected 6"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":\"fast\"}\n", expect: &["line 1", "malformed"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,\"a\",0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "malformed"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0],\"velocity\":1}\n", expect: &["line 1", "unknown field `velocity`"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0],\"prev_ee_pos\":[0,0]}\n", expect: &["line 1", "`prev_ee_pos` has 2 values, expected 3"] },
    Case { args: &["reward", "--function", "stride", "--config", "$DIR/displacement.toml"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "prev_ee_pos"] },
    Case { args: &["reward", "--function", "sar"], stdin: "$GOOD\n\n$GOOD\n{\"ee_pos\":[0,0,0]}\n", expect: &["line 4", "missing field"] },
    Case { args: &["reward", "--function", "sar"], stdin: "null\n", expect: &["line 1", "malformed"] },
    // joint_vel has one value per joint of --robot (the UR5 by default).
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":[0,0,0]}\n", expect: &["line 1", "`joint_vel` has 3 values, expected 6", "ur5"] },
    Case { args: &["reward", "--function", "sar", "--robot", "$DIR/two.urdf"], stdin: "$GOOD\n", expect: &["line 1", "`joint_vel` has 6 values, expected 2", "two.urdf"] },
    Case { args: &["reward", "--function", "sar", "--robot", "$DIR/missing.urdf"], stdin: "$GOOD\n", expect: &["missing.urdf"] },
    // Export: run directories, checkpoints, an --out that exists (without --force), is a
    // directory or cannot be written.
    Case { args: &["export", "--run", "$DIR/nope", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["nope", "config.toml"] },
    Case { args: &["export", "--run", "$RUN"], stdin: "", expect: &["--out"] },
    Case { args: &["export", "--run", "$EMPTY", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["holds no checkpoint"] },
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "$DIR/garbage.safetensors", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["garbage.safetensors"] },
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "$DIR/truncated.safetensors", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["truncated.safetensors"] },
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "$DIR/missing.safetensors", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["missing.safetensors"] },
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "$DIR/runs/td3/checkpoints/final.safetensors", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["checkpoint of algorithm `td3`, the config says `sac`"] },
    Case { args: &["export", "--run", "$RUN", "--out", "$DIR/bad.toml"], stdin: "", expect: &["bad.toml exists", "--force"] },
    Case { args: &["export", "--run", "$RUN", "--out", "$DIR/empty-dir", "--force"], stdin: "", expect: &["empty-dir is a directory"] },
    Case { args: &["export", "--run", "$RUN", "--out", "$DIR/no-such-dir/p.onnx"], stdin: "", expect: &["no-such-dir/p.onnx", "No such file"] },
    // View: run directories, target counts, plans files with bad lines, --out.
    Case { args: &["view", "--run", "$DIR/nope", "--out", "$DIR/out/v.html"], stdin: "", expect: &["nope", "config.toml"] },
    Case { args: &["view", "--run", "$EMPTY", "--out", "$DIR/out/v.html"], stdin: "", expect: &["holds no checkpoint"] },
    Case { args: &["view", "--run", "$RUN", "--checkpoint", "$DIR/garbage.safetensors", "--out", "$DIR/out/v.html"], stdin: "", expect: &["garbage.safetensors"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "0", "--out", "$DIR/out/v.html"], stdin: "", expect: &["--targets", "0 is not in 1..=500"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "1000000", "--out", "$DIR/out/v.html"], stdin: "", expect: &["--targets", "1000000 is not in 1..=500"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "-3", "--out", "$DIR/out/v.html"], stdin: "", expect: &["-3"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "2", "--plans", "$DIR/plans_bad_json.jsonl"], stdin: "", expect: &["cannot be used with"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/missing.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["missing.jsonl", "No such file"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/plans_bad_json.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["plans_bad_json.jsonl line 3, column", "EOF while parsing"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/plans_bad_field.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["plans_bad_field.jsonl line 2", "unknown field `targt`"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/plans_far.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["plans_far.jsonl line 2", "out of reach"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/plans_start.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["plans_start.jsonl line 1", "start pose has 2 values, expected 6"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/empty-plans.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["holds no plan request"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/huge-plans.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["huge-plans.jsonl is larger than 1048576 bytes"] },
    Case { args: &["view", "--run", "$RUN", "--plans", "$DIR/plans_many.jsonl", "--out", "$DIR/out/v.html"], stdin: "", expect: &["501 plan requests", "1 to 500"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "1", "--out", "$DIR/bad.toml"], stdin: "", expect: &["bad.toml exists", "--force"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "1", "--out", "$DIR/no-such-dir/v.html"], stdin: "", expect: &["no-such-dir/v.html", "No such file"] },
    Case { args: &["plan", "--controller", "jacobian", "--target", "0.4,0.2,0.3", "--view", "$DIR/bad.toml"], stdin: "", expect: &["bad.toml exists", "--force"] },
    Case { args: &["plan", "--controller", "jacobian", "--target", "0.4,0.2,0.3", "--force"], stdin: "", expect: &["--view"] },
    // Negative values reach the flag's own check (not clap's "unexpected argument '-0'").
    Case { args: &["eval", "--run", "$RUN", "--obstacles-in-path", "-0.5"], stdin: "", expect: &["--obstacles-in-path", "-0.5", "a probability in [0, 1]"] },
    Case { args: &["eval", "--run", "$RUN", "--obstacles-in-path=-1e308"], stdin: "", expect: &["--obstacles-in-path", "a probability in [0, 1]"] },
    Case { args: &["train", "--seed", "-1"], stdin: "", expect: &["invalid value '-1' for '--seed"] },
    // Outputs and inputs that are not regular files: refused, never read.
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "/dev/zero", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["/dev/zero is a character device", "must be a regular file"] },
    Case { args: &["export", "--run", "$RUN", "--out", "/dev/full", "--force"], stdin: "", expect: &["/dev/full is a character device, not a regular file"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "1", "--out", "/dev/null"], stdin: "", expect: &["/dev/null is a character device"] },
    Case { args: &["plan", "--controller", "jacobian", "--target", "0.4,0.2,0.3", "--view", "/dev/full"], stdin: "", expect: &["/dev/full is a character device"] },
    Case { args: &["eval", "--run", "$DIR/devzero-run"], stdin: "", expect: &["config.toml is a character device"] },
    // A run's files are written by the run alone, whatever --force says (symbolic links and `..`
    // resolved); an output is never the checkpoint it is made from.
    Case { args: &["export", "--run", "$RUN", "--out", "$RUN/checkpoints/final.safetensors", "--force"], stdin: "", expect: &["checkpoints/final.safetensors", "in `checkpoints/`", "--force does not change that"] },
    Case { args: &["export", "--run", "$RUN", "--out", "$RUN/checkpoints/latest.safetensors", "--force"], stdin: "", expect: &["latest.safetensors", "in `checkpoints/`"] },
    Case { args: &["export", "--run", "$RUN", "--out", "$RUN/checkpoints/../config.toml", "--force"], stdin: "", expect: &["`config.toml`, a file of the run"] },
    Case { args: &["export", "--run", "$RUN", "--out", "$DIR/link-to-final.onnx", "--force"], stdin: "", expect: &["link-to-final.onnx", "in `checkpoints/`"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "1", "--out", "$RUN/episodes.csv", "--force"], stdin: "", expect: &["`episodes.csv`, a file of the run"] },
    Case { args: &["view", "--run", "$RUN", "--targets", "1", "--out", "$RUN/eval-final-seed0.csv", "--force"], stdin: "", expect: &["`eval-final-seed0.csv`, a file of the run"] },
    Case { args: &["plan", "--run", "$RUN", "--target", "0.4,0.2,0.3", "--view", "$RUN/eval.csv", "--force"], stdin: "", expect: &["--view", "`eval.csv`, a file of the run"] },
    Case { args: &["plan", "--run", "$RUN", "--target", "0.4,0.2,0.3", "--view", "$RUN/tb/v.html", "--force"], stdin: "", expect: &["in `tb/`"] },
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "$DIR/copy.safetensors", "--out", "$DIR/copy.safetensors", "--force"], stdin: "", expect: &["is the file this command reads"] },
    // A checkpoint under a config that changes its policy's inputs or outputs.
    Case { args: &["eval", "--run", "$RUN", "--checkpoint", "$DIR/runs/scale1/checkpoints/final.safetensors"], stdin: "", expect: &["trained with `observation.obs_delta_scale` = 1.0, used with 10.0 (config: `task.obs_delta_scale` = 1.0 there, 10.0 here)", "refused"] },
    Case { args: &["plan", "--run", "$RUN", "--checkpoint", "$DIR/runs/scale1/checkpoints/final.safetensors", "--target", "0.4,0.2,0.3"], stdin: "", expect: &["obs_delta_scale", "refused"] },
    Case { args: &["export", "--run", "$RUN", "--checkpoint", "$DIR/runs/scale1/checkpoints/final.safetensors", "--out", "$DIR/out/p.onnx"], stdin: "", expect: &["obs_delta_scale", "refused"] },
    Case { args: &["eval", "--run", "$DIR/runs/edited"], stdin: "", expect: &["task.obs_delta_scale", "refused"] },
    Case { args: &["view", "--run", "$DIR/runs/edited", "--targets", "1", "--out", "$DIR/out/v.html"], stdin: "", expect: &["task.obs_delta_scale", "refused"] },
    // Finite input whose terms overflow f64.
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[1e200,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "`distance` = inf is not finite"] },
    Case { args: &["reward", "--function", "stride"], stdin: "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0],\"joint_vel\":[1e200,0,0,0,0,0]}\n", expect: &["line 1", "`move` = inf is not finite"] },
    Case { args: &["reward", "--function", "sar"], stdin: "{\"ee_pos\":[-1.7e308,0,0],\"ee_quat\":[0,0,0,1],\"target\":[1.7e308,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n", expect: &["line 1", "is not finite"] },
];

fn small_run(dir: &Path, algo: Algo, hidden: usize) {
    small_run_of(dir, algo, hidden, Config::default());
}

/// [`small_run`] from another config than the default.
fn small_run_of(dir: &Path, algo: Algo, hidden: usize, mut cfg: Config) {
    cfg.agent.algo = algo;
    cfg.agent.hidden = vec![hidden, hidden];
    cfg.agent.batch_size = 8;
    cfg.agent.buffer_size = 1000;
    cfg.agent.learning_starts = 30;
    cfg.train.episodes = 2;
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 1;
    train(&cfg, dir, |_| {}).unwrap();
}

const TWO_JOINT_URDF: &str = r#"<robot name="two">
  <link name="base"/><link name="l1"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
    <origin xyz="0.5 0 0.2"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"#;

/// The fixture directory: three small runs and the files the cases point at.
fn fixture(dir: &Path) {
    std::fs::remove_dir_all(dir).ok();
    std::fs::create_dir_all(dir.join("out")).unwrap();
    let runs = dir.join("runs");
    small_run(&runs.join("sac"), Algo::Sac, 8);
    small_run(&runs.join("td3"), Algo::Td3, 8);
    small_run(&runs.join("wide"), Algo::Sac, 16);
    let empty = dir.join("empty-run");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::copy(RunDir::new(&runs.join("sac")).config(), RunDir::new(&empty).config()).unwrap();

    let good = std::fs::read(RunDir::new(&runs.join("sac")).final_checkpoint()).unwrap();
    std::fs::write(dir.join("garbage.safetensors"), b"\x00\x01 not a checkpoint").unwrap();
    std::fs::write(dir.join("truncated.safetensors"), &good[..good.len() / 2]).unwrap();
    let ck = Checkpoint::from_bytes(&good, Path::new("good")).unwrap();
    let mut nan = Checkpoint::new();
    for name in ck.tensor_names() {
        let (shape, data) = ck.tensor(name).unwrap();
        let mut data = data.to_vec();
        if name == "actor.layer1.weight" {
            data[3] = f32::NAN;
        }
        nan.put_tensor(name, shape, &data);
    }
    for key in ["algorithm", "agent_rng", "actor_opt.step", "q1_opt.step", "q2_opt.step", "alpha_opt.step"] {
        nan.put_meta(key, ck.meta(key).unwrap());
    }
    nan.save(&dir.join("nan.safetensors")).unwrap();

    // A run trained with obs_delta_scale = 1 (the others: 10, the default), and a run whose
    // config.toml was edited after training.
    let mut scale1 = Config::default();
    scale1.task.obs_delta_scale = 1.0;
    small_run_of(&runs.join("scale1"), Algo::Sac, 8, scale1);
    small_run(&runs.join("edited"), Algo::Sac, 8);
    let edited = RunDir::new(&runs.join("edited")).config();
    let text = std::fs::read_to_string(&edited).unwrap();
    assert!(text.contains("obs_delta_scale = 10.0"), "{text}");
    std::fs::write(&edited, text.replace("obs_delta_scale = 10.0", "obs_delta_scale = 2.0")).unwrap();
    // A run directory whose config.toml is /dev/zero; a link to a run's checkpoint; a copy of one.
    std::fs::create_dir_all(dir.join("devzero-run")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.join("devzero-run/config.toml")).unwrap();
    let final_ck = RunDir::new(&runs.join("sac")).final_checkpoint();
    std::os::unix::fs::symlink(&final_ck, dir.join("link-to-final.onnx")).unwrap();
    std::fs::copy(&final_ck, dir.join("copy.safetensors")).unwrap();
    std::fs::write(dir.join("bad.toml"), "[task]\nmax_step = 10\n").unwrap();
    std::fs::write(dir.join("huge_buffer.toml"), "[agent]\nbuffer_size = 100000000000000\n").unwrap();
    std::fs::write(dir.join("clearance.toml"), "[reward.clearance]\nweight = 1.0\n").unwrap();
    std::fs::write(dir.join("displacement.toml"), "[reward]\ndirection = \"displacement\"\n").unwrap();
    std::fs::write(dir.join("two.urdf"), TWO_JOINT_URDF).unwrap();
    let branchy =
        TWO_JOINT_URDF.replace("<link name=\"tip\"/>", "<link name=\"tip\"/><link name=\"side\"/>").replace(
            "</robot>",
            "<joint name=\"j3\" type=\"fixed\"><parent link=\"base\"/><child link=\"side\"/></joint></robot>",
        );
    std::fs::write(dir.join("branchy.urdf"), branchy).unwrap();
    std::fs::write(
        dir.join("deep.urdf"),
        format!("<robot name=\"r\">{}{}</robot>", "<a>".repeat(40_000), "</a>".repeat(40_000)),
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("empty-dir")).unwrap();
    let good_plan = "{\"target\":[0.4,0.2,0.3]}\n";
    std::fs::write(dir.join("plans_bad_json.jsonl"), format!("{good_plan}\n{{\"target\":[0.4,\n")).unwrap();
    std::fs::write(dir.join("plans_bad_field.jsonl"), format!("{good_plan}{{\"targt\":[0.4,0.2,0.3]}}\n"))
        .unwrap();
    std::fs::write(dir.join("plans_far.jsonl"), format!("{good_plan}{{\"target\":[3,0,0.3]}}\n")).unwrap();
    std::fs::write(dir.join("plans_start.jsonl"), "{\"target\":[0.4,0.2,0.3],\"start\":[0,0]}\n").unwrap();
    std::fs::write(dir.join("empty-plans.jsonl"), "\n  \n").unwrap();
    std::fs::write(dir.join("huge-plans.jsonl"), good_plan.repeat(50_000)).unwrap();
    std::fs::write(dir.join("plans_many.jsonl"), good_plan.repeat(501)).unwrap();
    std::fs::write(dir.join("huge_hidden.toml"), "[agent]\nhidden = [16384, 16384, 16384, 16384]\n").unwrap();
    std::fs::write(dir.join("huge_replay.toml"), "[agent]\nhidden = [4096, 4096]\nbuffer_size = 100000000\n")
        .unwrap();
    std::fs::write(dir.join("far.urdf"), TWO_JOINT_URDF.replace("0.5 0 0.2", "1e308 0 0.2")).unwrap();
    let slider = TWO_JOINT_URDF
        .replace("name=\"j1\" type=\"revolute\"", "name=\"s1\" type=\"prismatic\"")
        .replace("name=\"j2\" type=\"revolute\"", "name=\"s2\" type=\"prismatic\"")
        .replace("axis xyz=\"0 0 1\"", "axis xyz=\"1 0 0\"")
        .replace("axis xyz=\"0 1 0\"", "axis xyz=\"1 0 0\"")
        .replace("lower=\"-3\" upper=\"3\"", "lower=\"-1\" upper=\"1\"");
    std::fs::write(dir.join("slider.urdf"), &slider).unwrap();
    std::fs::write(dir.join("long_slider.urdf"), slider.replacen("lower=\"-1\"", "lower=\"-1e300\"", 1))
        .unwrap();
}

fn run(args: &[String], stdin: &str) -> Output {
    // A command may exit before reading its input (a bad argument): `feed` takes the broken pipe.
    crate::common::feed(spawn_piped(bin().args(args)), stdin)
}

/// Run every case of `table`; return the failures.
fn check(table: &[Case], dir: &Path) -> Vec<String> {
    let d = dir.to_string_lossy().into_owned();
    let subst = |s: &str| {
        s.replace("$RUN", &format!("{d}/runs/sac"))
            .replace("$EMPTY", &format!("{d}/empty-run"))
            .replace("$DIR", &d)
            .replace("$GOOD", GOOD_REWARD)
    };
    let mut failures = Vec::new();
    for c in table {
        let args: Vec<String> = c.args.iter().map(|a| subst(a)).collect();
        let stdin = subst(c.stdin);
        let before = snapshot(dir);
        let out = run(&args, &stdin);
        let err = String::from_utf8_lossy(&out.stderr);
        let case = format!("`stagerl {}` < {:?}", args.join(" "), stdin);
        if std::env::var_os("STAGERL_SHOW_ERRORS").is_some() {
            eprintln!("{case}\n    -> {:?} {}", out.status.code(), err.trim_end());
        }
        match out.status.code() {
            None => failures.push(format!("{case}: killed by a signal ({:?}); stderr: {err}", out.status)),
            Some(0) => failures.push(format!("{case}: succeeded, expected an error")),
            Some(101) => failures.push(format!("{case}: exit code 101 (a panic); stderr: {err}")),
            Some(_) => {}
        }
        if err.contains("panicked") {
            failures.push(format!("{case}: stderr reports a panic: {err}"));
        }
        for needle in c.expect {
            if !err.contains(needle) {
                failures.push(format!("{case}: stderr does not contain {needle:?}: {err}"));
            }
        }
        if snapshot(dir) != before {
            failures.push(format!("{case}: files in the fixture directory changed"));
        }
    }
    failures
}

#[test]
fn bad_input_to_the_cli_is_an_error_naming_the_problem() {
    let dir = std::env::temp_dir().join(format!("stagerl-bad-cli-{}", std::process::id()));
    fixture(&dir);
    // The fixture is sound: the good run evaluates, and the good lines are answered.
    let d = dir.to_string_lossy().into_owned();
    let ok =
        run(&["eval".into(), "--run".into(), format!("{d}/runs/sac"), "--trials".into(), "2".into()], "");
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    std::fs::remove_file(dir.join("runs/sac/eval-final-trials2-seed0.csv")).unwrap();
    let ok = run(&["reward".into(), "--function".into(), "sar".into()], &format!("{GOOD_REWARD}\n"));
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let two = format!("{d}/two.urdf");
    let ok = run(
        &["reward".into(), "--function".into(), "sar".into(), "--robot".into(), two],
        &GOOD_REWARD.replace("[0,0,0,0,0,0]", "[0.5,-0.5]"),
    );
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));

    let mut failures = check(ARGS, &dir);
    failures.extend(check(FK_LINES, &dir));
    failures.extend(check(REWARD_LINES, &dir));
    // Nothing was created where a failed `train` was pointed.
    let created: Vec<_> = std::fs::read_dir(dir.join("out")).unwrap().map(|e| e.unwrap().path()).collect();
    if !created.is_empty() {
        failures.push(format!("failed `train` commands created {created:?}"));
    }
    let total = ARGS.len() + FK_LINES.len() + REWARD_LINES.len();
    assert!(
        failures.is_empty(),
        "{} failures over {total} cases:\n{}",
        failures.len(),
        failures.join("\n\n")
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn answered_lines_before_a_bad_one_are_kept() {
    // The JSON-lines commands answer every good line before the bad one, then stop.
    let out = run(
        &["reward".into(), "--function".into(), "sar".into()],
        &format!("{GOOD_REWARD}\n{GOOD_REWARD}\n{{\"ee_pos\":[0,0,0]}}\n{GOOD_REWARD}\n"),
    );
    assert!(!out.status.success());
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 2);
    let out =
        run(&["fk".into()], "{\"joints\":[0,0,0,0,0,0]}\n{\"joints\":[0]}\n{\"joints\":[0,0,0,0,0,0]}\n");
    assert!(!out.status.success());
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 1);
}

#[test]
fn a_numerical_fault_is_a_clean_error_and_the_run_stays_usable() {
    // Learning rates of 1e30 blow the networks up on the first update (episode 2, step 10); the
    // checkpoint of episode 1 stays, and `eval` falls back to it.
    let dir = std::env::temp_dir().join(format!("stagerl-bad-cli-nan-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("explode.toml");
    std::fs::write(
        &cfg,
        "[agent]\nhidden = [8, 8]\nbatch_size = 8\nbuffer_size = 1000\nlearning_starts = 60\n\
         actor_lr = 1e30\ncritic_lr = 1e30\n[train]\nseed = 7\nepisodes = 20\neval_every_episodes = 0\n\
         checkpoint_every_episodes = 1\n",
    )
    .unwrap();
    let out = dir.join("run");
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let args: Vec<String> =
        ["train", "--config", &s(&cfg), "--out", &s(&out), "--eval-trials", "0"].map(String::from).to_vec();
    let r = run(&args, "");
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for needle in ["numerical fault", "actor loss", "at episode 2, step 10", "last good checkpoint"] {
        assert!(err.contains(needle), "{needle:?} not in {err}");
    }
    let run_dir = RunDir::new(&out);
    assert!(!run_dir.final_checkpoint().exists());
    let latest = Checkpoint::load(&run_dir.latest()).unwrap();
    assert_eq!(latest.json::<u64>("episode").unwrap(), 1);
    let args: Vec<String> = ["eval", "--run", &s(&out), "--trials", "3", "--json"].map(String::from).to_vec();
    let r = run(&args, "");
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(String::from_utf8_lossy(&r.stdout).contains("\"trials\":3"));
    std::fs::remove_dir_all(&dir).ok();
}

/// Known gap in `train/` and the `train` command, reported: the evaluation preallocates one
/// record per trial (`evaluate` in `train/eval.rs`), so 4e9 trials abort the process ("memory
/// allocation of 256000000000 bytes failed", SIGABRT) instead of being refused. `train.eval_trials`
/// is checked in `TrainConfig::validate` and `--eval-trials` in the train command, which this
/// branch does not touch; `eval --trials` is bounded (see `ARGS`). Enable when both are bounded.
#[rustfmt::skip]
const TRAIN_PENDING: &[Case] = &[
    Case { args: &["train", "--config", "$DIR/huge_eval.toml", "--out", "$DIR/out/a"], stdin: "", expect: &["train.eval_trials"] },
    Case { args: &["train", "--config", "$DIR/tiny.toml", "--eval-trials", "4000000000", "--out", "$DIR/out/b"], stdin: "", expect: &["--eval-trials"] },
];

#[test]

fn huge_evaluations_are_refused_not_aborted() {
    let dir = std::env::temp_dir().join(format!("stagerl-bad-cli-eval-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(dir.join("out")).unwrap();
    let tiny = "[agent]\nhidden = [8]\nbatch_size = 8\nlearning_starts = 10\n[train]\nepisodes = 1\n";
    std::fs::write(dir.join("tiny.toml"), format!("{tiny}eval_every_episodes = 0\n")).unwrap();
    std::fs::write(
        dir.join("huge_eval.toml"),
        format!("{tiny}eval_every_episodes = 1\neval_trials = 4000000000\n"),
    )
    .unwrap();
    let failures = check(TRAIN_PENDING, &dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn huge_inputs_are_quoted_as_bounded_excerpts() {
    // Each input holds a 2 MB token that the error used to echo whole: now an excerpt that ends
    // with the token's size, "... (2000000 bytes)".
    let dir = std::env::temp_dir().join(format!("stagerl-bad-cli-huge-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let big = "x".repeat(2_000_000);
    let d = dir.to_string_lossy().into_owned();
    std::fs::write(dir.join("long_line.toml"), format!("[task]\nmax_steps = {big}\n")).unwrap();
    std::fs::write(dir.join("long_value.toml"), format!("[reward]\nfunction = \"{big}\"\n")).unwrap();
    std::fs::write(
        dir.join("long_name.urdf"),
        TWO_JOINT_URDF.replace("<parent link=\"l1\"/>", &format!("<parent link=\"{big}\"/>")),
    )
    .unwrap();
    let cases: Vec<(Vec<String>, String, &str)> = vec![
        (vec!["fk".into()], format!("{{\"joints\":[0,0,0,0,0,0],\"{big}\":1}}\n"), "unknown field"),
        (vec!["fk".into()], format!("{{\"joints\":\"{big}\"}}\n"), "invalid type"),
        (
            vec!["reward".into(), "--function".into(), "sar".into()],
            format!("{{\"ee_pos\":\"{big}\"}}\n"),
            "line 1",
        ),
        (
            vec!["train".into(), "--config".into(), format!("{d}/long_line.toml")],
            String::new(),
            "long_line.toml",
        ),
        (
            vec!["demo".into(), "--config".into(), format!("{d}/long_value.toml")],
            String::new(),
            "long_value.toml",
        ),
        (vec!["fk".into(), "--robot".into(), format!("{d}/long_name.urdf")], String::new(), "does not exist"),
        (
            vec!["fk".into()],
            format!("{{\"joints\":[{}]}}\n", " ".repeat(17 << 20)),
            "longer than 16777216 bytes",
        ),
    ];
    let mut failures = Vec::new();
    for (args, stdin, needle) in cases {
        let out = run(&args, &stdin);
        let err = String::from_utf8_lossy(&out.stderr);
        let case = format!("`stagerl {}`", args.join(" "));
        if out.status.code() != Some(1) {
            failures.push(format!("{case}: exit {:?}", out.status));
        }
        if err.len() > 2000 || !err.contains(needle) || !err.contains("bytes") {
            failures.push(format!("{case}: stderr of {} bytes: {}", err.len(), &err[..err.len().min(3000)]));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    std::fs::remove_dir_all(&dir).ok();
}
