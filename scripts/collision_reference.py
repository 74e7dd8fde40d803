"""Collisions on the exact meshes, by Pinocchio and coal (PyPI `pin`): the slow reference of
selfmodel's sphere check. Never a dependency of the crate; tests and benchmarks run it beside
ours.

Reads the URDF with its collision geometry (`package://` paths resolved from the folder above
the URDF's package, as selfmodel resolves them), checks every pair of geometry objects of
different links except the allowed pairs (`--allowed`: a JSON list of [link1, link2], what
selfmodel's collision model allows; the same links' objects are never checked), and for each
configuration of `--joints` (CSV: one column per joint of selfmodel's joint vector, named
after the joints, radians) writes `collides` (0/1) and `distance` (m: the smallest distance
between checked objects, negative where they overlap, as coal reports it) to `--out`.
Joints of the description outside the CSV are held at 0, or at the limit nearest 0.

    python3 scripts/collision_reference.py --urdf panda.urdf --joints q.csv \
        --allowed allowed.json --out exact.csv
"""
import argparse
import csv
import json
import os
import sys

import numpy as np
import pinocchio as pin


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urdf", required=True)
    ap.add_argument("--joints", required=True, help="CSV, one column per joint (radians)")
    ap.add_argument("--allowed", required=True, help="JSON list of [link1, link2] pairs not checked")
    ap.add_argument("--out", required=True)
    ap.add_argument("--distances", action="store_true", help="also the smallest distance (slower)")
    a = ap.parse_args()

    urdf = os.path.abspath(a.urdf)
    package_root = os.path.dirname(os.path.dirname(os.path.dirname(urdf)))
    model, collision, _ = pin.buildModelsFromUrdf(urdf, package_dirs=[package_root])
    with open(a.allowed) as f:
        allowed = {tuple(sorted(p)) for p in json.load(f)}

    def link_of(g):
        return model.frames[g.parentFrame].name

    objects = collision.geometryObjects
    for i in range(len(objects)):
        for j in range(i + 1, len(objects)):
            li, lj = link_of(objects[i]), link_of(objects[j])
            if li != lj and tuple(sorted((li, lj))) not in allowed:
                collision.addCollisionPair(pin.CollisionPair(i, j))
    data = model.createData()
    cdata = pin.GeometryData(collision)

    with open(a.joints) as f:
        reader = csv.reader(f)
        names = next(reader)
        rows = [[float(x) for x in r] for r in reader]
    q0 = pin.neutral(model)
    for jid in range(1, model.njoints):
        lo, hi = model.lowerPositionLimit[model.idx_qs[jid]], model.upperPositionLimit[model.idx_qs[jid]]
        if model.nqs[jid] == 1:
            q0[model.idx_qs[jid]] = min(max(0.0, lo), hi)
    index = []
    for n in names:
        if not model.existJointName(n):
            sys.exit(f"collision_reference: joint {n} is not in {a.urdf}")
        index.append(model.idx_qs[model.getJointId(n)])

    out = []
    for r in rows:
        q = q0.copy()
        for k, v in zip(index, r):
            q[k] = v
        hit = pin.computeCollisions(model, data, collision, cdata, q, True)
        row = {"collides": int(bool(hit))}
        if a.distances:
            pin.computeDistances(model, data, collision, cdata, q)
            row["distance"] = min((d.min_distance for d in cdata.distanceResults), default=float("inf"))
        out.append(row)
    with open(a.out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(out[0].keys()) if out else ["collides"])
        w.writeheader()
        w.writerows(out)
    print(f"collision_reference: {len(rows)} configurations, {sum(r['collides'] for r in out)} colliding, "
          f"{len(collision.collisionPairs)} pairs checked")


if __name__ == "__main__":
    main()
