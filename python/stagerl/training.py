"""Training from Python: :func:`train` runs stagerl's Rust trainer, the same run as
``stagerl train`` makes, and :class:`Run` reads a run directory.

Example::

    import stagerl

    def report(r):                      # at every periodic evaluation
        print(r["episode"], r["env_steps"], r["eval_success_rate"])
        return r["eval_success_rate"] < 0.99   # False stops the run (saved, resumable)

    run = stagerl.train({"agent": {"algo": "sac"}}, out="runs/sac-sar", episodes=2000, callback=report)
    print(run.evaluations["success_rate"][-1], run.policy().checkpoint)
"""

from __future__ import annotations

import csv
import json
import os
import sys
from typing import Any, Callable, Mapping, Optional, Union

import numpy as np

from . import _core
from .policies import Policy, plan as _plan

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - the tests run on 3.11
    import tomli as tomllib

__all__ = ["train", "Run", "report", "reproduce"]

ConfigLike = Union[None, str, "os.PathLike[str]", Mapping[str, Any]]


def train(
    config: ConfigLike = None,
    *,
    out: Union[str, "os.PathLike[str]"],
    algo: Optional[str] = None,
    reward: Optional[str] = None,
    seed: Optional[int] = None,
    episodes: Optional[int] = None,
    env_steps: Optional[int] = None,
    eval_trials: Optional[int] = None,
    eval_every_episodes: Optional[int] = None,
    threads: int = 1,
    callback: Optional[Callable[[dict], Optional[bool]]] = None,
    callback_every_episodes: int = 0,
    resume: bool = False,
) -> "Run":
    """Train a run into ``out`` and return it as a :class:`Run`.

    The same run as ``stagerl train --out OUT`` with the same settings: ``config`` is a dict
    in the shape of a TOML config file (``{"agent": {"algo": "sac"}, "train": {...}}``), a
    path to one, or None for the defaults; the keyword arguments override it as the CLI's flags
    do (``algo``, ``reward``, ``seed``, ``episodes``, ``env_steps``: ``--env-steps``,
    ``eval_every_episodes``: ``train.eval_every_episodes``, ``eval_trials``: the trials of
    the closing evaluation, ``--eval-trials``, default 500, 0 skips it; ``threads``: 1 to 64,
    the same run on any number). The GIL is released while it trains; the run directory is
    locked as the CLI locks it, and a directory that already holds a run is refused unless
    ``resume=True``, which continues it with its own config (no other settings then).

    ``callback(report)`` is called at every periodic evaluation (and every
    ``callback_every_episodes`` episodes when > 0) with a dict: ``episode``, ``env_steps``,
    ``wall_s``, ``episode_reward``, ``curriculum_stage`` (the episode's stage with
    ``[train.curriculum]``, 0-based; None without one), ``train_success_rate`` and
    ``train_mean_reward`` (the last 100 episodes), ``last``, and ``eval_success_rate``, ``eval_mean_reward``,
    ``eval_mean_steps``, ``eval_median_final_distance_m`` (None between evaluations). Returning
    ``False`` stops the run: it is saved (``resume=True`` continues it) and returned. An
    exception in the callback stops and saves the run, then propagates.

    Ctrl-C (KeyboardInterrupt) is honoured within about a second: the run is saved as SIGINT
    saves it, then KeyboardInterrupt is raised. Bad settings raise ValueError with the CLI's
    messages (field, value and what is allowed).
    """
    out = os.fspath(out)
    json_text = path = None
    if isinstance(config, Mapping):
        try:
            json_text = json.dumps(config, allow_nan=False)
        except (TypeError, ValueError) as e:
            raise ValueError(f"`config` = a dict is invalid: JSON-serialisable values of a config file: {e}") from None
    elif config is not None:
        path = os.fspath(config)
    for name, value in [("seed", seed), ("episodes", episodes), ("env_steps", env_steps),
                        ("eval_trials", eval_trials), ("eval_every_episodes", eval_every_episodes),
                        ("threads", threads), ("callback_every_episodes", callback_every_episodes)]:
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0):
            raise ValueError(f"`{name}` = {value!r} is invalid: a non-negative integer")
    if callback is not None and not callable(callback):
        raise ValueError(f"`callback` = {callback!r} is invalid: a callable taking the report dict")
    directory, _how = _core.train(
        out,
        json=json_text,
        path=path,
        algo=algo,
        reward=reward,
        seed=seed,
        episodes=episodes,
        env_steps=env_steps,
        eval_every_episodes=eval_every_episodes,
        closing_trials=500 if eval_trials is None else eval_trials,
        threads=threads,
        resume=resume,
        callback=callback,
        callback_every_episodes=callback_every_episodes,
    )
    return Run.load(directory)


def report(runs, out, trajectories: int = 5, include_incomplete: bool = False) -> dict:
    """``stagerl report``: Table 1, the claims with their verdicts, aggregates and figures of the
    runs under ``runs`` (a folder of run directories, or a study's ``runs.tar.xz``), written into
    ``out``; returns the report (``out``/table1.json) as a dict, with ``files``: the paths
    written. The GIL is released meanwhile."""
    if isinstance(trajectories, bool) or not isinstance(trajectories, (int, np.integer)) or not 0 <= trajectories <= 1000:
        raise ValueError(f"`trajectories` = {trajectories!r} is invalid: an integer from 0 to 1000")
    out = os.fspath(out)
    files = _core.report(os.fspath(runs), out, int(trajectories), bool(include_incomplete))
    with open(os.path.join(out, "table1.json"), encoding="utf-8") as f:
        doc = json.load(f)
    doc["files"] = files
    return doc


def reproduce(preset, out, jobs: int = 1, task_index: Optional[int] = None,
              task_count: Optional[int] = None) -> dict:
    """``stagerl reproduce``: train and evaluate every run of ``preset`` (a bundled preset's name,
    ``quick``, ``tuned``, ``paper``..., or a preset file) into ``out``, ``jobs`` at once;
    finished runs are skipped and interrupted ones resume. ``task_index`` of ``task_count``
    takes one shard (default: Slurm's array variables, else all). Ctrl-C saves the runs under
    way and raises KeyboardInterrupt; failed runs raise RuntimeError naming each. Returns
    ``runs`` (in this shard), ``taken`` (by other processes) and ``wall_s``; then
    :func:`report` makes the tables."""
    for name, value in [("jobs", jobs), ("task_index", task_index), ("task_count", task_count)]:
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0):
            raise ValueError(f"`{name}` = {value!r} is invalid: a non-negative integer")
    runs, taken, wall_s = _core.reproduce(os.fspath(preset), os.fspath(out), int(jobs), task_index, task_count)
    return {"runs": runs, "taken": taken, "wall_s": wall_s}


def _columns(path: str) -> dict:
    """A CSV file as a dict of numpy arrays (integers, floats; empty fields NaN)."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    if not rows:
        return {}
    header, body = rows[0], rows[1:]
    out = {}
    for i, name in enumerate(header):
        values = [r[i] if i < len(r) else "" for r in body]
        if all(v.lstrip("-").isdigit() for v in values):
            out[name] = np.array([int(v) for v in values], dtype=np.int64)
        else:
            out[name] = np.array([float(v) if v != "" else np.nan for v in values], dtype=np.float64)
    return out


class Run:
    """A run directory written by :func:`train` or ``stagerl train``.

    Attributes: ``dir`` (the directory), ``config`` (its resolved ``config.toml`` as a dict),
    ``episodes`` (``episodes.csv`` as a dict of numpy arrays: ``episode``, ``reward``,
    ``steps``, ``success``, ``final_distance_m``, ``env_steps``, ``collision_steps``,
    ``curriculum_stage`` with ``[train.curriculum]`` only, ``wall_s``) and ``evaluations`` (``eval.csv``, the periodic evaluations: ``episode``,
    ``env_steps``, ``success_rate``, ``mean_reward``, ``mean_steps``,
    ``median_final_distance_m``; empty when there were none). Methods: :meth:`policy`,
    :meth:`evaluate`, :meth:`export_onnx`, :meth:`plan`.
    """

    def __init__(self, directory: Union[str, "os.PathLike[str]"]):
        self.dir = os.fspath(directory)
        config = os.path.join(self.dir, "config.toml")
        if not os.path.isfile(config):
            raise FileNotFoundError(f"{self.dir}: not a run directory (it has no config.toml)")
        with open(config, "rb") as f:
            self.config = tomllib.load(f)

    @classmethod
    def load(cls, directory: Union[str, "os.PathLike[str]"]) -> "Run":
        """The run in ``directory``."""
        return cls(directory)

    @property
    def episodes(self) -> dict:
        return _columns(os.path.join(self.dir, "episodes.csv"))

    @property
    def evaluations(self) -> dict:
        path = os.path.join(self.dir, "eval.csv")
        return _columns(path) if os.path.isfile(path) else {}

    def policy(self, checkpoint: str = "best") -> Policy:
        """The run's trained policy: ``checkpoint`` is "best" (the best periodic evaluation's,
        else the final one), "final", "latest" or a checkpoint file's path."""
        names = {"best": None, "final": "final.safetensors", "latest": "latest.safetensors"}
        if checkpoint in names:
            name = names[checkpoint]
            return Policy.load(self.dir if name is None else os.path.join(self.dir, "checkpoints", name))
        return Policy.load(checkpoint)

    def _checkpoint(self, checkpoint: str) -> str:
        if not isinstance(checkpoint, (str, os.PathLike)):
            raise ValueError(f"`checkpoint` = {checkpoint!r} is invalid: \"best\", \"final\", \"latest\" or a path")
        return os.fspath(checkpoint)

    def evaluate(self, trials: int = 500, seed: int = 0, checkpoint: str = "best",
                 obstacles_in_path: Optional[float] = None) -> dict:
        """``stagerl eval``'s figures for the run's deterministic policy under its config, on
        ``trials`` random targets of ``seed`` (nothing is written): ``trials``,
        ``success_rate``, ``mean_reward``, ``mean_steps_success``, ``median_final_distance_m``,
        ``mean_final_distance_m`` and ``collision_rate`` when contacts are checked.
        ``obstacles_in_path``: the probability that the first random obstacle is placed across
        the way (the run's task must have random obstacles). The GIL is released meanwhile."""
        for name, value in [("trials", trials), ("seed", seed)]:
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"`{name}` = {value!r} is invalid: a non-negative integer")
        if obstacles_in_path is not None and not (isinstance(obstacles_in_path, (int, float)) and 0.0 <= obstacles_in_path <= 1.0):
            raise ValueError(f"`obstacles_in_path` = {obstacles_in_path!r} is invalid: a probability in [0, 1]")
        text = _core.evaluate_run(self.dir, int(trials), int(seed), self._checkpoint(checkpoint),
                                  None if obstacles_in_path is None else float(obstacles_in_path))
        return json.loads(text)

    def export_onnx(self, path, checkpoint: str = "best", force: bool = False) -> str:
        """Write the run's policy as an ONNX model to ``path`` (``stagerl export``: observation in,
        joint velocities in rad/s out); an existing file is replaced only with ``force=True``, and
        never one of the run's own files. Returns the checkpoint exported."""
        return _core.export_onnx(self.dir, os.fspath(path), self._checkpoint(checkpoint), bool(force))

    def plan(self, target, start=None, checkpoint: Optional[str] = None, max_steps: Optional[int] = None,
             obstacles=None, shield: Optional[bool] = None) -> dict:
        """:func:`stagerl.plan` with this run's policy."""
        return _plan(self.dir, target, start=start, checkpoint=checkpoint, max_steps=max_steps, obstacles=obstacles,
                     shield=shield)

    def __repr__(self) -> str:
        return f"Run({self.dir!r})"
