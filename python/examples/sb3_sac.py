"""Stable-Baselines3 SAC on ``stagerl/Reach-v0``, beside stagerl's own SAC on the same number
of environment steps (figures in docs/python.md; not run in CI: torch is heavy).

    python -m venv sb3-venv && sb3-venv/bin/pip install ./python stable-baselines3
    sb3-venv/bin/python python/examples/sb3_sac.py --stagerl-bin target/release/stagerl --episodes 1000
    sb3-venv/bin/python python/examples/sb3_sac.py --steps 50000     # SB3 alone

With ``--stagerl-bin``, ``stagerl train`` (SAC, SAR reward, ``--seed``) runs first for
``--episodes`` episodes (a budget in episodes: they end early on success), and SB3 then trains
for exactly as many environment steps as it took; without it, SB3 trains ``--steps`` steps.
SB3's SAC gets stagerl's SAC settings (networks 64 x 64, gamma 0.95, tau 0.005, batch 256,
1000 random steps first, one update per step, automatic entropy with target -dim(A) from
alpha 1.0; one learning rate, 1e-3, where stagerl tunes alpha at 3e-4; one torch thread).
Both deterministic policies are evaluated in the Python environment on the same ``--trials``
targets (``reset(seed=--eval-seed)``, then unseeded resets); stagerl's through
:class:`stagerl.Policy` (its best checkpoint). Prints one JSON line per agent, with the wall and
CPU seconds of training.
"""

import argparse
import json
import pathlib
import re
import resource
import subprocess
import tempfile
import time

import gymnasium as gym
import numpy as np

import stagerl
from stagerl.envs import ReachEnv


def evaluate(act, trials: int, seed: int) -> dict:
    """Success rate and mean final distance (m) of ``act(obs) -> action`` on ``trials`` targets."""
    env = ReachEnv(reward="sar")
    successes, final = 0, []
    for trial in range(trials):
        obs, _ = env.reset(seed=seed if trial == 0 else None)
        while True:
            obs, _, term, trunc, info = env.step(act(obs))
            if term or trunc:
                break
        successes += bool(term)
        final.append(info["distance"])
    return {"success_rate": successes / trials, "mean_final_distance_m": float(np.mean(final)), "trials": trials}


def train_sb3(steps: int, seed: int) -> tuple:
    import torch
    from stable_baselines3 import SAC

    torch.set_num_threads(1)
    env = gym.make("stagerl/Reach-v0", reward="sar")
    model = SAC(
        "MlpPolicy", env, learning_rate=1e-3, buffer_size=1_000_000, learning_starts=1000, batch_size=256,
        tau=0.005, gamma=0.95, train_freq=1, gradient_steps=1, ent_coef="auto_1.0",
        policy_kwargs={"net_arch": [64, 64]}, seed=seed, verbose=0, device="cpu",
    )
    t, cpu = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=steps)
    wall, cpu = time.perf_counter() - t, time.process_time() - cpu
    return (lambda obs: model.predict(obs, deterministic=True)[0]), wall, cpu


def train_stagerl(binary: str, episodes: int, seed: int, out: pathlib.Path) -> tuple:
    t, before = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(
        [binary, "train", "--algo", "sac", "--reward", "sar", "--seed", str(seed), "--episodes", str(episodes),
         "--out", str(out), "--eval-trials", "0"],
        capture_output=True, text=True, check=True,
    )
    wall, after = time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    found = re.search(r"trained \d+ episodes, (\d+) env steps", done.stdout + done.stderr)
    if not found:
        raise SystemExit(f"stagerl train printed no step count:\n{done.stdout}")
    policy = stagerl.Policy.load(out)
    return (lambda obs: policy(obs)), wall, cpu, int(found.group(1))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=50_000, help="SB3's environment steps without --stagerl-bin")
    ap.add_argument("--episodes", type=int, default=1000, help="stagerl's training episodes (with --stagerl-bin)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trials", type=int, default=500, help="evaluation targets")
    ap.add_argument("--eval-seed", type=int, default=0)
    ap.add_argument("--stagerl-bin", help="the stagerl binary, to train stagerl's SAC on the same budget")
    args = ap.parse_args()

    steps = args.steps
    with tempfile.TemporaryDirectory() as tmp:
        if args.stagerl_bin:
            act, wall, cpu, steps = train_stagerl(args.stagerl_bin, args.episodes, args.seed, pathlib.Path(tmp) / "run")
            print(json.dumps({"agent": "stagerl-sac", "episodes": args.episodes, "env_steps": steps,
                              "train_wall_s": round(wall, 1), "train_cpu_s": round(cpu, 1),
                              **evaluate(act, args.trials, args.eval_seed)}), flush=True)
        act, wall, cpu = train_sb3(steps, args.seed)
        print(json.dumps({"agent": "sb3-sac", "env_steps": steps, "train_wall_s": round(wall, 1),
                          "train_cpu_s": round(cpu, 1), **evaluate(act, args.trials, args.eval_seed)}), flush=True)


if __name__ == "__main__":
    main()
