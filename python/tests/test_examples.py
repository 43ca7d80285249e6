"""The examples that run in CI: the Optuna study on tiny trials."""

import importlib.util
import os


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
