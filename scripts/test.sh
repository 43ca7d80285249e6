#!/usr/bin/env bash
# The project's test command: the Rust tests, then the Python package's tests.
#
#   0. the headless browser of the view's test (crates/stagerl-cli/tests/it/view_browser.rs):
#      Debian's chromium, installed with apt-get when `chromium` is not on PATH (47 s
#      with apt-get update, measured on a machine of this class without it; set CHROMIUM to use
#      another binary). Without it that test fails: it does not skip.
#   1. cargo test --release --workspace --locked    (also builds target/release/stagerl)
#   2. a venv in target/py-venv, `pip install ./python pytest onnxruntime onnx optuna moviepy
#      "ray[tune]"`
#      (maturin builds the extension crate crates/stagerl-py through pip; gymnasium and numpy come
#      as the package's dependencies; onnxruntime and onnx are the independent ONNX runtime and
#      checker of python/tests/test_onnx.py, about 10 s to install; optuna runs the example
#      python/examples/optuna_tune.py in python/tests/test_examples.py, about 3 s; moviepy is
#      what Gymnasium's RecordVideo writes videos with, in python/tests/test_render.py, about
#      7 s with its imageio-ffmpeg; ray[tune] runs python/examples/ray_tune.py in
#      test_examples.py, 28-34 s to install, about 14 s to run), then pytest python/tests
#      against the installed package.
#
# PYTHON picks the interpreter (default python3, >= 3.9). pytest's exit status 5 (no tests
# collected) is a failure like any other.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

start=$SECONDS
if [ -z "${CHROMIUM:-}" ] && ! command -v chromium >/dev/null 2>&1; then
    echo "scripts/test.sh: installing chromium (apt-get) for the view's browser test"
    if [ "$(id -u)" -eq 0 ]; then sudo=""; else sudo="sudo"; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq chromium >/dev/null
fi
browser_s=$((SECONDS - start))
cargo test --release --workspace --locked
rust_s=$((SECONDS - start - browser_s))

python=${PYTHON:-python3}
venv="$root/target/py-venv"
if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
# pip >= 21.3 builds a local directory in place (older pips copy python/ away from crates/).
"$venv/bin/python" -m pip install --quiet "pip>=21.3"
# pip rebuilds and reinstalls a local directory on every call (maturin reuses target/).
"$venv/bin/python" -m pip install --quiet ./python pytest onnxruntime onnx optuna moviepy "ray[tune]"
install_s=$((SECONDS - start - browser_s - rust_s))
cd "$root"  # not python/: its stagerl/ (without _core) would shadow the installed package
STAGERL_BIN="$root/target/release/stagerl" "$venv/bin/python" -m pytest -q -p no:cacheprovider python/tests
echo "scripts/test.sh: browser install ${browser_s} s, Rust tests ${rust_s} s," \
    "Python venv + build + install ${install_s} s, pytest $((SECONDS - start - browser_s - rust_s - install_s)) s"
