#!/usr/bin/env python3
"""Shielded plan times of two (or more) stagerl binaries side by side: every problem of
`stagerl bench obstacles --problems-out FILE` planned as a request of `stagerl plan --shield
--targets -` by the policy of docs/results/quick-obstacles/in-path/runs/sac-sar-seed1 and by the
Jacobian controller, the binaries alternated per round (one thread each, one after the other).
Prints plan time median / p95 per set, planner and binary (`plan_time_s`, as `plan` reports
it), and the success / contact / intervention / stop counts, which must be the same.

Usage: shield_plan_times.py PROBLEMS.jsonl ROUNDS BIN [BIN...]"""
import collections
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RUN = os.path.join(ROOT, "docs/results/quick-obstacles/in-path/runs/sac-sar-seed1")
problems_file, rounds, bins = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
by_set = collections.OrderedDict()
for line in open(problems_file):
    p = json.loads(line)
    by_set.setdefault(p["set"], []).append({"target": p["target_m"], "start": p["start_rad"], "obstacles": p["obstacles"]})
planners = {"policy+shield": ["--run", RUN], "jacobian+shield": ["--run", RUN, "--controller", "jacobian"]}
times = collections.defaultdict(list)
counts = {}
for r in range(rounds):
    order = bins if r % 2 == 0 else bins[::-1]
    for s, reqs in by_set.items():
        inp = "".join(json.dumps(q) + "\n" for q in reqs)
        for pl, flags in planners.items():
            for b in order:
                out = subprocess.run([b, "plan", "--shield", "--targets", "-", *flags], input=inp, capture_output=True, text=True, check=True).stdout
                lines = [json.loads(l) for l in out.splitlines() if l.strip()]
                times[(s, pl, b)].extend(l["plan_time_s"] for l in lines)
                c = (sum(l["reached"] and not l["collision"] for l in lines), sum(l["collision"] for l in lines),
                     sum(l["shield_interventions"] for l in lines), sum(l["shield_stops"] for l in lines))
                if counts.setdefault((s, pl, b), c) != c:
                    print("NONDETERMINISTIC", s, pl, b, c, counts[(s, pl, b)])
def q(v, x):
    v = sorted(v); return v[round((len(v) - 1) * x)]
print("| set | planner | " + " | ".join(f"{b} median / p95 ms" for b in bins) + " | success, collisions, interventions, stops |")
for s in by_set:
    for pl in planners:
        cells = [f"{1e3*q(times[(s,pl,b)],0.5):.3f} / {1e3*q(times[(s,pl,b)],0.95):.3f}" for b in bins]
        cs = {counts[(s, pl, b)] for b in bins}
        print(f"| {s} | {pl} | " + " | ".join(cells) + f" | {'same ' + str(cs.pop()) if len(cs)==1 else 'DIFFER ' + str([counts[(s,pl,b)] for b in bins])} |")
