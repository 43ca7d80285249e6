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
