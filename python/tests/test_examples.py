"""The examples that run in CI: the Optuna study and the Ray Tune sweep, on tiny trials."""

import importlib.util
import os

import stagerl


EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "examples")


def load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(EXAMPLES, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_optuna_example_tunes_prunes_and_shares_its_journal(tmp_path):
    import optuna  # installed by scripts/test.sh; its absence is a failure, not a skip

    example = load("optuna_tune")
    out = str(tmp_path / "study")
    args = ["--trials", "3", "--episodes", "60", "--eval-every", "20", "--eval-trials", "5", "--out", out]
    study = example.main(args)
    trials = study.trials
    assert len(trials) == 3
    assert all(t.state in (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED) for t in trials)
    complete = [t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert complete and all(0.0 <= t.value <= 1.0 for t in complete)
    # Every trial reported its evaluations through the callback, at the evaluation episodes.
    for t in trials:
        assert set(t.intermediate_values) <= {20, 40, 60} and t.intermediate_values, t.number
        assert os.path.isfile(os.path.join(out, f"trial-{t.number}", "config.toml"))
    assert set(trials[0].params) == {"learning_rate", "gamma", "hidden", "reward"}
    # A second process (here: a second call) continues the same study from the shared journal.
    again = example.main(args[:1] + ["1"] + args[2:])
    assert len(again.trials) == 4


def test_the_ray_tune_example_runs_its_trials_and_evaluates_the_best(tmp_path, monkeypatch):
    import ray  # installed by scripts/test.sh (ray[tune], about 35 s); its absence is a failure

    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")  # no usage report from a test

    example = load("ray_tune")
    out = tmp_path / "ray"
    summary = example.main(["--trials", "2", "--episodes", "40", "--eval-every", "20", "--eval-trials", "5",
                            "--grace", "20", "--cpus", "2", "--out", str(out)])
    assert not ray.is_initialized()  # the script shut its local Ray down
    assert summary["trials"] == 2 and summary["errors"] == 0, summary
    assert set(summary["best_config"]) == {"learning_rate", "gamma", "hidden", "reward"}
    assert 0.0 <= summary["best_eval_success_rate"] <= 1.0 and 0.0 <= summary["best_success_rate_500"] <= 1.0
    # Each trial is a stagerl run that reported its evaluations to Tune (episodes 20 and 40).
    runs = sorted(os.listdir(out / "runs"))
    assert len(runs) == 2, runs
    for r in runs:
        run = stagerl.Run.load(str(out / "runs" / r))
        assert list(run.evaluations["episode"]) == [20, 40], r
    assert summary["best_run"] in [str(out / "runs" / r) for r in runs]
    assert os.path.isfile(out / "summary.json")
