"""The reference IK solvers on the targets `bench_ik` (or `ik targets`) writes, in the same
sitting as ours: how many targets each solves exactly (within 1 mm and 0.572 degrees, every
joint inside the URDF's limits) and in how many seconds, at several time budgets.

- Robotics Toolbox for Python (`pip install roboticstoolbox-python`): its compiled
  Levenberg-Marquardt `ets.ik_LM` on the chain it reads from the same URDF, 30 iterations a
  search, the budget being its number of searches (random restarts; 100 is its default).
- TRAC-IK through PyPI `pytracik` (`pip install pytracik`), given the URDF, in its Speed mode,
  the budget being its timeout (5 ms is its default). Its parser reads Franka's
  `<safety_controller soft_lower_limit soft_upper_limit>` as 0 and TRAC-IK bounds each joint by
  the intersection of its hard and soft limits, so every Panda joint is pinned to [0, 0]
  (joint 4 to the empty [0, -0.0698]) and every pose fails with -3: the script drops the
  `<safety_controller>` elements (Franka's soft limits equal its hard ones) and prints the
  bounds TRAC-IK then reads.

Each solver runs at its default tolerance (ik_LM's `tol` 1e-6 on its error E; TRAC-IK's
`eps` 1e-5) over every budget, and at its default budget with tighter tolerances (`--tight`:
ik_LM tol 1e-10 and 1e-14, TRAC-IK eps 1e-7 and 1e-9), so that solvers are compared at equal
precision: each row gives the median, 98th percentile and largest pose error of the answers it
returned (millimetres, degrees), and `precise` counts the answers within `--precision MM,DEG`
(default 1e-4 mm and 1e-4 degrees, ours' convergence tolerance) and inside the limits: the
ranking at a common precision.

Each solver runs in `--processes` worker processes (the targets split between them; seconds are
the wall time of the whole batch, pool start-up excluded). Writes CSV to `--out`:
solver,budget,standard,processes,targets,exact,outside_limits,seconds,tolerance,precise,pos_err_mm_median,
pos_err_mm_p98,pos_err_mm_max,rot_err_deg_median,rot_err_deg_p98,rot_err_deg_max. A solver whose
package is absent is skipped with a line saying so.

    python3 scripts/ik_reference.py --targets T.csv --urdf panda.urdf --base panda_link0 \
        --tip panda_hand --processes 2 --out reference.csv
"""
import argparse
import csv
import multiprocessing as mp
import re
import sys
import time

import numpy as np

RTB_SEARCHES = [1, 3, 10, 30, 100]
RTB_STANDARD = 100
RTB_TOL = 1e-6
RTB_TIGHT = [1e-10, 1e-14]
TRACIK_TIMEOUTS_MS = [0.5, 1, 2, 5, 20]
TRACIK_STANDARD = 5
TRACIK_EPS = 1e-5
TRACIK_TIGHT = [1e-7, 1e-9]


def register_packages(urdf):
    """Let the Robotics Toolbox's xacro step find `package://` paths next to the URDF."""
    import os

    import xacrodoc.packages

    root = os.path.dirname(os.path.dirname(os.path.abspath(urdf)))
    xacrodoc.packages.update_package_cache({os.path.basename(root): root})


def load_ets(urdf, tip):
    import os

    import warnings

    import roboticstoolbox as rtb

    register_packages(urdf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rtb.Robot.URDF(os.path.abspath(urdf)).ets(end=tip)


STATE = {}


def spread(values):
    """Median, 98th percentile and largest (nearest rank, as the Rust tables), NaN for none."""
    if not values:
        return [float("nan")] * 3
    v = np.sort(np.asarray(values))
    rank = lambda q: v[min(len(v), max(1, int(np.ceil(q * len(v))))) - 1]
    return [float(rank(0.5)), float(rank(0.98)), float(v[-1])]


def init_worker(kind, urdf, base, tip, budget, tol):
    if kind == "rtb":
        STATE["ets"] = load_ets(urdf, tip)
    else:
        import pytracik

        text = re.sub(r"<safety_controller[^>]*/>", "", open(urdf).read())
        STATE["solver"] = pytracik.TRAC_IK(
            base, tip, text, budget / 1000.0, tol, pytracik.SolveType.Speed
        )
    STATE["kind"], STATE["budget"], STATE["tol"] = kind, budget, tol


def solve_chunk(rows):
    """Answers (None where the solver gave up) for rows of x,y,z,qw,qx,qy,qz."""
    out = []
    if STATE["kind"] == "rtb":
        from spatialmath import SE3, UnitQuaternion

        ets = STATE["ets"]
        for r in rows:
            t = SE3.Rt(UnitQuaternion(r[3:7]).R, r[0:3])
            s = ets.ik_LM(t.A, ilimit=30, slimit=STATE["budget"], tol=STATE["tol"], joint_limits=True)
            out.append(list(s.q) if s.success else None)
    else:
        import pytracik

        solver = STATE["solver"]
        n = len(pytracik.get_joint_lower_bounds(solver))
        for r in rows:
            x, y, z, qw, qx, qy, qz = r
            res = pytracik.ik(solver, np.zeros(n), x, y, z, qx, qy, qz, qw)
            out.append(list(res[1 : 1 + n]) if res[0] >= 0 else None)
    return out


def run(kind, budget, tol, args, rows):
    chunks = [rows[i :: args.processes] for i in range(args.processes)]
    with mp.Pool(args.processes, init_worker, (kind, args.urdf, args.base, args.tip, budget, tol)) as pool:
        pool.map(solve_chunk, [rows[:2]] * args.processes)  # start-up and warm-up
        t0 = time.perf_counter()
        parts = pool.map(solve_chunk, chunks)
        seconds = time.perf_counter() - t0
    answers = [None] * len(rows)
    for i, part in enumerate(parts):
        answers[i :: args.processes] = part
    return answers, seconds


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--targets", required=True)
    p.add_argument("--urdf", required=True)
    p.add_argument("--base", required=True)
    p.add_argument("--tip", required=True)
    p.add_argument("--processes", type=int, default=2)
    p.add_argument("--out", required=True)
    p.add_argument("--standard-only", action="store_true", help="each solver's default budget only")
    p.add_argument("--tight", action="store_true", help="also each solver's default budget at tighter tolerances")
    p.add_argument("--precision", default="0.0001,0.0001", help="MM,DEG: the common precision answers are also counted at (column precise)")
    args = p.parse_args()
    rows = [
        [float(r[k]) for k in ("x", "y", "z", "qw", "qx", "qy", "qz")]
        for r in csv.DictReader(open(args.targets))
    ]
    try:
        from spatialmath import SE3, UnitQuaternion
    except ImportError:
        print("skipped: roboticstoolbox-python is not installed (pip install roboticstoolbox-python); it also checks the answers")
        return
    ets = load_ets(args.urdf, args.tip)
    lo, hi = ets.qlim
    precise_mm, precise_deg = (float(v) for v in args.precision.split(","))

    def score(answers):
        """Exact answers, answers within the common precision, answers outside the limits, and the
        spread (median, p98, max) of the returned answers' position (mm) and rotation (degrees)
        errors."""
        exact = precise = outside = 0
        mm, deg = [], []
        for r, q in zip(rows, answers):
            if q is None:
                continue
            q = np.array(q)
            t = SE3.Rt(UnitQuaternion(r[3:7]).R, r[0:3])
            e = ets.fkine(q)
            dp = np.linalg.norm(e.t - t.t)
            dr = abs((e.inv() * t).angvec()[0])
            mm.append(1e3 * dp)
            deg.append(np.degrees(dr))
            # 1e-6 rad: TRAC-IK keeps its bounds in float32 (2.8973 becomes 2.8973000049).
            inside = np.all(q >= lo - 1e-6) and np.all(q <= hi + 1e-6)
            outside += not inside
            exact += bool(dp <= 1e-3 and dr <= 0.01 and inside)
            precise += bool(mm[-1] <= precise_mm and deg[-1] <= precise_deg and inside)
        return exact, precise, outside, spread(mm) + spread(deg)

    solvers = [("Robotics Toolbox ik_LM", "rtb", RTB_SEARCHES, RTB_STANDARD, "searches", "tol", RTB_TOL, RTB_TIGHT)]
    try:
        import pytracik

        text = re.sub(r"<safety_controller[^>]*/>", "", open(args.urdf).read())
        s = pytracik.TRAC_IK(args.base, args.tip, text, 0.005, 1e-5, pytracik.SolveType.Speed)
        b = (pytracik.get_joint_lower_bounds(s), pytracik.get_joint_upper_bounds(s))
        print(f"TRAC-IK reads bounds {np.round(b[0], 4).tolist()} .. {np.round(b[1], 4).tolist()}")
        solvers.append(("TRAC-IK (Speed)", "tracik", TRACIK_TIMEOUTS_MS, TRACIK_STANDARD, "ms", "eps", TRACIK_EPS, TRACIK_TIGHT))
    except ImportError:
        print("skipped TRAC-IK: pytracik is not installed (pip install pytracik)")
    columns = ["solver", "budget", "standard", "processes", "targets", "exact", "outside_limits", "seconds", "tolerance", "precise"]
    columns += [f"{e}_{s}" for e in ("pos_err_mm", "rot_err_deg") for s in ("median", "p98", "max")]
    with open(args.out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for name, kind, budgets, standard, unit, tol_name, tol, tight in solvers:
            runs = [(b, tol) for b in ([standard] if args.standard_only else budgets)]
            runs += [(standard, t) for t in tight] if args.tight else []
            for budget, t in runs:
                answers, seconds = run(kind, budget, t, args, rows)
                exact, precise, outside, errors = score(answers)
                tolerance = f"{tol_name} {t:g}"
                w.writerow([name, f"{budget} {unit}", budget == standard and t == tol, args.processes, len(rows), exact, outside, seconds, tolerance, precise] + errors)
                f.flush()
                print(
                    f"{name}, {budget} {unit}, {tolerance}: {exact} of {len(rows)} exact ({100 * exact / len(rows):.2f}%), "
                    f"{exact / seconds:.0f} exact/s on {args.processes} processes, position error median/p98/max "
                    f"{errors[0]:.2g}/{errors[1]:.2g}/{errors[2]:.2g} mm, {precise} within {args.precision} mm,deg",
                    flush=True,
                )


if __name__ == "__main__":
    sys.exit(main())
