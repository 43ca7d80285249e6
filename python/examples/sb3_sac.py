"""Stable-Baselines3 SAC on ``stagerl/Reach-v0``, beside stagerl's own SAC on the same budget
(figures in the README's Python section; not run in CI: torch is heavy).

    python -m venv sb3-venv && sb3-venv/bin/pip install ./python stable-baselines3
    sb3-venv/bin/python python/examples/sb3_sac.py --steps 50000 [--stagerl-bin target/release/stagerl]

SB3's SAC gets stagerl's SAC settings (networks 64 x 64, gamma 0.95, tau 0.005, batch 256,
1000 random steps first, one update per step, automatic entropy with target -dim(A) from
alpha 1.0; one learning rate, 1e-3, where stagerl tunes alpha at 3e-4). With ``--stagerl-bin``,
``stagerl train`` runs with ``steps / max_steps`` episodes (at most as many environment steps).
Both deterministic policies are then evaluated in the Python environment on the same
``--trials`` targets (``reset(seed=--eval-seed)``, then unseeded resets); stagerl's through
:class:`stagerl.Policy` (its best checkpoint). Prints one JSON line per agent.
"""

import argparse
import json
import pathlib
import re
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
    t = time.perf_counter()
    model.learn(total_timesteps=steps)
    wall = time.perf_counter() - t
    return (lambda obs: model.predict(obs, deterministic=True)[0]), wall


def train_stagerl(binary: str, steps: int, seed: int, out: pathlib.Path) -> tuple:
    episodes = steps // ReachEnv().max_steps
    t = time.perf_counter()
    done = subprocess.run(
        [binary, "train", "--algo", "sac", "--reward", "sar", "--seed", str(seed), "--episodes", str(episodes),
         "--out", str(out), "--eval-trials", "0"],
        capture_output=True, text=True, check=True,
    )
    wall = time.perf_counter() - t
    found = re.search(r"trained \d+ episodes, (\d+) env steps", done.stdout + done.stderr)
    env_steps = int(found.group(1)) if found else None
    policy = stagerl.Policy.load(out)
    return (lambda obs: policy(obs)), wall, episodes, env_steps


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=50_000, help="environment steps of training")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trials", type=int, default=500, help="evaluation targets")
    ap.add_argument("--eval-seed", type=int, default=0)
    ap.add_argument("--stagerl-bin", help="the stagerl binary, to train stagerl's SAC on the same budget")
    args = ap.parse_args()

    act, wall = train_sb3(args.steps, args.seed)
    print(json.dumps({"agent": "sb3-sac", "env_steps": args.steps, "train_wall_s": round(wall, 1),
                      **evaluate(act, args.trials, args.eval_seed)}), flush=True)
    if args.stagerl_bin:
        with tempfile.TemporaryDirectory() as tmp:
            act, wall, episodes, env_steps = train_stagerl(args.stagerl_bin, args.steps, args.seed, pathlib.Path(tmp) / "run")
            print(json.dumps({"agent": "stagerl-sac", "episodes": episodes, "env_steps": env_steps,
                              "train_wall_s": round(wall, 1), **evaluate(act, args.trials, args.eval_seed)}), flush=True)


if __name__ == "__main__":
    main()
