#!/usr/bin/env bash
# Issue 10's comparison, in one run on one machine: stagerl's update and end-to-end training
# against PyTorch (the same updates, scripts/bench/bench_pytorch.py) and Stable-Baselines3 (its
# training loop on stagerl/Reach-v0, scripts/bench/bench_sb3.py), one thread each, then the ratios.
#
#   scripts/bench/bench_vs_python.sh VENV [TRAIN_STEPS]
#
# VENV: a virtualenv with torch, stable-baselines3 and this project's package (`pip install
# ./python`). TRAIN_STEPS (default 6000): environment steps of each end-to-end run, the first
# 1000 random in both. stagerl's end-to-end runs are timed on one thread and on two (`--threads 2`,
# the same bits); SB3 on one torch thread, which is faster for it than two. Not part of the tests: torch is heavy and timings are not assertions.
set -euo pipefail
cd "$(dirname "$0")/../.."
venv=${1:?usage: scripts/bench/bench_vs_python.sh VENV [TRAIN_STEPS]}
steps=${2:-6000}
bin=${STAGERL_BIN:-target/release/stagerl}
py="$venv/bin/python"
json() { tail -n 1 | sed -E "s/.*\"$1\": *([0-9.]+).*/\1/"; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", a / b }'; }

echo "| update, batch 256, one thread | stagerl ms | PyTorch ms | ratio |"
echo "|---|---|---|---|"
for algo in sac td3 ddpg; do
    for h in 64 256; do
        ours=$("$bin" bench update --algo "$algo" --hidden "$h" --updates 500 | json ms_per_update)
        torch=$("$py" scripts/bench/bench_pytorch.py --algo "$algo" --hidden "$h" --updates 300 | json ms_per_update)
        echo "| $algo hidden $h | $ours | $torch | $(ratio "$torch" "$ours") |"
    done
done
echo
echo "| training end to end, hidden 64, $steps env steps | stagerl steps/s | stagerl --threads 2 | SB3 steps/s (one torch thread, its best) | ratio | ratio, 2 threads |"
echo "|---|---|---|---|---|---|"
for algo in sac td3 ddpg; do
    ours=$("$bin" bench train --algo "$algo" --steps "$steps" | json steps_per_sec)
    two=$("$bin" bench train --algo "$algo" --steps "$steps" --threads 2 | json steps_per_sec)
    sb3=$("$py" scripts/bench/bench_sb3.py --algo "$algo" --steps $((steps - 1000)) | json steps_per_sec)
    echo "| $algo | $ours | $two | $sb3 | $(ratio "$ours" "$sb3") | $(ratio "$two" "$sb3") |"
done
