#!/usr/bin/env python3
"""Stable-Baselines3's end-to-end training throughput on stagerl's task, the reference of
`stagerl bench train` (issue 10): environment steps per second with one gradient step per
environment step, hidden 64 x 64, batch 256, 1000 random steps first, one thread (or --threads).

Not part of the tests (torch is heavy). In a venv with torch, stable-baselines3 and this
project's package (`pip install ./python`), in the same session as the Rust figures:

    python scripts/bench/bench_sb3.py --algo sac ddpg td3 --steps 5000
    target/release/stagerl bench train --algo sac

Prints one JSON line per algorithm: {"algo", "steps", "steps_per_sec", "sb3", "torch"}.
"""

import argparse
import json
import time

import gymnasium as gym
import stable_baselines3 as sb3
import torch

import stagerl  # noqa: F401  (registers stagerl/Reach-v0)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--algo", nargs="+", default=["sac", "ddpg", "td3"])
    p.add_argument("--steps", type=int, default=5000, help="timed steps after the 1000 random ones")
    p.add_argument("--threads", type=int, default=1, help="torch's intra-op threads (stagerl: --threads)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    for algo in args.algo:
        env = gym.make("stagerl/Reach-v0", reward="sar")
        cls = {"sac": sb3.SAC, "ddpg": sb3.DDPG, "td3": sb3.TD3}[algo]
        kwargs = dict(
            policy_kwargs=dict(net_arch=[64, 64]),
            batch_size=256,
            learning_starts=1000,
            train_freq=1,
            gradient_steps=1,
            gamma=0.95,
            device="cpu",
            seed=0,
            verbose=0,
        )
        model = cls("MlpPolicy", env, **kwargs)
        total = 1000 + args.steps
        start = time.perf_counter()
        model.learn(total_timesteps=total)
        secs = time.perf_counter() - start
        print(json.dumps({
            "algo": algo,
            "steps": total,
            "steps_per_sec": round(total / secs, 1),
            "sb3": sb3.__version__,
            "torch": torch.__version__,
        }))


if __name__ == "__main__":
    main()
