"""stagerl.Policy and stagerl.plan on a run trained by the CLI (the `trained_run` fixture): the
policy acts as the Rust policy (a rollout in the Python env reproduces `stagerl plan` bit for
bit), plan returns the CLI's numbers, the checkpoint's portable description holds, bad input
is a ValueError or FileNotFoundError naming it."""

import json
import os
import struct
import subprocess

import numpy as np
import pytest

import stagerl
from stagerl.envs import ReachEnv


def training_targets(run, n):
    """Targets of the training distribution (so that plans carry no warning)."""
    env = ReachEnv(config=run / "config.toml")
    env.reset(seed=5)
    targets = []
    for _ in range(n):
        targets.append(env.target.tolist())
        env.reset()
    return targets


def test_a_rollout_of_the_policy_in_the_python_env_is_the_plan(trained_run):
    policy = stagerl.Policy.load(trained_run)
    env = ReachEnv(config=trained_run / "config.toml")
    starts = [None, [0.1, -1.2, 1.0, -1.4, -1.5, 0.2]]
    for target, start in zip(training_targets(trained_run, 2), starts):
        plan = stagerl.plan(trained_run, target, start=start)
        assert plan["warning"] is None
        options = {"target": target} if start is None else {"target": target, "start": start}
        obs, info = env.reset(seed=0, options=options)
        np.testing.assert_array_equal(env.target, target)
        assert info["distance"] == plan["distance"][0]
        rewards, distances, ee = [], [], [env.ee_position]
        while True:
            obs, reward, term, trunc, info = env.step(policy(obs))
            rewards.append(reward)
            distances.append(info["distance"])
            ee.append(env.ee_position)
            if term or trunc:
                break
        assert plan["summary"]["steps"] == len(rewards) and plan["summary"]["reached"] == term
        np.testing.assert_array_equal(plan["reward"][1:], rewards)
        np.testing.assert_array_equal(plan["distance"][1:], distances)
        np.testing.assert_array_equal(plan["ee_pos"], ee)


def cli_plan(stagerl_bin, run, target, start=None, shield=False):
    args = [stagerl_bin, "plan", "--run", str(run), "--target", ",".join(map(repr, target)), "--format", "jsonl"]
    if shield:
        args.append("--shield")
    if start is not None:
        args += ["--start", ",".join(map(repr, start))]
    done = subprocess.run(args, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    return lines[:-1], lines[-1]["summary"], done.stderr


def test_plan_returns_the_cli_numbers(stagerl_bin, trained_run):
    target = training_targets(trained_run, 1)[0]
    outside = [0.4, 0.1, 0.4]  # off the training targets (their 0.05 m grid cells)
    for target, start in [(target, None), (target, [0.0, -1.0, 1.2, -1.5, -1.5, 0.0]), (outside, None)]:
        rows, summary, stderr = cli_plan(stagerl_bin, trained_run, target, start)
        plan = stagerl.plan(trained_run, target, start=start)
        assert plan["summary"].pop("plan_time_s") > 0 and summary.pop("plan_time_s") > 0  # wall time
        assert plan["summary"] == summary
        assert len(plan["step"]) == len(rows) == summary["steps"] + 1
        for key in rows[0]:
            np.testing.assert_array_equal(plan[key], np.array([r[key] for r in rows]), err_msg=key)
        assert plan["q"].shape == (len(rows), 6) and plan["ee_quat"].shape == (len(rows), 4)
        if target is outside:
            assert "outside the training target distribution" in plan["warning"]
            assert plan["warning"] in stderr
        else:
            assert plan["warning"] is None
    short = stagerl.plan(trained_run, target, max_steps=3)
    assert short["summary"]["steps"] <= 3


def test_a_shielded_plan_is_the_cli_one_with_the_shield_counts(stagerl_bin, trained_run):
    target = training_targets(trained_run, 1)[0]
    rows, summary, _ = cli_plan(stagerl_bin, trained_run, target, shield=True)
    plan = stagerl.plan(trained_run, target, shield=True)
    assert plan["summary"].pop("plan_time_s") > 0 and summary.pop("plan_time_s") > 0  # wall time
    assert plan["summary"] == summary
    assert plan["summary"]["shield_steps"] == plan["summary"]["steps"]
    for key in ["shield_interventions", "shield_stops", "shield_mean_change_rad_per_s", "shield_max_change_rad_per_s"]:
        assert key in plan["summary"]
    np.testing.assert_array_equal(plan["q"], np.array([r["q"] for r in rows]))
    free = stagerl.plan(trained_run, target)
    assert "shield_steps" not in free["summary"]
    # Obstacles and the shield together: a ball across the unshielded path is not touched.
    on_path = free["ee_pos"][int(0.6 * (len(free["ee_pos"]) - 1))]
    ball = [{"shape": "sphere", "position_m": [float(x) for x in on_path], "radius_m": 0.04}]
    unshielded = stagerl.plan(trained_run, target, obstacles=ball)
    shielded = stagerl.plan(trained_run, target, obstacles=ball, shield=True)
    assert unshielded["summary"]["collision"] and "shield_steps" not in unshielded["summary"]
    assert not shielded["summary"]["collision"] and shielded["summary"]["min_clearance_m"] > 0
    assert shielded["summary"]["shield_interventions"] > 0
    with pytest.raises(ValueError, match="shield"):
        stagerl.plan(trained_run, target, shield="yes")


def test_a_run_trained_behind_the_shield_plans_behind_it_unless_told_not_to(stagerl_bin, tmp_path):
    """`shield=None` (the default) plans as the run was trained, here behind the shield;
    `shield=False` is the policy alone, the command line's `--no-shield`."""
    config = tmp_path / "shielded.toml"
    config.write_text('[task]\non_collision = "terminate"\n[task.shield]\nenabled = true\n'
                      '[task.random_obstacles]\ncount = [1, 1]\n[train]\nepisodes = 2\neval_trials = 2\n')
    run = tmp_path / "run"
    done = subprocess.run([stagerl_bin, "train", "--config", str(config), "--out", str(run)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    target = [0.4, 0.2, 0.5]
    assert "shield_steps" in stagerl.plan(run, target)["summary"]
    alone = stagerl.plan(run, target, shield=False)
    assert "shield_steps" not in alone["summary"]
    args = [stagerl_bin, "plan", "--run", str(run), "--target", "0.4,0.2,0.5", "--format", "jsonl", "--no-shield"]
    cli = subprocess.run(args, capture_output=True, text=True)
    assert cli.returncode == 0, cli.stderr
    rows = [json.loads(line) for line in cli.stdout.splitlines()][:-1]
    np.testing.assert_array_equal(alone["q"], np.array([r["q"] for r in rows]))


def test_policy_from_a_checkpoint_file_batched_and_one_row(trained_run):
    by_dir = stagerl.Policy.load(trained_run)
    best = trained_run / "checkpoints" / "best.safetensors"
    assert by_dir.checkpoint == str(best)
    by_file = stagerl.Policy.load(best)
    final = stagerl.Policy.load(trained_run / "checkpoints" / "final.safetensors")
    assert (by_dir.obs_dim, by_dir.act_dim, by_dir.algorithm) == (16, 6, "sac")
    env = ReachEnv()
    obs = np.stack([env.reset(seed=s)[0] for s in range(64)])
    actions = by_dir(obs)
    assert actions.shape == (64, 6) and actions.dtype == np.float32
    assert np.all(np.abs(actions) <= 1.0)
    np.testing.assert_array_equal(by_file(obs), actions)
    np.testing.assert_array_equal(np.stack([by_dir(o) for o in obs]), actions)
    assert by_dir(obs[0]).shape == (6,)
    # The final checkpoint's policy: the same actions exactly when its actor is the best one's.
    assert final.checkpoint.endswith("final.safetensors")
    same_actor = all(np.array_equal(read_safetensors(best)[0][layer["weight"]], read_safetensors(final.checkpoint)[0][layer["weight"]])
                     for layer in final.spec["actor"]["layers"])
    assert np.array_equal(final(obs), actions) == same_actor


def read_safetensors(path):
    data = open(path, "rb").read()
    (n,) = struct.unpack("<Q", data[:8])
    header = json.loads(data[8:8 + n])
    body = data[8 + n:]
    tensors = {}
    for name, t in header.items():
        if name == "__metadata__":
            continue
        assert t["dtype"] == "F32"
        lo, hi = t["data_offsets"]
        tensors[name] = np.frombuffer(body[lo:hi], np.float32).reshape(t["shape"])
    return tensors, header["__metadata__"]


def test_the_portable_policy_description_reproduces_the_actions(trained_run):
    """The checkpoint's `policy` metadata and tensors alone, run in numpy, give the actions."""
    policy = stagerl.Policy.load(trained_run)
    tensors, meta = read_safetensors(policy.checkpoint)
    spec = json.loads(meta["policy"])
    assert spec == policy.spec
    obs = np.stack([ReachEnv().reset(seed=s)[0] for s in range(32)]).astype(np.float64)
    x = obs
    act = {"relu": lambda z: np.maximum(z, 0), "tanh": np.tanh, "identity": lambda z: z}
    for layer in spec["actor"]["layers"]:
        w, b = tensors[layer["weight"]].astype(np.float64), tensors[layer["bias"]].astype(np.float64)
        x = act[layer["activation"]](x @ w.T + b)
    assert spec["action"]["rule"] == "tanh_of_mean"
    expected = np.tanh(x[:, : spec["action"]["dim"]])
    np.testing.assert_allclose(policy(obs.astype(np.float32)), expected, atol=2e-5)


def test_bad_policy_and_plan_arguments(trained_run, tmp_path):
    with pytest.raises(FileNotFoundError, match=r"`path` = '.*nowhere': no such file or directory"):
        stagerl.Policy.load(tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError, match=r"config.toml"):
        stagerl.Policy.load(tmp_path)
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="junk.safetensors"):
        stagerl.Policy.load(junk)
    with pytest.raises(ValueError, match=r"`path` = 3 is invalid"):
        stagerl.Policy.load(3)
    # Not regular files: refused unread (/dev/zero used to be read until memory ran out; a FIFO
    # without a writer blocked for ever).
    with pytest.raises(ValueError, match=r"/dev/zero is a character device; a checkpoint must be a regular file"):
        stagerl.Policy.load("/dev/zero")
    fifo = tmp_path / "ck.fifo"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match=r"ck.fifo is a FIFO \(named pipe\); a checkpoint must be a regular file"):
        stagerl.Policy.load(fifo)
    policy = stagerl.Policy.load(trained_run)
    with pytest.raises(ValueError, match=r"`obs.shape` = \(2, 15\) is invalid: \(N, 16\)"):
        policy(np.zeros((2, 15), np.float32))
    bad = np.zeros((2, 16), np.float32)
    bad[1, 3] = np.inf
    with pytest.raises(ValueError, match=r"`obs\[1, 3\]` = inf is invalid: a finite number"):
        policy(bad)
    with pytest.raises(ValueError, match=r"out of reach"):
        stagerl.plan(trained_run, [3.0, 0.0, 0.5])
    with pytest.raises(ValueError, match=r"below the floor"):
        stagerl.plan(trained_run, [0.3, 0.0, -0.1])
    with pytest.raises(ValueError, match=r"`target` = \[0.3, 0.0\] is invalid: 3 numbers"):
        stagerl.plan(trained_run, [0.3, 0.0])
    with pytest.raises(ValueError, match=r"joint|limit"):
        stagerl.plan(trained_run, [0.3, 0.1, 0.4], start=[0.0, 0.0, 9.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"has 2 values|2 values|expected 6|6 joints"):
        stagerl.plan(trained_run, [0.3, 0.1, 0.4], start=[0.0, 0.0])
    with pytest.raises(ValueError, match=r"`max_steps` = 0 is invalid"):
        stagerl.plan(trained_run, [0.3, 0.1, 0.4], max_steps=0)
    with pytest.raises(ValueError, match=r"`run_dir` = .* is invalid: a run directory"):
        stagerl.plan(junk, [0.3, 0.1, 0.4])
    with pytest.raises(FileNotFoundError, match=r"`run_dir`"):
        stagerl.plan(tmp_path / "nowhere", [0.3, 0.1, 0.4])


def test_bad_reset_options():
    env = ReachEnv()
    for options in ({"start": [0.0] * 6}, {"target": [0.3, 0.1]}, {"target": [0.3, 0.1, 0.4], "speed": 1}, {"target": "x"}):
        with pytest.raises(ValueError, match=r"`options`|`target`"):
            env.reset(seed=0, options=options)
    with pytest.raises(ValueError, match=r"not finite"):
        env.reset(options={"target": [0.3, np.nan, 0.4]})
    obs, info = env.reset(options={"target": [0.3, 0.1, 0.4]})
    np.testing.assert_array_equal(obs[9:12], np.float32([0.3, 0.1, 0.4]))


def test_a_normalised_sac_policy_applies_its_statistics(stagerl_bin, tmp_path):
    """SAC with `agent.norm_obs` (the off-policy agents' running normalisation): the Policy
    normalises with the checkpoint's statistics, then takes tanh of the actor's mean half."""
    config = tmp_path / "sac.toml"
    config.write_text('[agent]\nalgo = "sac"\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 200\n'
                      'norm_obs = { clip = 10.0 }\n[train]\nepisodes = 20\neval_every_episodes = 10\n')
    run = tmp_path / "run"
    done = subprocess.run([stagerl_bin, "train", "--config", str(config), "--out", str(run), "--eval-trials", "0"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    policy = stagerl.Policy.load(run)
    tensors, _ = read_safetensors(policy.checkpoint)
    spec, norm = policy.spec, policy.spec["observation"]["normalization"]
    assert spec["format_version"] == 2 and norm["clip"] == 10.0 and spec["action"]["rule"] == "tanh_of_mean"
    obs = np.stack([ReachEnv().reset(seed=s)[0] for s in range(32)]).astype(np.float32)
    x = np.clip((obs - tensors[norm["mean"]]) / tensors[norm["std"]], np.float32(-10), np.float32(10))
    assert x.dtype == np.float32 and np.abs(x - obs).max() > 0.1, "the statistics moved from (0, 1)"
    x = x.astype(np.float64)
    act = {"relu": lambda z: np.maximum(z, 0), "tanh": np.tanh, "identity": lambda z: z}
    for layer in spec["actor"]["layers"]:
        w, b = tensors[layer["weight"]].astype(np.float64), tensors[layer["bias"]].astype(np.float64)
        x = act[layer["activation"]](x @ w.T + b)
    np.testing.assert_allclose(policy(obs), np.tanh(x[:, :spec["action"]["dim"]]), atol=2e-5)


def test_a_normalised_ppo_policy_applies_its_statistics(stagerl_bin, tmp_path):
    """PPO with `norm_obs`: the Policy normalises as the checkpoint's description says (the f32
    formula on the tensors it names), and that description is format 2."""
    config = tmp_path / "ppo.toml"
    config.write_text('[agent]\nalgo = "ppo"\nhidden = [16, 16]\n[agent.ppo]\nnum_envs = 2\nnum_steps = 32\n'
                      'norm_obs = { clip = 10.0 }\n[train]\nepisodes = 20\neval_every_episodes = 10\n')
    run = tmp_path / "run"
    done = subprocess.run([stagerl_bin, "train", "--config", str(config), "--out", str(run), "--eval-trials", "0"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    policy = stagerl.Policy.load(run)
    tensors, _ = read_safetensors(policy.checkpoint)
    spec, norm = policy.spec, policy.spec["observation"]["normalization"]
    assert spec["format_version"] == 2 and norm["clip"] == 10.0 and spec["action"]["rule"] == "actor_output"
    obs = np.stack([ReachEnv().reset(seed=s)[0] for s in range(32)]).astype(np.float32)
    x = np.clip((obs - tensors[norm["mean"]]) / tensors[norm["std"]], np.float32(-10), np.float32(10))
    assert x.dtype == np.float32 and np.abs(x - obs).max() > 0.1, "the statistics moved from (0, 1)"
    x = x.astype(np.float64)
    act = {"relu": lambda z: np.maximum(z, 0), "tanh": np.tanh, "identity": lambda z: z}
    for layer in spec["actor"]["layers"]:
        w, b = tensors[layer["weight"]].astype(np.float64), tensors[layer["bias"]].astype(np.float64)
        x = act[layer["activation"]](x @ w.T + b)
    np.testing.assert_allclose(policy(obs), np.clip(x, -1, 1), atol=2e-5)
