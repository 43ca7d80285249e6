"""Trained stagerl policies, and planning with them, from numpy.

``Policy.load(path)``: ``path`` is a run directory of ``stagerl train`` (its best available
checkpoint: best, else final, else latest, with its ``config.toml``) or a checkpoint file
(``*.safetensors``, with the config it embeds). ``policy(obs)`` maps observations (N, obs_dim)
float32 (one row also works as a 1-D array) to the deterministic actions (N, act_dim) float32 in
[-1, 1], exactly as ``stagerl eval`` and ``stagerl plan`` act (the agent's ``predict``); an
action of 1 commands the joint's speed limit (``policy.spec["action"]["speed_limits"]``, rad/s).

``plan(run_dir, target, start=None)``: the trajectory ``stagerl plan --run RUN_DIR --target
X,Y,Z [--start Q1,..]`` writes, as numpy arrays keyed like its JSON lines: ``step``, ``t_s``
(seconds), ``q`` (rows, dof) radians, ``joint_vel`` (rows, dof) rad/s, ``ee_pos`` (rows, 3)
metres, ``ee_quat`` (rows, 4) (x, y, z, w), ``distance`` (metres), ``reward``; with ``summary``
(the summary line's fields: ``reached``, ``steps``, ``final_distance``, ``episode_reward``,
``path_length_m``, ``joint_travel_rad``) and ``warning`` (a text when the target lies outside
the training target distribution, else None). ``checkpoint=`` and ``max_steps=`` as the
command's flags.
"""

from __future__ import annotations

import json
import os
from typing import Optional

import numpy as np

from . import _core


def _path(name: str, value) -> str:
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    if not isinstance(value, str):
        raise ValueError(f"`{name}` = {value!r} is invalid: a path to a run directory or a checkpoint file")
    if not os.path.exists(value):
        raise FileNotFoundError(f"`{name}` = {value!r}: no such file or directory (expected a run directory or a checkpoint file)")
    return value


def _numbers(name: str, value, n: Optional[int], what: str) -> list:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` = {value!r} is invalid: {what}") from None
    if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
        raise ValueError(f"`{name}` = {value!r} is invalid: {what}")
    return arr.tolist()


class Policy:
    """A trained deterministic policy (see the module documentation)."""

    def __init__(self, core):
        self._core = core
        self.obs_dim = core.obs_dim
        self.act_dim = core.act_dim
        self.algorithm = core.algorithm
        self.checkpoint = core.checkpoint
        #: The checkpoint's portable policy description (``stagerl::run::policy::PolicySpec``).
        self.spec = json.loads(core.spec_json)

    @classmethod
    def load(cls, path) -> "Policy":
        """The policy of a run directory or of a checkpoint file."""
        return cls(_core.PolicyCore(_path("path", path)))

    def __call__(self, obs) -> np.ndarray:
        """Actions (N, act_dim) for observations (N, obs_dim); a 1-D observation gives (act_dim,)."""
        try:
            arr = np.ascontiguousarray(obs, dtype=np.float32)
        except (TypeError, ValueError) as e:
            raise ValueError(f"`obs` is invalid: an array of numbers ({e})") from None
        if arr.ndim == 1 and arr.shape[0] == self.obs_dim:
            return self._core.predict(arr[None, :])[0]
        if arr.ndim != 2:
            raise ValueError(f"`obs.shape` = {arr.shape} is invalid: expected (N, {self.obs_dim}) or ({self.obs_dim},)")
        return self._core.predict(arr)

    def __repr__(self) -> str:
        return f"Policy({self.algorithm}, obs_dim={self.obs_dim}, act_dim={self.act_dim}, checkpoint={self.checkpoint!r})"


def plan(run_dir, target, start=None, checkpoint=None, max_steps: Optional[int] = None, obstacles=None,
         shield: Optional[bool] = None) -> dict:
    """The ``stagerl plan`` trajectory from ``start`` (radians; default the home pose) to
    ``target`` (metres) with the run's policy (see the module documentation). ``obstacles``: a
    list of dicts in the schema of ``[[task.obstacles]]`` (as a ``stagerl plan --targets`` line's
    ``"obstacles"``), checked with the command line's messages; the summary then reports
    ``collision``, ``min_clearance_m`` and ``plan_time_s`` against them. ``shield=True`` filters
    every command through the safety shield (``--shield``; the summary then adds its ``shield_*``
    counts), ``shield=False`` plans without it (``--no-shield``), ``None`` as the run was trained
    (behind the shield for a run with ``[task.shield] enabled = true``)."""
    run_dir = _path("run_dir", run_dir)
    if not os.path.isdir(run_dir):
        raise ValueError(f"`run_dir` = {run_dir!r} is invalid: a run directory (use `checkpoint=` for a checkpoint file)")
    target = _numbers("target", target, 3, "3 numbers x, y, z in metres")
    if start is not None:
        start = _numbers("start", start, None, "one number per joint, radians")
    if checkpoint is not None:
        checkpoint = _path("checkpoint", checkpoint)
    if max_steps is not None and (isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or not 1 <= max_steps <= 1_000_000):
        raise ValueError(f"`max_steps` = {max_steps!r} is invalid: an integer from 1 to 1 000 000")
    if shield is not None and not isinstance(shield, (bool, np.bool_)):
        raise ValueError(f"`shield` = {shield!r} is invalid: True, False or None (as the run was trained)")
    arrays, summary, warning = _core.plan(run_dir, target, start, checkpoint, None if max_steps is None else int(max_steps),
                                          obstacles, None if shield is None else bool(shield))
    arrays["summary"] = json.loads(summary)
    arrays["warning"] = warning
    return arrays
