"""Speed of the Python bindings (figures in docs/python.md; not run in CI).

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


def vector_env(num_envs=256, batches=100, rounds=100, threads=1):
    """Steps/s of the native vector env through ``step`` and of the Rust ``VecEnv`` it wraps
    (timed in Rust, no Python in the loop, on a copy of the same batch with the same actions),
    in ``rounds`` interleaved rounds of ``batches`` steps, so that both see the same machine
    load: the best round of each, and the median of the rounds' ratios. ``threads``: the
    vector env's threads (both are split over them)."""
    envs = gym.make_vec("stagerl/Reach-v0", num_envs=num_envs, vectorization_mode="vector_entry_point",
                        threads=threads)
    actions = np.random.default_rng(0).uniform(-1, 1, (64, num_envs, 6)).astype(np.float32)
    envs.reset(seed=0)
    py, native = [], []
    for _ in range(rounds):
        t = time.perf_counter()
        for k in range(batches):
            envs.step(actions[k % 64])
        py.append(time.perf_counter() - t)
        native.append(envs.unwrapped._core.time_native_steps(actions, batches))
    steps = num_envs * batches
    return steps / min(py), steps / min(native), float(np.median(np.array(native) / np.array(py)))


def main():
    print(f"ReachEnv.step directly: {steps_per_s(ReachEnv()):,.0f} steps/s")
    print(f"through gymnasium.make's wrappers: {steps_per_s(gym.make('stagerl/Reach-v0')):,.0f} steps/s")
    for threads in (1, 2):
        py, native, median = vector_env(threads=threads)
        print(f"vector env, 256 sub-environments, {threads} thread(s): {py:,.0f} steps/s through step, "
              f"Rust VecEnv {native:,.0f} steps/s ({py / native:.0%} of it; median ratio of the rounds {median:.0%})")
    rng = np.random.default_rng(1)
    n = 1_000_000
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    args = (rng.uniform(-1, 1, (n, 3)), q, rng.uniform(-1, 1, (n, 3)), rng.uniform(-3, 3, (n, 6)))
    best = min(_timed(lambda: stagerl.rewards.compute(*args)) for _ in range(5))
    print(f"rewards.compute over 1 M rows: {best * 1e3:.0f} ms")
    policy_bench()
    chain = stagerl.Chain()
    qs = rng.uniform(-np.pi, np.pi, (n, 6))
    print(f"Chain.fk over 1 M rows: {min(_timed(lambda: chain.fk(qs)) for _ in range(3)) * 1e3:.0f} ms")
    print(f"Chain.jacobian over 1 M rows: {min(_timed(lambda: chain.jacobian(qs)) for _ in range(3)) * 1e3:.0f} ms")


def policy_bench():
    """Policy(obs) over a batch of 100 000 observations, an untrained-size (64 x 64) SAC run."""
    import os
    import subprocess
    import tempfile

    binary = os.environ.get("STAGERL_BIN", "target/release/stagerl")
    if not os.path.isfile(binary):
        print(f"Policy: skipped ({binary} not built; set STAGERL_BIN)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([binary, "train", "--episodes", "30", "--out", f"{tmp}/run", "--eval-trials", "0"],
                       check=True, capture_output=True)
        policy = stagerl.Policy.load(f"{tmp}/run")
        env = ReachEnv()
        obs = np.stack([env.reset(seed=s)[0] for s in range(1000)] * 100)
        best = min(_timed(lambda: policy(obs)) for _ in range(3))
        print(f"Policy (64 x 64 SAC) over 100 000 observations: {best * 1e3:.0f} ms ({len(obs) / best:,.0f} actions/s)")
        t = [_timed(lambda: stagerl.plan(f"{tmp}/run", env.target.tolist())) for _ in range(5)]
        print(f"stagerl.plan, one {ReachEnv().max_steps}-step plan: {min(t) * 1e3:.1f} ms")


def _timed(f):
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


if __name__ == "__main__":
    main()
