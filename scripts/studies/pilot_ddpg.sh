#!/usr/bin/env bash
# The DDPG pilot of the paper regime (issue 13.6), in two stages (the rule is in docs/reproducing.md,
# "Paper regime"): presets in configs/studies/pilot-ddpg/, each DDPG on the four dense rewards, seed 1,
# 2000 episodes, 200 evaluation trials.
#   1. hidden 64: learning rate 1e-3 | 3e-4 x Gaussian 0.1 | OU 0.2 noise (four cells);
#   2. hidden 256 with the learning rate and noise of stage 1's best cell.
# Prints one line per cell: the mean success over its four runs for the final checkpoint (the
# paper's protocol; the rule reads this one) and the best checkpoint, with the runs' values.
#
#   scripts/studies/pilot_ddpg.sh OUT [--jobs N]        (resumable: run it again after an interruption)
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:?usage: scripts/studies/pilot_ddpg.sh OUT [--jobs N]}
shift
bin=${STAGERL_BIN:-target/release/stagerl}
[ -x "$bin" ] || cargo build --release --locked -p stagerl-cli

# Success rate (%) of a closing-evaluation file: the mean of its `success` column.
success() { awk -F, 'NR > 1 { s += $4; n++ } END { if (n) printf "%.1f", 100 * s / n; else printf "nan" }' "$1"; }
mean() { printf '%s\n' "$@" | awk '{ s += $1; n++ } END { if (n) printf "%.1f", s / n }'; }
# "mean final | mean best | finals | bests" of a finished cell.
cell_summary() {
    local finals=() bests=() run
    for run in "$1"/*/; do
        [ -f "$run/eval-final-seed0.json" ] || continue
        finals+=("$(success "$run/eval-final-seed0-final-checkpoint.csv")")
        bests+=("$(success "$run/eval-final-seed0.csv")")
    done
    printf '%s|%s|%s|%s\n' "$(mean "${finals[@]}")" "$(mean "${bests[@]}")" "${finals[*]}" "${bests[*]}"
}

best="" best_final=-1
for cell in h64-lr1e-3-gaussian h64-lr1e-3-ou h64-lr3e-4-gaussian h64-lr3e-4-ou; do
    "$bin" reproduce --preset "configs/studies/pilot-ddpg/$cell.toml" --out "$out/$cell" "$@"
    final=$(cell_summary "$out/$cell" | cut -d'|' -f1)
    # Strictly higher wins, so a tie keeps the earlier cell.
    if awk -v a="$final" -v b="$best_final" 'BEGIN { exit !(a > b) }'; then best=$cell best_final=$final; fi
done
wide=h256-${best#h64-}
"$bin" reproduce --preset "configs/studies/pilot-ddpg/$wide.toml" --out "$out/$wide" "$@"

printf '%-22s %-12s %-12s %-26s %s\n' cell "final mean" "best mean" "final per run" "best per run"
for cell in h64-lr1e-3-gaussian h64-lr1e-3-ou h64-lr3e-4-gaussian h64-lr3e-4-ou "$wide"; do
    IFS='|' read -r f b fs bs <<<"$(cell_summary "$out/$cell")"
    printf '%-22s %-12s %-12s %-26s %s\n' "$cell" "$f %" "$b %" "[$fs]" "[$bs]"
done
echo "stage 1 best: $best ($best_final %); stage 2: $wide"
