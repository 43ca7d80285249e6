"""The paper's rewards over numpy arrays, identical to ``stagerl reward``.

``compute(ee_pos, ee_quat, target, joint_vel, function="sar", **constants)`` takes N rows:
``ee_pos`` (N, 3) metres, ``ee_quat`` (N, 4) unit quaternions (x, y, z, w), ``target`` (N, 3)
metres, ``joint_vel`` (N, J) rad/s (one row also works as 1-D arrays). It returns a dict of
arrays of length N keyed like ``stagerl reward``'s output (:data:`KEYS`): ``distance`` (m),
``reached`` (bool), ``position``, ``direction``, ``posture``, ``move``, ``stride``, ``alpha1``,
``alpha2``, ``reward`` (the chosen function), ``bonus``, ``total``.

``out``: a dict of arrays to write the result into instead of new ones, such as the result of an
earlier call with the same number of rows: every key of :data:`KEYS`, each a writable C-contiguous
array of shape (N,), float64 (``reached``: bool), sharing no memory with another or with the
inputs. The call then returns ``out``. Reusing the arrays of a large call skips allocating
fresh memory, whose pages the system clears on first use (about a sixth of a 1 M-row call).

``constants``: any field of the config's ``[reward]`` section (``beta_m``, ``success_bonus``,
``har_boundary_m``, ``sar_sigma1``, ``sar_sigma2``, ``sar_scale_m``, ``direction``,
``direction_fold``), ``dt_s`` (the control period of eq. 9, seconds, default 0.05) and
``prev_ee_pos`` ((N, 3) metres, needed by ``direction="displacement"``). The clearance term
(``[reward.clearance]``, our extension: a penalty as the arm comes near an obstacle) needs the
whole arm and the obstacles, which these rows do not hold: ``clearance=`` is refused with a
ValueError naming ``reward.clearance`` (the environment, ``ReachEnv``, charges it), and so is
``shield_penalty=`` (the safety shield's penalty needs what the shield did to each command).
"""

from __future__ import annotations

import json
import math

import numpy as np


from . import _core
from ._arrays import rows as _rows

KEYS = tuple(_core.keys())
FUNCTIONS = ("basic", "posture", "stride", "har", "sar")


def _out_arrays(out, n: int):
    """The float columns of ``out`` in KEYS order (without ``reached``) and its ``reached``
    array, each checked; a ValueError naming the key otherwise."""
    if not isinstance(out, dict):
        raise ValueError(f"`out` = {type(out).__name__} is invalid: a dict of arrays keyed like the result (KEYS)")
    missing = [k for k in KEYS if k not in out]
    if missing:
        raise ValueError(f"`out` is invalid: it lacks the keys {missing} (every key of KEYS is needed)")
    arrays = []
    for k in KEYS:
        a = out[k]
        dtype = np.bool_ if k == "reached" else np.float64
        if not isinstance(a, np.ndarray) or a.dtype != dtype:
            got = a.dtype if isinstance(a, np.ndarray) else type(a).__name__
            raise ValueError(f"`out[{k!r}]` = {got} is invalid: a numpy array of {np.dtype(dtype).name}")
        if a.shape != (n,):
            raise ValueError(f"`out[{k!r}].shape` = {a.shape} is invalid: ({n},), one value per row")
        if not a.flags.c_contiguous or not a.flags.writeable:
            raise ValueError(f"`out[{k!r}]` is invalid: a writable C-contiguous array")
        arrays.append(a)
    floats = [a for k, a in zip(KEYS, arrays) if k != "reached"]
    return floats, out["reached"]


def compute(ee_pos, ee_quat, target, joint_vel, function: str = "sar", out=None, **constants) -> dict:
    """Every reported reward term for every row (see the module documentation)."""
    if function not in FUNCTIONS:
        raise ValueError(f"`function` = {function!r} is invalid: one of {list(FUNCTIONS)}")
    dt_s = constants.pop("dt_s", 0.05)
    if isinstance(dt_s, bool) or not isinstance(dt_s, (int, float)) or not math.isfinite(dt_s) or dt_s <= 0:
        raise ValueError(f"`dt_s` = {dt_s!r} is invalid: a finite number of seconds > 0")
    prev = constants.pop("prev_ee_pos", None)
    arrays = [_rows("ee_pos", ee_pos, 3), _rows("ee_quat", ee_quat, 4), _rows("target", target, 3), _rows("joint_vel", joint_vel, None)]
    n = arrays[0].shape[0]
    for name, arr in zip(("ee_quat", "target", "joint_vel"), arrays[1:]):
        if arr.shape[0] != n:
            raise ValueError(f"`{name}` has {arr.shape[0]} rows, `ee_pos` has {n}: every input needs the same number of rows")
    if prev is not None:
        prev = _rows("prev_ee_pos", prev, 3)
    try:
        config_json = json.dumps({"function": function, **constants}, allow_nan=True)
    except (TypeError, ValueError) as e:
        raise ValueError(f"`constants` = {constants!r} is invalid: numbers, booleans or strings ({e})") from None
    if out is None:
        return _core.compute(*arrays, config_json, float(dt_s), prev)
    floats, reached = _out_arrays(out, n)
    _core.compute(*arrays, config_json, float(dt_s), prev, floats, reached)
    return out
