"""Batched forward kinematics and Jacobians."""

import numpy as np
import pytest

from stagerl import Chain


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def test_ur5_zero_pose_is_the_dh_value():
    p, q = Chain().fk(np.zeros(6))
    # a2 + a3 = -0.81725, -(d4 + d6) = -0.19145, d1 - d5 = -0.005491 (UR5 DH parameters).
    np.testing.assert_allclose(p[0], [-0.81725, -0.19145, -0.005491], atol=1e-12)
    assert q.shape == (1, 4) and abs(np.linalg.norm(q[0]) - 1) < 1e-12 and q[0, 3] >= 0


@pytest.mark.parametrize("robot, tip", [("ur5", None), ("test_arm", "tool")])
def test_batch_equals_rows_and_jacobian_matches_finite_differences(robot, tip, root):
    if robot == "test_arm":
        robot = str(root / "crates" / "stagerl" / "tests" / "robot_test_arm.urdf")
    chain = Chain(robot, tip)
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(chain.lower_limits), chain.lower_limits, -np.pi)
    hi = np.where(np.isfinite(chain.upper_limits), chain.upper_limits, np.pi)
    qs = rng.uniform(lo, hi, (50, chain.dof))
    p, quat = chain.fk(qs)
    jac, p2, quat2 = chain.jacobian(qs)
    assert p.shape == (50, 3) and quat.shape == (50, 4) and jac.shape == (50, 6, chain.dof)
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(quat, quat2)
    for i in range(0, 50, 7):
        pi, qi = chain.fk(qs[i])
        np.testing.assert_array_equal(pi[0], p[i])
        h = 1e-6
        for j in range(chain.dof):
            dq = qs[i].copy()
            dq[j] += h
            ph, qh = chain.fk(dq)
            np.testing.assert_allclose((ph[0] - p[i]) / h, jac[i, :3, j], atol=1e-5)
            d = quat_mul(qh[0], quat[i] * np.array([-1, -1, -1, 1]))
            d *= np.sign(d[3])
            np.testing.assert_allclose(2 * d[:3] / h, jac[i, 3:, j], atol=1e-5)


@pytest.mark.parametrize(
    "call, exc, words",
    [
        (lambda: Chain().fk(np.zeros((2, 5))), ValueError, ["q.shape", "(2, 5)", "(N, 6)"]),
        (lambda: Chain().fk([0, 0, np.nan, 0, 0, 0]), ValueError, ["q row 0", "q[2]", "not finite"]),
        (lambda: Chain().jacobian([[0] * 6, [0, 0, 0, np.inf, 0, 0]]), ValueError, ["q row 1", "q[3]"]),
        (lambda: Chain().fk(np.zeros((2, 2, 6))), ValueError, ["q.shape", "(2, 2, 6)"]),
        (lambda: Chain("/nonexistent.urdf"), FileNotFoundError, ["robot", "/nonexistent.urdf"]),
        (lambda: Chain("ur5", "nowhere"), ValueError, ["nowhere"]),
        (lambda: Chain(5), ValueError, ["robot", "5"]),
    ],
)
def test_bad_inputs(call, exc, words):
    with pytest.raises(exc) as e:
        call()
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_collision_checker_agrees_with_the_cli_and_measures_distance(stagerl_bin):
    """Floor and self checks: the clearance of `stagerl fk --collisions` (the CLI's own path);
    a sphere moved away along the line from the arm's closest point gains exactly that distance."""
    import json
    import subprocess

    from stagerl import CollisionChecker

    chain = Chain()
    rng = np.random.default_rng(3)
    qs = rng.uniform(-2.0, 2.0, (20, 6))
    hit, clear = chain.checker().check(qs)
    lines = "".join(json.dumps({"joints": list(q)}) + "\n" for q in qs)
    out = subprocess.run([stagerl_bin, "fk", "--collisions"], input=lines, capture_output=True, text=True, check=True)
    for i, line in enumerate(out.stdout.splitlines()):
        row = json.loads(line)
        assert hit[i] == bool(row["contacts"]), (i, row)
        assert abs(clear[i] - row["clearance_m"]) < 1e-9, (i, clear[i], row["clearance_m"])
    assert [chain.checker().collides(q) for q in qs] == list(hit)
    # A sphere only (no floor, no self): at the tip it touches. Away from the arm, at clearance c,
    # growing its radius by c - 1 mm keeps it clear and by c + 1 mm makes a contact, and a larger
    # radius lowers the clearance by exactly as much (distance and overlap tests agree).
    q = np.array([0.0, -1.2, 1.0, 0.0, 0.0, 0.0])
    tip = chain.fk(q)[0][0]
    ball = lambda r, c=tip + [0.3, 0.2, 0.4]: [{"shape": "sphere", "radius_m": r, "position_m": c}]  # noqa: E731
    only = dict(floor=False, self_collision=False)
    assert CollisionChecker(chain, ball(0.05, tip), **only).check(q)[0][0]
    hit0, c0 = chain.checker(ball(0.05), **only).check(q)
    assert not hit0[0] and c0[0] > 0.1
    hit1, c1 = chain.checker(ball(0.05 + c0[0] - 1e-3), **only).check(q)
    hit2, _ = chain.checker(ball(0.05 + c0[0] + 1e-3), **only).check(q)
    assert not hit1[0] and hit2[0]
    np.testing.assert_allclose(c1[0], 1e-3, atol=1e-6)


def test_collision_checker_refuses_bad_scenes(root):
    chain = Chain()
    with pytest.raises(ValueError, match=r"obstacles\[0\]\.radius_m"):
        chain.checker([{"shape": "sphere", "radius_m": -1.0, "position_m": [1, 0, 0]}])
    with pytest.raises(ValueError, match=r"obstacles\[0\]\.radius_m"):
        chain.checker([{"shape": "sphere", "radius_m": float("nan"), "position_m": [1, 0, 0]}])
    with pytest.raises(ValueError, match="a field `colour`"):
        chain.checker([{"shape": "sphere", "radius_m": 0.1, "position_m": [1, 0, 0], "colour": "red"}])
    with pytest.raises(ValueError, match="a list of dicts"):
        chain.checker({"shape": "sphere"})
    with pytest.raises(ValueError, match=r"q\.shape|one value per joint"):
        chain.checker().check(np.zeros((2, 5)))
    bare = Chain(str(root / "crates" / "stagerl" / "tests" / "robot_test_arm.urdf"), "tool")
    with pytest.raises(ValueError, match="no collision shapes|has none"):
        bare.checker()
