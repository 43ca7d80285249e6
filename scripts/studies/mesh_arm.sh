#!/usr/bin/env bash
# A mesh arm beyond the bundled two, trained from the config `stagerl robot --config-out` writes
# (issue 33): the KUKA iiwa of pybullet_data (kuka_iiwa/model.urdf, 8 links with binary STL
# collision meshes), SAC + SAR, seed 1, 15 000 episodes, then the closing evaluation on 500 targets.
# The URDF comes out of the pybullet wheel on PyPI (downloaded, not installed: nothing is built).
#
#   scripts/studies/mesh_arm.sh OUT        (OUT/run is the run; --resume after an interruption)
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:?usage: scripts/studies/mesh_arm.sh OUT}
bin=${STAGERL_BIN:-target/release/stagerl}
[ -x "$bin" ] || cargo build --release --locked -p stagerl-cli
mkdir -p "$out"
out=$(cd "$out" && pwd)
if [ ! -f "$out/pybullet_data/kuka_iiwa/model.urdf" ]; then
    python3 -m pip download --quiet --no-deps --only-binary=:all: "pybullet==3.2.7" -d "$out/wheel"
    python3 -m zipfile -e "$out"/wheel/pybullet-3.2.7-*.whl "$out/wheel/x"
    mkdir -p "$out/pybullet_data"
    cp -r "$out/wheel/x/pybullet_data/kuka_iiwa" "$out/pybullet_data/"
    rm -rf "$out/wheel"
fi
"$bin" robot "$out/pybullet_data/kuka_iiwa/model.urdf" --config-out "$out/iiwa.toml"
if [ -f "$out/run/config.toml" ]; then
    "$bin" train --resume "$out/run"
else
    "$bin" train --config "$out/iiwa.toml" --algo sac --reward sar --seed 1 --episodes 15000 --out "$out/run"
fi
