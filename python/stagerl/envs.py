"""The reaching task of the paper as a Gymnasium environment, ``stagerl/Reach-v0``.

Keyword arguments of ``gymnasium.make("stagerl/Reach-v0", ...)``:

- ``reward``: the reward the agent receives, one of ``"basic"``, ``"posture"``, ``"stride"``,
  ``"har"``, ``"sar"`` (default: the config's ``reward.function``, ``"sar"`` by default).
- ``config``: a TOML config file (path) or a dict with the TOML's sections and fields (e.g.
  ``{"task": {"max_steps": 100}}``); defaults otherwise.
- ``robot``: ``"ur5"`` or ``"panda"`` (bundled) or a path to a URDF file (overrides ``robot.urdf``).

Observation (float32): q / pi per joint, end-effector position (m), target (m),
``obs_delta_scale * (target - end effector)`` and its norm. Action (float32): one value per joint
in [-1, 1], scaled by the joint's speed limit. The episode terminates when the target is reached
(``info["is_success"]``) and is truncated at ``task.max_steps``. ``info`` holds every reward term
(``distance`` in metres, ``reached``, ``position``, ``phi``, ``direction``, ``posture``, ``move``,
``stride``, ``gamma_posture``, ``har``, ``alpha1``, ``alpha2``, ``sar``, ``basic``, ``reward``,
``bonus``, ``total``) and ``is_success``; ``reset`` returns ``distance`` and ``is_success``.

With ``[task.random_obstacles]``, the config's ``train.obstacles_in_path`` (a probability,
default 0) places each episode's first random obstacle across the straight line from the start
end effector to the target, a training curriculum as in ``stagerl train``; leave it 0 in an
environment that evaluates, so that its obstacles are drawn as the task says.

``reset(options={"target": [x, y, z], "start": [q1, ..]})`` starts the episode at ``start``
(radians; default: the home pose) with the given target (metres) instead of a random one (as
``stagerl plan`` does); the target stream is not advanced.

Seeding: each ``reset`` draws a 64-bit seed for the Rust environment from ``self.np_random``
(after ``super().reset(seed=seed)``), so the same seed gives the same episodes.
"""

from __future__ import annotations

import json
import os
from typing import Any, Optional, Union

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from . import _core

ENV_ID = "stagerl/Reach-v0"


def _config_args(config: Union[None, str, os.PathLike, dict]) -> dict:
    """The keyword arguments of the native constructor for ``config``."""
    if config is None:
        return {}
    if isinstance(config, (str, os.PathLike)):
        path = os.fspath(config)
        if not os.path.isfile(path):
            raise FileNotFoundError(f"`config` = {path!r}: no such file (expected a TOML config file or a dict)")
        return {"config_path": path}
    if isinstance(config, dict):
        try:
            return {"config_json": json.dumps(config, allow_nan=False)}
        except (TypeError, ValueError) as e:
            raise ValueError(f"`config` = {config!r} is invalid: a dict of TOML sections with finite numbers, strings, lists ({e})") from None
    raise ValueError(f"`config` = {config!r} is invalid: None, a path to a TOML file, or a dict of the TOML's sections")


def _str_arg(name: str, value: Any, allowed: str) -> Optional[str]:
    if value is None:
        return None
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    if not isinstance(value, str):
        raise ValueError(f"`{name}` = {value!r} is invalid: {allowed}")
    return value


def core_args(reward, config, robot, render_mode) -> dict:
    """The native constructor's keyword arguments for the environment's arguments, checked."""
    if render_mode is not None:
        raise ValueError(f"`render_mode` = {render_mode!r} is invalid: stagerl/Reach-v0 renders nothing (None)")
    reward = _str_arg("reward", reward, "one of 'basic', 'posture', 'stride', 'har', 'sar'")
    robot = _str_arg("robot", robot, "'ur5', 'panda' or a path to a URDF file")
    if robot is not None and robot not in ("ur5", "panda") and not os.path.isfile(robot):
        raise FileNotFoundError(f"`robot` = {robot!r}: no such file (expected 'ur5', 'panda' or a path to a URDF file)")
    return {"reward": reward, "robot": robot, **_config_args(config)}


def describe(env, core) -> tuple:
    """Set ``env``'s ``render_mode`` (None), ``max_steps``, ``dt_s`` (seconds), ``joint_names``
    and ``_beta_m`` (metres) from the native ``core``; one environment's observation and action
    spaces (float32, finite bounds; actions in [-1, 1])."""
    facts = core.describe()
    env.render_mode = None
    env.max_steps, env.dt_s, env.joint_names = facts["max_steps"], facts["dt_s"], facts["joint_names"]
    env._beta_m = facts["beta_m"]
    n = facts["act_dim"]
    obs = spaces.Box(facts["observation_low"], facts["observation_high"], dtype=np.float32)
    return obs, spaces.Box(-np.ones(n, np.float32), np.ones(n, np.float32), dtype=np.float32)


def draw_seed(rng: np.random.Generator) -> int:
    """The 64-bit seed of the Rust environment's next episode, drawn from ``rng``."""
    return int(rng.integers(0, 2**64, dtype=np.uint64))


class ReachEnv(gym.Env):
    """One reaching environment over the Rust ``ReachEnv`` (see the module documentation)."""

    metadata = {"render_modes": []}

    def __init__(self, reward: Optional[str] = None, config=None, robot=None, render_mode: Optional[str] = None):
        self._core = _core.ReachCore(**core_args(reward, config, robot, render_mode))
        self.observation_space, self.action_space = describe(self, self._core)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        if options:
            obs, distance = self._reset_to(options)
        else:
            obs, distance = self._core.reset(draw_seed(self.np_random))
        return obs, {"distance": distance, "is_success": distance < self._beta_m}

    def _reset_to(self, options: dict):
        allowed = "a dict with `target` (3 numbers, metres) and optionally `start` (one number per joint, radians)"
        if not isinstance(options, dict) or "target" not in options or set(options) - {"target", "start"}:
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}")
        try:
            target = np.asarray(options["target"], dtype=np.float64).tolist()
            start = options.get("start")
            start = None if start is None else np.asarray(start, dtype=np.float64).tolist()
        except (TypeError, ValueError):
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}") from None
        if not isinstance(target, list) or (start is not None and not isinstance(start, list)):
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}")
        return self._core.reset_to(target, start)

    def step(self, action):
        action = np.asarray(action, dtype=np.float32)
        if action.shape != self.action_space.shape:
            raise ValueError(f"`action.shape` = {action.shape} is invalid: expected {self.action_space.shape}")
        return self._core.step(action)

    @property
    def ee_position(self) -> np.ndarray:
        """End-effector position, metres (base frame)."""
        return np.array(self._core.positions()[0])

    @property
    def target(self) -> np.ndarray:
        """The episode's target, metres (base frame)."""
        return np.array(self._core.positions()[1])


def register_envs() -> None:
    """Register ``stagerl/Reach-v0`` with Gymnasium (done on ``import stagerl``)."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="stagerl.envs:ReachEnv", vector_entry_point="stagerl.vector:ReachVectorEnv")
