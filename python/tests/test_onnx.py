"""`stagerl export`: the ONNX model checked with an independent runtime (onnxruntime) and the
ONNX checker.

- Parity: on >= 1000 observations of real plans (`stagerl plan`, rebuilt from each row's q,
  end-effector position and target by the documented layout), the model's joint velocities equal
  the ones stagerl applied (the next row's `joint_vel`) to 1e-5 rad/s.
- Rollout: the model rolled out here (stagerl.Chain("ur5").fk and the policy's integration rule,
  q += v * dt clamped to the limits) on the 100 targets of a `stagerl eval` reaches exactly the
  targets that evaluation reached.

Each algorithm is covered: DDPG and TD3 (the actor's tanh output), SAC and CrossQ (tanh of the
mean half; CrossQ's actor is its batch-renormalised network folded into plain layers), PPO (the
linear mean, clipped), and PPO, SAC, TD3 and CrossQ with normalised observations
(`agent.ppo.norm_obs`, `agent.norm_obs`: the model subtracts the running means and divides by
the standard deviations first). The runs are tiny (trained here in a few seconds): parity needs no good policy, and
the rollout comparison holds for any success count; a larger success radius (beta = 0.05 m)
makes some targets reached.
"""

import json
import pathlib
import re
import subprocess

import numpy as np
import onnx
import onnxruntime as ort
import pytest

from stagerl import Chain

TINY = """[reward]
beta_m = 0.05
[agent]
hidden = [32, 32]
batch_size = 32
learning_starts = 200
[train]
eval_every_episodes = 50
"""


def run_cli(stagerl_bin, *args, stdin=None):
    p = subprocess.run([stagerl_bin, *args], input=stdin, capture_output=True, text=True)
    assert p.returncode == 0, f"stagerl {' '.join(args)} failed: {p.stderr}"
    return p.stdout


@pytest.fixture(scope="module", params=["ddpg", "td3", "sac", "ppo", "ppo-norm", "sac-norm", "td3-norm", "crossq", "crossq-norm"])
def exported(request, stagerl_bin, tmp_path_factory):
    """A tiny trained run of the algorithm, its exported model and the model's session."""
    d = tmp_path_factory.mktemp(f"onnx-{request.param}")
    algo, norm = request.param.split("-")[0], request.param.endswith("-norm")
    if not norm:
        config = TINY
    elif algo == "ppo":
        config = TINY + "[agent.ppo]\nnorm_obs = { clip = 10.0 }\n"
    else:  # the off-policy agents' setting
        config = TINY.replace("[agent]\n", "[agent]\nnorm_obs = { clip = 10.0 }\n")
    if algo == "crossq":  # critics as small as the actor (its default, 1024 wide, is for real runs)
        config += "[agent.crossq]\ncritic_hidden = [32, 32]\n"
    (d / "tiny.toml").write_text(config)
    run = d / "run"
    run_cli(stagerl_bin, "train", "--config", str(d / "tiny.toml"), "--algo", algo,
            "--episodes", "150", "--seed", "5", "--eval-trials", "10", "--out", str(run))
    model = d / "policy.onnx"
    run_cli(stagerl_bin, "export", "--run", str(run), "--out", str(model))
    session = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
    assert ("obs_norm.mean" in [i.name for i in onnx.load(str(model)).graph.initializer]) == norm
    return algo, run, model, session


def policy_of(run: pathlib.Path) -> dict:
    """The checkpoint's `policy` metadata entry (read from the safetensors header)."""
    raw = (run / "checkpoints" / "best.safetensors").read_bytes()
    n = int.from_bytes(raw[:8], "little")
    return json.loads(json.loads(raw[8:8 + n])["__metadata__"]["policy"])


def observations(q, ee, target, k):
    """The standard observation (f32) of rows of q (N, dof), ee (N, 3) and target (N, 3)."""
    d = (target - ee) * k
    obs = np.concatenate([q / np.pi, ee, target, d, np.linalg.norm(d, axis=1, keepdims=True)], axis=1)
    return obs.astype(np.float32)


def test_the_model_is_valid_onnx_with_its_interface_and_metadata(exported):
    algo, run, model, session = exported
    m = onnx.load(str(model))
    onnx.checker.check_model(m, full_check=True)
    assert m.opset_import[0].version >= 13
    (inp,), (out,) = session.get_inputs(), session.get_outputs()
    assert (inp.name, inp.shape, inp.type) == ("observation", ["batch", 16], "tensor(float)")
    assert (out.name, out.shape, out.type) == ("joint_velocity", ["batch", 6], "tensor(float)")
    props = {p.key: p.value for p in m.metadata_props}
    for key in ["observation_layout", "robot", "config_hash", "stagerl_version", "algorithm", "action_rule"]:
        assert props.get(key), f"metadata `{key}` missing: {props}"
    assert props["robot"] == "ur5" and props["algorithm"] == algo
    assert "q_over_pi" in props["observation_layout"] and "scaled_distance" in props["observation_layout"]
    ck = (run / "checkpoints" / "best.safetensors").read_bytes()
    header = json.loads(ck[8:8 + int.from_bytes(ck[:8], "little")])
    assert props["config_hash"] == header["__metadata__"]["config_hash"]
    # A batch of any size; actions within the speed limits.
    x = np.random.default_rng(0).normal(size=(7, 16)).astype(np.float32)
    (v,) = session.run(None, {"observation": x})
    limits = np.array(policy_of(run)["action"]["speed_limits"])
    assert v.shape == (7, 6) and np.all(np.abs(v) <= limits * (1 + 1e-6))


def test_the_model_matches_stagerls_own_actions(exported, stagerl_bin):
    _, run, _, session = exported
    policy = policy_of(run)
    k, upper = policy["observation"]["obs_delta_scale"], np.array(policy["action"]["upper_limits"])
    lower = np.array(policy["action"]["lower_limits"])
    rng = np.random.default_rng(1)
    obs, expected = [], []
    while sum(len(o) for o in obs) < 1000:
        target = [rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(0.1, 0.6)]
        text = run_cli(stagerl_bin, "plan", "--run", str(run), "--max-steps", "200", "--format", "jsonl",
                       "--target", ",".join(map(str, target)))
        rows = [json.loads(line) for line in text.splitlines()[:-1]]
        q = np.array([r["q"] for r in rows])
        ee = np.array([r["ee_pos"] for r in rows])
        vel = np.array([r["joint_vel"] for r in rows])
        # The velocity applied in step k+1 is the command where no joint limit was hit.
        free = np.all((q[1:] > lower) & (q[1:] < upper), axis=1)
        obs.append(observations(q[:-1], ee[:-1], np.tile(target, (len(rows) - 1, 1)), k)[free])
        expected.append(vel[1:][free])
    obs, expected = np.concatenate(obs), np.concatenate(expected)
    (got,) = session.run(None, {"observation": obs})
    worst = np.max(np.abs(got - expected))
    print(f"parity: {len(obs)} observations, largest difference {worst:.2e} rad/s")
    assert len(obs) >= 1000 and worst <= 1e-5, f"{len(obs)} observations, largest difference {worst} rad/s"


def test_the_model_rolled_out_here_reaches_what_stagerl_eval_reaches(exported, stagerl_bin):
    _, run, _, session = exported
    policy = policy_of(run)
    cfg = (run / "config.toml").read_text()
    beta = float(re.search(r"(?m)^beta_m = (.*)$", cfg).group(1))
    max_steps = int(re.search(r"(?m)^max_steps = (.*)$", cfg).group(1))
    text = run_cli(stagerl_bin, "eval", "--run", str(run), "--trials", "100", "--seed", "77")
    csv = run / text.split("per-trial CSV ")[1].split(" (")[0].rsplit("/", 1)[1]
    trials = np.genfromtxt(csv, delimiter=",", names=True)
    targets = np.stack([trials["target_x_m"], trials["target_y_m"], trials["target_z_m"]], axis=1)
    # The home pose: row 0 of a plan.
    home = json.loads(run_cli(stagerl_bin, "plan", "--run", str(run), "--target", "0.4,0.1,0.3",
                              "--format", "jsonl").splitlines()[0])["q"]
    chain = Chain("ur5")
    dt, lower, upper = policy["action"]["dt_s"], chain.lower_limits, chain.upper_limits
    k = policy["observation"]["obs_delta_scale"]
    q = np.tile(home, (len(targets), 1))
    ee, _ = chain.fk(q)
    active = np.ones(len(targets), dtype=bool)
    reached = np.zeros(len(targets), dtype=bool)
    for _ in range(max_steps):
        (v,) = session.run(None, {"observation": observations(q, ee, targets, k)})
        q = np.where(active[:, None], np.clip(q + v.astype(np.float64) * dt, lower, upper), q)
        ee, _ = chain.fk(q)
        hit = active & (np.linalg.norm(targets - ee, axis=1) < beta)
        reached |= hit
        active &= ~hit
    eval_success = trials["success"].astype(bool)
    print(f"rollout: {reached.sum()} of {len(targets)} reached here, {eval_success.sum()} by stagerl eval")
    assert reached.sum() == eval_success.sum(), f"{reached.sum()} reached here, {eval_success.sum()} by stagerl eval"
    assert np.array_equal(reached, eval_success), np.flatnonzero(reached != eval_success)
