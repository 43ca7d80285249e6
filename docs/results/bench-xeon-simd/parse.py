#!/usr/bin/env python3
"""Per round, from measure.sh's output: stagerl's and PyTorch's SAC update at hidden 256 (wall:
their own median; CPU: the difference of the two run lengths' user + sys over the difference of
their update counts) and the DDPG end-to-end rates (stagerl's and SB3's own figures), at each
instruction set; then the ratios.  usage: parse.py rounds.txt"""
import json
import re
import sys


def rounds(path):
    out, cur = [], None
    for line in open(path):
        if line.startswith("round "):
            cur = {}
            out.append(cur)
        m = re.match(r"(\S+ \S+ \S+ \d+) (\{.*\}) CPU ([\d.]+) ([\d.]+)", line)
        if m and cur is not None:
            cur[m.group(1)] = (json.loads(m.group(2)), float(m.group(3)) + float(m.group(4)))
    return out


def main(path):
    print("| round | instruction set | stagerl SAC h256 ms (wall / CPU) | PyTorch ms (wall / CPU) | ratio (wall) | DDPG h64 stagerl steps/s | SB3 steps/s | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for i, r in enumerate(rounds(path), 1):
        for isa in ["avx2", "wide"]:
            ours, ours50 = r[f"sac256 ours {isa} 300"], r[f"sac256 ours {isa} 50"]
            torch, torch50 = r[f"sac256 torch {isa} 200"], r[f"sac256 torch {isa} 50"]
            ow, oc = ours[0]["ms_per_update"], (ours[1] - ours50[1]) / 250 * 1000
            tw, tc = torch[0]["ms_per_update"], (torch[1] - torch50[1]) / 150 * 1000
            d, s = r[f"ddpg ours {isa} 6000"][0]["steps_per_sec"], r[f"ddpg sb3 {isa} 5000"][0]["steps_per_sec"]
            name = "AVX2" if isa == "avx2" else "AVX-512 (" + ours[0]["simd"] + ")"
            print(f"| {i} | {name} | {ow:.2f} / {oc:.2f} | {tw:.2f} / {tc:.2f} | {tw / ow:.2f}x | {d:.0f} | {s:.0f} | {d / s:.1f}x |")


if __name__ == "__main__":
    main(sys.argv[1])
