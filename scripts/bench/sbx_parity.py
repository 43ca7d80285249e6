#!/usr/bin/env python3
"""sbx's CrossQ and DroQ on ``stagerl/Reach-v0`` at stagerl's settings (issue 36, item 4).

Reads a stagerl config (``docs/results/sbx-parity/crossq.toml`` or ``droq.toml``): the
environment is built from the same file (robot, task, reward, observation), and sbx gets the
file's ``[agent]`` settings (network sizes, learning rates, gamma, tau, batch size, buffer size,
learning starts, updates per step, policy delay, entropy coefficient, CrossQ's batch
renormalisation, DroQ's dropout and layer norm, SAC's policy delay and, when the file sets it,
its actor's log-std bound: unset, sbx keeps its own clip). Every ``[train] eval_every_env_steps`` the
deterministic policy is evaluated, as ``stagerl train`` does, after the episode that passes a
multiple of it and after the last, on the same ``[train] eval_trials`` targets: the targets of
``stagerl train``'s periodic evaluations (seed ``train.eval_seed``), read from ``--targets``
(a CSV with columns target_x, target_y, target_z, written by ``--write-targets``), each episode
started at the home pose, success as the environment says (``info["is_success"]``, within
``reward.beta_m``).

Usage (a venv with sbx-rl and this repository's Python package, see
docs/results/sbx-parity/README.md)::

    XLA_FLAGS=--xla_cpu_multi_thread_eigen=false taskset -c 1 python scripts/bench/sbx_parity.py \\
        --config docs/results/sbx-parity/crossq.toml --algo crossq --seed 1 \\
        --targets docs/results/sbx-parity/eval-targets.csv --out sbx.csv

    # The evaluator itself, on a stagerl run's final checkpoint (must give the run's own last
    # evaluation in eval.csv):
    python scripts/bench/sbx_parity.py --config ... --check-stagerl RUN_DIR --targets ...

Output: one CSV row per evaluation (algo, impl, seed, env_steps, success_rate,
median_final_distance_m, wall_s, eval_s): ``wall_s`` the process's time since start (imports and
JAX compilation included), ``eval_s`` the part of it spent in evaluations.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

T0 = time.perf_counter()

import numpy as np  # noqa: E402

try:
    import tomllib  # Python >= 3.11
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib  # type: ignore

import gymnasium as gym  # noqa: E402

import stagerl  # noqa: E402,F401  (registers stagerl/Reach-v0)

FIELDS = ["algo", "impl", "seed", "env_steps", "success_rate", "median_final_distance_m", "wall_s", "eval_s"]


def read_targets(path: str, n: int) -> np.ndarray:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if len(rows) < n:
        sys.exit(f"{path}: {len(rows)} targets, {n} needed (train.eval_trials)")
    return np.array([[float(r["target_x"]), float(r["target_y"]), float(r["target_z"])] for r in rows[:n]])


class Evaluator:
    """The deterministic policy on fixed targets, all episodes stepped together (one batched
    forward pass per step), each in its own ``stagerl/Reach-v0`` from the same config."""

    def __init__(self, config: str, targets: np.ndarray):
        self.targets = targets
        self.envs = [gym.make("stagerl/Reach-v0", config=config).unwrapped for _ in targets]

    def __call__(self, act) -> tuple[float, float]:
        """``act(obs (N, obs_dim)) -> actions (N, act_dim)``: (success rate, median final distance)."""
        obs = np.stack([e.reset(options={"target": t})[0] for e, t in zip(self.envs, self.targets)])
        n = len(self.envs)
        live = np.ones(n, bool)
        success = np.zeros(n, bool)
        dist = np.zeros(n)
        while live.any():
            idx = np.flatnonzero(live)
            actions = np.asarray(act(obs[idx]), dtype=np.float32).reshape(len(idx), -1)
            for j, i in enumerate(idx):
                o, _, terminated, truncated, info = self.envs[i].step(np.clip(actions[j], -1.0, 1.0))
                obs[i], dist[i] = o, info["distance"]
                if terminated or truncated:
                    live[i] = False
                    success[i] = bool(info["is_success"])
        return float(success.mean()), float(np.median(dist))


def torch_dense(fan_in: int, features: int):
    """A flax Dense layer initialised as PyTorch's ``nn.Linear`` (stagerl's): weights and biases
    from U(-1/sqrt(fan_in), 1/sqrt(fan_in))."""
    import flax.linen as nn
    import jax

    bound = 1.0 / fan_in ** 0.5

    def uniform(key, shape, dtype=None):
        return jax.random.uniform(key, shape, minval=-bound, maxval=bound)

    return nn.Dense(features, kernel_init=uniform, bias_init=uniform)


def tanh_log_std_actor(torch_init: bool = False):
    """sbx's SAC actor with stagerl's SAC log-std bound (``-5 + 3.5 (tanh s + 1)``, in [-5, 2],
    CleanRL's) instead of sbx's clip to [-20, 2]: the one difference of the actors that no
    setting removes (``--actor-log-std tanh``, a diagnostic); with ``torch_init``, its layers
    initialised as stagerl's (PyTorch's) instead of flax's."""
    import flax.linen as nn
    import jax.numpy as jnp
    from sbx.common.distributions import TanhTransformedDistribution
    from sbx.common.policies import Flatten, SquashedGaussianActor, tfd

    class TanhLogStdActor(SquashedGaussianActor):
        @nn.compact
        def __call__(self, x):
            x = Flatten()(x)
            dense = (lambda n: torch_dense(x.shape[-1], n)) if torch_init else nn.Dense
            for n_units in self.net_arch:
                x = self.activation_fn(dense(n_units)(x))
            mean = dense(self.action_dim)(x)
            log_std = -5.0 + 3.5 * (jnp.tanh(dense(self.action_dim)(x)) + 1.0)
            return TanhTransformedDistribution(tfd.MultivariateNormalDiag(loc=mean, scale_diag=jnp.exp(log_std)))

    return TanhLogStdActor


def torch_init_critics():
    """sbx's critic ensemble (dropout, layer norm as ``VectorCritic``) with every layer
    initialised as PyTorch's (``--torch-init``, a diagnostic)."""
    import flax.linen as nn
    import jax.numpy as jnp
    from sbx.common.policies import Flatten, VectorCritic

    class TorchInitCritic(nn.Module):
        net_arch: tuple
        use_layer_norm: bool = False
        dropout_rate: float = 0.0
        activation_fn: object = nn.relu
        output_dim: int = 1

        @nn.compact
        def __call__(self, x, action):
            x = jnp.concatenate([Flatten()(x), action], -1)
            for n_units in self.net_arch:
                x = torch_dense(x.shape[-1], n_units)(x)
                if self.dropout_rate is not None and self.dropout_rate > 0:
                    x = nn.Dropout(rate=self.dropout_rate)(x, deterministic=False)
                if self.use_layer_norm:
                    x = nn.LayerNorm()(x)
                x = self.activation_fn(x)
            return torch_dense(x.shape[-1], self.output_dim)(x)

    class TorchInitVectorCritic(VectorCritic):
        @nn.compact
        def __call__(self, obs, action):
            vmap_critic = nn.vmap(TorchInitCritic, variable_axes={"params": 0},
                                  split_rngs={"params": True, "dropout": True}, in_axes=None, out_axes=0,
                                  axis_size=self.n_critics)
            return vmap_critic(use_layer_norm=self.use_layer_norm, dropout_rate=self.dropout_rate,
                               net_arch=tuple(self.net_arch), activation_fn=self.activation_fn,
                               output_dim=self.output_dim)(obs, action)

    return TorchInitVectorCritic


def sbx_model(algo: str, cfg: dict, env, seed: int, ups_override: int | None, actor_log_std: str = "clip",
              torch_init: bool = False):
    import flax.linen as nn
    from sbx import SAC, CrossQ

    a = cfg.get("agent", {})
    hidden = list(a.get("hidden", [64, 64]))
    common = dict(
        learning_rate=a.get("actor_lr", 1e-3),
        qf_learning_rate=a.get("critic_lr", a.get("actor_lr", 1e-3)),
        buffer_size=a.get("buffer_size", 1_000_000),
        learning_starts=a.get("learning_starts", 1000),
        batch_size=a.get("batch_size", 256),
        gamma=a.get("gamma", 0.95),
        train_freq=1,
        gradient_steps=ups_override or a.get("updates_per_step", 1),
        seed=seed,
        verbose=0,
    )
    if algo == "crossq":
        c = a.get("crossq", {})
        sub = dict(
            alpha_lr=(c.get("alpha_lr", 1e-3), common["learning_rate"]),
            adam_beta1=(c.get("adam_beta1", 0.5), 0.5),
        )
        for k, (ours, theirs) in sub.items():
            if abs(ours - theirs) > 1e-12:
                sys.exit(f"agent.crossq.{k} = {ours}: sbx has {theirs} (not settable), the config must match it")
        ent = "auto" if not c.get("fixed_alpha", False) else float(c.get("init_alpha", 1.0))
        if ent == "auto" and c.get("init_alpha", 1.0) != 1.0:
            ent = f"auto_{c['init_alpha']}"
        act_dim = env.action_space.shape[0]
        return CrossQ(
            "MlpPolicy", env,
            policy_delay=c.get("policy_delay", 3),
            ent_coef=ent,
            target_entropy=float(c.get("target_entropy_per_dim", -1.0)) * act_dim,
            policy_kwargs=dict(
                net_arch=dict(pi=hidden, qf=list(c.get("critic_hidden", [1024, 1024]))),
                n_critics=c.get("n_critics", 2),
                batch_norm_momentum=c.get("bn_momentum", 0.99),
                renorm_warmup_steps=c.get("renorm_warmup_steps", 100_000),
                activation_fn=nn.relu,
            ),
            **common,
        )
    s = a.get("sac", {})
    if s.get("actor_q", "min") != "min":
        sys.exit("agent.sac.actor_q must be \"min\": sbx's SAC takes the critics' minimum in the actor loss")
    if abs(s.get("alpha_lr", 3e-4) - common["learning_rate"]) > 1e-12:
        sys.exit("agent.sac.alpha_lr must equal agent.actor_lr: sbx's entropy coefficient runs at learning_rate")
    ent = "auto" if not s.get("fixed_alpha", False) else float(s.get("init_alpha", 1.0))
    if ent == "auto" and s.get("init_alpha", 1.0) != 1.0:
        ent = f"auto_{s['init_alpha']}"
    act_dim = env.action_space.shape[0]
    return SAC(
        "MlpPolicy", env,
        tau=a.get("tau", 0.005),
        policy_delay=s.get("policy_delay", 1),  # stagerl's agent.sac.policy_delay, counted as sbx's
        ent_coef=ent,
        target_entropy=float(s.get("target_entropy_per_dim", -1.0)) * act_dim,
        policy_kwargs=dict(
            net_arch=hidden,
            n_critics=s.get("n_critics", 2),
            dropout_rate=s.get("critic_dropout", 0.0),
            layer_norm=s.get("critic_layer_norm", False),
            activation_fn=nn.relu,
            **({"actor_class": tanh_log_std_actor(torch_init)} if actor_log_std == "tanh" else {}),
            **({"vector_critic_class": torch_init_critics()} if torch_init else {}),
        ),
        **common,
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, help="the stagerl config (TOML) both sides train with")
    p.add_argument("--algo", choices=["crossq", "droq"], help="sbx's CrossQ, or sbx's SAC as DroQ")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--env-steps", type=int, help="default: the config's train.env_steps")
    p.add_argument("--updates-per-step", type=int, help="default: the config's agent.updates_per_step")
    p.add_argument("--actor-log-std", choices=["clip", "tanh"],
                   help="DroQ: sbx's actor log-std clip to [-20, 2], or stagerl SAC's tanh bound to [-5, 2] "
                        "(default: the config's agent.sac.actor_log_std if set, else sbx's clip)")
    p.add_argument("--torch-init", action="store_true",
                   help="DroQ with --actor-log-std tanh: initialise every layer as stagerl (PyTorch) does (a diagnostic)")
    p.add_argument("--impl", default="sbx", help="the impl column of the CSV (default sbx)")
    p.add_argument("--targets", help="CSV of the evaluation targets (target_x, target_y, target_z)")
    p.add_argument("--out", help="CSV to append the evaluations to (default: stdout)")
    p.add_argument("--check-stagerl", metavar="RUN_DIR",
                   help="evaluate the final checkpoint of a stagerl run with this evaluator, print it beside the run's eval.csv")
    p.add_argument("--write-targets", metavar="TRIALS_CSV",
                   help="convert `stagerl eval`'s per-trial CSV (targets of the config's eval_seed) to --targets's format and exit")
    args = p.parse_args()

    with open(args.config, "rb") as f:
        cfg = tomllib.load(f)
    train = cfg.get("train", {})
    trials = int(train.get("eval_trials", 100))

    if args.write_targets:
        with open(args.write_targets, newline="") as f:
            rows = list(csv.DictReader(f))
        keys = [k for k in rows[0] if k.startswith("target")]
        if len(keys) != 3:
            sys.exit(f"{args.write_targets}: no target columns in {list(rows[0])}")
        w = csv.writer(sys.stdout if not args.targets else open(args.targets, "w", newline=""))
        w.writerow(["trial", "target_x", "target_y", "target_z"])
        for r in rows:
            w.writerow([r.get("trial", "")] + [r[k] for k in keys])
        return

    if not args.targets:
        sys.exit("--targets is required")
    targets = read_targets(args.targets, trials)
    evaluate = Evaluator(args.config, targets)

    if args.check_stagerl:
        policy = stagerl.Policy.load(os.path.join(args.check_stagerl, "checkpoints", "final.safetensors"))
        ok, d = evaluate(policy)
        with open(os.path.join(args.check_stagerl, "eval.csv"), newline="") as f:
            last = list(csv.DictReader(f))[-1]
        print(f"this evaluator: success {ok:.4f}, median final distance {d:.5f} m; "
              f"the run's eval.csv (last row): {dict(last)}")
        return

    if args.algo is None:
        sys.exit("--algo is required")
    budget = args.env_steps or int(train["env_steps"])
    every = int(train.get("eval_every_env_steps", 1000))
    env = gym.make("stagerl/Reach-v0", config=args.config)
    if args.actor_log_std is None:
        args.actor_log_std = cfg.get("agent", {}).get("sac", {}).get("actor_log_std", "clip") if args.algo == "droq" else "clip"
    if args.actor_log_std != "clip" and args.algo != "droq":
        sys.exit("--actor-log-std is for DroQ (sbx's SAC) only")
    if args.torch_init and args.actor_log_std != "tanh":
        sys.exit("--torch-init needs --actor-log-std tanh (it replaces that actor's initialisation)")
    model = sbx_model(args.algo, cfg, env, args.seed, args.updates_per_step, args.actor_log_std, args.torch_init)

    from stable_baselines3.common.callbacks import BaseCallback

    out = open(args.out, "a", newline="") if args.out else sys.stdout
    writer = csv.DictWriter(out, fieldnames=FIELDS)
    if not args.out or out.tell() == 0:
        writer.writeheader()
    eval_s = [0.0]

    def record(steps: int) -> None:
        t = time.perf_counter()
        ok, d = evaluate(lambda o: model.predict(o, deterministic=True)[0])
        eval_s[0] += time.perf_counter() - t
        writer.writerow(dict(algo=args.algo, impl=args.impl, seed=args.seed, env_steps=steps, success_rate=f"{ok:.4f}",
                             median_final_distance_m=f"{d:.5f}", wall_s=f"{time.perf_counter() - T0:.2f}",
                             eval_s=f"{eval_s[0]:.2f}"))
        out.flush()

    class Periodic(BaseCallback):
        """As ``stagerl train``: evaluate after each episode that passes a multiple of ``every``
        and after the episode in which the budget's last step falls (which ends the run)."""

        def __init__(self):
            super().__init__()
            self.next_eval = every

        def _on_step(self) -> bool:
            if not self.locals["dones"][0]:
                return True
            n = self.num_timesteps
            if n >= budget:
                record(n)
                return False
            if n >= self.next_eval:
                record(n)
                self.next_eval = (n // every + 1) * every
            return True

    # The budget ends with the episode in which its last step falls: learn() is given room for
    # one more episode and the callback stops it.
    model.learn(total_timesteps=budget + 10 * env.unwrapped.max_steps, callback=Periodic())


if __name__ == "__main__":
    main()
