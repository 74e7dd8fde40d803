"""Learned inverse kinematics of a Franka Panda from Python: solve 1,000 poses, render the
answers beside the poses asked for, and save a figure.

    pip install ./python matplotlib
    python examples/python/panda_ik.py [--model DIR] [--out runs/examples/panda_ik.png]

Without --model it trains a model first with the command line (`ik train --preset quick`,
seconds; `--preset paper` is the one to use for real work), so `cargo build --release --bin ik`
must have run. The Panda's description is read from ../shared/robots, as ROS ships it.
"""

import argparse
import pathlib
import subprocess
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import selfmodel

ROOT = pathlib.Path(__file__).resolve().parents[2]
PANDA = ROOT.parent / "shared" / "robots" / "franka_description" / "urdf" / "panda.urdf"


def quaternion(r):
    """A rotation matrix's unit quaternion (w, x, y, z), w >= 0."""
    w = np.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = np.copysign(np.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return np.array([w, x, y, z])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", help="a folder `ik train` wrote for the Panda's hand (default: train a quick one)")
    ap.add_argument("--out", default="runs/examples/panda_ik.png", help="the figure (default: runs/examples/panda_ik.png)")
    a = ap.parse_args()
    out = pathlib.Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = pathlib.Path(a.model) if a.model else out.parent / "panda_ik_model"
    if not a.model:
        ik_bin = ROOT / "target" / "release" / "ik"
        subprocess.run([str(ik_bin), "train", "--urdf", str(PANDA), "--tip", "panda_hand",
                        "--preset", "quick", "--out", str(model)], check=True, capture_output=True)

    # 1,000 reachable hand poses: the hand's pose at random joints within the limits.
    robot = selfmodel.Robot.from_urdf(str(PANDA), tip="panda_hand")
    limits = robot.limits
    asked = np.random.default_rng(0).uniform(limits[:, 0], limits[:, 1], size=(1000, robot.dof))
    poses = robot.fk(asked)
    targets = np.array([[*p[:3, 3], *quaternion(p[:3, :3])] for p in poses])

    ik = selfmodel.IkSolver.load(model)
    t0 = time.perf_counter()
    answer = ik.solve(targets)
    seconds = time.perf_counter() - t0
    joints, exact = answer["joints"][:, 0], answer["exact"][:, 0]
    errors = answer["pos_err_mm"][:, 0]
    p50, p98, top = np.percentile(errors, 50), np.percentile(errors, 98), errors.max()
    print(f"{len(targets)} Panda hand poses: {exact.mean():.1%} exact (within 1 mm and 0.57 degrees), "
          f"converged to 1e-4 mm: position error median/p98/max {p50:.1e}/{p98:.1e}/{top:.1e} mm, "
          f"{exact.sum() / seconds:.0f} exact solutions/s")

    # The first six poses as asked and as answered, by one camera that frames them all.
    shown = 6
    silhouettes, _ = robot.render(np.vstack([asked[:shown], joints[:shown]]), size=320)
    # One crop for all: the pixels any of them covers, with a margin.
    rows, cols = np.nonzero(silhouettes.max(axis=0))
    m = 6
    silhouettes = silhouettes[:, max(rows.min() - m, 0):rows.max() + m, max(cols.min() - m, 0):cols.max() + m]
    fig, axes = plt.subplots(2, shown + 1, figsize=(2.0 * (shown + 1), 4.4),
                             gridspec_kw={"width_ratios": [1] * shown + [1.4]})
    for i in range(shown):
        for row, label in ((0, "asked"), (1, "answered")):
            ax = axes[row, i]
            ax.imshow(silhouettes[row * shown + i], cmap="Greys")
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_ylabel(f"joints {label}")
        axes[1, i].set_xlabel(f"{errors[i]:.1e} mm", fontsize=8)
    gs = axes[0, shown].get_gridspec()
    for ax in axes[:, shown]:
        ax.remove()
    hist = fig.add_subplot(gs[:, shown])
    hist.hist(np.log10(np.maximum(errors, 1e-9)), bins=30, color="tab:blue")
    hist.axvline(0.0, color="tab:red", lw=1, label="exact: 1 mm")
    hist.axvline(-4.0, color="tab:green", lw=1, label="tolerance: 1e-4 mm")
    hist.legend(fontsize=7, loc="upper left")
    hist.set_xlabel("log10 position error, mm\n(1e-9 and below at -9)", fontsize=8)
    hist.set_title(f"{exact.mean():.1%} exact", fontsize=9)
    fig.suptitle("Learned IK of a Franka Panda from Python: the same hand pose from other joints", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
