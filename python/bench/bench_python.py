"""The Python package's speed against the command line, in one sitting (issue 51's targets).

    target/pyenv/bin/python python/bench/bench_python.py [--out runs/python_bench]

Needs the `ik` and `neurokin` binaries (cargo build --release --bin ik --bin neurokin) and the
Panda (../shared/robots). It trains a quick IK model of the Panda and NeuroKin's short preset
(the paper's architecture, training cut short), then measures, each side in the same sitting:

- `solve` on 10,000 random reachable Panda targets: exact solutions/s from Python against what
  `ik solve` prints for the same model and targets (best of 3 each);
- `solve_one`'s overhead: a Python call's median time minus the solver's own median time on
  the same target, timed inside Rust;
- `predict` at batch 1: images/s from Python (median of 300 calls after 20 warm-up calls)
  against the batch-1 images/s NeuroKin's run measured (its results.csv).

It writes results.csv (figure, python, command_line, ratio or overhead) and prints the table.
"""

import argparse
import csv
import os
import pathlib
import platform
import re
import statistics
import subprocess
import time

import numpy as np

import selfmodel

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = ROOT / "target" / "release"
PANDA = ROOT.parent / "shared" / "robots" / "franka_description" / "urdf" / "panda.urdf"


def cli(*args):
    out = subprocess.run([str(a) for a in args], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"error: {' '.join(map(str, args[:2]))} failed: {out.stderr.strip().splitlines()[-1]}")
    return out.stdout + out.stderr


def cpu_name():
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def revision():
    try:
        return subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "unknown"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/python_bench", help="output folder (default: runs/python_bench, git-ignored)")
    ap.add_argument("--targets", type=int, default=10000, help="Panda targets to solve (default 10,000)")
    a = ap.parse_args()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []

    # Learned IK of the Panda: the command line, then Python, on the same model and targets.
    model = out / "panda_ik"
    if not (model / "model.json").is_file():
        cli(BIN / "ik", "train", "--urdf", PANDA, "--tip", "panda_hand", "--preset", "quick", "--out", model)
    targets = out / "targets.csv"
    cli(BIN / "ik", "targets", "--model", model, "--n", a.targets, "--out", targets)
    cli_rates = []
    for _ in range(3):
        said = cli(BIN / "ik", "solve", "--model", model, "--targets", targets, "--out", out / "answers.csv")
        cli_rates.append(float(re.search(r"([0-9.]+) exact solutions/s", said).group(1)))
    ik = selfmodel.IkSolver.load(model)
    with open(targets, newline="") as f:
        reader = csv.DictReader(f)
        t = np.array([[float(r[c]) for c in ik.target_columns] for r in reader])
    py_rates = []
    for _ in range(3):
        t0 = time.perf_counter()
        answer = ik.solve(t)
        py_rates.append(answer["exact"].sum() / (time.perf_counter() - t0))
    rows.append(("solve: exact solutions/s (10,000 Panda targets)", max(py_rates), max(cli_rates), max(py_rates) / max(cli_rates)))

    # solve_one: what a Python call adds to the solver's own time.
    calls, own = [], []
    for row in t[:200]:
        target = list(row)
        ik.solve_one(target)
        t0 = time.perf_counter()
        ik.solve_one(target)
        calls.append(time.perf_counter() - t0)
        own.append(ik._solve_one_seconds(target, 3))
    call_us, own_us = 1e6 * statistics.median(calls), 1e6 * statistics.median(own)
    rows.append(("solve_one: microseconds a call (Python; the solver's own)", call_us, own_us, call_us - own_us))

    # A self-model at batch 1: Python against the command line's own timing of the same model.
    run = out / "neurokin"
    if not (run / "model" / "model.json").is_file():
        cli(BIN / "neurokin", "--preset", "short", "--out", run)
    with open(run / "results.csv", newline="") as f:
        cli_b1 = float(next(csv.DictReader(f))["infer_b1_img_per_s"])
    sm = selfmodel.SelfModel.load(run)
    q = np.radians(np.random.default_rng(0).uniform(-60, 60, size=(1, sm.inputs)))
    for _ in range(20):
        sm.predict(q)
    times = []
    for _ in range(300):
        t0 = time.perf_counter()
        sm.predict(q)
        times.append(time.perf_counter() - t0)
    py_b1 = 1.0 / statistics.median(times)
    rows.append(("predict: NeuroKin images/s at batch 1", py_b1, cli_b1, py_b1 / cli_b1))

    machine = f"{os.cpu_count()} cores of {cpu_name()}"
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["figure", "python", "command_line", "ratio_or_overhead", "machine", "git_revision"])
        for r in rows:
            w.writerow([r[0], f"{r[1]:.4g}", f"{r[2]:.4g}", f"{r[3]:.4g}", machine, revision()])
    print(f"{'figure':60} {'python':>10} {'command line':>13} {'ratio':>8}")
    for r in rows:
        print(f"{r[0]:60} {r[1]:10.1f} {r[2]:13.1f} {r[3]:8.3f}")
    print(f"({machine}; wrote {out / 'results.csv'})")


if __name__ == "__main__":
    main()
