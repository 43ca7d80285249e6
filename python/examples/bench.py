"""Speed of the Python bindings (figures in the README's Python section; not run in CI).

    target/py-venv/bin/python python/examples/bench.py
"""

import time

import gymnasium as gym
import numpy as np

import stagerl
from stagerl.envs import ReachEnv


def steps_per_s(env, n=200_000):
    actions = np.random.default_rng(0).uniform(-1, 1, (1024, 6)).astype(np.float32)
    env.reset(seed=0)
    t = time.perf_counter()
    for i in range(n):
        _, _, term, trunc, _ = env.step(actions[i % 1024])
        if term or trunc:
            env.reset()
    return n / (time.perf_counter() - t)


def main():
    print(f"ReachEnv.step directly: {steps_per_s(ReachEnv()):,.0f} steps/s")
    print(f"through gymnasium.make's wrappers: {steps_per_s(gym.make('stagerl/Reach-v0')):,.0f} steps/s")
    rng = np.random.default_rng(1)
    n = 1_000_000
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    args = (rng.uniform(-1, 1, (n, 3)), q, rng.uniform(-1, 1, (n, 3)), rng.uniform(-3, 3, (n, 6)))
    best = min(_timed(lambda: stagerl.rewards.compute(*args)) for _ in range(3))
    print(f"rewards.compute over 1 M rows: {best * 1e3:.0f} ms")
    chain = stagerl.Chain()
    qs = rng.uniform(-np.pi, np.pi, (n, 6))
    print(f"Chain.fk over 1 M rows: {min(_timed(lambda: chain.fk(qs)) for _ in range(3)) * 1e3:.0f} ms")
    print(f"Chain.jacobian over 1 M rows: {min(_timed(lambda: chain.jacobian(qs)) for _ in range(3)) * 1e3:.0f} ms")


def _timed(f):
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


if __name__ == "__main__":
    main()
