"""render_mode="rgb_array": offscreen frames of stagerl/Reach-v0, as Gymnasium's RecordVideo and
Stable-Baselines3's make_vec_env and VecVideoRecorder open the environment."""

import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import stagerl  # noqa: F401  (registers the environment)
from stagerl.envs import ReachEnv
from stagerl.vector import ReachVectorEnv

PATH_RGB = (30, 80, 230)  # the end effector's path (crates/stagerl-py/src/render.rs)


def count(frame, predicate):
    r, g, b = (frame[..., k].astype(int) for k in range(3))
    return int(predicate(r, g, b).sum())


def red_target(r, g, b):
    return (r > 120) & (g < 60) & (b < 60)


def path_pixels(frame):
    return int(np.all(frame == PATH_RGB, axis=-1).sum())


def test_frames_have_the_shape_and_show_the_arm_the_target_and_the_path():
    env = gym.make("stagerl/Reach-v0", render_mode="rgb_array")
    assert env.unwrapped.metadata["render_modes"] == ["rgb_array"]
    assert env.unwrapped.metadata["render_fps"] == pytest.approx(20.0)  # 1 / dt_s
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (360, 480, 3) and first.dtype == np.uint8
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 50  # shaded solids, floor, sky: not blank
    assert count(first, red_target) > 20  # the target (not yet reached)
    assert path_pixels(first) == 0  # one point: no segment yet
    for _ in range(5):
        env.step(np.full(6, 0.8, np.float32))
    moved = env.render()
    changed = np.any(moved != first, axis=-1).mean()
    assert changed > 0.01, changed  # the arm moved
    assert path_pixels(moved) > 20  # the path so far
    assert env.render() is not moved and np.array_equal(env.render(), moved)  # a new array, same frame
    # The path starts again with the next episode.
    env.reset(seed=1)
    assert path_pixels(env.render()) == 0


def test_frame_size_obstacles_and_contact_are_drawn():
    ball = {"shape": "sphere", "radius_m": 0.2, "position_m": [0.0, 0.0, 0.3]}  # around the shoulder
    box = {"shape": "cuboid", "half_extents_m": [0.05, 0.1, 0.08], "position_m": [0.3, 0.3, 0.2],
           "rotation_xyzw": [0.0, 0.0, 0.38268343, 0.92387953]}
    plain = gym.make("stagerl/Reach-v0", render_mode="rgb_array", render_width=160, render_height=120)
    scene = gym.make("stagerl/Reach-v0", render_mode="rgb_array", render_width=160, render_height=120,
                     config={"task": {"obstacles": [ball, box]}})
    plain.reset(seed=2)
    scene.reset(seed=2)
    a, b = plain.render(), scene.render()
    assert a.shape == b.shape == (120, 160, 3)

    def orange(r, g, b):
        return (r > 150) & (g > 70) & (g < 170) & (b < 60)

    assert count(a, orange) == 0 and count(b, orange) > 200
    # An arm in contact (with the ball around its shoulder, or the floor) is drawn red.
    def contact_red(r, g, b):
        return (r > 150) & (g > 40) & (g < 110) & (b < 100)

    _, _, _, _, info = scene.step(np.zeros(6, np.float32))
    assert info["collision"] == 1.0
    floor = gym.make("stagerl/Reach-v0", render_mode="rgb_array", render_width=160, render_height=120)
    floor.reset(options={"start": [0.0, 0.6, 0.0, 0.0, 0.0, 0.0], "target": [0.4, 0.2, 0.3]})  # tool below the floor
    assert floor.step(np.zeros(6, np.float32))[4]["collision"] == 1.0
    free = count(a, contact_red)
    assert count(scene.render(), contact_red) > free + 100 and count(floor.render(), contact_red) > free + 100


def run(render_mode, seed=4, episodes=3):
    env = gym.make("stagerl/Reach-v0", render_mode=render_mode)
    rng = np.random.default_rng(0)
    out = []
    obs, info = env.reset(seed=seed)
    for _ in range(episodes):
        out.append((obs, info))
        while True:
            if render_mode:
                env.render()
            obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            out.append((obs, r, term, trunc, info))
            if term or trunc:
                break
        obs, info = env.reset()
    return out


def test_rendering_does_not_change_the_results():
    a, b = run(None), run("rgb_array")
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert gym.utils.env_checker.data_equivalence(x, y, exact=True)


def test_check_env_with_its_render_check():
    env = gym.make("stagerl/Reach-v0", render_mode="rgb_array", render_width=64, render_height=48)
    check_env(env.unwrapped)  # also makes it with each render mode it declares


def test_the_vector_env_renders_each_sub_environment_and_its_results_do_not_change():
    envs = gym.make_vec("stagerl/Reach-v0", num_envs=3, vectorization_mode="vector_entry_point",
                        render_mode="rgb_array", render_width=96, render_height=64)
    plain = ReachVectorEnv(num_envs=3)
    assert envs.metadata["render_modes"] == ["rgb_array"] and envs.render_mode == "rgb_array"
    rng = np.random.default_rng(5)
    ra, rb = envs.reset(seed=7), plain.reset(seed=7)
    assert gym.utils.env_checker.data_equivalence(ra, rb, exact=True)
    frames = envs.render()
    assert isinstance(frames, tuple) and len(frames) == 3
    assert all(f.shape == (64, 96, 3) and f.dtype == np.uint8 for f in frames)
    assert not np.array_equal(frames[0], frames[1])  # different targets
    for _ in range(120):  # past the 50-step episodes: autoresets restart each path
        actions = rng.uniform(-1, 1, (3, 6)).astype(np.float32)
        sa, sb = envs.step(actions), plain.step(actions)
        assert gym.utils.env_checker.data_equivalence(sa, sb, exact=True)
        later = envs.render()
    assert any(not np.array_equal(x, y) for x, y in zip(frames, later))
    with pytest.warns(UserWarning, match="render_mode='rgb_array'"):
        assert plain.render() is None


def test_the_make_vec_env_call_pattern_of_stable_baselines3():
    """SB3's make_vec_env("stagerl/Reach-v0", n_envs=4) calls gym.make(id, render_mode="rgb_array")
    for each of its 4 environments (its default render mode) and VecVideoRecorder calls render()
    on each; Stable-Baselines3 itself (with torch) is too heavy for the test install."""
    envs = [gym.make("stagerl/Reach-v0", render_mode="rgb_array") for _ in range(4)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
        env.step(env.action_space.sample())
    frames = [env.render() for env in envs]
    assert all(f.shape == (360, 480, 3) and f.dtype == np.uint8 for f in frames)
    assert len({f.tobytes() for f in frames}) == 4


def test_record_video_writes_a_video_file(tmp_path):
    import moviepy  # noqa: F401  (installed by scripts/test.sh: its absence is a failure)

    from gymnasium.wrappers import RecordVideo

    folder = tmp_path / "videos"
    env = RecordVideo(gym.make("stagerl/Reach-v0", render_mode="rgb_array", render_width=160, render_height=120),
                      str(folder), episode_trigger=lambda e: True, disable_logger=True)
    env.reset(seed=0)
    steps = 0
    while True:
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        steps += 1
        if term or trunc:
            break
    env.close()
    files = sorted(os.listdir(folder))
    assert files == ["rl-video-episode-0.mp4"], files
    assert os.path.getsize(folder / files[0]) > 1000 and steps == 50


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(render_mode="human"), r"`render_mode` = 'human' is invalid: None or 'rgb_array'"),
        (dict(render_mode="rgb_array", render_width=8), r"`render_width` = 8 is invalid: an integer from 16 to 4096"),
        (dict(render_mode="rgb_array", render_height=5000), r"`render_height` = 5000 is invalid: an integer from 16 to 4096"),
        (dict(render_mode="rgb_array", render_width=True), r"`render_width` = True is invalid"),
        (dict(render_mode="rgb_array", render_height=2.5), r"`render_height` = 2.5 is invalid"),
        (dict(render_width=320), r"`render_width` = 320 is invalid without a render mode"),
    ],
)
def test_bad_render_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ReachEnv(**kwargs)
    with pytest.raises(ValueError, match=match):
        ReachVectorEnv(num_envs=2, **kwargs)


def test_gymnasium_builds_the_other_modes_on_rgb_array():
    """gym.make wraps an rgb_array env for "rgb_array_list" (RenderCollection: the frames since
    the last render) and "human" (HumanRendering, a pygame window; not opened here)."""
    from gymnasium.wrappers import HumanRendering, RenderCollection

    env = gym.make("stagerl/Reach-v0", render_mode="rgb_array_list", render_width=64, render_height=48)
    assert isinstance(env, RenderCollection)
    env.reset(seed=0)
    env.step(np.zeros(6, np.float32))
    frames = env.render()
    assert len(frames) == 2 and all(f.shape == (48, 64, 3) for f in frames)
    with pytest.warns(UserWarning, match="HumanRendering"):
        assert isinstance(gym.make("stagerl/Reach-v0", render_mode="human"), HumanRendering)


def test_render_without_a_render_mode_warns_and_returns_none():
    env = ReachEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode='rgb_array'"):
        assert env.render() is None
