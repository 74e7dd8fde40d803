"""Check our forward kinematics against Pinocchio on any URDF (a trusted outside reference).

Reads a target file written by `ik targets` (x,y,z,qw,qx,qy,qz then the joints q1..qN that
reach it, radians/metres), computes the tip frame's pose in Pinocchio with the same joints
(joints the chain holds stay at 0, mimic joints follow their leader), and prints the largest
position and rotation differences.

    pip install pin numpy
    python3 scripts/check_fk_pinocchio.py URDF TIP_LINK TARGETS.csv
"""
import csv
import sys

import numpy as np
import pinocchio as pin

urdf, tip, path = sys.argv[1:4]
model = pin.buildModelFromUrdf(urdf)
data = model.createData()
frame = model.getFrameId(tip)
rows = list(csv.DictReader(open(path)))
names = [k for k in rows[0] if k.startswith("q") and k[1:].isdigit()]
# Our joint vector is the chain's joints in URDF order: match them to Pinocchio's by order of
# the movable joints on the path to the tip.
path_joints = []
j = model.frames[frame].parentJoint
while j > 0:
    path_joints.append(j)
    j = model.parents[j]
path_joints = sorted(path_joints)
assert len(path_joints) == len(names), (path_joints, names)
worst_p, worst_r = 0.0, 0.0
for r in rows:
    q = pin.neutral(model)
    for name, jid in zip(names, path_joints):
        q[model.joints[jid].idx_q] = float(r[name])
    pin.framesForwardKinematics(model, data, q)
    m = data.oMf[frame]
    p = np.array([float(r[k]) for k in "xyz"])
    w, x, y, z = (float(r[k]) for k in ("qw", "qx", "qy", "qz"))
    ours = pin.Quaternion(w, x, y, z).toRotationMatrix()
    worst_p = max(worst_p, np.linalg.norm(m.translation - p))
    worst_r = max(worst_r, np.linalg.norm(pin.log3(ours.T @ m.rotation)))
print(f"{len(rows)} poses of {tip}: largest difference from Pinocchio {worst_p:.3e} m, {worst_r:.3e} rad")
