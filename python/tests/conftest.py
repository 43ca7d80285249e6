"""Shared fixtures: the repository root and the `stagerl` binary built by cargo."""

import os
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
