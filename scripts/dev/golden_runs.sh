#!/usr/bin/env bash
# Behaviour check for refactors: fixed-seed runs of every algorithm (DDPG, TD3, SAC, PPO,
# SAC + HER, SAC among observed random obstacles, DDPG in the dynamic simulation), each reduced
# to a fingerprint: episodes.csv without its wall-time column, and every evaluation CSV.
# Run it with the binary before and after a change and compare the two outputs:
#
#   scripts/dev/golden_runs.sh OLD_BIN /tmp/before
#   scripts/dev/golden_runs.sh target/release/stagerl /tmp/after
#   diff -r /tmp/before/fingerprints /tmp/after/fingerprints
set -euo pipefail
bin=$(realpath "$1")
out=$2
root=$(cd "$(dirname "$0")/../.." && pwd)
mkdir -p "$out/runs" "$out/fingerprints"


run() { # name, then train flags
    local name=$1; shift
    rm -rf "$out/runs/$name"
    "$bin" train --seed 7 --episodes "${EPISODES:-150}" --eval-trials 50 --out "$out/runs/$name" "$@" >/dev/null
    local d="$out/runs/$name" f="$out/fingerprints/$name.txt"
    {
        # every column but the last (wall time)
        sed 's/,[^,]*$//' "$d/episodes.csv" | sha256sum
        find "$d" -name '*.csv' ! -name episodes.csv -printf '%P\n' | sort | while read -r c; do
            echo "$c $(sha256sum < "$d/$c" | cut -c1-64)"
        done
    } > "$f"
    echo "$name: $(head -c 16 "$f")"
}
run ddpg --algo ddpg
run td3 --algo td3
run sac --algo sac
run ppo --algo ppo
run sac-her --algo sac --her future
cat > "$out/obstacles.toml" <<'TOML'
[task]
on_collision = "terminate"
observe_obstacles = true
obstacle_observation = "nearest"
obstacle_range_m = 0.15
[task.random_obstacles]
count = [1, 3]
shapes = ["sphere", "cuboid"]
size_m = [0.04, 0.1]
region_min_m = [-0.6, -0.6, 0.0]
region_max_m = [0.6, 0.6, 0.7]
target_clearance_m = 0.05
[reward]
collision_penalty = 10.0
[train]
obstacles_in_path = 0.5
TOML
printf '[task]\nsim = "dynamic"\n' > "$out/dynamic.toml"
run sac-obstacles --config "$out/obstacles.toml" --algo sac
EPISODES=40 run ddpg-dynamic --config "$out/dynamic.toml" --algo ddpg
