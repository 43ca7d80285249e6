#!/usr/bin/env bash
# The DDPG pilot of the paper regime (issue 13.6): the eight presets of configs/pilot-ddpg/
# (hidden 64|256 x learning rate 1e-3|3e-4 x Gaussian 0.1|OU 0.2 noise; the four dense rewards,
# seed 1, 2000 episodes, 200 evaluation trials each), then one line per cell with the mean
# success over its four runs, for the final checkpoint (the paper's protocol) and the best one.
#
#   scripts/pilot_ddpg.sh OUT [--jobs N]        (resumable: run it again after an interruption)
#
# The rule that picks the paper regime's DDPG settings from it is in the README ("Paper regime").
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/pilot_ddpg.sh OUT [--jobs N]}
shift
bin=${STAGERL_BIN:-target/release/stagerl}
[ -x "$bin" ] || cargo build --release --locked -p stagerl-cli
for preset in configs/pilot-ddpg/*.toml; do
    cell=$(basename "$preset" .toml)
    "$bin" reproduce --preset "$preset" --out "$out/$cell" "$@"
done
# Success rate (%) of a closing-evaluation file: the mean of its `success` column.
success() { awk -F, 'NR > 1 { s += $4; n++ } END { if (n) printf "%.1f", 100 * s / n; else printf "nan" }' "$1"; }
printf '%-24s %-34s %-34s\n' cell "final checkpoint: mean [per run]" "best checkpoint: mean [per run]"
for dir in "$out"/*/; do
    cell=$(basename "$dir")
    finals=() bests=()
    for run in "$dir"*/; do
        [ -f "$run/eval-final-seed0.json" ] || continue
        finals+=("$(success "$run/eval-final-seed0-final-checkpoint.csv")")
        bests+=("$(success "$run/eval-final-seed0.csv")")
    done
    mean() { printf '%s\n' "$@" | awk '{ s += $1; n++ } END { if (n) printf "%.1f", s / n }'; }
    printf '%-24s %-34s %-34s\n' "$cell" "$(mean "${finals[@]}") [${finals[*]}]" "$(mean "${bests[@]}") [${bests[*]}]"
done
