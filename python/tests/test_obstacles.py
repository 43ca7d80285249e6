"""Obstacles per request from Python: `stagerl.plan(..., obstacles=)` and
`ReachEnv.reset(options={"obstacles": ...})` take the schema of `[[task.obstacles]]`, report the
collision check of `stagerl plan` and refuse bad obstacles with its messages."""

import json
import subprocess

import numpy as np
import pytest

import stagerl
from stagerl.envs import ReachEnv

TARGET = [0.4, 0.2, 0.3]
FAR = {"shape": "sphere", "radius_m": 0.05, "position_m": [0.3, -0.3, 0.9]}
BOX = {"shape": "cuboid", "half_extents_m": [0.05, 0.05, 0.05], "position_m": [-0.4, 0.4, 0.6],
       "rotation_xyzw": [0.0, 0.0, 0.0, 1.0]}

BAD = [
    ({"shape": "sphere", "radius_m": -0.1, "position_m": [0.3, 0.3, 0.3]}, "`obstacles[1].radius_m` = -0.1"),
    ({"shape": "cuboid", "half_extents_m": [0.1, 0.0, 0.1], "position_m": [0.3, 0.3, 0.6]},
     "`obstacles[1].half_extents_m`"),
    ({"shape": "cuboid", "half_extents_m": [0.1, 0.1, 0.1], "position_m": [0.3, 0.3, 0.6],
      "rotation_xyzw": [0.0, 0.0, 0.5, 0.5]}, "`obstacles[1].rotation_xyzw`"),
    ({"shape": "sphere", "radius_m": 0.02, "position_m": [0.41, 0.2, 0.3]}, "encloses the target"),
    ({"shape": "cuboid", "half_extents_m": [0.1, 0.1, 0.1], "position_m": [0.0, 0.0, 0.1]}, "start pose"),
]


def cli_error(stagerl_bin, trained_run, obstacles):
    """`stagerl plan --targets -` on one line with `obstacles`: its error message, without the
    CLI's prefixes (`stagerl: error: line 1: `)."""
    line = json.dumps({"target": TARGET, "obstacles": obstacles}) + "\n"
    done = subprocess.run([stagerl_bin, "plan", "--run", str(trained_run), "--targets", "-"],
                          input=line, capture_output=True, text=True)
    assert done.returncode == 1, done.stderr
    prefix = "stagerl: error: line 1: "
    assert done.stderr.startswith(prefix), done.stderr
    return done.stderr[len(prefix):].strip()


def test_plan_among_obstacles_reports_them_and_matches_the_cli(stagerl_bin, trained_run):
    free = stagerl.plan(trained_run, TARGET)
    assert free["summary"]["min_clearance_m"] is None and free["summary"]["collision"] is False
    plan = stagerl.plan(trained_run, TARGET, obstacles=[FAR, BOX])
    s = plan["summary"]
    assert s["min_clearance_m"] > 0 and s["plan_time_s"] > 0 and isinstance(s["collision"], bool)
    line = json.dumps({"target": TARGET, "obstacles": [FAR, BOX]}) + "\n"
    done = subprocess.run([stagerl_bin, "plan", "--run", str(trained_run), "--targets", "-"],
                          input=line, capture_output=True, text=True, check=True)
    cli = json.loads(done.stdout)
    assert cli["min_clearance_m"] == s["min_clearance_m"] and cli["collision"] == s["collision"]
    np.testing.assert_array_equal(plan["q"], np.array(cli["q"]))
    # Deterministic.
    again = stagerl.plan(trained_run, TARGET, obstacles=[FAR, BOX])
    np.testing.assert_array_equal(again["q"], plan["q"])


@pytest.mark.parametrize("bad, want", BAD)
def test_bad_obstacles_get_the_cli_message(stagerl_bin, trained_run, bad, want):
    with pytest.raises(ValueError) as e:
        stagerl.plan(trained_run, TARGET, obstacles=[FAR, bad])
    assert want in str(e.value)
    assert str(e.value) == cli_error(stagerl_bin, trained_run, [FAR, bad])
    env = ReachEnv()
    with pytest.raises(ValueError) as e2:
        env.reset(seed=1, options={"target": TARGET, "obstacles": [FAR, bad]})
    assert str(e2.value) == str(e.value)


def test_shapes_of_values_are_checked_in_python():
    env = ReachEnv()
    for obstacles, want in [
        ("ball", "`obstacles`"),
        ([{"shape": "cone", "radius_m": 0.1, "position_m": [0, 0, 1]}], "`obstacles[0].shape`"),
        ([{"shape": "sphere", "radius": 0.1, "position_m": [0, 0, 1]}], "`obstacles[0]`"),
        ([{"shape": "sphere", "radius_m": 0.1, "position_m": [0, 1]}], "`obstacles[0].position_m`"),
        ([{"shape": "sphere", "radius_m": float("nan"), "position_m": [0, 0, 1]}], "`obstacles[0].radius_m` = NaN"),
    ]:
        with pytest.raises(ValueError, match=None) as e:
            env.reset(options={"obstacles": obstacles})
        assert want in str(e.value), str(e.value)


def test_reset_with_obstacles_and_back_to_the_task_scene():
    env = ReachEnv()
    obs, info = env.reset(seed=3, options={"obstacles": [FAR, BOX]})
    assert obs.shape == env.observation_space.shape and info["distance"] > 0
    obs, info = env.reset(seed=3, options={"target": TARGET, "start": [0.0, -1.2, 1.2, -1.5, -1.5, 0.0],
                                            "obstacles": [FAR]})
    np.testing.assert_allclose(env.target, TARGET)
    # A step into the scene runs; a plain reset drops the scene.
    env.step(np.zeros(6, dtype=np.float32))
    env.reset(seed=4)
    with pytest.raises(ValueError, match="`options`"):
        env.reset(options={"start": [0.0] * 6})
