#!/usr/bin/env bash
# One binary at two instruction sets on one CPU: stagerl with STAGERL_SIMD=avx2 and unset (AVX-512
# on a CPU that has it), PyTorch and SB3 with their AVX2 caps (ATEN_CPU_CAPABILITY, MKL's and
# oneDNN's) and without, in interleaved rounds; every run prints its JSON line and its CPU seconds
# (user + sys). Per-update and per-step CPU times are the differences of two run lengths, so
# start-up and warm-up cancel (parse.py).
#   BIN=target/release/stagerl VENV=V ROUNDS=3 docs/results/bench-xeon-simd/measure.sh > rounds.txt
#   python3 docs/results/bench-xeon-simd/parse.py rounds.txt
cd "$(dirname "$0")/../../.."
PY=${VENV:?a venv with torch, stable-baselines3 and ./python}/bin/python
BIN=${BIN:-target/release/stagerl}
t() { # label, command...
  local label=$1; shift
  local out; out=$( { /usr/bin/time -f "CPU %U %S" "$@" 2>"${TMPDIR:-/tmp}/measure-time.err" | tail -1; } ; grep CPU "${TMPDIR:-/tmp}/measure-time.err")
  echo "$label $(echo $out | tr '\n' ' ')"
}
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
# Each instruction set as the environment of a command (/usr/bin/time runs them).
avx2=(env STAGERL_SIMD=avx2 ATEN_CPU_CAPABILITY=avx2 MKL_ENABLE_INSTRUCTIONS=AVX2 ONEDNN_MAX_CPU_ISA=AVX2)
wide=(env -u STAGERL_SIMD -u ATEN_CPU_CAPABILITY -u MKL_ENABLE_INSTRUCTIONS -u ONEDNN_MAX_CPU_ISA)
cap='import torch; print(torch.backends.cpu.get_cpu_capability())'
echo "torch capability: avx2 $("${avx2[@]}" $PY -c "$cap" 2>/dev/null), wide $("${wide[@]}" $PY -c "$cap" 2>/dev/null)"
for r in $(seq 1 ${ROUNDS:-3}); do
  echo "round $r $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
  for isa in avx2 wide; do
    if [ $isa = avx2 ]; then e=("${avx2[@]}"); else e=("${wide[@]}"); fi
    for n in 300 50; do t "sac256 ours $isa $n" "${e[@]}" $BIN bench update --algo sac --hidden 256 --updates $n; done
    for n in 200 50; do t "sac256 torch $isa $n" "${e[@]}" $PY scripts/bench/bench_pytorch.py --algo sac --hidden 256 --updates $n; done
    for n in 6000 3000; do t "ddpg ours $isa $n" "${e[@]}" $BIN bench train --algo ddpg --steps $n; done
    for n in 5000 2000; do t "ddpg sb3 $isa $n" "${e[@]}" $PY scripts/bench/bench_sb3.py --algo ddpg --steps $n; done
  done
  echo "end $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
done
