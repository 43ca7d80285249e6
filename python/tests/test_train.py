"""stagerl.train: the CLI's run from Python (same bits), the GIL released while it trains, the
callback's reports and stop, Ctrl-C, and bad settings."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import stagerl

TINY = {
    "agent": {"hidden": [16, 16], "batch_size": 32, "learning_starts": 200},
    "train": {"eval_every_episodes": 20, "eval_trials": 5, "checkpoint_every_episodes": 20},
}


def rows_without_wall(directory):
    with open(os.path.join(directory, "episodes.csv"), encoding="utf-8") as f:
        return [line.rsplit(",", 1)[0] for line in f.read().splitlines()]


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_the_same_run_as_the_cli(tmp_path, stagerl_bin, algo):
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        '[agent]\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 200\n'
        '[train]\neval_every_episodes = 20\neval_trials = 5\ncheckpoint_every_episodes = 20\n'
    )
    cli = tmp_path / "cli"
    subprocess.run(
        [stagerl_bin, "train", "--config", str(cfg), "--algo", algo, "--seed", "4", "--episodes", "60",
         "--eval-trials", "20", "--out", str(cli)],
        check=True, capture_output=True,
    )
    run = stagerl.train(TINY, out=tmp_path / "py", algo=algo, seed=4, episodes=60, eval_trials=20)
    assert isinstance(run, stagerl.Run) and run.dir == str(tmp_path / "py")
    assert rows_without_wall(cli) == rows_without_wall(run.dir)
    assert (cli / "eval.csv").read_text() == open(os.path.join(run.dir, "eval.csv")).read()
    assert (cli / "eval-final-seed0.csv").read_text() == open(os.path.join(run.dir, "eval-final-seed0.csv")).read()
    assert (cli / "config.toml").read_text() == open(os.path.join(run.dir, "config.toml")).read()
    # The same from the config file's path.
    again = stagerl.train(cfg, out=tmp_path / "path", algo=algo, seed=4, episodes=60, eval_trials=0)
    assert rows_without_wall(again.dir) == rows_without_wall(cli)
    assert run.config["agent"]["algo"] == algo and run.config["train"]["episodes"] == 60
    ep = run.episodes
    assert list(ep["episode"]) == list(range(1, 61)) and ep["reward"].dtype == np.float64
    assert list(run.evaluations["episode"]) == [20, 40, 60]
    p = run.policy()
    assert p.checkpoint.endswith("best.safetensors") and p(np.zeros(p.obs_dim)).shape == (p.act_dim,)
    assert run.policy("final").checkpoint.endswith("final.safetensors")


def test_the_gil_is_released_while_training(tmp_path):
    done = threading.Event()
    result = {}

    def work():
        result["run"] = stagerl.train(TINY, out=tmp_path / "run", episodes=400, eval_trials=0)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    ticks, ticks_while_running = 0, 0
    while not done.is_set():
        ticks += 1
        if (tmp_path / "run" / "episodes.csv").exists():
            ticks_while_running += 1
        time.sleep(0.0005)
    t.join()
    assert len(result["run"].episodes["episode"]) == 400
    # This thread ran on throughout: hundreds of turns while episodes were being written.
    assert ticks_while_running > 100, (ticks, ticks_while_running)


def test_the_callback_reports_and_its_false_stops_and_saves_the_run(tmp_path):
    reports = []

    def stop_at_the_second_evaluation(r):
        reports.append(r)
        return not (r["eval_success_rate"] is not None and r["episode"] == 40)

    run = stagerl.train(TINY, out=tmp_path / "cut", episodes=100, eval_trials=0,
                        callback=stop_at_the_second_evaluation, callback_every_episodes=10)
    assert [r["episode"] for r in reports] == [10, 20, 30, 40]
    assert [r["eval_success_rate"] is None for r in reports] == [True, False, True, False]
    first = reports[1]
    for key in ["env_steps", "wall_s", "train_success_rate", "train_mean_reward", "eval_mean_reward"]:
        assert isinstance(first[key], float if key != "env_steps" else int), key
    assert 0.0 <= first["eval_success_rate"] <= 1.0 and first["env_steps"] > 0
    assert len(run.episodes["episode"]) == 40
    # Resumed, the run ends as an uninterrupted one.
    resumed = stagerl.train(out=tmp_path / "cut", resume=True, eval_trials=0)
    whole = stagerl.train(TINY, out=tmp_path / "whole", episodes=100, eval_trials=0)
    assert rows_without_wall(resumed.dir) == rows_without_wall(whole.dir)


def test_an_exception_in_the_callback_stops_the_run_and_propagates(tmp_path):
    def boom(r):
        raise RuntimeError("from the callback")

    with pytest.raises(RuntimeError, match="from the callback"):
        stagerl.train(TINY, out=tmp_path / "run", episodes=100, eval_trials=0, callback=boom)
    assert os.path.isfile(tmp_path / "run" / "checkpoints" / "latest.safetensors")


def test_ctrl_c_saves_the_run_and_raises_keyboard_interrupt(tmp_path):
    out = tmp_path / "run"
    script = (
        "import stagerl\n"
        f"stagerl.train({TINY!r}, out={str(out)!r}, episodes=100000, eval_trials=0)\n"
    )
    child = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True)

    def lines():
        csv = out / "episodes.csv"
        return len(csv.read_text().splitlines()) if csv.exists() else None

    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (lines() or 0) <= 50 and child.poll() is None:
        time.sleep(0.01)
    if (lines() or 0) <= 50:
        child.kill()
        _, err = child.communicate()
        pytest.fail(f"the run did not reach 50 episodes (episodes.csv lines: {lines()}, exit {child.returncode}): {err}")
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    try:
        _, err = child.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        at = lines()
        child.kill()
        _, err = child.communicate()
        pytest.fail(f"no exit 30 s after SIGINT (episodes.csv lines then: {at}, at the signal: > 50): {err}")
    assert time.monotonic() - sent < 5
    assert child.returncode != 0 and "KeyboardInterrupt" in err, err
    assert os.path.isfile(out / "checkpoints" / "latest.safetensors")
    saved = len((out / "episodes.csv").read_text().splitlines()) - 1
    assert 50 <= saved < 100000


def test_bad_settings_raise_value_errors_with_the_cli_messages(tmp_path):
    cases = [
        (dict(config={"agent": {"algo": "nope"}}), "nope"),
        (dict(episodes=0), "`train.episodes` = 0"),
        (dict(env_steps=0), "`train.env_steps` = 0"),
        (dict(episodes=5, env_steps=100), "one budget"),
        (dict(threads=0), "`threads` = 0"),
        (dict(config={"agent": {"no_such_field": 1}}), "no_such_field"),
        (dict(config={"train": {"episodes": None}}), "config"),
        (dict(seed=-1), "`seed` = -1"),
        (dict(callback=5), "`callback`"),
    ]
    for kwargs, want in cases:
        with pytest.raises(ValueError, match=None) as e:
            stagerl.train(out=tmp_path / "never", **kwargs)
        assert want in str(e.value), (kwargs, str(e.value))
    assert not (tmp_path / "never" / "config.toml").exists()
    stagerl.train(TINY, out=tmp_path / "once", episodes=5, eval_trials=0)
    with pytest.raises(ValueError, match="already|holds a run|without a run"):
        stagerl.train(TINY, out=tmp_path / "once", episodes=5)
    with pytest.raises(FileNotFoundError):
        stagerl.Run.load(tmp_path / "nothing")


def test_a_run_evaluates_exports_and_plans_as_the_cli_does(tmp_path, stagerl_bin):
    run = stagerl.train(TINY, out=tmp_path / "run", episodes=60, eval_trials=0)
    ours = run.evaluate(trials=20, seed=3)
    cli = subprocess.run([stagerl_bin, "eval", "--run", run.dir, "--trials", "20", "--seed", "3", "--json"],
                         check=True, capture_output=True, text=True)
    import json

    theirs = json.loads(cli.stdout.strip().splitlines()[-1])
    for key in ["trials", "success_rate", "mean_reward", "median_final_distance_m"]:
        assert ours[key] == theirs[key], key
    final = run.evaluate(trials=20, seed=3, checkpoint="final")
    assert final["trials"] == 20
    onnx = tmp_path / "policy.onnx"
    used = run.export_onnx(onnx)
    assert used.endswith("best.safetensors") and onnx.stat().st_size > 1000
    assert run.export_onnx(onnx) == used  # the same bytes again: left as it is
    with pytest.raises(ValueError, match="force"):
        run.export_onnx(onnx, checkpoint="final")  # other bytes onto an existing file
    assert run.export_onnx(onnx, checkpoint="final", force=True).endswith("final.safetensors")
    with pytest.raises(ValueError):
        run.export_onnx(os.path.join(run.dir, "checkpoints", "final.safetensors"), force=True)
    plan = run.plan([0.4, 0.2, 0.3])
    assert plan["summary"]["steps"] >= 1 and plan["q"].shape == (plan["summary"]["steps"] + 1, 6)
    for bad in [dict(trials=-1), dict(seed="x"), dict(obstacles_in_path=2.0), dict(checkpoint=5)]:
        with pytest.raises(ValueError):
            run.evaluate(**bad)


def test_report_writes_the_committed_report_of_the_quick_study(tmp_path, root):
    study = root / "docs" / "results" / "quick"
    doc = stagerl.report(study / "runs.tar.xz", tmp_path / "report", trajectories=0)
    assert len(doc["claims"]) == 21 and any(f.endswith("claims.md") for f in doc["files"])
    keep = lambda t: [l for l in t.splitlines() if not l.startswith("This report: `")]  # noqa: E731
    for name in ["claims.md", "aggregates.md"]:
        assert keep((tmp_path / "report" / name).read_text()) == keep((study / name).read_text()), name
    with pytest.raises(ValueError, match="trajectories"):
        stagerl.report(study / "runs.tar.xz", tmp_path / "r2", trajectories=5000)
    with pytest.raises((ValueError, FileNotFoundError)):
        stagerl.report(tmp_path / "nothing", tmp_path / "r3")


def test_reproduce_then_report_a_tiny_sweep(tmp_path):
    preset = tmp_path / "tiny.toml"
    preset.write_text(
        '[sweep]\nalgorithms = ["sac"]\nrewards = ["posture", "sar"]\nseeds = [1, 2]\neval_trials = 10\nregime = "tuned"\n'
        '[agent]\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 200\n'
        '[train]\nepisodes = 40\neval_every_episodes = 20\neval_trials = 5\n'
    )
    out = tmp_path / "sweep"
    done = stagerl.reproduce(preset, out, jobs=2)
    assert done["runs"] == 4 and done["taken"] == 0
    for name in ["sac-posture-seed1", "sac-sar-seed2"]:
        assert len(stagerl.Run.load(out / name).episodes["episode"]) == 40
    again = stagerl.reproduce(preset, out)  # finished runs are skipped
    assert again["runs"] == 4 and again["wall_s"] < done["wall_s"] + 5
    doc = stagerl.report(out, tmp_path / "report", trajectories=0)
    assert sorted((g["algo"], g["reward"], g["seeds"]) for g in doc["groups"]) == [("sac", "posture", 2), ("sac", "sar", 2)]
    with pytest.raises(ValueError):
        stagerl.reproduce("no-such-preset", tmp_path / "x")
    with pytest.raises(ValueError):
        stagerl.reproduce(preset, tmp_path / "y", jobs=0)


def test_the_callback_reports_the_curriculum_stage_of_episodes_csv(tmp_path):
    config = {
        "agent": {"hidden": [64, 64], "batch_size": 32, "learning_starts": 200},
        "task": {"observe_obstacles": True, "obstacle_observation": "per_link",
                 "random_obstacles": {"count": [1, 3]}},
        "train": {"eval_every_episodes": 50, "eval_trials": 5, "checkpoint_every_episodes": 50,
                  "curriculum": {"window": 10, "advance_at": 0.1, "obstacles_in_path": [0.0, 0.5, 1.0],
                                 "max_obstacles": [1, 2, 3]}},
    }
    reports = []
    run = stagerl.train(config, out=tmp_path / "run", episodes=150, eval_trials=0,
                        callback=lambda r: reports.append(r), callback_every_episodes=1)
    stage = {int(e): int(s) for e, s in zip(run.episodes["episode"], run.episodes["curriculum_stage"])}
    assert len(reports) == 150
    assert [r["curriculum_stage"] for r in reports] == [stage[r["episode"]] for r in reports]
    assert max(stage.values()) >= 1, "the stage advanced within the run"
    plain = []
    stagerl.train(TINY, out=tmp_path / "plain", episodes=20, eval_trials=0,
                  callback=lambda r: plain.append(r), callback_every_episodes=10)
    assert [r["curriculum_stage"] for r in plain] == [None, None]
