"""The reaching task of the paper as a Gymnasium environment, ``stagerl/Reach-v0``.

Keyword arguments of ``gymnasium.make("stagerl/Reach-v0", ...)``:

- ``reward``: the reward the agent receives, one of ``"basic"``, ``"posture"``, ``"stride"``,
  ``"har"``, ``"sar"`` (default: the config's ``reward.function``, ``"sar"`` by default).
- ``config``: a TOML config file (path) or a dict with the TOML's sections and fields (e.g.
  ``{"task": {"max_steps": 100}}``); defaults otherwise.
- ``robot``: ``"ur5"`` or ``"panda"`` (bundled) or a path to a URDF file (overrides ``robot.urdf``).
- ``render_mode``: None (default) or ``"rgb_array"``: ``render()`` then returns the current frame,
  a new ``(render_height, render_width, 3)`` uint8 array (RGB) drawn offscreen in Rust (no GPU):
  the arm (its collision shapes; red while in contact), the target (a ball of radius
  ``reward.beta_m``, at least 2.5 cm so that it shows; green once reached), the end effector's path since the episode began (a blue
  polyline), the episode's obstacles (orange) and the floor with a 10 cm grid (the base frame's x
  axis red, y green), seen by a fixed perspective camera. ``metadata["render_fps"]`` is
  ``1 / task.dt_s`` (20 by default), so Gymnasium's ``RecordVideo`` plays episodes in real time.
  Rendering only reads the state: observations and rewards are the same with or without it.
  ``gymnasium.make`` builds ``"rgb_array_list"`` and ``"human"`` (a pygame window) on it.
- ``render_width``, ``render_height``: the frame's size in pixels, 16 to 4096 (default 480 x 360);
  only with ``render_mode="rgb_array"``.

Observation (float32): q / pi per joint, end-effector position (m), target (m),
``obs_delta_scale * (target - end effector)`` and its norm. Action (float32): one value per joint
in [-1, 1], scaled by the joint's speed limit. The episode terminates when the target is reached
(``info["is_success"]``) and is truncated at ``task.max_steps``. ``info`` holds every reward term
(``distance`` in metres, ``reached``, ``position``, ``phi``, ``direction``, ``posture``, ``move``,
``stride``, ``gamma_posture``, ``har``, ``alpha1``, ``alpha2``, ``sar``, ``basic``, ``reward``,
``bonus``, ``total``, ``clearance``: the clearance penalty already taken off ``total``, 0 without
``[reward.clearance]``; ``shield``: the shield's penalty, likewise, 0 without
``reward.shield_penalty``), ``collision`` and ``is_success``; ``reset`` returns ``distance`` and
``is_success``.

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


#: The render modes of ``stagerl/Reach-v0`` (besides None).
RENDER_MODES = ["rgb_array"]


def check_render_args(render_mode: Optional[str], render_width: Optional[int], render_height: Optional[int]) -> None:
    """Raise ValueError unless ``render_mode`` is None or ``"rgb_array"`` and the frame sizes are
    None or integers (their range, 16 to 4096 pixels, is checked in Rust), given only with a
    render mode."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"`render_mode` = {render_mode!r} is invalid: None or 'rgb_array' "
                         "(stagerl/Reach-v0 draws offscreen frames only; no window)")
    for name, v in (("render_width", render_width), ("render_height", render_height)):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"`{name}` = {v!r} is invalid: an integer from 16 to 4096 (pixels)")
        if render_mode is None:
            raise ValueError(f"`{name}` = {v!r} is invalid without a render mode: pass render_mode='rgb_array' too")


def enable_render(env: Union[gym.Env, "gym.vector.VectorEnv"], core: Any, render_mode: Optional[str], render_width: Optional[int], render_height: Optional[int]) -> None:
    """Set ``env.render_mode`` and, for ``"rgb_array"``, make the native ``core`` draw frames of
    the given size (pixels; None: 480 x 360) and ``env.metadata["render_fps"]`` ``1 / dt_s``."""
    env.render_mode = render_mode
    if render_mode is not None:
        core.enable_render(None if render_width is None else int(render_width),
                           None if render_height is None else int(render_height))
    env.metadata = {**type(env).metadata, "render_fps": 1.0 / env.dt_s}


def core_args(reward: Optional[str], config: Union[None, str, os.PathLike, dict],
              robot: Union[None, str, os.PathLike]) -> dict:
    """The native constructor's keyword arguments for the environment's arguments (see
    :class:`ReachEnv`), checked: ValueError or FileNotFoundError naming a bad one."""
    reward = _str_arg("reward", reward, "one of 'basic', 'posture', 'stride', 'har', 'sar'")
    robot = _str_arg("robot", robot, "'ur5', 'panda' or a path to a URDF file")
    if robot is not None and robot not in ("ur5", "panda") and not os.path.isfile(robot):
        raise FileNotFoundError(f"`robot` = {robot!r}: no such file (expected 'ur5', 'panda' or a path to a URDF file)")
    return {"reward": reward, "robot": robot, **_config_args(config)}


def describe(env: Union[gym.Env, "gym.vector.VectorEnv"], core: Any) -> tuple:
    """Set ``env``'s ``max_steps``, ``dt_s`` (seconds), ``joint_names`` and ``_beta_m``
    (metres) from the native ``core``; one environment's observation and action spaces (float32,
    finite bounds; actions in [-1, 1])."""
    facts = core.describe()
    env.max_steps, env.dt_s, env.joint_names = facts["max_steps"], facts["dt_s"], facts["joint_names"]
    env._beta_m = facts["beta_m"]
    n = facts["act_dim"]
    obs = spaces.Box(facts["observation_low"], facts["observation_high"], dtype=np.float32)
    return obs, spaces.Box(-np.ones(n, np.float32), np.ones(n, np.float32), dtype=np.float32)


def draw_seed(rng: np.random.Generator) -> int:
    """The 64-bit seed of the Rust environment's next episode, drawn from ``rng``."""
    return int(rng.integers(0, 2**64, dtype=np.uint64))


class ReachEnv(gym.Env):
    """One reaching environment over the Rust ``ReachEnv`` (see the module documentation).

    Args:
        reward: the reward the agent receives (``"basic"``, ``"posture"``, ``"stride"``,
            ``"har"``, ``"sar"``); None: the config's ``reward.function``.
        config: a TOML config file (``str`` or path) or a ``dict`` of the TOML's sections; None:
            the defaults.
        robot: ``"ur5"``, ``"panda"`` or a path to a URDF file; None: the config's ``robot.urdf``.
        render_mode: None or ``"rgb_array"`` (see :meth:`render`).
        render_width: the frame's width in pixels (16 to 4096; None: 480).
        render_height: the frame's height in pixels (16 to 4096; None: 360).

    Raises:
        ValueError: a bad argument (the message names it, its value and what is allowed).
        FileNotFoundError: a ``config`` or ``robot`` file that does not exist.
    """

    #: ``render_fps`` is the default ``1 / task.dt_s``; an instance's ``metadata`` holds its own.
    metadata = {"render_modes": RENDER_MODES, "render_fps": 20}

    def __init__(self, reward: Optional[str] = None, config: Union[None, str, os.PathLike, dict] = None,
                 robot: Union[None, str, os.PathLike] = None, render_mode: Optional[str] = None,
                 render_width: Optional[int] = None, render_height: Optional[int] = None):
        check_render_args(render_mode, render_width, render_height)
        self._core = _core.ReachCore(**core_args(reward, config, robot))
        self.observation_space, self.action_space = describe(self, self._core)
        enable_render(self, self._core, render_mode, render_width, render_height)

    def render(self) -> Optional[np.ndarray]:
        """The current frame with ``render_mode="rgb_array"``: a new ``(render_height,
        render_width, 3)`` uint8 array (RGB) of the arm, the target, the end effector's path since
        the last ``reset`` and the obstacles (see the module documentation). With
        ``render_mode=None``: None, with a warning (Gymnasium's convention)."""
        if self.render_mode is None:
            gym.logger.warn("stagerl/Reach-v0: render() was called with render_mode=None; make the "
                            "environment with render_mode='rgb_array' to get frames")
            return None
        return self._core.render()

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None) -> tuple[np.ndarray, dict]:
        """Start an episode: ``(observation, {"distance": metres, "is_success": bool})``; ``seed``
        reseeds ``np_random``, ``options={"target": [x, y, z], "start": [q1, ...], "obstacles":
        [...]}`` sets the target (metres), the start pose (radians) and the scene: a list of dicts
        in the schema of ``[[task.obstacles]]`` (``{"shape": "sphere", "radius_m": r,
        "position_m": [x, y, z]}``, ``{"shape": "cuboid", "half_extents_m": [..], "position_m":
        [..], "rotation_xyzw": [..]}``), which replaces the task's random obstacles (its fixed
        ones stay) and is checked as ``stagerl plan`` checks a request's, with the same
        ``ValueError`` messages. Every key is optional; a reset without ``obstacles`` goes back
        to the task's scene. The path drawn by :meth:`render` restarts."""
        super().reset(seed=seed)
        if options:
            obs, distance = self._reset_to(options)
        else:
            obs, distance = self._core.reset(draw_seed(self.np_random))
        return obs, {"distance": distance, "is_success": distance < self._beta_m}

    def _reset_to(self, options: dict):
        allowed = ("a dict with optional `target` (3 numbers, metres), `start` (one number per joint, radians; "
                   "with a target) and `obstacles` (a list of dicts)")
        if not isinstance(options, dict) or set(options) - {"target", "start", "obstacles"}:
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}")
        if "start" in options and "target" not in options:
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}")
        obstacles = options.get("obstacles")
        if "target" not in options:
            return self._core.reset(draw_seed(self.np_random), obstacles)
        try:
            target = np.asarray(options["target"], dtype=np.float64).tolist()
            start = options.get("start")
            start = None if start is None else np.asarray(start, dtype=np.float64).tolist()
        except (TypeError, ValueError):
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}") from None
        if not isinstance(target, list) or (start is not None and not isinstance(start, list)):
            raise ValueError(f"`options` = {options!r} is invalid: {allowed}")
        return self._core.reset_to(target, start, obstacles)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        """One step with ``action`` (one value per joint in [-1, 1]): ``(observation, reward,
        terminated, truncated, info)``, ``info`` holding every reward term, ``collision`` and
        ``is_success``."""
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
