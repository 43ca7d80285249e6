"""Tune stagerl's SAC with Optuna: a TPE sampler over the learning rate, gamma, the hidden size and
the reward, pruned by the median of the trials before at each periodic evaluation (through the
callback of :func:`stagerl.train`), on a journal storage that several processes can share.

    python python/examples/optuna_tune.py --trials 50 --episodes 2000 --out runs/optuna
    # more workers on the same study: run the same command again, in other processes

Each trial is a run directory under ``--out`` (``trial-<number>``); the best trial's settings
and success rate are printed at the end and kept in the study (``--out``/study.log).
"""

import argparse
import os

import optuna
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend

import stagerl


def objective(trial, args):
    lr = trial.suggest_float("learning_rate", 1e-4, 3e-3, log=True)
    config = {
        "agent": {
            "algo": "sac",
            "actor_lr": lr,
            "critic_lr": lr,
            "gamma": trial.suggest_float("gamma", 0.9, 0.99),
            "hidden": [trial.suggest_categorical("hidden", [32, 64, 128])] * 2,
        },
        "reward": {"function": trial.suggest_categorical("reward", ["posture", "stride", "har", "sar"])},
        "train": {
            "eval_every_episodes": args.eval_every,
            "eval_trials": args.eval_trials,
            "checkpoint_every_episodes": args.eval_every,
        },
    }

    def report(r):
        # Called at every periodic evaluation: report it, and stop (saved) when pruned.
        if r["eval_success_rate"] is None:
            return True
        trial.report(r["eval_success_rate"], step=r["episode"])
        return not trial.should_prune()

    out = os.path.join(args.out, f"trial-{trial.number}")
    run = stagerl.train(config, out=out, seed=args.seed, episodes=args.episodes, eval_trials=0, callback=report)
    success = run.evaluations["success_rate"]
    if len(run.episodes["episode"]) < args.episodes:
        raise optuna.TrialPruned()
    return float(success.max()) if len(success) else 0.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20, help="trials this process runs")
    ap.add_argument("--episodes", type=int, default=2000, help="training episodes per trial")
    ap.add_argument("--eval-every", type=int, default=250, help="episodes between evaluations (pruning points)")
    ap.add_argument("--eval-trials", type=int, default=100, help="targets of each periodic evaluation")
    ap.add_argument("--seed", type=int, default=1, help="training seed of every trial")
    ap.add_argument("--sampler-seed", type=int, default=0, help="seed of the TPE sampler")
    ap.add_argument("--out", default="runs/optuna", help="folder of the study's journal and runs")
    ap.add_argument("--study", default="stagerl-sac", help="study name in the journal")
    args = ap.parse_args(argv)
    for name in ["trials", "episodes", "eval_every", "eval_trials"]:
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be at least 1")
    os.makedirs(args.out, exist_ok=True)
    storage = JournalStorage(JournalFileBackend(os.path.join(args.out, "study.log")))
    study = optuna.create_study(
        study_name=args.study,
        storage=storage,
        load_if_exists=True,
        direction="maximize",
        sampler=optuna.samplers.TPESampler(seed=args.sampler_seed),
        pruner=optuna.pruners.MedianPruner(n_startup_trials=2, n_warmup_steps=args.eval_every),
    )
    study.optimize(lambda t: objective(t, args), n_trials=args.trials)
    best = study.best_trial
    print(f"best trial {best.number}: success {best.value:.3f} with {best.params}")
    return study


if __name__ == "__main__":
    main()
