"""Shared fixtures: the repository root and the `stagerl` binary built by cargo."""

import os
import subprocess
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def stagerl_bin() -> str:
    """The CLI built by `cargo test --release --workspace` (or STAGERL_BIN); missing is a failure."""
    path = os.environ.get("STAGERL_BIN") or str(ROOT / "target" / "release" / "stagerl")
    assert os.path.isfile(path), f"the stagerl binary {path} is missing: run `cargo build --release` or set STAGERL_BIN"
    return path


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    return ROOT


# A tiny SAC run (16 x 16 networks, 30 episodes of 50 steps): trained in well under a second.
TINY_RUN_CONFIG = """
[agent]
algo = "sac"
hidden = [16, 16]
batch_size = 32
learning_starts = 200

[train]
seed = 3
episodes = 30
eval_every_episodes = 15
eval_trials = 5
checkpoint_every_episodes = 15
"""


@pytest.fixture(scope="session")
def trained_run(stagerl_bin, tmp_path_factory) -> pathlib.Path:
    """A run directory trained once per session by `stagerl train` (the release binary)."""
    base = tmp_path_factory.mktemp("trained")
    config = base / "config.toml"
    config.write_text(TINY_RUN_CONFIG)
    run = base / "run"
    done = subprocess.run([stagerl_bin, "train", "--config", str(config), "--out", str(run), "--eval-trials", "0"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (run / "checkpoints" / "best.safetensors").is_file()
    return run
