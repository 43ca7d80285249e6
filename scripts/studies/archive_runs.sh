#!/usr/bin/env bash
# Copy the finished runs of a sweep directory (`stagerl reproduce --out SRC`) into DEST, small:
# each run's config.toml, CSVs and closing-evaluation record, without its resumable checkpoint
# (checkpoints/latest.safetensors holds the replay buffer: about 80 MB for a 10 000-episode
# run) and its TensorBoard events; the best and final checkpoints are kept for the seed-1 run of
# each (algorithm, reward), the one `stagerl report` rolls out for its trajectory figures and
# views. The sweep's preset.toml and provenance.json come along.
#
# An archived run counts as done for `stagerl reproduce` (nothing trains or evaluates it
# again) and `stagerl report` reads it as it reads the full run. A run is finished when its
# closing evaluation's record (eval-final-seed<S>.json) exists; runs still under way are left
# out. Runs already in DEST are not copied again. So a long sweep goes on across machines:
#
#   scripts/studies/archive_runs.sh /work/runs/paper /work/keep/paper   # keep what finished
#   scripts/studies/archive_runs.sh /work/keep/paper /work/runs/paper   # on a new machine
#   stagerl reproduce --preset paper --out /work/runs/paper            # the rest
#
# What goes under docs/results/ is the archive scripts/studies/pack_runs.py makes of such a
# folder (runs.tar.xz; docs/results/README.md, "How results are kept").
set -euo pipefail
if [ $# -ne 2 ]; then
    echo "usage: $0 SRC DEST" >&2
    exit 2
fi
src=$1 dest=$2
if [ ! -d "$src" ]; then
    echo "$0: $src is not a directory" >&2
    exit 2
fi
mkdir -p "$dest"
for f in preset.toml provenance.json; do
    if [ -f "$src/$f" ]; then cp -p "$src/$f" "$dest/$f"; fi
done
copied=0 kept=0 skipped=0
for run in "$src"/*/; do
    run=${run%/}
    name=$(basename "$run")
    ls "$run"/eval-final-seed*.json >/dev/null 2>&1 || { skipped=$((skipped + 1)); continue; }
    if ls "$dest/$name"/eval-final-seed*.json >/dev/null 2>&1; then
        kept=$((kept + 1))
        continue
    fi
    tmp="$dest/.$name.partial"
    rm -rf "$tmp"
    mkdir -p "$tmp"
    for f in "$run"/*.toml "$run"/*.csv "$run"/*.json; do
        if [ -f "$f" ]; then cp -p "$f" "$tmp/"; fi
    done
    case $name in
    *-seed1)
        mkdir -p "$tmp/checkpoints"
        for c in best final; do
            if [ -f "$run/checkpoints/$c.safetensors" ]; then
                cp -p "$run/checkpoints/$c.safetensors" "$tmp/checkpoints/"
            fi
        done
        ;;
    esac
    rm -rf "${dest:?}/$name"
    mv "$tmp" "$dest/$name"
    copied=$((copied + 1))
done
echo "$0: $copied runs copied to $dest, $kept already there, $skipped not finished (left out)"
