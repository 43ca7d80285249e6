#!/usr/bin/env bash
# Interleaved rounds of the binaries before and after, PyTorch and SB3; every run prints its JSON
# line and its CPU seconds (user + sys, /usr/bin/time). Per-update and per-step CPU times are the
# differences of two run lengths (parse.py), so start-up and warm-up cancel.
#   OLD=BIN NEW=BIN VENV=V ROUNDS=3 docs/results/bench-amd-epyc-zen3/measure.sh > rounds.txt
#   python3 docs/results/bench-amd-epyc-zen3/parse.py rounds.txt
cd "$(dirname "$0")/../../.."
PY=${VENV:?a venv with torch, stable-baselines3 and ./python}/bin/python
OLD=${OLD:?the binary before} NEW=${NEW:?the binary after}
t() { # label, command...
  local label=$1; shift
  local out; out=$( { /usr/bin/time -f "CPU %U %S" "$@" 2>"${TMPDIR:-/tmp}/measure-time.err" | tail -1; } ; grep CPU "${TMPDIR:-/tmp}/measure-time.err")
  echo "$label $(echo $out | tr '\n' ' ')"
}
export OMP_NUM_THREADS=1
for r in $(seq 1 ${ROUNDS:-3}); do
  echo "round $r $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
  for n in 300 50; do
    t "sac256 old $n" $OLD bench update --algo sac --hidden 256 --updates $n
    t "sac256 new $n" $NEW bench update --algo sac --hidden 256 --updates $n
  done
  for n in 200 50; do t "sac256 torch $n" $PY scripts/bench/bench_pytorch.py --algo sac --hidden 256 --updates $n; done
  for n in 6000 3000; do
    t "ddpg old $n" $OLD bench train --algo ddpg --steps $n
    t "ddpg new $n" $NEW bench train --algo ddpg --steps $n
  done
  for n in 5000 2000; do t "ddpg sb3 $n" $PY scripts/bench/bench_sb3.py --algo ddpg --steps $n; done
  for b in old new; do
    B=$OLD; [ $b = new ] && B=$NEW
    t "sac64 $b" $B bench update --algo sac --hidden 64 --updates 2000
    t "crossq64-256 $b" $B bench update --algo crossq --hidden 64 --critic-hidden 256 --updates 300
    t "crossq64-1024 $b" $B bench update --algo crossq --hidden 64 --critic-hidden 1024 --updates 20
  done
  echo "end $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
done
