"""stagerl: the stage-incentive dense rewards and the UR5 reaching task of the stagerl Rust
workspace, for Gymnasium and numpy.

Importing the package registers the Gymnasium environment ``stagerl/Reach-v0``::

    import gymnasium as gym
    import stagerl

    env = gym.make("stagerl/Reach-v0", reward="sar")
    envs = gym.make_vec("stagerl/Reach-v0", num_envs=256, vectorization_mode="vector_entry_point")

Modules: :mod:`stagerl.envs` (the environment), :mod:`stagerl.vector` (the native batch of
environments), :mod:`stagerl.rewards` (the rewards over numpy
arrays), :mod:`stagerl.policies` (trained policies: :class:`Policy`, :func:`plan`),
:mod:`stagerl.kinematics` (batched forward kinematics and Jacobians of URDF chains),
:mod:`stagerl.training` (the Rust trainer: :func:`train`, :class:`Run`).
Units: metres, radians, seconds; quaternions are (x, y, z, w).

``SIMD_LEVEL`` is the instruction set the native code runs at (``"avx512"``, ``"avx2"`` or
``"baseline"``): the widest the CPU has, capped by the environment variable ``STAGERL_SIMD`` (the
same names; the results are the same bits at every level, only the speed changes). A value
that is not a level makes the import fail with a ValueError naming it.
"""

from . import _core
from . import envs, kinematics, policies, rewards, training, vector
from .envs import ReachEnv, register_envs
from .kinematics import Chain, CollisionChecker
from .policies import Policy, plan
from .training import Run, report, reproduce, train
from .vector import ReachVectorEnv

__version__ = _core.__version__
SIMD_LEVEL = _core.SIMD_LEVEL
__all__ = ["SIMD_LEVEL", "ReachEnv", "ReachVectorEnv", "Chain", "CollisionChecker", "Policy", "plan", "train", "Run", "report", "reproduce", "training", "policies", "envs", "kinematics", "rewards", "vector", "register_envs", "__version__"]

register_envs()
