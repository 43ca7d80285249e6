"""Tune stagerl's SAC with Ray Tune: a function trainable per trial that calls :func:`stagerl.train`
with a callback reporting each periodic evaluation through ``ray.tune.report``, an ASHA scheduler
that stops the trials behind, one CPU a trial (``tune.with_resources``), on a local Ray that the
script starts.

    pip install "ray[tune]" ./python
    python python/examples/ray_tune.py --trials 8 --episodes 600 --out runs/ray

Searched: the learning rate (log-uniform, 1e-4 to 3e-3), gamma (0.9 to 0.99), the hidden size
(32, 64, 128) and the reward (posture, stride, har, sar), drawn at random (seeded). Each trial is
a run directory under ``--out``/runs (``trial-<n>``); Ray's own records go to ``--out``/ray. At
the end the best trial's run (by its best periodic success rate) is evaluated on 500 targets
(``Run.evaluate``), and the figures are printed and written to ``--out``/summary.json.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Callable, Optional

import ray
from ray import tune
from ray.tune.schedulers import ASHAScheduler

import stagerl


def search_space() -> dict:
    """The hyperparameters Ray samples per trial (see :func:`seeded_search`)."""
    return {
        "learning_rate": tune.loguniform(1e-4, 3e-3),
        "gamma": tune.uniform(0.9, 0.99),
        "hidden": tune.choice([32, 64, 128]),
        "reward": tune.choice(["posture", "stride", "har", "sar"]),
    }


def make_trainable(args: argparse.Namespace) -> Callable[[dict], None]:
    """The function trainable: one stagerl run per trial, reporting every periodic evaluation
    (its episode is ASHA's time axis)."""
    runs = os.path.abspath(os.path.join(args.out, "runs"))

    def trainable(params: dict) -> None:
        lr = params["learning_rate"]
        config = {
            "agent": {"algo": "sac", "actor_lr": lr, "critic_lr": lr, "gamma": params["gamma"],
                      "hidden": [params["hidden"]] * 2},
            "reward": {"function": params["reward"]},
            "train": {"eval_every_episodes": args.eval_every, "eval_trials": args.eval_trials,
                      "checkpoint_every_episodes": args.eval_every},
        }

        def report(r: dict) -> Optional[bool]:
            # Called at every periodic evaluation: report it to Tune (ASHA may then stop the trial).
            if r["eval_success_rate"] is not None:
                tune.report({"episode": r["episode"], "eval_success_rate": r["eval_success_rate"],
                             "eval_mean_reward": r["eval_mean_reward"], "env_steps": r["env_steps"],
                             "run_wall_s": r["wall_s"], "train_success_rate": r["train_success_rate"]})
            return True

        out = os.path.join(runs, f"trial-{tune.get_context().get_trial_id()}")
        stagerl.train(config, out=out, seed=args.seed, episodes=args.episodes, eval_trials=0, callback=report)

    return trainable


def parse(argv: Optional[list] = None) -> argparse.Namespace:
    """The command line (see the module documentation)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=8, help="trials (samples of the search space)")
    ap.add_argument("--episodes", type=int, default=600, help="training episodes per trial (ASHA's max_t)")
    ap.add_argument("--eval-every", type=int, default=100, help="episodes between evaluations (reports)")
    ap.add_argument("--eval-trials", type=int, default=50, help="targets of each periodic evaluation")
    ap.add_argument("--grace", type=int, default=200, help="episodes before ASHA may stop a trial")
    ap.add_argument("--seed", type=int, default=1, help="training seed of every trial, and of the sampling")
    ap.add_argument("--cpus", type=int, default=os.cpu_count() or 1, help="CPUs of the local Ray (trials in parallel)")
    ap.add_argument("--out", default="runs/ray", help="folder of the runs, Ray's records and summary.json")
    args = ap.parse_args(argv)
    for name in ["trials", "episodes", "eval_every", "eval_trials", "grace", "cpus"]:
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be at least 1")
    return args


def main(argv: Optional[list] = None) -> dict:
    """Run the study; return the summary (also written to ``--out``/summary.json)."""
    args = parse(argv)
    os.makedirs(args.out, exist_ok=True)
    start = time.perf_counter()
    ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    try:
        scheduler = ASHAScheduler(time_attr="episode", max_t=args.episodes, grace_period=min(args.grace, args.episodes),
                                  reduction_factor=2)
        tuner = tune.Tuner(
            tune.with_resources(make_trainable(args), {"cpu": 1}),
            param_space=search_space(),
            tune_config=tune.TuneConfig(metric="eval_success_rate", mode="max", scheduler=scheduler,
                                        num_samples=args.trials, search_alg=seeded_search(args.seed)),
            run_config=tune.RunConfig(name="stagerl-sac", storage_path=os.path.abspath(os.path.join(args.out, "ray")),
                                      verbose=1),
        )
        results = tuner.fit()
    finally:
        ray.shutdown()
    wall_s = time.perf_counter() - start
    best = results.get_best_result(metric="eval_success_rate", mode="max", scope="all")
    run_dir = os.path.join(os.path.abspath(args.out), "runs", f"trial-{best.metrics['trial_id']}")
    final = stagerl.Run.load(run_dir).evaluate(trials=500, seed=0)
    episodes = {r.metrics["trial_id"]: r.metrics.get("episode", 0) for r in results}
    summary = {
        "trials": len(results), "errors": results.num_errors, "wall_s": round(wall_s, 1),
        "stopped_early": sum(e < args.episodes for e in episodes.values()),
        "best_config": best.config,
        "best_eval_success_rate": float(best.metrics_dataframe["eval_success_rate"].max()),
        "best_run": run_dir, "best_success_rate_500": final["success_rate"],
        "ray": ray.__version__, "args": vars(args),
    }
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(json.dumps(summary, indent=2))
    return summary


def seeded_search(seed: int):
    """Random sampling of the search space with a fixed seed (Ray's BasicVariantGenerator)."""
    from ray.tune.search.basic_variant import BasicVariantGenerator

    return BasicVariantGenerator(random_state=seed)


if __name__ == "__main__":
    main()
