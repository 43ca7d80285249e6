#!/usr/bin/env python3
"""Contact verdicts of `stagerl fk --collisions` against PyBullet's getClosestPoints on random
poses of a mesh URDF (issue 33's check; PyBullet is too heavy for CI, so this is a recorded
script: `pip install pybullet` in a venv, then

    python scripts/dev/check_meshes_pybullet.py STAGERL_BIN URDF [--tip LINK] [--poses 300]

e.g. with pybullet_data's `kuka_iiwa/model.urdf` or `franka_panda/panda.urdf --tip panda_hand`).

For each pose: the floor verdict (a link of the chain below z = 0, the root excluded) and the
self verdict (two links two or more actuated joints apart overlapping, stagerl's adjacency
rule), from both tools; poses where PyBullet's distance for that check is within the band
(5 mm) are skipped. Prints the agreement and forward kinematics' largest difference (m).
"""
import argparse
import json
import random
import subprocess

import pybullet as p


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("stagerl")
    ap.add_argument("urdf")
    ap.add_argument("--tip")
    ap.add_argument("--poses", type=int, default=300)
    ap.add_argument("--band", type=float, default=0.005)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()

    p.connect(p.DIRECT)
    robot = p.loadURDF(a.urdf, useFixedBase=True)
    plane = p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE))
    names = {p.getJointInfo(robot, j)[12].decode(): j for j in range(p.getNumJoints(robot))}
    movable = [j for j in range(p.getNumJoints(robot)) if p.getJointInfo(robot, j)[2] in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC)]
    tip = names[a.tip] if a.tip else max(names.values())
    # The chain: the tip's ancestors (PyBullet's link index = its parent joint's index).
    chain, j = [], tip
    while j != -1:
        chain.append(j)
        j = p.getJointInfo(robot, j)[16]
    chain.reverse()
    dofs = [j for j in chain if j in movable]
    # Segment of each link: the count of actuated joints up to it, minus one.
    seg = {-1: -1}
    for j in chain:
        seg[j] = sum(1 for d in dofs if d <= j) - 1
    links = [-1] + chain
    has_shape = {l: bool(p.getCollisionShapeData(robot, l)) for l in links}
    links = [l for l in links if has_shape[l]]
    pairs = [(x, y) for i, x in enumerate(links) for y in links[i + 1:] if abs(seg[x] - seg[y]) >= 2]

    rnd = random.Random(a.seed)
    lims = [p.getJointInfo(robot, j)[8:10] for j in dofs]
    poses = [[rnd.uniform(lo, hi) for lo, hi in lims] for _ in range(a.poses)]
    args = [a.stagerl, "fk", "--robot", a.urdf, "--collisions"] + (["--tip", a.tip] if a.tip else [])
    inp = "".join(json.dumps({"joints": q}) + "\n" for q in poses)
    out = subprocess.run(args, input=inp, capture_output=True, text=True, check=True).stdout.splitlines()

    agree = {"floor": [0, 0, 0], "self": [0, 0, 0]}
    fk_err = 0.0
    for q, line in zip(poses, out):
        ours = json.loads(line)
        for j, v in zip(dofs, q):
            p.resetJointState(robot, j, v)
        pos = p.getLinkState(robot, tip, computeForwardKinematics=True)[4]
        fk_err = max(fk_err, max(abs(x - y) for x, y in zip(pos, ours["position"])))
        floor_d = min(
            (c[8] for l in links if seg[l] >= 0 for c in p.getClosestPoints(robot, plane, 1.0, linkIndexA=l)),
            default=1.0,
        )
        self_d = min(
            (c[8] for x, y in pairs for c in p.getClosestPoints(robot, robot, 1.0, linkIndexA=x, linkIndexB=y)),
            default=1.0,
        )
        kinds = {c["with"] for c in ours["contacts"]}
        for kind, d in (("floor", floor_d), ("self", self_d)):
            if abs(d) < a.band:
                continue
            agree[kind][1] += 1
            agree[kind][0] += int((d < 0) == (kind in kinds))
            agree[kind][2] += int(d < 0)
    for kind, (ok, n, hits) in agree.items():
        print(f"{kind}: {ok} of {n} poses agree ({100.0 * ok / max(n, 1):.1f} %; {hits} in contact by PyBullet)")
    print(f"forward kinematics: largest difference {fk_err:.2e} m over {len(poses)} poses")


if __name__ == "__main__":
    main()
