"""Batched forward kinematics and geometric Jacobians of any URDF serial chain.

``Chain(robot="ur5", tip=None)``: the bundled UR5 ("ur5"), the bundled Franka Panda ("panda") or a URDF file (tip: the tip link; default the
URDF's only leaf). ``chain.fk(q)`` takes ``q`` of shape (N, dof) or (dof,) (radians, metres for
prismatic joints) and returns positions (N, 3) in metres and quaternions (N, 4) as (x, y, z, w)
with w >= 0, in the root link's frame. ``chain.jacobian(q)`` returns the geometric Jacobians
(N, 6, dof) (rows vx, vy, vz, wx, wy, wz in the base frame), with the same positions and
quaternions. ``chain.checker(obstacles=None, floor=True, self_collision=True)`` returns a
``CollisionChecker`` whose ``check(q)`` gives, per row, whether the arm is in contact and its
clearance in metres, with the environment's own checks over the same geometry.
"""

from __future__ import annotations

import os

import numpy as np

from . import _core
from ._arrays import rows as _rows


class Chain:
    """A serial chain from a URDF (see the module documentation)."""

    def __init__(self, robot="ur5", tip=None):
        if isinstance(robot, os.PathLike):
            robot = os.fspath(robot)
        if not isinstance(robot, str):
            raise ValueError(f"`robot` = {robot!r} is invalid: 'ur5', 'panda' or a path to a URDF file")
        if robot not in ("ur5", "panda") and not os.path.isfile(robot):
            raise FileNotFoundError(f"`robot` = {robot!r}: no such file (expected 'ur5', 'panda' or a path to a URDF file)")
        if tip is not None and not isinstance(tip, str):
            raise ValueError(f"`tip` = {tip!r} is invalid: a link name or None")
        self._core = _core.Chain(robot, tip)
        self.dof = self._core.dof
        self.joint_names = self._core.joint_names
        self.base_link = self._core.base_link
        self.tip_link = self._core.tip_link
        self.lower_limits = np.array(self._core.lower_limits)
        self.upper_limits = np.array(self._core.upper_limits)
        self.velocity_limits = np.array(self._core.velocity_limits)

    def fk(self, q):
        """Tip positions (N, 3), metres, and quaternions (N, 4), (x, y, z, w)."""
        return self._core.fk(_rows("q", q, self.dof))

    def jacobian(self, q):
        """Jacobians (N, 6, dof), positions (N, 3) and quaternions (N, 4)."""
        return self._core.jacobian(_rows("q", q, self.dof))

    def checker(self, obstacles=None, floor=True, self_collision=True):
        """A :class:`CollisionChecker` of this chain among ``obstacles``."""
        return CollisionChecker(self, obstacles, floor=floor, self_collision=self_collision)


class CollisionChecker:
    """The environment's collision checks of a chain among obstacles, from Python.

    ``obstacles``: a list of dicts in ``[[task.obstacles]]``'s schema
    (``{"shape": "sphere", "radius_m": r, "position_m": [x, y, z]}`` or
    ``{"shape": "cuboid", "half_extents_m": [..], "position_m": [..], "rotation_xyzw": [x, y, z, w]}``),
    metres, base frame. ``floor``: the arm's moving shapes against z = 0; ``self_collision``: the
    arm against itself (links two or more joints apart).
    """

    def __init__(self, chain, obstacles=None, floor=True, self_collision=True):
        if not isinstance(chain, Chain):
            raise ValueError(f"`chain` = {chain!r} is invalid: a stagerl.kinematics.Chain")
        for name, v in (("floor", floor), ("self_collision", self_collision)):
            if not isinstance(v, bool):
                raise ValueError(f"`{name}` = {v!r} is invalid: True or False")
        self.dof = chain.dof
        self._core = chain._core.checker(_obstacle_list(obstacles), floor, self_collision)

    def check(self, q):
        """For each row of ``q`` (N, dof) or one pose (dof,): in contact (N,) bool, and the
        clearance (N,) in metres (negative: a penetration's depth)."""
        return self._core.check(_rows("q", q, self.dof))

    def collides(self, q):
        """Whether the arm at one pose ``q`` (dof values, radians) touches anything checked: the
        environment's per-step test, faster than :meth:`check` (no clearance)."""
        return self._core.collides([float(v) for v in q])


def _obstacle_list(obstacles):
    """``obstacles`` as a list (a tuple or any sequence of dicts; numpy arrays inside are read as
    numbers), or None."""
    if obstacles is None or isinstance(obstacles, list):
        return obstacles
    if isinstance(obstacles, (str, bytes, dict)) or not hasattr(obstacles, "__iter__"):
        raise ValueError(f"`obstacles` = {obstacles!r} is invalid: a list of dicts")
    return list(obstacles)
