#!/usr/bin/env bash
# The obstacle benchmark (issue 32, docs/results/obstacle-benchmark): `stagerl bench obstacles`
# on its five problem sets (200 problems each, seed 0), every planner (Jacobian, Jacobian +
# shield, RRT-Connect, a trained policy and the policy + shield), then OMPL's RRTConnect on the
# same problems (the `ompl` wheel from PyPI, in a venv of its own).
#
#   scripts/studies/obstacle_benchmark.sh OUT [RUN]
#
# RUN: the trained run whose policy is benchmarked (default: the SAC + SAR run of seed 1 trained
# with obstacles in the way, docs/results/quick-obstacles/in-path/runs/sac-sar-seed1). Each set is
# its own process (sets are independent streams: the same problems and plans as one process with
# every set), JOBS at a time (default 2); OUT/<set>/ holds each set's table, problems and plans,
# OUT/ompl.jsonl OMPL's results, and OUT/table.md every planner's (scripts/studies/obstacle_table.py).
# Environment: STAGERL_BIN, PROBLEMS (200), JOBS (2), PYTHON (python3).
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
out=${1:?usage: scripts/studies/obstacle_benchmark.sh OUT [RUN]}
run=${2:-docs/results/quick-obstacles/in-path/runs/sac-sar-seed1}
bin=${STAGERL_BIN:-target/release/stagerl}
problems=${PROBLEMS:-200}
jobs=${JOBS:-2}
[ -x "$bin" ] || cargo build --release --locked -p stagerl-cli
bin=$(realpath "$bin")
mkdir -p "$out"
out=$(cd "$out" && pwd)

sets="free in-the-way random-3 random-6 narrow-gap"
bench_set() {
    local set=$1 dir="$out/$1"
    mkdir -p "$dir"
    [ -f "$dir/table.md" ] && return 0 # done in an earlier call
    "$bin" bench obstacles --problems "$problems" --seed 0 --sets "$set" --run "$root/$run" \
        --problems-out "$dir/problems.jsonl" --out "$dir/plans.jsonl" --force >"$dir/table.md.part"
    mv "$dir/table.md.part" "$dir/table.md"
}
export -f bench_set
export bin out problems root run
printf '%s\n' $sets | xargs -P "$jobs" -I{} bash -c 'bench_set {}'

# OMPL's RRTConnect on the same problems.
venv="$out/ompl-venv"
if [ ! -x "$venv/bin/python" ]; then
    "${PYTHON:-python3}" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet "ompl==2.0.1" numpy ./python
fi
cat $(printf "$out/%s/problems.jsonl " $sets) >"$out/problems.jsonl"
"$venv/bin/python" scripts/bench/ompl_rrt_connect.py "$out/problems.jsonl" --out "$out/ompl.jsonl" \
    >"$out/ompl.md"
# Every planner, OMPL's beside, in one table.
"${PYTHON:-python3}" scripts/studies/obstacle_table.py "$out" >"$out/table.md"
{
    echo "binary: $("$bin" --version) at $(git -C "$root" rev-parse HEAD)"
    echo "run: $run"
    echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
    echo "date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
} >"$out/provenance.txt"
