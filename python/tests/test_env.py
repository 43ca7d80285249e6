"""stagerl/Reach-v0 through Gymnasium."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import stagerl  # noqa: F401  (registers the environment)
from stagerl.envs import ReachEnv

TERMS = ["distance", "reached", "position", "phi", "direction", "posture", "move", "stride",
         "gamma_posture", "har", "alpha1", "alpha2", "sar", "basic", "reward", "bonus", "total",
         "clearance", "shield"]


@pytest.mark.parametrize("reward", ["basic", "posture", "stride", "har", "sar"])
def test_check_env_passes(reward):
    env = gym.make("stagerl/Reach-v0", reward=reward)
    check_env(env.unwrapped, skip_render_check=True)


def test_spaces_are_float32_with_finite_bounds():
    env = gym.make("stagerl/Reach-v0")
    for space in (env.observation_space, env.action_space):
        assert space.dtype == np.float32
        assert np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))
    assert env.observation_space.shape == (16,) and env.action_space.shape == (6,)
    np.testing.assert_array_equal(env.action_space.low, -1.0)


def episodes(seed, n=4, reward="sar"):
    env = gym.make("stagerl/Reach-v0", reward=reward)
    rng = np.random.default_rng(0)
    out = []
    obs, _ = env.reset(seed=seed)
    for _ in range(n):
        out.append(obs.copy())
        while True:
            obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            out.append(np.array([r, term, trunc, info["distance"]]))
            if term or trunc:
                break
        obs, _ = env.reset()
    return out


def test_same_seed_same_episodes_and_observations_in_bounds():
    a, b, c = episodes(11), episodes(11), episodes(12)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not (len(a) == len(c) and all(np.array_equal(x, y) for x, y in zip(a, c)))


def test_observations_stay_within_the_space():
    env = gym.make("stagerl/Reach-v0")
    space = env.observation_space
    rng = np.random.default_rng(1)
    obs, _ = env.reset(seed=1)
    for _ in range(3000):
        assert space.contains(obs), obs
        # Full-speed pushes drive joints to their limits.
        obs, _, term, trunc, _ = env.step(np.sign(rng.uniform(-1, 1, 6)).astype(np.float32))
        if term or trunc:
            obs, _ = env.reset()


@pytest.mark.parametrize("encoding", ["absolute", "nearest"])
def test_observed_obstacles_stay_within_the_space(encoding):
    """Random obstacles in the observation (7 values a slot, 1 fixed + 3 random slots), either
    encoding: check_env passes and every observation lies in the Box."""
    ball = {"shape": "sphere", "radius_m": 0.05, "position_m": [0.0, 0.6, 0.3]}
    task = {"obstacles": [ball], "random_obstacles": {"count": [1, 3]}, "observe_obstacles": True,
            "obstacle_observation": encoding}
    env = gym.make("stagerl/Reach-v0", config={"task": task})
    assert env.observation_space.shape == (16 + 7 * 4,)
    check_env(env.unwrapped, skip_render_check=True)
    rng = np.random.default_rng(2)
    obs, _ = env.reset(seed=2)
    for _ in range(1000):
        assert env.observation_space.contains(obs), obs
        obs, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
        if term or trunc:
            obs, _ = env.reset()
    with pytest.raises(ValueError, match="task.obstacle_observation"):
        gym.make("stagerl/Reach-v0", config={"task": {"obstacles": [ball], "obstacle_observation": "nearest"}})


def test_per_link_observation_is_bounded_and_sized_by_the_arm():
    """task.obstacle_observation = "per_link": one slot of 4 values per collision shape of the
    arm, whatever the number of obstacles, every value in [-1, 1] (the Box's bounds); the
    clearance term of the reward is charged (total = reward + bonus - clearance)."""
    task = {"random_obstacles": {"count": [1, 3]}, "observe_obstacles": True,
            "obstacle_observation": "per_link"}
    reward = {"clearance": {"weight": 1.0, "margin_m": 0.1}}
    env = gym.make("stagerl/Reach-v0", config={"task": task, "reward": reward})
    n = env.observation_space.shape[0] - 16
    assert n % 4 == 0 and n >= 4 * 6, n
    np.testing.assert_array_equal(env.observation_space.low[16:], -np.ones(n, dtype=np.float32))
    np.testing.assert_array_equal(env.observation_space.high[16:], np.ones(n, dtype=np.float32))
    check_env(env.unwrapped, skip_render_check=True)
    rng = np.random.default_rng(3)
    obs, _ = env.reset(seed=3)
    near, charged = 0, 0
    for _ in range(500):
        assert env.observation_space.contains(obs), obs
        near += int((obs[16:].reshape(-1, 4)[:, 3] < 1.0).sum())
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
        if not info["collision"]:
            assert r == info["total"] == info["reward"] + info["bonus"] - info["clearance"]
        assert 0.0 <= info["clearance"] <= 4.0
        charged += info["clearance"] > 0
        if term or trunc:
            obs, _ = env.reset()
    assert near > 0 and charged > 0, (near, charged)
    with pytest.raises(ValueError, match="reward.clearance"):
        gym.make("stagerl/Reach-v0", config={"reward": reward})  # no obstacle to keep clear of


def test_obstacle_range_empties_far_slots():
    """task.obstacle_range_m: with the nearest encoding, an obstacle farther than the range
    from the end effector reads as an empty slot (zeros, then the far distance); out of range
    settings are ValueErrors naming the field."""
    far_ball = {"shape": "sphere", "radius_m": 0.05, "position_m": [0.0, 3.0, 0.3]}
    task = {"obstacles": [far_ball], "observe_obstacles": True, "obstacle_observation": "nearest"}
    seen = gym.make("stagerl/Reach-v0", config={"task": task})
    gated = gym.make("stagerl/Reach-v0", config={"task": {**task, "obstacle_range_m": 0.5}})
    o_seen, _ = seen.reset(seed=4)
    o_gated, _ = gated.reset(seed=4)
    np.testing.assert_array_equal(o_seen[:16], o_gated[:16])
    assert o_seen[16:22].any(), o_seen[16:]  # the ball, about 3 m away, 10 x scaled
    np.testing.assert_array_equal(o_gated[16:22], np.zeros(6, dtype=np.float32))
    # An empty slot's distance: farther than any obstacle can be, inside the space.
    assert o_seen[22] < o_gated[22] <= gated.observation_space.high[22], (o_seen[22], o_gated[22])
    assert gated.observation_space.contains(o_gated)
    for bad in [0.0, -1.0]:  # (a NaN is refused before, as any non-finite number in `config`)
        with pytest.raises(ValueError, match="task.obstacle_range_m"):
            gym.make("stagerl/Reach-v0", config={"task": {**task, "obstacle_range_m": bad}})
    with pytest.raises(ValueError, match="task.obstacle_range_m"):
        gym.make("stagerl/Reach-v0", config={"task": {**task, "obstacle_observation": "absolute",
                                                       "obstacle_range_m": 0.5}})


def _in_path_share(fraction, resets=200):
    """Share of resets whose random obstacle's centre (its absolute observation slot) is
    within 18 cm of the straight line from the end effector to the target; every observation
    inside the observation space."""
    config = {"task": {"random_obstacles": {"count": [1, 1]}, "observe_obstacles": True},
              "train": {"obstacles_in_path": fraction}}
    env = gym.make("stagerl/Reach-v0", config=config)
    near = 0
    for seed in range(resets):
        obs, _ = env.reset(seed=seed)
        assert env.observation_space.contains(obs), obs[16:]  # centres stay in the region
        a, b, c = env.unwrapped.ee_position, env.unwrapped.target, obs[16:19].astype(np.float64)
        u = np.clip(np.dot(c - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        near += np.linalg.norm(a + u * (b - a) - c) <= 0.18
    return near / resets


def test_obstacles_in_path_stand_in_the_way():
    """train.obstacles_in_path in an env's config: with 1, the first random obstacle is drawn
    in the way from the end effector to the target; bad values are ValueErrors naming it."""
    never, always = _in_path_share(0.0), _in_path_share(1.0)
    assert never < 0.25 and always > 0.8, (never, always)
    for bad in [1.5, -0.2]:
        with pytest.raises(ValueError, match="train.obstacles_in_path"):
            gym.make("stagerl/Reach-v0", config={"task": {"random_obstacles": {}},
                                                 "train": {"obstacles_in_path": bad}})
    with pytest.raises(ValueError, match="train.obstacles_in_path"):
        gym.make("stagerl/Reach-v0", config={"train": {"obstacles_in_path": 0.5}})


def test_info_holds_every_term_and_the_reward_is_the_chosen_one():
    for reward in ["posture", "stride", "har", "sar", "basic"]:
        env = gym.make("stagerl/Reach-v0", reward=reward)
        _, info = env.reset(seed=3)
        assert set(info) == {"distance", "is_success"} and info["is_success"] is False
        _, r, term, trunc, info = env.step(np.full(6, 0.1, np.float32))
        assert list(info) == TERMS + ["collision", "is_success"]
        assert info["collision"] == 0.0
        assert r == info["total"] == info[reward] + info["bonus"]
        assert info["reward"] == info[reward]
        assert info["is_success"] == bool(info["reached"]) == term


def test_info_reports_a_contact_and_terminate_ends_the_episode_without_success():
    """A sphere around the arm's shoulder: every step ends in contact; with
    task.on_collision = "terminate" that scene is refused (every episode would end at its first
    step). Started below the floor, "terminate" ends the episode at the first step with the
    penalty."""
    ball = {"shape": "sphere", "radius_m": 0.2, "position_m": [0.0, 0.0, 0.3]}
    env = gym.make("stagerl/Reach-v0", config={"task": {"obstacles": [ball]}})
    env.reset(seed=1)
    _, r, term, trunc, info = env.step(np.zeros(6, np.float32))
    assert info["collision"] == 1.0 and not term and not trunc
    with pytest.raises(ValueError, match=r"home pose .* the arm touches \(link `\w+` with obstacle 0\)"):
        gym.make("stagerl/Reach-v0", config={"task": {"obstacles": [ball], "on_collision": "terminate"}})
    low = {"start": [0.0, 0.6, 0.0, 0.0, 0.0, 0.0], "target": [0.4, 0.2, 0.3]}  # the tool below the floor
    env = gym.make("stagerl/Reach-v0")
    env.reset(options=low)
    _, r, term, trunc, info = env.step(np.zeros(6, np.float32))
    assert info["collision"] == 1.0 and not term and not trunc
    stop = gym.make("stagerl/Reach-v0", config={"task": {"on_collision": "terminate"},
                                                 "reward": {"collision_penalty": 5.0}})
    stop.reset(options=low)
    _, r2, term2, _, info2 = stop.step(np.zeros(6, np.float32))
    assert term2 and info2["collision"] == 1.0 and info2["is_success"] is False
    assert r2 == r - 5.0
    with pytest.raises(ValueError, match="reward.collision_penalty"):
        gym.make("stagerl/Reach-v0", config={"reward": {"collision_penalty": 5.0}})


def test_truncated_at_the_step_limit_and_step_after_the_end_is_an_error():
    env = gym.make("stagerl/Reach-v0", config={"task": {"max_steps": 5}})
    env.reset(seed=0)
    flags = [env.step(np.zeros(6, np.float32))[2:4] for _ in range(5)]
    assert flags == [(False, False)] * 4 + [(False, True)]
    with pytest.raises(ValueError, match="reset"):
        env.unwrapped.step(np.zeros(6, np.float32))


def test_terminated_on_success_with_the_bonus():
    # A success radius of 3 m: every target is reached at the first step.
    env = gym.make("stagerl/Reach-v0", config={"reward": {"beta_m": 3.0, "success_bonus": 7.0}})
    env.reset(seed=0)
    _, r, term, trunc, info = env.step(np.zeros(6, np.float32))
    assert term and not trunc and info["is_success"] is True
    assert info["bonus"] == 7.0 and r == info["sar"] + 7.0


def test_config_from_a_toml_file_and_robot_from_a_urdf_path(tmp_path, root):
    path = tmp_path / "c.toml"
    path.write_text("[task]\nmax_steps = 3\n[reward]\nfunction = \"har\"\n")
    env = gym.make("stagerl/Reach-v0", config=str(path), robot=str(root / "assets" / "robots" / "ur5.urdf"))
    env.reset(seed=0)
    steps = 0
    while True:
        _, r, term, trunc, info = env.step(np.zeros(6, np.float32))
        steps += 1
        if term or trunc:
            break
    assert steps == 3 and r == info["har"]
    # The reward argument overrides the file's reward.function.
    env = gym.make("stagerl/Reach-v0", config=path, reward="stride")
    env.reset(seed=0)
    _, r, _, _, info = env.step(np.zeros(6, np.float32))
    assert r == info["stride"]


def test_the_ur5_urdf_file_equals_the_bundled_arm(root):
    a = episodes(5)
    env = gym.make("stagerl/Reach-v0", robot=str(root / "assets" / "robots" / "ur5.urdf"))
    obs, _ = env.reset(seed=5)
    np.testing.assert_array_equal(obs, a[0])


@pytest.mark.parametrize(
    "kwargs, exc, words",
    [
        (dict(reward="fancy"), ValueError, ["reward", "fancy", "sar"]),
        (dict(reward=3), ValueError, ["reward", "3"]),
        (dict(config="/nonexistent/c.toml"), FileNotFoundError, ["config", "/nonexistent/c.toml"]),
        (dict(config={"task": {"max_steps": 0}}), ValueError, ["task.max_steps", "0", ">= 1"]),
        (dict(config={"task": {"dt": 0.1}}), ValueError, ["dt", "dt_s"]),
        (dict(config={"reward": {"beta_m": float("nan")}}), ValueError, ["config"]),
        (dict(config=42), ValueError, ["config", "42"]),
        (dict(robot="/nonexistent/arm.urdf"), FileNotFoundError, ["robot", "/nonexistent/arm.urdf"]),
        (dict(render_mode="human"), ValueError, ["render_mode", "human"]),
    ],
)
def test_bad_arguments(kwargs, exc, words):
    with pytest.raises(exc) as e:
        ReachEnv(**kwargs)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_bad_urdf_is_a_value_error(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text("<robot name='x'><link name='a'/></robot>")
    with pytest.raises(ValueError, match="URDF"):
        ReachEnv(robot=str(path))


def test_bad_actions():
    env = ReachEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action.shape.*\(5,\)"):
        env.step(np.zeros(5, np.float32))
    with pytest.raises(ValueError, match=r"action\[2\]"):
        env.step(np.array([0, 0, np.nan, 0, 0, 0], np.float32))
    assert env.step(np.zeros(6))[3] is False  # float64 actions are converted


@pytest.mark.parametrize("method", ["forkserver", "spawn"])
def test_the_module_prefixed_id_makes_the_env_in_a_fresh_worker(method):
    """SB3's SubprocVecEnv starts its workers with forkserver (else spawn): a fresh interpreter
    that has not imported stagerl. "stagerl:stagerl/Reach-v0" imports it there (and renders);
    the plain id is unknown there, as Gymnasium >= 1.0 loads no plugin entry points (the
    registry holds what the process imported): docs/python.md says to use the prefixed id."""
    import multiprocessing

    from env_worker import make_in_child  # a module that does not import stagerl

    ctx = multiprocessing.get_context(method)
    results = {}
    for env_id in ["stagerl:stagerl/Reach-v0", "stagerl/Reach-v0"]:
        q = ctx.Queue()
        p = ctx.Process(target=make_in_child, args=(env_id, q))
        p.start()
        results[env_id] = q.get(timeout=120)
        p.join(timeout=60)
    obs_shape = (stagerl.ReachEnv().observation_space.shape[0],)
    assert results["stagerl:stagerl/Reach-v0"] == ("ok", obs_shape, (360, 480, 3)), results
    assert results["stagerl/Reach-v0"][0] == "error", results
    assert "NamespaceNotFound: Namespace stagerl not found" in results["stagerl/Reach-v0"][1], results


@pytest.mark.parametrize(
    "target, match",
    [
        ([8.7, 0.0, 0.3], r"out of reach"),
        ([1e308, 0.0, 0.3], r"out of reach"),
        ([0.4, 0.2, -0.05], r"below the floor"),
        ([float("nan"), 0.2, 0.3], r"not finite"),
        ([0.4, 0.2], r"`target` = \[0.4, 0.2\] is invalid: 3 values x, y, z in metres"),
    ],
)
def test_reset_targets_are_checked_as_stagerl_plan_checks_them(target, match):
    """reset(options={"target": ...}) takes the targets `stagerl plan` takes: within the arm's
    reach of its first joint, above the floor, finite (one check in Rust for both)."""
    env = gym.make("stagerl/Reach-v0")
    with pytest.raises(ValueError, match=match):
        env.reset(options={"target": target})
    obs, info = env.reset(options={"target": [0.4, 0.2, 0.3]})
    assert env.observation_space.contains(obs)


def test_the_shield_through_the_config_keeps_random_actions_clear_of_obstacles():
    """``[task.shield]`` in the config dict: 2000 random actions among three random obstacles
    touch nothing shielded (and do unshielded); the dynamic simulation is refused."""
    hits = {}
    for on in (False, True):
        env = ReachEnv(config={"task": {"shield": {"enabled": on}, "random_obstacles": {"count": [3, 3]}}})
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        hits[on] = 0
        for _ in range(2000):
            _, _, term, trunc, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            hits[on] += bool(info["collision"])
            if term or trunc:
                env.reset()
    assert hits[True] == 0 and hits[False] > 0, hits
    with pytest.raises(ValueError, match="task.shield.enabled"):
        ReachEnv(config={"task": {"shield": {"enabled": True}, "sim": "dynamic"}})


def test_the_shield_penalty_is_charged_behind_the_shield():
    """reward.shield_penalty with [task.shield] on: a step's ``shield`` term is the weight times
    the change the shield made to the command (so twice the weight charges twice as much, and no
    weight nothing), taken off ``total``; the penalty changes no motion; refused without the
    shield, naming the field."""
    task = {"obstacles": [{"shape": "sphere", "radius_m": 0.08, "position_m": [0.25, 0.1, 0.45]}],
            "shield": {"enabled": True}}
    envs = [gym.make("stagerl/Reach-v0", config={"task": task, "reward": r})
            for r in ({"shield_penalty": 2.0}, {"shield_penalty": 1.0}, {})]
    rng = np.random.default_rng(5)
    for e in envs:
        e.reset(seed=5)
    charged = 0
    for _ in range(300):
        a = rng.uniform(-1, 1, 6).astype(np.float32)
        (o2, r2, t2, u2, i2), (o1, _, _, _, i1), (o0, _, _, _, i0) = (e.step(a) for e in envs)
        np.testing.assert_array_equal(o2, o1)
        np.testing.assert_array_equal(o2, o0)
        assert i2["shield"] == 2.0 * i1["shield"] >= 0.0 and i0["shield"] == 0.0, (i2, i1, i0)
        assert r2 == i2["total"] == i2["reward"] + i2["bonus"] - i2["shield"]
        charged += i2["shield"] > 0
        if t2 or u2:
            for e in envs:
                e.reset()
    assert charged > 10, charged
    with pytest.raises(ValueError, match="reward.shield_penalty"):
        gym.make("stagerl/Reach-v0", config={"reward": {"shield_penalty": 1.0}})


def test_stagerl_simd_caps_the_level_and_a_bad_value_fails_the_import():
    """STAGERL_SIMD as the command line reads it: the level is reported, a bad value refused."""
    import os
    import subprocess
    import sys
    code = "import stagerl; print(stagerl.SIMD_LEVEL)"
    base = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "STAGERL_SIMD": "baseline"})
    assert base.returncode == 0 and base.stdout.strip() == "baseline", base.stderr
    bad = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "STAGERL_SIMD": "sse9"})
    assert bad.returncode != 0 and "ValueError" in bad.stderr and "STAGERL_SIMD" in bad.stderr, bad.stderr
