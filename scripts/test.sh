#!/usr/bin/env bash
# The project's test command: the Rust tests, then the Python package's tests.
#
#   1. cargo test --release --workspace --locked    (also builds target/release/stagerl)
#   2. a venv in target/py-venv, `pip install ./python pytest` (maturin builds the extension
#      crate crates/stagerl-py through pip; gymnasium and numpy come as the package's
#      dependencies), then pytest python/tests against the installed package.
#
# PYTHON picks the interpreter (default python3, >= 3.9). pytest's exit status 5 (no tests
# collected) is a failure like any other.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

start=$SECONDS
cargo test --release --workspace --locked
rust_s=$((SECONDS - start))

python=${PYTHON:-python3}
venv="$root/target/py-venv"
if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
# pip >= 21.3 builds a local directory in place (older pips copy python/ away from crates/).
"$venv/bin/python" -m pip install --quiet "pip>=21.3"
# pip rebuilds and reinstalls a local directory on every call (maturin reuses target/).
"$venv/bin/python" -m pip install --quiet ./python pytest
install_s=$((SECONDS - start - rust_s))
cd "$root"  # not python/: its stagerl/ (without _core) would shadow the installed package
STAGERL_BIN="$root/target/release/stagerl" "$venv/bin/python" -m pytest -q -p no:cacheprovider python/tests
echo "scripts/test.sh: Rust tests ${rust_s} s, Python venv + build + install ${install_s} s," \
    "pytest $((SECONDS - start - rust_s - install_s)) s"
