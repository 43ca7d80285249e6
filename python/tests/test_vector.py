"""The native vector env (stagerl.vector.ReachVectorEnv): make_vec, next-step autoreset, seeding,
and value-for-value equality with Gymnasium's SyncVectorEnv over single ReachEnvs."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import stagerl
from stagerl.envs import ReachEnv
from stagerl.vector import SEED_BLOCK, STEP_KEYS, ReachVectorEnv

# Short episodes that often end either way: truncated after 4 steps, terminated within 0.35 m.
SHORT = {"task": {"max_steps": 4}, "reward": {"beta_m": 0.35}}


def make_vec(n, **kwargs):
    return gym.make_vec("stagerl/Reach-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


def sync_vec(n, **kwargs):
    return SyncVectorEnv([lambda: ReachEnv(**kwargs) for _ in range(n)], autoreset_mode=AutoresetMode.NEXT_STEP)


def test_make_vec_returns_the_native_vector_env():
    envs = make_vec(3, reward="har")
    assert isinstance(envs, ReachVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.num_envs == 3
    assert envs.observation_space.shape == (3, 16) and envs.observation_space.dtype == np.float32
    assert envs.action_space.shape == (3, 6) and envs.action_space.dtype == np.float32
    assert envs.single_observation_space == ReachEnv().observation_space
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, 16) and obs.dtype == np.float32
    assert set(info) == {"distance", "_distance", "is_success", "_is_success"}


def test_equals_sync_vector_env_of_single_envs_value_for_value():
    """Same seeds, same actions: every observation, reward, flag and info array is equal, over
    enough autoresets to use several seed blocks, a reset without a seed and a reseed."""
    n = 4
    native, sync = make_vec(n, config=SHORT), sync_vec(n, config=SHORT)
    rng = np.random.default_rng(7)
    ends = {"terminated": 0, "truncated": 0}
    for seed in (3, None, [5, None, 9, 2]):
        assert data_equivalence(native.reset(seed=seed), sync.reset(seed=seed), exact=True)
        for _ in range(2 * SEED_BLOCK * 5 // 2):
            actions = rng.uniform(-1, 1, (n, 6)).astype(np.float32)
            a, b = native.step(actions), sync.step(actions)
            assert data_equivalence(a, b, exact=True), (a, b)
            ends["terminated"] += int(a[2].sum())
            ends["truncated"] += int(a[3].sum())
    # Each sub-env went through more than one block of episode seeds, ending both ways.
    assert ends["terminated"] > 50 and ends["truncated"] > 3 * SEED_BLOCK, ends


def test_threads_give_the_same_values():
    """40 sub-environments among random obstacles stepped on 2 threads (``make_vec(...,
    threads=2)``) and on one: every array equal, over enough steps for many autoresets."""
    n = 40
    cfg = {**SHORT, "task": {**SHORT["task"], "random_obstacles": {"count": [1, 2]}, "observe_obstacles": True}}
    one = make_vec(n, config=cfg)
    two = make_vec(n, config=cfg, threads=2)
    assert two.unwrapped._core is not None and two.num_envs == n
    rng = np.random.default_rng(3)
    assert data_equivalence(one.reset(seed=11), two.reset(seed=11), exact=True)
    ends = 0
    for _ in range(60):
        actions = rng.uniform(-1, 1, (n, 6)).astype(np.float32)
        a, b = one.step(actions), two.step(actions)
        assert data_equivalence(a, b, exact=True)
        ends += int(a[2].sum() + a[3].sum())
    assert ends > n, ends


def test_next_step_autoreset():
    n = 3
    envs = make_vec(n, config=SHORT)
    obs, info = envs.reset(seed=1)
    home, k = obs[0, :6].copy(), obs[0, 15] / info["distance"][0]  # q / pi at home; obs_delta_scale
    rng = np.random.default_rng(2)
    checked = 0
    for _ in range(200):
        obs, reward, term, trunc, info = envs.step(rng.uniform(-1, 1, (n, 6)).astype(np.float32))
        ended = term | trunc
        if not ended.any():
            continue
        # The ended episodes' last observations: their distance is the step's distance.
        np.testing.assert_allclose(obs[ended, 15] / k, info["distance"][ended], rtol=1e-6)
        np.testing.assert_array_equal(info["is_success"][ended], term[ended])
        # The next step resets them whatever the action: reward 0, not ended, a new target, and
        # only distance and is_success in their info.
        before = obs.copy()
        obs2, reward2, term2, trunc2, info2 = envs.step(np.ones((n, 6), np.float32))
        assert np.all(reward2[ended] == 0.0) and not term2[ended].any() and not trunc2[ended].any()
        assert np.all(np.any(obs2[ended, 9:12] != before[ended, 9:12], axis=1)), "a new target"
        assert np.all(obs2[ended, :6] == home), "a new episode starts at the home pose"
        if (~ended).any():
            assert not info2["_reward"][ended].any() and info2["_reward"][~ended].all()
            assert np.all(info2["reward"][ended] == 0.0)
        else:
            assert "reward" not in info2
        assert info2["_distance"].all() and info2["_is_success"].all()
        np.testing.assert_allclose(obs2[ended, 15] / k, info2["distance"][ended], rtol=1e-6)
        obs = obs2
        checked += 1
    assert checked >= 20


def test_reset_step_ignores_the_action():
    results = []
    for push in (-1.0, 1.0):
        envs = make_vec(2, config={"task": {"max_steps": 2}})
        envs.reset(seed=4)
        zeros = np.zeros((2, 6), np.float32)
        envs.step(zeros)
        _, _, _, trunc, _ = envs.step(zeros)
        assert trunc.all()
        results.append(envs.step(np.full((2, 6), push, np.float32)))
    assert data_equivalence(results[0], results[1], exact=True)


def test_same_seed_same_episodes_and_sub_envs_differ():
    def run(seed):
        envs = make_vec(3, config=SHORT)
        rng = np.random.default_rng(0)
        out = [envs.reset(seed=seed)]
        out += [envs.step(rng.uniform(-1, 1, (3, 6)).astype(np.float32)) for _ in range(100)]
        return out

    a, b, c = run(11), run(11), run(12)
    assert data_equivalence(a, b, exact=True)
    assert not data_equivalence(a, c)
    obs = a[0][0]
    assert not np.array_equal(obs[0, 6:12], obs[1, 6:12]), "sub-environments draw their own targets"
    # Sub-env i of reset(seed=s) starts as a single ReachEnv reset with seed s + i.
    single, _ = ReachEnv(config=SHORT).reset(seed=12)
    np.testing.assert_array_equal(obs[1], single)


def test_info_holds_every_term_and_observations_stay_in_the_space():
    envs = make_vec(8)
    envs.reset(seed=0)
    space = envs.single_observation_space
    rng = np.random.default_rng(3)
    full = 0
    for _ in range(300):
        obs, reward, _, _, info = envs.step(np.sign(rng.uniform(-1, 1, (8, 6))).astype(np.float32))
        assert all(space.contains(o) for o in obs)
        assert info["is_success"].dtype == bool and info["distance"].dtype == np.float64
        if "_total" not in info:  # every sub-env was reset in this step
            assert set(info) == {"distance", "_distance", "is_success", "_is_success"} and np.all(reward == 0)
            continue
        stepped = info["_total"]
        np.testing.assert_array_equal(reward[stepped], info["total"][stepped])
        assert set(STEP_KEYS) <= set(info) and {"_" + k for k in STEP_KEYS} <= set(info)
        full += 1
    assert full > 250


def test_native_speed_measurement_steps_a_copy():
    envs, twin = ReachVectorEnv(num_envs=4, config=SHORT), ReachVectorEnv(num_envs=4, config=SHORT)
    envs.reset(seed=0)
    twin.reset(seed=0)
    actions = np.random.default_rng(1).uniform(-1, 1, (3, 4, 6)).astype(np.float32)
    assert envs._core.time_native_steps(actions, 10) > 0.0
    # The batch itself was not stepped.
    assert data_equivalence(envs.step(actions[0]), twin.step(actions[0]), exact=True)
    with pytest.raises(ValueError, match=r"actions.shape.*\(K, 4, 6\)"):
        envs._core.time_native_steps(np.zeros((3, 5, 6), np.float32), 10)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"num_envs": 0}, r"`num_envs` = 0 is invalid: an integer >= 1"),
        # Refused before anything is allocated for them (it used to abort the interpreter).
        ({"num_envs": 10_000_000}, r"`num_envs` = 10000000 is invalid: an integer from 1 to 65536"),
        ({"num_envs": 2.5}, r"`num_envs` = 2.5 is invalid"),
        ({"num_envs": 2, "reward": "fast"}, r"`reward` = \"fast\" is invalid: one of"),
        ({"num_envs": 2, "render_mode": "human"}, r"`render_mode` = 'human' is invalid"),
        ({"num_envs": 2, "config": {"task": {"max_steps": 0}}}, r"max_steps"),
        ({"num_envs": 2, "threads": 0}, r"`threads` = 0 is invalid: an integer from 1 to 64"),
        ({"num_envs": 2, "threads": 65}, r"`threads` = 65 is invalid"),
        ({"num_envs": 2, "threads": 1.5}, r"`threads` = 1.5 is invalid"),
    ],
)
def test_bad_constructor_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ReachVectorEnv(**kwargs)


def test_bad_step_and_reset_arguments():
    envs = ReachVectorEnv(num_envs=2)
    with pytest.raises(ValueError, match="before `reset`"):
        envs.step(np.zeros((2, 6), np.float32))
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"`actions.shape` = \(2, 5\) is invalid: expected \(2, 6\)"):
        envs.step(np.zeros((2, 5), np.float32))
    bad = np.zeros((2, 6), np.float32)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match=r"environment 1, joint 2\) = NaN is not finite"):
        envs.step(bad)
    with pytest.raises(ValueError, match=r"`seed` = \[1, 2, 3\] is invalid: .*a list of 2"):
        envs.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="`options`"):
        envs.reset(options={"target": [0.3, 0.0, 0.3]})
    # The env still works after refused calls.
    obs, *_ = envs.step(np.zeros((2, 6), np.float32))
    assert obs.shape == (2, 16)
    assert stagerl.ReachVectorEnv is ReachVectorEnv


# Random obstacles observed: the scene given to reset shows in the observations.
SCENE_CFG = {"task": {"max_steps": 6, "observe_obstacles": True, "random_obstacles": {"count": [1, 2]}},
             "reward": {"beta_m": 0.35}}
SCENE = [{"shape": "sphere", "radius_m": 0.08, "position_m": [0.35, 0.1, 0.45]},
         {"shape": "cuboid", "half_extents_m": [0.05, 0.2, 0.05], "position_m": [-0.3, 0.3, 0.5],
          "rotation_xyzw": [0.0, 0.0, 0.3826834, 0.9238795]},
         {"shape": "sphere", "radius_m": 0.05, "position_m": [0.0, -0.5, 0.7]}]


def test_obstacles_in_reset_equal_sync_vector_env_value_for_value():
    """reset(options={"obstacles": ...}) puts every sub-environment's episode among the scene and
    its autoresets back among the task's random obstacles, exactly as SyncVectorEnv over
    ReachEnvs does; a reset without options drops the scene."""
    n = 3
    native, sync = make_vec(n, config=SCENE_CFG), sync_vec(n, config=SCENE_CFG)
    rng = np.random.default_rng(5)
    plain = make_vec(n, config=SCENE_CFG).reset(seed=11)[0]
    for seed, options in ((11, {"obstacles": SCENE}), (12, None), (13, {"obstacles": SCENE[:1]})):
        a, b = native.reset(seed=seed, options=options), sync.reset(seed=seed, options=options)
        assert data_equivalence(a, b, exact=True), (a, b)
        if seed == 11:
            # Same seeds, same targets: only the scene differs, and the observation shows it.
            assert not np.array_equal(a[0], plain), "the scene is in the observations"
        for _ in range(40):
            actions = rng.uniform(-1, 1, (n, 6)).astype(np.float32)
            a, b = native.step(actions), sync.step(actions)
            assert data_equivalence(a, b, exact=True), (a, b)


def test_bad_obstacles_in_reset_get_reach_env_messages():
    envs = ReachVectorEnv(num_envs=2)
    single = ReachEnv()
    bad = [{"shape": "sphere", "radius_m": -0.1, "position_m": [0.3, 0.3, 0.3]}]
    on_start = [{"shape": "cuboid", "half_extents_m": [0.1, 0.1, 0.1], "position_m": [0.0, 0.0, 0.1]}]
    for obstacles, want in ((bad, r"`obstacles\[0\].radius_m` = -0.1"), (on_start, "start pose")):
        with pytest.raises(ValueError, match=want) as native:
            envs.reset(seed=0, options={"obstacles": obstacles})
        with pytest.raises(ValueError) as one:
            single.reset(seed=0, options={"obstacles": obstacles})
        assert str(native.value) == str(one.value)
    with pytest.raises(ValueError, match="`options`.*`obstacles`"):
        envs.reset(options={"obstacles": [], "start": [0.0] * 6})
    obs, _ = envs.reset(seed=0, options={"obstacles": []})
    assert obs.shape == (2, 16)
