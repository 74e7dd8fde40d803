"""The reference IK solvers on the targets `ik targets` writes, for side-by-side ratios with
`ik solve` (run in the same sitting). Reports the share of targets solved exactly (within
1 mm and 0.572 degrees, every joint inside its limits) and solves per second on one thread.

Robotics Toolbox for Python (`pip install roboticstoolbox-python`): its compiled
Levenberg-Marquardt `ets.ik_LM`, on its built-in model of the robot (its Panda; the script
checks that model's forward kinematics against the targets' joints first).

TRAC-IK through PyPI `pytracik` (`pip install pytracik`), given the URDF: its parser reads
the Panda's `<safety_controller soft_lower_limit soft_upper_limit>` as 0, and TRAC-IK bounds
each joint by the intersection of its hard and soft limits, so every joint is pinned to [0, 0]
(joint 4 to the empty [0, -0.0698]) and every pose fails with -3. The script drops the
`<safety_controller>` elements (the soft limits equal the hard ones in Franka's description)
and prints the bounds TRAC-IK then reads.

    python3 scripts/ik_reference.py panda data/ik/panda_targets.csv [URDF BASE_LINK]
"""
import csv
import sys
import time

import numpy as np

robot_name, path = sys.argv[1:3]
urdf_base = sys.argv[3:5]
try:
    import roboticstoolbox as rtb
    from spatialmath import SE3, UnitQuaternion
except ImportError:
    print("skipped: roboticstoolbox-python is not installed (pip install roboticstoolbox-python)")
    sys.exit(0)

models = {"panda": (rtb.models.Panda, "panda_hand"), "ur5": (rtb.models.UR5, "tool0")}
make, tip = models[robot_name]
ets = make().ets(end=tip)
rows = list(csv.DictReader(open(path)))
targets = [
    SE3.Rt(
        UnitQuaternion([float(r[k]) for k in ("qw", "qx", "qy", "qz")]).R,
        [float(r[k]) for k in "xyz"],
    )
    for r in rows
]
qs = [[float(r[f"q{i}"]) for i in range(1, ets.n + 1)] for r in rows]
fk = max(np.linalg.norm(ets.fkine(q).t - t.t) for q, t in zip(qs, targets))
print(f"Robotics Toolbox's {robot_name} model against the targets' joints: {fk:.1e} m")
lo, hi = ets.qlim
t0 = time.perf_counter()
exact = 0
for t in targets:
    s = ets.ik_LM(t.A, ilimit=30, slimit=100, joint_limits=True)
    e = ets.fkine(s.q)
    dp = np.linalg.norm(e.t - t.t)
    dr = np.linalg.norm((e.inv() * t).angvec()[0])
    inside = np.all(s.q >= lo - 1e-9) and np.all(s.q <= hi + 1e-9)
    exact += bool(s.success) and dp <= 1e-3 and dr <= 0.01 and inside
seconds = time.perf_counter() - t0
print(
    f"roboticstoolbox ik_LM: {len(targets)} targets, {exact} solved exactly "
    f"({100 * exact / len(targets):.2f}%), {exact / seconds:.0f} exact solutions/s on 1 thread"
)

if len(urdf_base) == 2:
    try:
        import pytracik
    except ImportError:
        print("skipped TRAC-IK: pytracik is not installed (pip install pytracik)")
        sys.exit(0)
    import re

    text = re.sub(r"<safety_controller[^>]*/>", "", open(urdf_base[0]).read())
    solver = pytracik.TRAC_IK(urdf_base[1], tip, text, 0.005, 1e-5, pytracik.SolveType.Speed)
    lo = np.array(pytracik.get_joint_lower_bounds(solver))
    hi = np.array(pytracik.get_joint_upper_bounds(solver))
    print(f"TRAC-IK reads bounds {np.round(lo, 4).tolist()} .. {np.round(hi, 4).tolist()}")
    t0 = time.perf_counter()
    exact = 0
    for r, t in zip(rows, targets):
        out = pytracik.ik(solver, np.zeros(len(lo)), *[float(r[k]) for k in ("x", "y", "z", "qx", "qy", "qz", "qw")])
        if out[0] < 0:
            continue
        q = np.array(out[1 : 1 + len(lo)])
        e = ets.fkine(q)
        dp = np.linalg.norm(e.t - t.t)
        dr = np.linalg.norm((e.inv() * t).angvec()[0])
        exact += dp <= 1e-3 and dr <= 0.01 and np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9)
    seconds = time.perf_counter() - t0
    print(
        f"TRAC-IK (Speed, 5 ms): {len(targets)} targets, {exact} solved exactly "
        f"({100 * exact / len(targets):.2f}%), {exact / seconds:.0f} exact solutions/s on 1 thread"
    )
