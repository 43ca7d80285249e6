"""stagerl.rewards.compute against the `stagerl reward` CLI, bit for bit."""

import json
import math
import re
import subprocess

import numpy as np
import pytest

import stagerl
from stagerl import rewards

FUNCTIONS = ["basic", "posture", "stride", "har", "sar"]
IDENTITY = [0.0, 0.0, 0.0, 1.0]


def cli(bin_path, function, ee_pos, ee_quat, target, joint_vel, config_toml=None, tmp_path=None, prev=None):
    """The CLI's output for the rows, as a dict of arrays keyed like compute()."""
    lines = []
    for i in range(len(ee_pos)):
        row = {"ee_pos": list(map(float, ee_pos[i])), "ee_quat": list(map(float, ee_quat[i])),
               "target": list(map(float, target[i])), "joint_vel": list(map(float, joint_vel[i]))}
        if prev is not None:
            row["prev_ee_pos"] = list(map(float, prev[i]))
        lines.append(json.dumps(row))
    args = [bin_path, "reward", "--function", function]
    if config_toml is not None:
        path = tmp_path / "reward.toml"
        path.write_text(config_toml)
        args += ["--config", str(path)]
    out = subprocess.run(args, input="\n".join(lines) + "\n", capture_output=True, text=True, check=True).stdout
    rows = [json.loads(l) for l in out.splitlines() if l.strip()]
    assert len(rows) == len(ee_pos), out[:500]
    assert list(rows[0].keys()) == list(rewards.KEYS)
    return {k: np.array([r[k] for r in rows]) for k in rewards.KEYS}


def assert_identical(py, ref):
    assert list(py.keys()) == list(rewards.KEYS)
    for k in rewards.KEYS:
        if k == "reached":
            assert py[k].dtype == np.bool_
            np.testing.assert_array_equal(py[k], ref[k].astype(bool))
        else:
            assert py[k].dtype == np.float64
            # Bit-identical: the CLI writes shortest round-trip floats.
            np.testing.assert_array_equal(py[k], ref[k], err_msg=k)


def random_rows(n, seed, joints=6):
    rng = np.random.default_rng(seed)
    ee = rng.uniform(-1.0, 1.0, (n, 3))
    target = rng.uniform(-1.0, 1.0, (n, 3))
    near = rng.random(n) < 0.1  # some rows within beta of the target
    target[near] = ee[near] + rng.uniform(-0.008, 0.008, (near.sum(), 3))
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    vel = rng.uniform(-math.pi, math.pi, (n, joints))
    return ee, quat, target, vel


@pytest.mark.parametrize("function", FUNCTIONS)
def test_equals_cli_on_random_rows(stagerl_bin, function):
    ee, quat, target, vel = random_rows(10_000, seed=FUNCTIONS.index(function))
    py = rewards.compute(ee, quat, target, vel, function=function)
    ref = cli(stagerl_bin, function, ee, quat, target, vel)
    assert_identical(py, ref)
    assert py["reached"].sum() > 100 and (~py["reached"]).sum() > 5000
    np.testing.assert_array_equal(py["total"], py["reward"] + py["bonus"])


def axis_angle(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    s = math.sin(angle / 2)
    return [axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2)]


# The inputs of the Rust reward tests (crates/stagerl/src/reward.rs): (ee, quat, target, vel).
AX60 = [0.5, math.sqrt(3.0) / 2.0, 0.0]
EDGE_ROWS = [
    ([0.0] * 3, IDENTITY, [0.01, 0.0, 0.0], [0.0] * 6),  # exactly at beta: not reached
    ([0.0] * 3, IDENTITY, [0.0, 0.0, 0.009], [0.0] * 6),  # just inside
    ([0.1, 0.1, 0.1], IDENTITY, [0.4, 0.5, 0.1], [0.0] * 6),  # 3-4-5 triangle
    ([0.0] * 3, axis_angle([1, 0, 0], 0.7), [0.3, 0.0, 0.0], [0.0] * 6),  # phi 0
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [0.3, 0.0, 0.0], [0.0] * 6),  # phi pi/2
    ([1.0] * 3, axis_angle(AX60, 0.4), [1.2, 1.0, 1.0], [0.0] * 6),  # phi pi/3
    ([1.0] * 3, axis_angle([-AX60[0], -AX60[1], 0.0], 0.4), [1.2, 1.0, 1.0], [0.0] * 6),  # 2pi/3
    ([0.1, 0.2, 0.3], axis_angle([0.3, -0.5, 0.8], 2.0), [0.4, -0.1, 0.5], [0.0] * 6),
    ([0.1, 0.2, 0.3], [-x for x in axis_angle([0.3, -0.5, 0.8], 2.0)], [0.4, -0.1, 0.5], [0.0] * 6),
    ([0.2] * 3, axis_angle([0, 0, 1], 1.0), [0.2] * 3, [0.0] * 6),  # target at the end effector
    ([0.0] * 3, IDENTITY, [0.2, 0.0, 0.0], [1.0, 2.0, 0.0, 0.0, 0.0, 1.0]),  # movement 0.05
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [0.5 + 1e-9, 0.0, 0.0], [1.0] * 6),  # HAR far side
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [0.5, 0.0, 0.0], [1.0] * 6),  # HAR boundary
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [0.3, 0.0, 0.0], [1.0] * 6),  # SAR D = 0.3
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [1.0, 0.0, 0.0], [1.0] * 6),  # SAR clamp at 1
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [1.7, 0.0, 0.0], [1.0] * 6),
    ([0.0] * 3, axis_angle([0, 0, 1], 1.0), [0.0] * 3, [1.0] * 6),  # D = 0
    ([0.0] * 3, IDENTITY, [0.005, 0.0, 0.0], [2.0] * 6),  # basic: reached
]


def edge_arrays():
    return [np.array([r[k] for r in EDGE_ROWS], dtype=float) for k in range(4)]


@pytest.mark.parametrize("function", FUNCTIONS)
def test_equals_cli_on_the_rust_tests_edge_cases(stagerl_bin, function):
    ee, quat, target, vel = edge_arrays()
    py = rewards.compute(ee, quat, target, vel, function=function)
    assert_identical(py, cli(stagerl_bin, function, ee, quat, target, vel))
    # The Rust tests' own expectations hold here too.
    assert py["distance"][0] == 0.01 and not py["reached"][0] and py["position"][0] == -0.01
    assert py["reached"][1] and py["bonus"][1] == 20.0
    assert abs(py["direction"][4] - 0.25) < 1e-12
    assert abs(py["direction"][5] - 1 / 6) < 1e-12 and abs(py["direction"][6] - 1 / 6) < 1e-12
    assert abs(py["move"][10] - 0.05) < 1e-15
    assert py["alpha1"][14] == 0.0 and py["alpha2"][14] == 1.0
    assert (py["alpha1"][16], py["alpha2"][16]) == (1.0, 0.0)


def test_constants_equal_the_cli_with_a_config(stagerl_bin, tmp_path):
    ee, quat, target, vel = random_rows(2_000, seed=7)
    consts = dict(beta_m=0.05, success_bonus=5.0, har_boundary_m=0.3, sar_sigma1=2.0, sar_sigma2=0.5, sar_scale_m=0.5)
    toml = "[task]\ndt_s = 0.1\n[reward]\n" + "".join(f"{k} = {v}\n" for k, v in consts.items())
    for function in ["har", "sar"]:
        py = rewards.compute(ee, quat, target, vel, function=function, dt_s=0.1, **consts)
        assert_identical(py, cli(stagerl_bin, function, ee, quat, target, vel, toml, tmp_path))
    default = rewards.compute(ee, quat, target, vel)
    assert not np.array_equal(default["reward"], py["reward"])


def test_displacement_direction_equals_the_cli(stagerl_bin, tmp_path):
    ee, quat, target, vel = random_rows(2_000, seed=8)
    prev = ee + np.random.default_rng(9).uniform(-0.05, 0.05, ee.shape)
    toml = '[reward]\ndirection = "displacement"\ndirection_fold = false\n'
    py = rewards.compute(ee, quat, target, vel, function="posture", direction="displacement",
                         direction_fold=False, prev_ee_pos=prev)
    assert_identical(py, cli(stagerl_bin, "posture", ee, quat, target, vel, toml, tmp_path, prev=prev))
    assert py["direction"].max() > 0.25  # unfolded: up to 1/2


def test_one_row_as_1d_arrays():
    r = rewards.compute([0.0, 0.0, 0.0], IDENTITY, [0.3, 0.4, 0.0], [0.0] * 6, function="stride")
    assert r["distance"].shape == (1,)
    assert abs(r["distance"][0] - 0.5) < 1e-15 and r["reward"][0] == r["stride"][0]


def test_a_large_call_equals_small_ones():
    # 150 000 rows are split over threads (one per core above 65 536 rows) and written into one
    # buffer whose rows are the result's arrays; 10 000-row calls take the one-thread path, which
    # test_equals_cli_on_random_rows checks against the CLI.
    ee, quat, target, vel = random_rows(150_000, seed=7)
    whole = rewards.compute(ee, quat, target, vel, function="har")
    for start in range(0, 150_000, 10_000):
        part = rewards.compute(*(a[start:start + 10_000] for a in (ee, quat, target, vel)), function="har")
        for k in rewards.KEYS:
            np.testing.assert_array_equal(whole[k][start:start + 10_000], part[k], err_msg=k)
    # Each key's array is its own: writing one changes no other.
    before = {k: whole[k].copy() for k in rewards.KEYS}
    whole["distance"][:] = -1.0
    for k in rewards.KEYS:
        if k != "distance":
            np.testing.assert_array_equal(whole[k], before[k], err_msg=k)


def test_out_reuses_the_arrays_of_an_earlier_result():
    # 100 000 rows (the threaded path) into the arrays of an earlier call: the same values as a
    # fresh call, the same dict and arrays returned, nothing else written.
    a = random_rows(100_000, seed=3)
    b = random_rows(100_000, seed=4)
    first = rewards.compute(*a, function="sar")
    ids = {k: (id(v), v.__array_interface__["data"][0]) for k, v in first.items()}
    again = rewards.compute(*b, function="posture", out=first)
    assert again is first
    assert {k: (id(v), v.__array_interface__["data"][0]) for k, v in again.items()} == ids
    fresh = rewards.compute(*b, function="posture")
    for k in rewards.KEYS:
        np.testing.assert_array_equal(again[k], fresh[k], err_msg=k)
    # Arrays the caller made work too (float64 and bool, C-contiguous, writable).
    mine = {k: np.empty(100_000, dtype=bool if k == "reached" else np.float64) for k in rewards.KEYS}
    rewards.compute(*b, function="posture", out=mine)
    for k in rewards.KEYS:
        np.testing.assert_array_equal(mine[k], fresh[k], err_msg=k)


def test_bad_out_raises_value_error_naming_the_key():
    ee, quat, target, vel = random_rows(5, seed=1)

    def good():
        return {k: np.zeros(5, dtype=bool if k == "reached" else np.float64) for k in rewards.KEYS}

    def changed(key, value):
        d = good()
        if value is None:
            del d[key]
        else:
            d[key] = value(d) if callable(value) else value
        return d

    def read_only(d):
        d["bonus"].flags.writeable = False
        return d["bonus"]

    cases = [
        (changed("posture", None), "lacks the keys ['posture']"),
        (changed("stride", np.zeros(5, np.float32)), "out['stride']"),
        (changed("reached", np.zeros(5)), "out['reached']"),
        (changed("total", np.zeros(4)), "out['total'].shape"),
        (changed("move", np.zeros(10)[::2]), "out['move']"),
        (changed("bonus", read_only), "out['bonus']"),
        (changed("alpha2", lambda d: d["alpha1"]), "share no memory"),
        ([1, 2], "a dict of arrays"),
    ]
    for out, words in cases:
        with pytest.raises(ValueError, match=re.escape(words)):
            rewards.compute(ee, quat, target, vel, out=out)
    # The extension refuses a half-given output (the float columns without `reached`).
    floats = [a for k, a in good().items() if k != "reached"]
    with pytest.raises(ValueError, match="out_reached"):
        stagerl._core.compute(ee, quat, target, vel, '{"function": "sar"}', 0.05, None, floats)
    # An output array that is also an input (one joint velocity per row, read from it).
    d = good()
    with pytest.raises(ValueError, match="share no memory"):
        rewards.compute(ee, quat, target, d["distance"].reshape(5, 1), out=d)


def test_zero_rows_give_empty_arrays():
    r = rewards.compute(np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros((0, 6)))
    assert list(r) == list(rewards.KEYS)
    for k, v in r.items():
        assert v.shape == (0,), k
        assert v.dtype == (bool if k == "reached" else np.float64), k


def test_any_number_of_joints():
    r = rewards.compute([0.0] * 3, IDENTITY, [0.2, 0.0, 0.0], [1.0, 1.0, 1.0], function="stride")
    assert abs(r["move"][0] - 0.05) < 1e-15


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(function="fancy"), ["function", "fancy", "sar"]),
        (dict(beta_m=0.0), ["reward.beta_m", "0"]),
        (dict(sar_scale_m=-1.0), ["reward.sar_scale_m", "-1"]),
        (dict(beta=0.1), ["beta", "beta_m"]),
        (dict(direction="sideways"), ["sideways", "quaternion"]),
        (dict(dt_s=0.0), ["dt_s", "0.0", "> 0"]),
        (dict(dt_s=float("nan")), ["dt_s", "nan"]),
        (dict(direction="displacement"), ["prev_ee_pos", "displacement"]),
        # The clearance term needs the arm and the obstacles, which the rows do not hold.
        (dict(clearance={"weight": 1.0, "margin_m": 0.1}), ["reward.clearance", "stagerl.rewards.compute", "end effector"]),
        # So does the shield's penalty, which needs what the safety shield did to each command.
        (dict(shield_penalty=1.0), ["reward.shield_penalty", "stagerl.rewards.compute", "safety shield"]),
        (dict(shield_penalty=-1.0), ["reward.shield_penalty", "-1", "a finite number >= 0"]),
    ],
)
def test_bad_constants_name_field_value_and_allowed(kwargs, words):
    with pytest.raises(ValueError) as e:
        rewards.compute([0.0] * 3, IDENTITY, [0.3, 0.0, 0.0], [0.0] * 6, **kwargs)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


@pytest.mark.parametrize(
    "args, words",
    [
        (([0.0] * 2, IDENTITY, [0.3, 0.0, 0.0], [0.0] * 6), ["ee_pos.shape", "(2,)", "(N, 3)"]),
        (([0.0] * 3, [0.0, 0.0, 0.0, 1.1], [0.3, 0.0, 0.0], [0.0] * 6), ["row 0", "ee_quat", "norm"]),
        (([0.0] * 3, IDENTITY, [0.3, float("nan"), 0.0], [0.0] * 6), ["row 0", "target[1]", "NaN"]),
        (([1e200, 0.0, 0.0], IDENTITY, [0.0] * 3, [0.0] * 6), ["row 0", "not finite", "overflow"]),
        (([[0.0] * 3] * 2, [IDENTITY] * 3, [[0.3, 0.0, 0.0]] * 2, [[0.0] * 6] * 2), ["ee_quat", "3 rows", "2"]),
        (([0.0] * 3, IDENTITY, [0.3, 0.0, 0.0], np.zeros((1, 0))), ["joint_vel.shape", "J >= 1"]),
        (([0.0] * 3, IDENTITY, [0.3, 0.0, 0.0], ["a"] * 6), ["joint_vel", "numbers"]),
    ],
)
def test_bad_rows_raise_value_error(args, words):
    with pytest.raises(ValueError) as e:
        rewards.compute(*args)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_keys_are_the_cli_order():
    assert stagerl.rewards.KEYS == ("distance", "reached", "position", "direction", "posture", "move",
                                    "stride", "alpha1", "alpha2", "reward", "bonus", "total")
