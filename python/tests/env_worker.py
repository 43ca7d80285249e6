"""A worker for test_env's process-pool test: it imports Gymnasium only, never stagerl, as a
forkserver or spawn worker of Stable-Baselines3's SubprocVecEnv does."""


def make_in_child(env_id, queue):
    """Make ``env_id`` with ``render_mode="rgb_array"`` (as SB3's make_vec_env does), reset it
    and render a frame; put ("ok", observation shape, frame shape) or ("error", message)."""
    try:
        import gymnasium as gym

        env = gym.make(env_id, render_mode="rgb_array")
        obs, _ = env.reset(seed=0)
        queue.put(("ok", obs.shape, env.render().shape))
    except Exception as e:  # the plain id is unknown in a fresh interpreter
        queue.put(("error", f"{type(e).__name__}: {e}"))
