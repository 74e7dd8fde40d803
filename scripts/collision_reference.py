"""Collisions on the exact meshes, by Pinocchio and coal (PyPI `pin`): the slow reference of
selfmodel's sphere check. Never a dependency of the crate; tests and benchmarks run it beside
ours.

Reads the URDF with its collision geometry (`package://` paths resolved from the folder above
the URDF's package, as selfmodel resolves them), checks the pairs of geometry objects of the
link pairs selfmodel checks (`--checked`: a JSON list of [link1, link2], `Robot.collision_pairs`)
and, with `--scene`, every moving link's objects against the scene's obstacles, and for each
configuration of `--joints` (CSV: one column per joint of selfmodel's joint vector, named
after the joints, radians) writes `collides` (0/1) and `distance` (m: the smallest distance
between checked objects, negative where they overlap, as coal reports it) to `--out`.
Joints of the description outside the CSV are held at 0, or at the limit nearest 0, except a
joint that mimics another (`<mimic>`, a gripper's second finger), which follows it as selfmodel's
kinematics makes it follow.

    python3 scripts/collision_reference.py --urdf panda.urdf --joints q.csv \
        --checked pairs.json --scene table.yml --out exact.csv
"""
import argparse
import csv
import json
import os
import sys

import numpy as np
import pinocchio as pin


def add_scene(collision, path):
    """The scene's obstacles as geometry objects fixed to the world, each paired with every
    geometry object of a moving link (one whose joint is not the universe)."""
    import coal
    import yaml

    with open(path) as f:
        scene = yaml.safe_load(f) or {}
    robot_objects = [i for i, g in enumerate(collision.geometryObjects) if g.parentJoint != 0]
    for kind, entries in scene.items():
        for name, e in (entries or {}).items():
            pose = e.get("pose", list(e.get("position", [0, 0, 0])) + [1, 0, 0, 0])
            x, y, z, qw, qx, qy, qz = pose
            placement = pin.SE3(pin.Quaternion(qw, qx, qy, qz).normalized().matrix(), np.array([x, y, z]))
            if kind == "cuboid":
                shape = coal.Box(*e["dims"])
            elif kind == "sphere":
                shape = coal.Sphere(e["radius"])
            elif kind == "cylinder":
                shape = coal.Cylinder(e["radius"], e["height"])
            elif kind == "capsule":
                base, tip = np.array(e["base"]), np.array(e["tip"])
                axis = tip - base
                length = np.linalg.norm(axis)
                shape = coal.Capsule(e["radius"], length)
                z_axis = axis / length
                rot = pin.Quaternion.FromTwoVectors(np.array([0, 0, 1.0]), z_axis).matrix()
                placement = placement * pin.SE3(rot, (base + tip) / 2)
            else:
                sys.exit(f"collision_reference: {kind} obstacles are not supported here")
            obj = pin.GeometryObject(f"scene/{name}", 0, 0, placement, shape)
            k = collision.addGeometryObject(obj)
            for i in robot_objects:
                collision.addCollisionPair(pin.CollisionPair(i, k))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urdf", required=True)
    ap.add_argument("--joints", required=True, help="CSV, one column per joint (radians)")
    ap.add_argument("--checked", required=True, help="JSON list of [link1, link2]: the pairs selfmodel checks (Robot.collision_pairs)")
    ap.add_argument("--scene", help="cuRobo world YAML: its cuboids, spheres, cylinders and capsules checked against every moving link")
    ap.add_argument("--out", required=True)
    ap.add_argument("--distances", action="store_true", help="also the smallest distance (slower)")
    a = ap.parse_args()

    urdf = os.path.abspath(a.urdf)
    package_root = os.path.dirname(os.path.dirname(os.path.dirname(urdf)))
    model, collision, _ = pin.buildModelsFromUrdf(urdf, package_dirs=[package_root])
    with open(a.checked) as f:
        checked = {tuple(sorted(p)) for p in json.load(f)}

    def link_of(g):
        return model.frames[g.parentFrame].name

    objects = collision.geometryObjects
    for i in range(len(objects)):
        for j in range(i + 1, len(objects)):
            li, lj = link_of(objects[i]), link_of(objects[j])
            if tuple(sorted((li, lj))) in checked:
                collision.addCollisionPair(pin.CollisionPair(i, j))
    if a.scene:
        add_scene(collision, a.scene)
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

    mimics = []
    import xml.etree.ElementTree as ET
    for joint in ET.parse(urdf).getroot().iter("joint"):
        m = joint.find("mimic")
        if m is not None and model.existJointName(joint.get("name")) and model.existJointName(m.get("joint")):
            mimics.append((
                model.idx_qs[model.getJointId(joint.get("name"))],
                model.idx_qs[model.getJointId(m.get("joint"))],
                float(m.get("multiplier", 1.0)),
                float(m.get("offset", 0.0)),
            ))

    out = []
    for r in rows:
        q = q0.copy()
        for k, v in zip(index, r):
            q[k] = v
        for k, source, multiplier, offset in mimics:
            if k not in index:
                q[k] = multiplier * q[source] + offset
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
