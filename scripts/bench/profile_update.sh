#!/usr/bin/env bash
# Where an agent update's time goes (issue 10): samples `stagerl bench update` with perf (a
# software clock, so it works inside VMs without hardware counters) and sums the samples by
# kind of work. Usage: scripts/bench/profile_update.sh [ALGO HIDDEN [UPDATES]] (default sac 64 2000).
# Needs perf (Debian: linux-perf) and a release build with symbols (the default profile keeps
# line tables).
set -euo pipefail
cd "$(dirname "$0")/../.."
algo=${1:-sac} hidden=${2:-64} updates=${3:-2000}
bin=${STAGERL_BIN:-target/release/stagerl}
data=$(mktemp)
trap 'rm -f "$data"' EXIT
perf record -q -e cpu-clock -F 4000 -o "$data" "$bin" bench update --algo "$algo" --hidden "$hidden" \
    --updates "$updates" >/dev/null 2>&1
echo "$algo hidden $hidden: share of the update's samples"
perf report -i "$data" --no-children --stdio --sort symbol 2>/dev/null | awk '
    /^ *[0-9.]+%/ {
        p = $1; sub("%", "", p); sym = $0
        if (sym ~ /nn::matmul/) k = "matrix products (nn::matmul kernels, packing included)"
        else if (sym ~ /microkernel/) k = "matrix products (gemm micro-kernels)"
        else if (sym ~ /pack|vectorize/) k = "packing (gemm)"
        else if (sym ~ /gemm/) k = "gemm set-up and dispatch"
        else if (sym ~ /adam/) k = "Adam"
        else if (sym ~ /activation|polyak|scale|sum_of_squares|mse|clip|concat|copy_row|memmove|memcpy|memset|zero_grad/) k = "element-wise (bias, activations, their backward, Polyak, copies)"
        else if (sym ~ /expf|logf|log_fma|sincos|exp_fma|ieee754/) k = "exp, log, sin/cos (libm)"
        else if (sym ~ /gaussian|Gaussian/) k = "squashed Gaussian head"
        else if (sym ~ /rng|Rng|xoshiro|normal/) k = "random numbers"
        else if (sym ~ /update|backprop|forward|Mlp|Net/) k = "agent and network glue"
        else k = "other"
        share[k] += p
    }
    END { for (k in share) printf "  %5.1f %%  %s\n", share[k], k }' | sort -rn
