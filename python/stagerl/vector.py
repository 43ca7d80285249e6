"""A native batch of ``stagerl/Reach-v0`` environments: a ``gymnasium.vector.VectorEnv`` over the
Rust ``VecEnv``, stepped in one call per batch.

``gymnasium.make_vec("stagerl/Reach-v0", num_envs=N, vectorization_mode="vector_entry_point")``
returns a :class:`ReachVectorEnv` (the keyword arguments ``reward``, ``config`` and ``robot`` as
for ``gymnasium.make``). It behaves exactly as ``gymnasium.vector.SyncVectorEnv`` over N
:class:`stagerl.envs.ReachEnv` in next-step autoreset mode (tested value for value), only faster:

- Autoreset (Gymnasium 1.x's default, ``AutoresetMode.NEXT_STEP``): when sub-environment ``i``'s
  episode ends (terminated on success, truncated at ``task.max_steps``), ``step`` returns its last
  observation; the *next* ``step`` ignores its action and resets it, returning the first
  observation of its new episode with reward 0, ``terminated`` and ``truncated`` False.
- Seeding: ``reset(seed=s)`` seeds sub-environment ``i`` with ``s + i`` (a list: one seed per
  sub-environment; None: fresh entropy the first time, else the sub-environment's generator goes
  on). Each sub-environment owns a ``numpy.random.Generator`` from which every episode (the first
  and each autoreset) draws the 64-bit seed of its Rust environment, as ``ReachEnv.reset`` does;
  the seeds are drawn :data:`SEED_BLOCK` at a time (the same values as one at a time), so that an
  autoreset costs no Python call.
- ``info`` follows Gymnasium's vector convention: ``info[key]`` an array over sub-environments,
  ``info["_" + key]`` a boolean mask of those that hold the key. After a step: every reward term
  of ``ReachEnv``'s step info (``distance`` in metres, ``reached``, ``position``, ..., ``total``)
  and ``is_success``; a sub-environment reset in this step holds only ``distance`` and
  ``is_success`` (of its new episode), as after ``reset``. The masks are read-only arrays (one
  array may serve several keys and steps).

- Obstacles: ``reset(options={"obstacles": [...]})`` starts every sub-environment's episode among
  that scene (a list of dicts in the schema of ``[[task.obstacles]]``, checked as
  ``ReachEnv.reset`` checks it, with the same ``ValueError`` messages), in place of the task's
  random obstacles; as in ``SyncVectorEnv``, which passes the options to each sub-environment's
  ``reset`` but none to its autoresets, the episodes after an autoreset are among the task's own
  scene again. Other reset options (``target``, ``start``) are per episode of a single
  environment: use ``ReachEnv`` for them.

Observations are float32 (N, obs_dim), actions float32 (N, act_dim) in [-1, 1], rewards float64.

``render_mode="rgb_array"`` (with ``render_width``, ``render_height``, as for ``ReachEnv``):
``render()`` returns a tuple of one frame per sub-environment, as ``SyncVectorEnv`` does; each
sub-environment's path restarts with its episode (autoresets included).
"""

from __future__ import annotations

import os
from typing import Optional, Sequence, Union

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _core
from .envs import RENDER_MODES, check_render_args, core_args, describe, enable_render

#: The keys of a step's reward terms in ``info``, in the order of ``ReachEnv``'s step info.
STEP_KEYS = tuple(_core.STEP_KEYS)

#: How many episode seeds a sub-environment draws from its generator at once.
SEED_BLOCK = 64


class ReachVectorEnv(VectorEnv):
    """``num_envs`` reaching environments over the Rust ``VecEnv`` (see the module documentation)."""

    metadata = {"render_modes": RENDER_MODES, "render_fps": 20, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, reward: Optional[str] = None,
                 config: Union[None, str, os.PathLike, dict] = None, robot: Union[None, str, os.PathLike] = None,
                 render_mode: Optional[str] = None, render_width: Optional[int] = None,
                 render_height: Optional[int] = None, threads: int = 1):
        """``num_envs`` (an integer >= 1) environments; ``threads`` (1 to 64): threads that
        ``step`` splits the environments over (the results do not depend on it; 16 or more
        environments are needed for a split); the other arguments as for
        :class:`stagerl.envs.ReachEnv`. Raises ValueError naming a bad argument."""
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"`num_envs` = {num_envs!r} is invalid: an integer >= 1")
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or not 1 <= threads <= 64:
            raise ValueError(f"`threads` = {threads!r} is invalid: an integer from 1 to 64 (threads stepping the environments)")
        check_render_args(render_mode, render_width, render_height)
        self._core = _core.VecCore(int(num_envs), **core_args(reward, config, robot), threads=int(threads))
        self.num_envs = int(num_envs)
        self.single_observation_space, self.single_action_space = describe(self, self._core)
        enable_render(self, self._core, render_mode, render_width, render_height)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs: list = [None] * self.num_envs
        self._ones = np.ones(self.num_envs, bool)
        self._ones.flags.writeable = False
        self._reset_done = False

    def reset(self, *, seed: Union[None, int, Sequence[Optional[int]]] = None, options: Optional[dict] = None):
        super().reset(seed=seed if isinstance(seed, int) else None)
        if options and (not isinstance(options, dict) or set(options) != {"obstacles"}):
            raise ValueError(f"`options` = {options!r} is invalid: a vector env takes `obstacles` (a list of dicts) "
                             "and no other reset option")
        seeds = self._sub_seeds(seed)
        for i, s in enumerate(seeds):
            if s is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(s)
                self._refill(i)
        obs, distance, exhausted = self._core.reset((options or {}).get("obstacles"))
        self._refill_all(exhausted)
        self._reset_done = True
        info = {"distance": distance, "_distance": self._ones}
        info["is_success"], info["_is_success"] = distance < self._beta_m, self._ones
        return obs, info

    def render(self) -> Optional[tuple]:
        """With ``render_mode="rgb_array"``: a tuple of each sub-environment's current frame, a
        ``(render_height, render_width, 3)`` uint8 array (see :meth:`stagerl.envs.ReachEnv.render`);
        with ``render_mode=None``: None, with a warning."""
        if self.render_mode is None:
            gym.logger.warn("stagerl/Reach-v0: render() was called with render_mode=None; make the "
                            "environments with render_mode='rgb_array' to get frames")
            return None
        return tuple(self._core.render(i) for i in range(self.num_envs))

    def _refill(self, i: int) -> None:
        """The next :data:`SEED_BLOCK` episode seeds of sub-environment ``i``, from its generator
        (the values :func:`stagerl.envs.draw_seed` would draw one by one)."""
        self._core.refill(i, self._rngs[i].integers(0, 2**64, size=SEED_BLOCK, dtype=np.uint64))

    def _refill_all(self, exhausted) -> None:
        for i in exhausted:
            self._refill(i)

    def _sub_seeds(self, seed) -> list:
        n = self.num_envs
        if seed is None:
            return [None] * n
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(n)]
        if isinstance(seed, (list, tuple)) and len(seed) == n:
            return list(seed)
        raise ValueError(f"`seed` = {seed!r} is invalid: None, an integer, or a list of {n} integers or None (one per sub-environment)")

    def step(self, actions):
        if not self._reset_done:
            raise ValueError("`step` was called before `reset`: call reset() first")
        actions = np.ascontiguousarray(actions, dtype=np.float32)
        if actions.shape != self.action_space.shape:
            raise ValueError(f"`actions.shape` = {actions.shape} is invalid: expected {self.action_space.shape}")
        obs, rewards, terminated, truncated, info, exhausted = self._core.step(actions)
        if exhausted:
            self._refill_all(exhausted)
        return obs, rewards, terminated, truncated, info
